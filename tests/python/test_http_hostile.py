"""A catalogue of malformed and hostile requests against the real daemon (docs/API.md "Errors",
docs/SERVICE.md "Errors").

One table drives one parametrized test. Each entry is a request — sent with requests, or as raw
bytes over a socket for what requests cannot send (invalid UTF-8, chunked uploads, bad
Content-Length values, unusual methods and paths) — and the exact status it must get: a
problem+json body whose `status` equals the HTTP status, the JSON pointer of the offending field
where there is one (`errors[0].pointer`), and `limit_name`/`limit`/`requested` for 413. After
every entry the daemon must be alive and answer /healthz, the sessions the request was aimed at
must keep their version, and a bystander session (a posted complex with computed levels) must be
byte-for-byte as before. The limit entries run on a second daemon with small limits.

Placeholders in paths and headers: {s} the victim session's path (a complex is posted), {e} a
session without a complex, {d} a deleted session, {tok}/{btok}/{dtok} the victim's, the
bystander's and the deleted session's tokens. A request to {s}/{e}/{d} carries that session's
token unless the entry says otherwise."""
import copy
import json
import re
import socket
import time
from typing import Callable, NamedTuple, Optional

import pytest
import requests
from requests.structures import CaseInsensitiveDict

from conftest import REPO
from daemon import Daemon, Session

MIXED = json.loads((REPO / "examples" / "mixed.json").read_text())
# The victim: the mixed example (a tet, a fin triangle, two curve segments, a point) with a second
# attribute. 8 vertices; simplices [0,1,2,3], [1,2,4], [3,5], [5,6], [7].
VICTIM = copy.deepcopy(MIXED)
VICTIM["attributes"]["temp"] = [20, 30, 25, 25, 90, 10, 11, 12]

SMALL_FLAGS = ("--max-cells", "1000", "--max-vertices", "50", "--max-body-bytes", "20000",
               "--max-sessions", "3", "--max-simplices", "100")
MAIN_FLAGS = ("--max-session-bytes", str(4 << 20), "--max-sessions", "100")
JSON_CT = {"Content-Type": "application/json"}


def V(edit=None, **fields):
    """A copy of the victim's complex with `fields` replaced and `edit(body)` applied."""
    b = copy.deepcopy(VICTIM)
    b.update(copy.deepcopy(fields))
    if edit:
        edit(b)
    return b


def setp(path, value):
    """An edit setting body[path[0]][path[1]]... = value."""
    def f(b):
        x = b
        for k in path[:-1]:
            x = x[k]
        x[path[-1]] = value
    return f


# ---- raw HTTP --------------------------------------------------------------------------------

class Resp(NamedTuple):
    status: int
    headers: CaseInsensitiveDict
    body: bytes


def raw_http(url, data, timeout=10):
    """Send `data` on a fresh connection and read the answer until the server closes it."""
    host, port = url.rsplit("/", 1)[-1].split(":")
    buf = b""
    with socket.create_connection((host, int(port)), timeout=timeout) as c:
        try:
            c.sendall(data)
        except (BrokenPipeError, ConnectionResetError):
            pass   # refused before the whole body was sent: the answer may still be there
        while True:
            try:
                chunk = c.recv(65536)
            except ConnectionResetError:
                break
            if not chunk:
                break
            buf += chunk
    head, _, body = buf.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    assert lines[0].startswith("HTTP/1."), f"no HTTP answer: {buf[:200]!r}"
    headers = CaseInsensitiveDict()
    for line in lines[1:]:
        k, _, v = line.partition(":")
        headers[k.strip()] = v.strip()
    if "Content-Length" in headers:
        body = body[:int(headers["Content-Length"])]
    return Resp(int(lines[0].split()[1]), headers, body)


def chunked(body, size=4096):
    out = b""
    for i in range(0, len(body), size):
        part = body[i:i + size]
        out += b"%x\r\n" % len(part) + part + b"\r\n"
    return out + b"0\r\n\r\n"


def R(method, path, body=b"", *headers, auth=True, length="auto"):
    """A raw request builder: `headers` are "Name: value" lines (placeholders allowed); a
    Content-Length is added for a non-empty body unless `length` says otherwise (None: none, a
    string: that value) or a Transfer-Encoding is given."""
    def build(ctx):
        p = path.format(**ctx)
        lines = [f"{method} {p} HTTP/1.1", "Host: 127.0.0.1", "Connection: close"]
        tok = ctx["token_for"](path) if auth else None
        if tok:
            lines.append(f"Authorization: Bearer {tok}")
        lines += [h.format(**ctx) for h in headers]
        te = any(h.lower().startswith("transfer-encoding") for h in headers)
        if length == "auto" and body and not te:
            lines.append(f"Content-Length: {len(body)}")
        elif length not in ("auto", None):
            lines.append(f"Content-Length: {length}")
        return ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1") + body
    return build


# ---- the catalogue ---------------------------------------------------------------------------

class C(NamedTuple):
    id: str
    method: str
    path: str
    status: int
    pointer: Optional[str] = None      # expected errors[0].pointer (None: not checked)
    body: object = None                # dict/list -> JSON, bytes -> as is (Content-Type JSON)
    headers: Optional[dict] = None     # extra headers (None value: drop the header)
    raw: Optional[Callable] = None     # R(...): sent over a socket instead
    on: str = "main"                   # "main" or "small" (the daemon with small limits)
    limit: Optional[tuple] = None      # (limit_name, limit, requested or None for "> limit")
    allow: Optional[str] = None        # expected Allow header (405)
    auth: bool = True                  # send the session's token
    problem: bool = True               # the answer is our problem+json (False: MHD's own page)


N30 = [[i, (i * i) % 7, i % 3] for i in range(51)]
DEEP20 = b'{"vertices": ' + b"[" * 20 + b"0" + b"]" * 20 + b', "simplices": [[0]]}'
DEEP5000 = b'{"vertices": ' + b"[" * 5000 + b"]" * 5000 + b"}"
VICTIM_BYTES = json.dumps(VICTIM).encode()

