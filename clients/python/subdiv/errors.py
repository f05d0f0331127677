"""Typed errors of the subdivd client.

Every refusal of the daemon is an `application/problem+json` body (RFC 9457, docs/SERVICE.md
"Errors"); the client raises the ProblemError subclass of its status, carrying the whole problem:
`status`, `type` (e.g. "/errors/invalid-surface"), `slug` ("invalid-surface"), `title`, `detail`,
`errors` (a list of {"pointer", "message"}), and for 413 `limit_name`, `limit`, `requested`.
Answers that are not problem+json (libmicrohttpd's own HTML 400/414 pages, a proxy's 502) are
mapped the same way with a synthetic problem. Connection failures and timeouts are TransportError.
"""


class SubdivError(Exception):
    """Base class of everything this client raises."""

    exit_code = 3


class TransportError(SubdivError):
    """The daemon could not be reached, or the connection broke."""


class ProblemError(SubdivError):
    """The daemon answered with an error status. `problem` is the problem+json as a dict."""

    status = None

    def __init__(self, problem, response=None):
        self.problem = dict(problem)
        self.response = response
        self.status = self.problem.get("status", self.status)
        super().__init__(self.summary())

    type = property(lambda self: self.problem.get("type", ""))
    slug = property(lambda self: self.type.rsplit("/", 1)[-1])
    title = property(lambda self: self.problem.get("title", ""))
    detail = property(lambda self: self.problem.get("detail", ""))
    errors = property(lambda self: list(self.problem.get("errors", [])))
    pointer = property(lambda self: (self.errors[0].get("pointer") if self.errors else None))
    limit_name = property(lambda self: self.problem.get("limit_name"))
    limit = property(lambda self: self.problem.get("limit"))
    requested = property(lambda self: self.problem.get("requested"))

    @property
    def retry_after(self):
        h = self.response.headers.get("Retry-After") if self.response is not None else None
        return int(h) if h and h.isdigit() else None

    def summary(self):
        s = f"{self.status} {self.slug or self.title}: {self.detail}"
        for e in self.errors[1:] if self.errors and self.errors[0].get("message") == self.detail else self.errors:
            s += f"\n  {e.get('pointer') or '(request)'}: {e.get('message')}"
        return s


class ClientError(ProblemError):
    """A 4xx not listed below."""

    exit_code = 1


class BadRequest(ClientError):
    status = 400


class Unauthorized(ClientError):
    status = 401
    exit_code = 3


class NotFound(ClientError):
    status = 404
    exit_code = 3


class MethodNotAllowed(ClientError):
    status = 405
    exit_code = 3


class Conflict(ClientError):
    status = 409


class Gone(ClientError):
    """410: a delta is not available (a change since that version was not an edit, the level is
    not computed, ...): fetch the level again."""

    status = 410


class PreconditionFailed(ClientError):
    """412: If-Match named a version the session has moved on from."""

    status = 412


class ContentTooLarge(ClientError):
    """413: a limit; `limit_name`, `limit` and `requested` say which and by how much."""

    status = 413


class UnsupportedMediaType(ClientError):
    status = 415


class Unprocessable(ClientError):
    """422: well-formed but invalid (a mesh, a tag, a fill surface...); see `errors`."""

    status = 422


class PreconditionRequired(ClientError):
    """428: an edit without If-Match."""

    status = 428


class TooManyRequests(ClientError):
    """429: busy or too many sessions; `retry_after` seconds."""

    status = 429
    exit_code = 3


class ServerError(ProblemError):
    """A 5xx not listed below."""

    status = 500
    exit_code = 3


class NotImplementedByServer(ServerError):
    """501: a valid option this daemon does not implement."""

    status = 501
    exit_code = 4


class ServiceUnavailable(ServerError):
    """503: starting, stopping or out of memory; `retry_after` seconds."""

    status = 503


BY_STATUS = {c.status: c for c in (BadRequest, Unauthorized, NotFound, MethodNotAllowed, Conflict,
                                   Gone, PreconditionFailed, ContentTooLarge, UnsupportedMediaType,
                                   Unprocessable, PreconditionRequired, TooManyRequests,
                                   ServerError, NotImplementedByServer, ServiceUnavailable)}


def error_for(response):
    """The ProblemError for an error response (of the requests library)."""
    status = response.status_code
    ctype = response.headers.get("Content-Type", "")
    problem = None
    if ctype.startswith("application/problem+json") or ctype.startswith("application/json"):
        try:
            problem = response.json()
        except ValueError:
            problem = None
    if not isinstance(problem, dict):
        text = response.text.strip() if response.content else ""
        problem = {"type": "about:blank", "title": response.reason or "", "status": status,
                   "detail": text[:300] or (response.reason or f"HTTP {status}")}
    problem.setdefault("status", status)
    cls = BY_STATUS.get(status) or (ClientError if 400 <= status < 500 else ServerError)
    return cls(problem, response)
