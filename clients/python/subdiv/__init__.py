"""Python client of the subdivd daemon (python3-requests only) and the `subdiv` batch tool.

    from subdiv import Client
    with Client("http://127.0.0.1:8080").create_session() as s:
        s.put_complex(body)
        s.level(3, format="vtu", out="level3.vtu")

See subdiv.client (the endpoints), subdiv.errors (typed errors with the problem+json),
subdiv.meshes (mesh files -> complex bodies) and subdiv.cli (the command-line tool).
"""
# the daemon's version too (subdivd --version, info.version of api/openapi.json)
__version__ = "1.0.0"

from .client import ROUTES, Client, EventStream, Session
from .errors import (BadRequest, ClientError, Conflict, ContentTooLarge, Gone, MethodNotAllowed,
                     NotFound, NotImplementedByServer, PreconditionFailed, PreconditionRequired,
                     ProblemError, ServerError, ServiceUnavailable, SubdivError, TooManyRequests,
                     TransportError, Unauthorized, Unprocessable, UnsupportedMediaType, error_for)
from .meshes import MeshError

__all__ = ["__version__", "Client", "Session", "EventStream", "ROUTES", "MeshError",
           "SubdivError", "TransportError", "ProblemError", "ClientError", "ServerError",
           "BadRequest", "Unauthorized", "NotFound", "MethodNotAllowed", "Conflict", "Gone",
           "PreconditionFailed", "ContentTooLarge", "UnsupportedMediaType", "Unprocessable",
           "PreconditionRequired", "TooManyRequests", "NotImplementedByServer",
           "ServiceUnavailable", "error_for"]