CASES = [
    # --- malformed JSON (400, no field) ---
    C("json-truncated", "PUT", "{s}/complex", 400, body=VICTIM_BYTES[:-7]),
    C("json-trailing-garbage", "PUT", "{s}/complex", 400, body=VICTIM_BYTES + b" x"),
    C("json-two-documents", "PUT", "{s}/complex", 400, body=VICTIM_BYTES + b"{}"),
    C("json-NaN", "PUT", "{s}/complex", 400, body=VICTIM_BYTES.replace(b"[3, 3, 3]", b"[NaN, 3, 3]")),
    C("json-Infinity", "PUT", "{s}/complex", 400, body=VICTIM_BYTES.replace(b"[3, 3, 3]", b"[Infinity, 3, 3]")),
    C("json-minus-Infinity", "PUT", "{s}/complex", 400, body=VICTIM_BYTES.replace(b"[3, 3, 3]", b"[3, -Infinity, 3]")),
    C("json-1e999", "PUT", "{s}/complex", 400, body=VICTIM_BYTES.replace(b"[3, 3, 3]", b"[3, 3, 1e999]")),
    C("json-int-beyond-int64", "PUT", "{s}/complex", 400, body=VICTIM_BYTES.replace(b"[7]", b"[99999999999999999999999]")),
    C("json-int-2**63", "PUT", "{s}/complex", 400, body=VICTIM_BYTES.replace(b"[7]", b"[9223372036854775808]")),
    C("json-duplicate-key", "PUT", "{s}/complex", 400, body=b'{"vertices": [[0,0,0]], "simplices": [[0]], "vertices": [[1,1,1]]}'),
    C("json-duplicate-nested-key", "PUT", "{s}/complex", 400,
      body=b'{"vertices": [[0,0,0]], "simplices": [[0]], "attributes": {"t": [1], "t": [2]}}'),
    C("json-top-level-array", "PUT", "{s}/complex", 400, "", body=b"[[0,0,0]]"),
    C("json-top-level-string", "PUT", "{s}/complex", 400, body=b'"vertices"'),
    C("json-top-level-number", "PUT", "{s}/complex", 400, body=b"42"),
    C("json-top-level-null", "PUT", "{s}/complex", 400, body=b"null"),
    C("json-nesting-21", "PUT", "{s}/complex", 400, body=DEEP20),
    C("json-nesting-5000", "PUT", "{s}/complex", 400, body=DEEP5000),
    C("json-nesting-5000-top", "PUT", "{s}/complex", 400, body=b"[" * 5000 + b"]" * 5000),
    C("json-invalid-utf8", "PUT", "{s}/complex", 400,
      raw=R("PUT", "{s}/complex", b'{"vertices": [[0,0,0]], "simplices": [[0]], "attributes": {"\xff\xfe": [1]}}',
            "Content-Type: application/json")),
    C("json-overlong-utf8", "PUT", "{s}/complex", 400,
      raw=R("PUT", "{s}/complex", b'{"vertices": "\xc0\xaf"}', "Content-Type: application/json")),
    C("json-lone-surrogate", "PUT", "{s}/complex", 400, body=b'{"vertices": [[0,0,0]], "simplices": [[0]], "attributes": {"\\ud800": [1]}}'),
    C("json-nul-in-string", "PUT", "{s}/complex", 400, body=b'{"vertices": [[0,0,0]], "simplices": [[0]], "attributes": {"a\\u0000b": [1]}}'),
    C("json-nul-in-key", "PUT", "{s}/complex", 400, body=b'{"vertices\\u0000": [[0,0,0]], "simplices": [[0]]}'),
    C("json-utf8-bom", "PUT", "{s}/complex", 400, body=b"\xef\xbb\xbf" + VICTIM_BYTES),
    C("body-empty-put", "PUT", "{s}/complex", 400, body=b""),
    C("body-whitespace-put", "PUT", "{s}/complex", 400, body=b" \r\n\t "),
    C("body-empty-object", "PUT", "{s}/complex", 400, "/vertices", body={}),
    C("body-missing-no-length", "PUT", "{s}/complex", 400, raw=R("PUT", "{s}/complex", b"", "Content-Type: application/json")),
    # --- wrong types (400 at the field) ---
    C("vertices-object", "PUT", "{s}/complex", 400, "/vertices", body=V(vertices={"0": [0, 0, 0]})),
    C("vertices-string", "PUT", "{s}/complex", 400, "/vertices", body=V(vertices="0 0 0")),
    C("vertices-missing", "PUT", "{s}/complex", 400, "/vertices", body={"simplices": [[0]]}),
    C("vertex-2-coords", "PUT", "{s}/complex", 400, "/vertices/1", body=V(setp(["vertices", 1], [1, 0]))),
    C("vertex-4-coords", "PUT", "{s}/complex", 400, "/vertices/6", body=V(setp(["vertices", 6], [0.5, 0, 3, 1]))),
    C("vertex-number", "PUT", "{s}/complex", 400, "/vertices/2", body=V(setp(["vertices", 2], 5))),
    C("coord-string", "PUT", "{s}/complex", 400, "/vertices/1/0", body=V(setp(["vertices", 1, 0], "1"))),
    C("coord-bool", "PUT", "{s}/complex", 400, "/vertices/4/2", body=V(setp(["vertices", 4, 2], True))),
    C("coord-null", "PUT", "{s}/complex", 400, "/vertices/0/1", body=V(setp(["vertices", 0, 1], None))),
    C("index-float-1.0", "PUT", "{s}/complex", 400, "/simplices/0/3", body=V(setp(["simplices", 0, 3], 3.0))),
    C("index-string", "PUT", "{s}/complex", 400, "/simplices/2/0", body=V(setp(["simplices", 2, 0], "3"))),
    C("index-bool", "PUT", "{s}/complex", 400, "/simplices/4/0", body=V(setp(["simplices", 4, 0], True))),
    C("simplex-number", "PUT", "{s}/complex", 400, "/simplices/4", body=V(setp(["simplices", 4], 7))),
    C("simplex-object", "PUT", "{s}/complex", 400, "/simplices/2", body=V(setp(["simplices", 2], {"a": 3}))),
    C("simplices-missing", "PUT", "{s}/complex", 400, "/simplices", body={"vertices": VICTIM["vertices"]}),
    C("simplices-null", "PUT", "{s}/complex", 400, "/simplices", body=V(simplices=None)),
    C("attributes-array", "PUT", "{s}/complex", 400, "/attributes", body=V(attributes=[1, 2])),
    C("attribute-number", "PUT", "{s}/complex", 400, "/attributes/temp", body=V(attributes={"temp": 5})),
    C("attribute-mixed-scalar-vector", "PUT", "{s}/complex", 400, "/attributes/temp/3", body=V(setp(["attributes", "temp", 3], [25]))),
    C("attribute-mixed-vector-scalar", "PUT", "{s}/complex", 400, "/attributes/vel/5",
      body=V(attributes={"vel": [[1, 0, 0]] * 5 + [1] + [[1, 0, 0]] * 2})),
    C("attribute-vector-length", "PUT", "{s}/complex", 400, "/attributes/vel/2",
      body=V(attributes={"vel": [[1, 0, 0], [1, 0, 0], [1, 0]] + [[1, 0, 0]] * 5})),
    C("attribute-component-string", "PUT", "{s}/complex", 400, "/attributes/vel/1/2",
      body=V(attributes={"vel": [[1, 0, 0], [1, 0, "x"]] + [[1, 0, 0]] * 6})),
    C("attribute-value-null", "PUT", "{s}/complex", 400, "/attributes/temp/0", body=V(setp(["attributes", "temp", 0], None))),
    # --- semantic mesh errors (422 at the field) ---
    C("index-out-of-range", "PUT", "{s}/complex", 422, "/simplices/3/2", body=V(setp(["simplices", 3], [5, 6, 17]))),
    C("index-negative", "PUT", "{s}/complex", 422, "/simplices/3/1", body=V(setp(["simplices", 3, 1], -1))),
    C("index-2**32", "PUT", "{s}/complex", 422, "/simplices/1/0", body=V(setp(["simplices", 1, 0], 2 ** 32))),
    C("index-int64-max", "PUT", "{s}/complex", 422, "/simplices/4/0", body=V(setp(["simplices", 4, 0], 2 ** 63 - 1))),
    C("repeated-vertex", "PUT", "{s}/complex", 422, "/simplices/1/2", body=V(setp(["simplices", 1], [1, 2, 2]))),
    C("duplicate-simplex", "PUT", "{s}/complex", 422, "/simplices/5", body=V(simplices=VICTIM["simplices"] + [[2, 4, 1]])),
    C("duplicate-point", "PUT", "{s}/complex", 422, "/simplices/5", body=V(simplices=VICTIM["simplices"] + [[7]])),
    C("five-vertex-simplex", "PUT", "{s}/complex", 422, "/simplices/0", body=V(setp(["simplices", 0], [0, 1, 2, 3, 4]))),
    C("empty-simplex", "PUT", "{s}/complex", 422, "/simplices/4", body=V(setp(["simplices", 4], []))),
    C("degenerate-edge-coincident", "PUT", "{s}/complex", 422, "/simplices/3", body=V(setp(["vertices", 6], [0, 0, 2]))),
    C("degenerate-triangle-collinear", "PUT", "{s}/complex", 422, "/simplices/1", body=V(setp(["vertices", 4], [-1, 2, 0]))),
    C("degenerate-tet-coplanar", "PUT", "{s}/complex", 422, "/simplices/0", body=V(setp(["vertices", 3], [0.3, 0.3, 0]))),
    C("coordinate-1e300", "PUT", "{s}/complex", 422, "/vertices/7/1", body=V(setp(["vertices", 7, 1], 1e300))),
    C("coordinate-minus-1e200", "PUT", "{s}/complex", 422, "/vertices/2/2", body=V(setp(["vertices", 2, 2], -1e200))),
    C("no-vertices", "PUT", "{s}/complex", 422, "/vertices", body={"vertices": [], "simplices": []}),
    C("no-simplices", "PUT", "{s}/complex", 422, "/simplices", body=V(simplices=[])),
    C("no-vertices-index", "PUT", "{s}/complex", 422, "/simplices/0/0", body={"vertices": [], "simplices": [[0]]}),
    C("attribute-wrong-length", "PUT", "{s}/complex", 422, "/attributes/temp", body=V(setp(["attributes", "temp"], [1] * 7))),
    C("attribute-name-slash", "PUT", "{s}/complex", 422, "/attributes/a~1b", body=V(attributes={"a/b": [0] * 8})),
    C("attribute-name-tilde", "PUT", "{s}/complex", 422, "/attributes/a~0b", body=V(attributes={"a~b": [0] * 8})),
    C("attribute-name-empty", "PUT", "{s}/complex", 422, "/attributes/", body=V(attributes={"": [0] * 8})),
    C("attribute-17-components", "PUT", "{s}/complex", 422, "/attributes/vel/0", body=V(attributes={"vel": [[0] * 17] * 8})),
    C("attribute-empty-vectors", "PUT", "{s}/complex", 422, "/attributes/vel/0", body=V(attributes={"vel": [[]] * 8})),
    C("attributes-17", "PUT", "{s}/complex", 422, "/attributes", body=V(attributes={f"a{i}": [0] * 8 for i in range(17)})),
    # --- unknown fields ---
    C("unknown-top-field", "PUT", "{s}/complex", 400, "/colour", body=V(colour="red")),
    C("unknown-field-case", "PUT", "{s}/complex", 400, "/Vertices", body=V(Vertices=[])),
    C("rules-unknown-field", "PUT", "{s}/rules", 400, "/smoothness", body={"smoothness": 2}),
    C("rules-override-unknown-field", "PUT", "{s}/rules", 400, "/overrides/0/weight",
      body={"overrides": [{"simplex": [1], "rule": "G1", "weight": 2}]}),
    C("tags-unknown-field", "PUT", "{s}/tags", 400, "/creases", body={"singular": [], "creases": []}),
    C("session-unknown-field", "POST", "/v1/sessions", 400, "/ttl", body={"ttl": 5}),
    # --- sessions ---
    C("ttl-string", "POST", "/v1/sessions", 400, "/ttl_s", body={"ttl_s": "60"}),
    C("ttl-float", "POST", "/v1/sessions", 400, "/ttl_s", body={"ttl_s": 60.0}),
    C("ttl-zero", "POST", "/v1/sessions", 422, "/ttl_s", body={"ttl_s": 0}),
    C("ttl-negative", "POST", "/v1/sessions", 422, "/ttl_s", body={"ttl_s": -60}),
    C("ttl-huge", "POST", "/v1/sessions", 422, "/ttl_s", body={"ttl_s": 10 ** 12}),
    C("ttl-beyond-int64", "POST", "/v1/sessions", 400, body=b'{"ttl_s": 99999999999999999999}'),
    C("session-body-array", "POST", "/v1/sessions", 400, "", body=[]),
    # --- rules: enumerations, unsupported choices ---
    C("solid-scheme-cubic", "PUT", "{s}/rules", 422, "/solid_scheme", body={"solid_scheme": "cubic"}),
    C("solid-scheme-uppercase", "PUT", "{s}/rules", 422, "/solid_scheme", body={"solid_scheme": "BOX"}),
    C("solid-scheme-null", "PUT", "{s}/rules", 400, "/solid_scheme", body={"solid_scheme": None}),
    C("surface-weights-3", "PUT", "{s}/rules", 400, "/surface_weights", body={"surface_weights": 3}),
    C("nonmanifold-default-N1", "PUT", "{s}/rules", 422, "/nonmanifold_default", body={"nonmanifold_default": "N1"}),
    C("nonmanifold-default-N2", "PUT", "{s}/rules", 422, "/nonmanifold_default", body={"nonmanifold_default": "N2"}),
    C("nonmanifold-default-G3", "PUT", "{s}/rules", 422, "/nonmanifold_default", body={"nonmanifold_default": "G3"}),
    C("nonmanifold-surface-unknown", "PUT", "{s}/rules", 422, "/nonmanifold_surface", body={"nonmanifold_surface": "loop"}),
    C("overrides-object", "PUT", "{s}/rules", 400, "/overrides", body={"overrides": {"simplex": [1]}}),
    C("override-number", "PUT", "{s}/rules", 400, "/overrides/0", body={"overrides": [3]}),
    C("rules-body-array", "PUT", "{s}/rules", 400, "", body=[{"solid_scheme": "box"}]),
    # --- fill (TetGen): the surface is checked before TetGen runs; TetGen's findings are 422 ---
    C("fill-one-triangle", "PUT", "{s}/complex", 422, "/fill/0/surface", body=V(fill=[{"surface": [[0, 1, 2]], "max_volume": 0.01}])),
    C("fill-not-array", "PUT", "{s}/complex", 400, "/fill", body=V(fill={"surface": []})),
    C("fill-entry-number", "PUT", "{s}/complex", 400, "/fill/0", body=V(fill=[7])),
    C("fill-unknown-key", "PUT", "{s}/complex", 400, "/fill/0/quality", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], "quality": 2}])),
    C("fill-surface-missing", "PUT", "{s}/complex", 400, "/fill/0/surface", body=V(fill=[{"max_volume": 1}])),
    C("fill-index-out-of-range", "PUT", "{s}/complex", 422, "/fill/0/surface/3/2", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 8]]}])),
    C("fill-index-float", "PUT", "{s}/complex", 400, "/fill/0/surface/1/0", body=V(fill=[{"surface": [[0, 2, 1], [0.0, 1, 3], [0, 3, 2], [1, 2, 3]]}])),
    C("fill-repeated-index", "PUT", "{s}/complex", 422, "/fill/0/surface/2/2", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 0], [1, 2, 3]]}])),
    C("fill-open", "PUT", "{s}/complex", 422, "/fill/0/surface/1", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 4]]}])),
    C("fill-max-volume-negative", "PUT", "{s}/complex", 422, "/fill/0/max_volume", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], "max_volume": -1}])),
    C("fill-max-volume-string", "PUT", "{s}/complex", 400, "/fill/0/max_volume", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], "max_volume": "small"}])),
    C("fill-min-ratio-0.5", "PUT", "{s}/complex", 422, "/fill/0/min_ratio", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], "min_ratio": 0.5}])),
    C("fill-too-many-tets", "PUT", "{s}/complex", 413, "/fill/0/max_volume", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], "max_volume": 1e-12}])),
    C("fill-17-entries", "PUT", "{s}/complex", 422, "/fill", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]}] * 17)),
    C("fill-duplicates-posted-tet", "PUT", "{s}/complex", 422, "/fill/0", body=V(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]}])),
    C("override-on-manifold-vertex", "PUT", "{s}/rules", 422, "/overrides/0/simplex", body={"overrides": [{"simplex": [0], "rule": "G1"}]}),
    C("override-on-triangle", "PUT", "{s}/rules", 422, "/overrides/0/simplex", body={"overrides": [{"simplex": [0, 1, 2], "rule": "G1"}]}),
    C("override-vertex-out-of-range", "PUT", "{s}/rules", 422, "/overrides/0/simplex/0", body={"overrides": [{"simplex": [99], "rule": "G1"}]}),
    C("override-N1-without-dimension", "PUT", "{s}/rules", 400, "/overrides/0/dimension", body={"overrides": [{"simplex": [1], "rule": "N1"}]}),
    C("override-pair-on-G1", "PUT", "{s}/rules", 422, "/overrides/0/pair", body={"overrides": [{"simplex": [1], "rule": "G1", "pair": [[0, 1], [1, 2]]}]}),
    C("tags-not-an-edge", "PUT", "{s}/tags", 422, "/singular/1", body={"singular": [[3], [0, 4]]}),
    C("tags-not-a-triangle", "PUT", "{s}/tags", 422, "/singular/0", body={"singular": [[0, 1, 4]]}),
    # --- tags ---
    C("tags-arity-4", "PUT", "{s}/tags", 422, "/singular/0", body={"singular": [[0, 1, 2, 3]]}),
    C("tags-arity-0", "PUT", "{s}/tags", 422, "/singular/1", body={"singular": [[0], []]}),
    C("tags-index-out-of-range", "PUT", "{s}/tags", 422, "/singular/1/1", body={"singular": [[0], [1, 8]]}),
    C("tags-index-negative", "PUT", "{s}/tags", 422, "/singular/0/0", body={"singular": [[-1]]}),
    C("tags-index-float", "PUT", "{s}/tags", 400, "/singular/0/0", body={"singular": [[1.0]]}),
    C("tags-tag-number", "PUT", "{s}/tags", 400, "/singular/0", body={"singular": [3]}),
    C("tags-not-array", "PUT", "{s}/tags", 400, "/singular", body={"singular": {"0": [1]}}),
    C("tags-missing", "PUT", "{s}/tags", 400, "/singular", body={}),
    # --- state conflicts (409) ---
    C("tags-before-complex", "PUT", "{e}/tags", 409, "/singular", body={"singular": [[0]]}),
    C("overrides-before-complex", "PUT", "{e}/rules", 409, "/overrides", body={"overrides": [{"simplex": [0], "rule": "G1"}]}),
    C("complex-before-complex", "GET", "{e}/complex", 409),
    C("level-before-complex", "GET", "{e}/levels/0", 409),
    C("stats-before-complex", "GET", "{e}/levels/1/stats", 409),
    # --- levels ---
    C("level-letters", "GET", "{s}/levels/abc", 400),
    C("level-negative", "GET", "{s}/levels/-1", 400),
    C("level-fraction", "GET", "{s}/levels/1.5", 400),
    C("level-plus", "GET", "{s}/levels/+1", 400),
    C("level-exponent", "GET", "{s}/levels/1e1", 400),
    C("level-13", "GET", "{s}/levels/13", 422),
    C("level-beyond-int64", "GET", "{s}/levels/99999999999999999999", 422),
    C("stats-level-13", "GET", "{s}/levels/13/stats", 422),
    C("stats-level-letters", "GET", "{s}/levels/x/stats", 400),
    C("level-unknown-parameter", "GET", "{s}/levels/1?colour=red", 400, "colour"),
    C("stats-any-parameter", "GET", "{s}/levels/1/stats?format=json", 400, "format"),
    C("level-bad-format", "GET", "{s}/levels/1?format=obj", 422, "format"),
    C("level-bad-parts", "GET", "{s}/levels/1?parts=volumes", 422, "parts"),
    C("level-empty-parts", "GET", "{s}/levels/1?parts=", 422, "parts"),
    C("level-slice-3-numbers", "GET", "{s}/levels/1?slice=1,2,3", 422, "slice"),
    C("level-slice-5-numbers", "GET", "{s}/levels/1?slice=1,2,3,4,5", 422, "slice"),
    C("level-slice-zero-normal", "GET", "{s}/levels/1?slice=0,0,0,1", 422, "slice"),
    C("level-slice-nan", "GET", "{s}/levels/1?slice=nan,0,1,0", 422, "slice"),
    C("level-slice-overflow", "GET", "{s}/levels/1?slice=1,0,0,1e999", 422, "slice"),
    C("level-colormap-min-above-max", "GET", "{s}/levels/1?colormap=temp:90:10", 422, "colormap"),
    C("level-colormap-no-range", "GET", "{s}/levels/1?colormap=temp", 422, "colormap"),
    C("level-colormap-unknown", "GET", "{s}/levels/1?colormap=pressure:0:1", 422, "colormap"),
    C("level-unknown-attribute", "GET", "{s}/levels/1?attributes=temp,pressure", 422, "attributes"),
    C("level-bad-octahedra", "GET", "{s}/levels/1?octahedra=cubes", 422, "octahedra"),
    C("level-over-session-bytes", "GET", "{s}/levels/7/stats", 413, limit=("max_session_bytes", 4 << 20, None)),
    # --- limits (the small daemon) ---
    C("limit-cells-level", "GET", "{s}/levels/5", 413, on="small", limit=("max_cells", 1000, None)),
    C("limit-cells-stats", "GET", "{s}/levels/5/stats", 413, on="small", limit=("max_cells", 1000, None)),
    C("limit-vertices", "PUT", "{s}/complex", 413, on="small", limit=("max_vertices", 50, 51),
      body={"vertices": N30, "simplices": [[0]]}),
    C("limit-simplices", "PUT", "{s}/complex", 413, on="small", limit=("max_simplices", 100, 101),
      body={"vertices": N30[:50], "simplices": [[i % 50, (i + 1) % 50] for i in range(101)]}),
    C("limit-body-content-length", "PUT", "{s}/complex", 413, on="small", limit=("max_body_bytes", 20000, 30000),
      body=b" " * 29998 + b"{}"),
    C("limit-body-announced-terabyte", "PUT", "{s}/complex", 413, on="small", limit=("max_body_bytes", 20000, 10 ** 12),
      raw=R("PUT", "{s}/complex", b"", "Content-Type: application/json", length=str(10 ** 12))),
    C("limit-body-chunked", "PUT", "{s}/complex", 413, on="small", limit=("max_body_bytes", 20000, 20001),
      raw=R("PUT", "{s}/complex", chunked(b" " * 25000 + b"{}"), "Content-Type: application/json",
            "Transfer-Encoding: chunked")),
    # the token is checked before anything else about the request: no limits leak to strangers
    C("auth-before-body-limit", "PUT", "{s}/complex", 401, on="small", auth=False,
      body=b" " * 29998 + b"{}"),
    # --- media types and bodies ---
    C("content-type-text-plain", "PUT", "{s}/complex", 415, body=VICTIM_BYTES, headers={"Content-Type": "text/plain"}),
    C("content-type-missing", "PUT", "{s}/complex", 415, body=VICTIM_BYTES, headers={"Content-Type": None}),
    C("content-type-jsonx", "PUT", "{s}/complex", 415, body=VICTIM_BYTES, headers={"Content-Type": "application/jsonx"}),
    C("content-type-form", "PUT", "{s}/rules", 415, body=b"solid_scheme=box",
      headers={"Content-Type": "application/x-www-form-urlencoded"}),
    C("content-type-session-text", "POST", "/v1/sessions", 415, body=b"{}", headers={"Content-Type": "text/plain"}),
    C("body-on-get", "GET", "{s}/complex", 400, body=b'{"a": 1}'),
    C("body-on-delete", "DELETE", "{s}", 400, body=b'{"a": 1}'),
    C("body-on-healthz-chunked", "GET", "/healthz", 400,
      raw=R("GET", "/healthz", chunked(b'{"a": 1}'), "Transfer-Encoding: chunked")),
    C("content-length-negative", "PUT", "{s}/complex", 400, problem=False,
      raw=R("PUT", "{s}/complex", b"{}", "Content-Type: application/json", length="-1")),
    C("content-length-letters", "PUT", "{s}/complex", 400, problem=False,
      raw=R("PUT", "{s}/complex", b"{}", "Content-Type: application/json", length="abc")),
    C("transfer-encoding-gzip", "PUT", "{s}/complex", 501,
      raw=R("PUT", "{s}/complex", b"{}", "Content-Type: application/json", "Transfer-Encoding: gzip")),
    # --- authentication (401 + WWW-Authenticate) ---
    C("auth-missing", "GET", "{s}/complex", 401, auth=False),
    C("auth-wrong-token", "GET", "{s}/complex", 401, headers={"Authorization": "Bearer AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA"}),
    C("auth-other-sessions-token", "GET", "{s}/complex", 401, headers={"Authorization": "Bearer {btok}"}),
    C("auth-deleted-sessions-token", "GET", "{s}", 401, headers={"Authorization": "Bearer {dtok}"}),
    C("auth-basic-scheme", "GET", "{s}", 401, headers={"Authorization": "Basic {tok}"}),
    C("auth-no-scheme", "GET", "{s}", 401, headers={"Authorization": "{tok}"}),
    C("auth-scheme-only", "GET", "{s}", 401, headers={"Authorization": "Bearer"}),
    C("auth-trailing-junk", "GET", "{s}", 401, headers={"Authorization": "Bearer {tok} junk"}),
    C("auth-token-plus-char", "GET", "{s}", 401, headers={"Authorization": "Bearer {tok}x"}),
    C("auth-token-truncated", "GET", "{s}", 401, headers={"Authorization": "Bearer {tok_cut}"}),
    C("auth-wrong-token-bad-body", "PUT", "{s}/complex", 401, body=b"{oops", headers={"Authorization": "Bearer {btok}"}),
    C("auth-missing-delete", "DELETE", "{s}", 401, auth=False),
    # --- unknown sessions and paths (404) ---
    C("session-unknown", "GET", "/v1/sessions/00000000000000000000000000000000", 404, headers={"Authorization": "Bearer {tok}"}),
    C("session-unknown-no-token", "GET", "/v1/sessions/00000000000000000000000000000000/complex", 404),
    C("session-id-short", "GET", "/v1/sessions/abc/complex", 404, headers={"Authorization": "Bearer {tok}"}),
    C("session-id-long", "GET", "/v1/sessions/" + "a" * 64, 404),
    C("session-id-uppercase", "GET", "/v1/sessions/{S_upper}", 404, headers={"Authorization": "Bearer {tok}"}),
    C("session-deleted-get", "GET", "{d}/complex", 404),
    C("session-deleted-put", "PUT", "{d}/complex", 404, body=VICTIM),
    C("session-deleted-delete", "DELETE", "{d}", 404),
    C("path-unknown", "GET", "/v1/nothing", 404),
    C("path-unknown-under-session", "GET", "{s}/nothing", 404),
    C("path-trailing-slash", "GET", "{s}/complex/", 404),
    C("path-sessions-slash", "GET", "/v1/sessions/", 404),
    C("path-traversal", "GET", "/../../etc/passwd", 404, raw=R("GET", "/../../etc/passwd")),
    C("path-traversal-under-api", "GET", "/v1/sessions/../../../etc/passwd", 404, raw=R("GET", "/v1/sessions/../../../etc/passwd")),
    C("path-traversal-encoded", "GET", "/%2e%2e/%2e%2e/etc/passwd", 404, raw=R("GET", "/%2e%2e/%2e%2e/etc/passwd")),
    C("path-traversal-static", "GET", "/web/../../../etc/passwd", 404, raw=R("GET", "/web/../../../etc/passwd")),
    C("url-2000-bytes", "GET", "/v1/" + "a" * 2000, 414),
    C("url-100000-bytes", "GET", "/v1/...", 414, problem=False, raw=R("GET", "/v1/" + "a" * 100000)),
    # --- methods (405 + Allow) ---
    C("method-post-complex", "POST", "{s}/complex", 405, body=VICTIM, allow="PUT, GET, HEAD, OPTIONS"),
    C("method-delete-complex", "DELETE", "{s}/complex", 405, allow="PUT, GET, HEAD, OPTIONS"),
    C("method-put-session", "PUT", "{s}", 405, body={}, allow="GET, HEAD, PATCH, DELETE, OPTIONS"),
    C("method-get-sessions", "GET", "/v1/sessions", 405, allow="POST, OPTIONS"),
    C("method-delete-sessions", "DELETE", "/v1/sessions", 405, allow="POST, OPTIONS"),
    C("method-put-level", "PUT", "{s}/levels/1", 405, body={}, allow="GET, HEAD, OPTIONS"),
    C("method-post-stats", "POST", "{s}/levels/1/stats", 405, body={}, allow="GET, HEAD, OPTIONS"),
    C("method-put-healthz", "PUT", "/healthz", 405, body={}, allow="GET, HEAD, OPTIONS"),
    C("method-post-static", "POST", "/", 405, body=b"x", allow="GET, HEAD, OPTIONS"),
    C("method-unknown-verb", "BREW", "/healthz", 405, allow="GET, HEAD, OPTIONS", raw=R("BREW", "/healthz")),
    # --- versions (412) ---
    C("if-match-stale", "PUT", "{s}/complex", 412, body=VICTIM, headers={"If-Match": '"999"'}),
    C("if-match-weak", "PUT", "{s}/rules", 412, body={}, headers={"If-Match": 'W/"{version}"'}),
    C("if-match-unquoted", "PUT", "{s}/rules", 412, body={}, headers={"If-Match": "{version}"}),
]


# ---- fixtures --------------------------------------------------------------------------------

class Env:
    """A daemon, its bystander (with a snapshot), the victim, a session without a complex and
    a deleted session."""

    def __init__(self, flags):
        self.d = Daemon(*flags)
        self.bystander = Session(self.d)
        b = self.bystander
        assert b.put_complex(MIXED).status_code == 200
        assert b.req("PUT", "/rules", json={"solid_scheme": "averaged"}).status_code == 200
        self.snapshot = self.bystander_state()
        assert self.snapshot[0] == 2
        self.victim = Session(self.d)
        assert self.victim.put_complex(VICTIM).status_code == 200
        assert self.victim.level(1, format="json").status_code == 200
        self.victim_complex = self.victim.req("GET", "/complex").content
        deleted = Session(self.d)
        assert deleted.delete().status_code == 204
        self.empty = Session(self.d)
        v, e = self.victim, self.empty
        self.ctx = {"s": v.base[len(self.d.url):], "e": e.base[len(self.d.url):],
                    "d": deleted.base[len(self.d.url):], "tok": v.token, "btok": b.token,
                    "dtok": deleted.token, "tok_cut": v.token[:-1], "S_upper": v.id.upper(),
                    "version": self.version(v)}
        tokens = {"{s}": v.token, "{e}": e.token, "{d}": deleted.token}
        self.ctx["token_for"] = lambda path: next((t for k, t in tokens.items() if path.startswith(k)), None)

    def bystander_state(self):
        b = self.bystander
        return (self.version(b), b.req("GET", "/complex").content,
                b.level(2, format="glb").content, b.level(2, format="json").content,
                b.req("GET", "/levels/2/stats").json()["counts"])

    @staticmethod
    def version(s):
        r = s.req("GET")
        assert r.status_code == 200, r.text
        return r.json()["version"]


@pytest.fixture(scope="module")
def main_env():
    env = Env(MAIN_FLAGS)
    yield env
    assert env.d.stop() == 0, "\n".join(env.d.log_lines[-20:])


@pytest.fixture(scope="module")
def small_env():
    env = Env(SMALL_FLAGS)
    yield env
    assert env.d.stop() == 0, "\n".join(env.d.log_lines[-20:])


def send(env, case):
    ctx = env.ctx
    if case.raw:
        return raw_http(env.d.url, case.raw(ctx if case.auth else dict(ctx, token_for=lambda p: None)))
    headers = {}
    tok = ctx["token_for"](case.path) if case.auth else None
    if tok:
        headers["Authorization"] = f"Bearer {tok}"
    kw = {}
    if case.body is not None:
        kw["data"] = case.body if isinstance(case.body, bytes) else json.dumps(case.body).encode()
        headers.update(JSON_CT)
    for k, v in (case.headers or {}).items():
        headers[k] = v.format(**ctx) if isinstance(v, str) else v
    r = requests.request(case.method, env.d.url + case.path.format(**ctx), headers=headers,
                         timeout=30, **kw)
    return Resp(r.status_code, r.headers, r.content)


def check_problem(resp, status, pointer=None, limit=None):
    assert resp.status == status, resp.body[:500]
    assert resp.headers.get("Content-Type") == "application/problem+json", resp.headers
    p = json.loads(resp.body)
    for k in ("type", "title", "detail"):
        assert isinstance(p.get(k), str) and p[k], p
    assert p["type"].startswith("/errors/"), p
    assert p["status"] == status, p
    if pointer is not None:
        assert p["errors"][0]["pointer"] == pointer, p
        assert p["errors"][0]["message"], p
    if limit is not None:
        name, lim, requested = limit
        assert (p["limit_name"], p["limit"]) == (name, lim), p
        if requested is None:
            assert p["requested"] > lim, p
        else:
            assert p["requested"] == requested, p
    return p


def test_catalogue_size():
    assert len(CASES) >= 70
    assert len({c.id for c in CASES}) == len(CASES), "catalogue ids must be unique"


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_hostile(request, case):
    env = request.getfixturevalue(case.on + "_env")
    t0 = time.time()
    resp = send(env, case)
    assert time.time() - t0 < 10, "a refused request must be answered promptly"
    if case.problem:
        check_problem(resp, case.status, case.pointer, case.limit)
    else:
        assert resp.status == case.status and 400 <= resp.status < 500, resp
    if case.status == 401:
        assert resp.headers["WWW-Authenticate"].startswith("Bearer "), resp.headers
    if case.status in (405,):
        assert resp.headers["Allow"] == case.allow, resp.headers
    if case.status == 429:
        assert int(resp.headers["Retry-After"]) > 0
    # the daemon lives, the sessions aimed at kept their state, the bystander is untouched
    assert env.d.alive(), "\n".join(env.d.log_lines[-20:])
    assert requests.get(env.d.url + "/healthz", timeout=10).status_code == 200
    assert env.version(env.victim) == env.ctx["version"]
    assert env.version(env.empty) == 0
    assert env.bystander_state() == env.snapshot


def test_after_catalogue(main_env, small_env):
    """Run after the table: every session is exactly as before, the logs hold no error."""
    for env in (main_env, small_env):
        assert env.d.alive()
        assert env.bystander_state() == env.snapshot
        assert env.victim.req("GET", "/complex").content == env.victim_complex
        assert env.version(env.victim) == env.ctx["version"]
        assert not [l for l in env.d.log_lines if " error " in l], env.d.log_lines
    # the small daemon holds its three sessions: a fourth makes room by letting the empty one go
    # (it never received a complex); with a complex in every resident session, the next is 429
    d = small_env.d
    fourth = Session(d)
    assert small_env.empty.req("GET").status_code == 404
    assert fourth.put_complex(VICTIM).status_code == 200
    r = requests.post(d.url + "/v1/sessions", json={})
    check_problem(Resp(r.status_code, r.headers, r.content), 429)
    assert int(r.headers["Retry-After"]) >= 1
    assert small_env.bystander_state() == small_env.snapshot


LOG = re.compile(r"^\d{4}-\d\d-\d\dT[\d:.]+Z info (\S+) (\S+) (\d{3}) \d+B [\d.]+ms "
                 r"route=\S+( type=/errors/[a-z-]+)?$")


def test_one_log_line_per_request(main_env):
    d = main_env.d
    s = Session(d)
    marker = f"/nowhere-{s.id}"
    expected = [("GET", marker, 404),
                ("PUT", f"/v1/sessions/{s.id}/complex", 400),
                ("PUT", f"/v1/sessions/{s.id}/complex", 422),
                ("GET", f"/v1/sessions/{s.id}/complex", 409),
                ("GET", f"/v1/sessions/{s.id}/levels/abc", 400),
                ("GET", f"/v1/sessions/{s.id}", 401),
                ("DELETE", f"/v1/sessions/{s.id}", 204)]
    assert requests.get(d.url + marker).status_code == 404
    assert s.put_complex({"vertices": 1, "simplices": []}).status_code == 400
    assert s.put_complex({"vertices": [], "simplices": []}).status_code == 422
    assert s.req("GET", "/complex").status_code == 409
    assert s.req("GET", "/levels/abc").status_code == 400
    assert requests.get(s.base).status_code == 401
    assert s.delete().status_code == 204
    deadline = time.time() + 5
    while time.time() < deadline and sum(s.id in l for l in d.log_lines) < len(expected):
        time.sleep(0.02)
    time.sleep(0.1)   # and nothing more arrives
    lines = [l for l in d.log_lines if s.id in l]
    got = []
    for line in lines:
        m = LOG.match(line)
        assert m, line
        got.append((m.group(1), m.group(2), int(m.group(3))))
    # a line is written when its response has been sent, which can come after the client's next
    # request on another connection has been answered: one line each, in any order
    assert sorted(got) == sorted(expected)


def raw_auth(env, value):
    req = (f"GET {env.ctx['s']} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n"
           f"Authorization: {value}\r\n\r\n").encode()
    return raw_http(env.d.url, req)


def test_bearer_scheme_and_whitespace(main_env):
    """RFC 9110 11.4 / 7235: the scheme is case-insensitive and separated from the token by one
    or more spaces; whitespace around a field value is not part of it."""
    tok = main_env.victim.token
    for value in (f"bearer {tok}", f"BEARER {tok}", f"BeArEr {tok}", f"Bearer   {tok}",
                  f"Bearer {tok}  ", f"Bearer {tok}\t", f"  Bearer {tok}"):
        r = raw_auth(main_env, value)
        assert r.status == 200, (value, r)
        assert json.loads(r.body)["id"] == main_env.victim.id
    for value in (f"Bearer{tok}", f"Bearer {tok[:-1]}", f"Bearer {tok} {tok}", f"Bearer {tok},",
                  f"Bearer\t{tok}x"):
        check_problem(raw_auth(main_env, value), 401)


def test_cut_connections_do_not_hurt(main_env):
    """Clients that vanish mid-request (half a header, half a body, half a chunked upload) leave
    the daemon and every session as they were."""
    env = main_env
    host, port = env.d.url.rsplit("/", 1)[-1].split(":")
    s, tok = env.ctx["s"], env.victim.token
    partials = [
        b"GET /healthz HTTP/1.1\r\nHost: x\r\n",
        (f"PUT {s}/complex HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {tok}\r\n"
         f"Content-Type: application/json\r\nContent-Length: 5000\r\n\r\n").encode() + VICTIM_BYTES[:100],
        (f"PUT {s}/complex HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {tok}\r\n"
         f"Content-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n").encode() + b"400\r\n" + b"[" * 100,
        (f"GET {s}/levels/2?format=vtu HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {tok}\r\n\r\n").encode(),
    ]
    for data in partials:
        c = socket.create_connection((host, int(port)), timeout=5)
        c.sendall(data)
        c.close()
    time.sleep(0.2)
    assert env.d.alive()
    assert requests.get(env.d.url + "/healthz").status_code == 200
    assert env.version(env.victim) == env.ctx["version"]
    assert env.victim.req("GET", "/complex").content == env.victim_complex
    assert env.bystander_state() == env.snapshot
