"""The subdivd HTTP client: one method per endpoint of the v1 API (docs/API.md, docs/SERVICE.md).

    from subdiv import Client
    c = Client("http://127.0.0.1:8080")
    with c.create_session() as s:                  # DELETEd when the block ends
        s.put_complex({"vertices": [...], "simplices": [...]})
        s.put_rules({"solid_scheme": "averaged"})
        s.level(3, format="vtu", out="level3.vtu")  # streamed to the file
        s.edit(moves=[{"index": 0, "position": [0, 0, 0.1]}])   # If-Match sent for you

Errors are typed (subdiv.errors): every refusal raises the ProblemError subclass of its status with
the problem+json attached. Versions: each answer's ETag updates `Session.version`; `edit()` sends
it as If-Match (the daemon requires one), other changes send it when asked (`if_match=True`, or a
version number) so that a concurrent change makes them fail with PreconditionFailed (412).

numpy, meshio and scipy are optional: `level_arrays` (numpy arrays), `level_mesh` (a meshio.Mesh),
`matrix_sparse` (a scipy.sparse.csr_matrix) and `delta` import them when called.

Progress: pass `progress=callable(kind, done, total)`; kind is "upload" or "download" (bytes;
total None when unknown) or "server", polled from GET /v1/sessions/{id}'s "progress" while the
daemon works on a request: done = the fraction of the work done and total = 1.0 while it computes
levels, else done = the seconds it has been at it and total None.
"""
from __future__ import annotations

import io
import json
import os
import socket
import threading
import time
from typing import Any, Callable, Dict, Iterator, List, Mapping, Optional, Sequence, Union

import requests

from .errors import ProblemError, TransportError, error_for

# Type names of the public API: JSON documents as Python values; a progress callback
# progress(kind, done, total): kind "upload"/"download" (bytes; total None when unknown) or
# "server" (the fraction of the levels' work done, total 1.0; or seconds, total None).
JSON = Dict[str, Any]
Progress = Callable[[str, float, Optional[float]], Any]
Version = Union[int, str]
PathLike = Union[str, "os.PathLike[str]"]

FORMATS = ("glb", "gltf", "vtu", "vtk", "json")
# The cell kinds of format=json's "cells" and the vertices of each.
_CELL_WIDTHS = {"points": 1, "edges": 2, "triangles": 3, "tetrahedra": 4, "octahedra": 6}
LEVEL_OPTIONS = ("parts", "slice", "attributes", "colormap", "octahedra", "names", "compress",
                 "limit")


class _Upload:
    """A request body that reports how much of it has been read (sent)."""

    def __init__(self, data, progress):
        self._buf = io.BytesIO(data)
        self._n = len(data)
        self._progress = progress
        self._progress("upload", 0, self._n)

    def __len__(self):
        return self._n

    def read(self, size=-1):
        chunk = self._buf.read(size)
        self._progress("upload", self._buf.tell(), self._n)
        return chunk


class _ServerProgress:
    """Polls GET /v1/sessions/{id} on its own connection while a request is in flight."""

    def __init__(self, session, progress):
        self.s, self.progress, self.interval = session, progress, session.client.poll_interval
        self.stop = threading.Event()
        self.t = threading.Thread(target=self._run, daemon=True)

    def __enter__(self):
        if self.progress:
            self.t.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        if self.t.is_alive():
            self.t.join(2)

    def _run(self):
        http = requests.Session()
        while not self.stop.wait(self.interval):
            try:
                r = http.get(self.s.url, headers=self.s.headers(), timeout=5)
                p = r.json().get("progress") if r.status_code == 200 else None
            except (requests.RequestException, ValueError):
                p = None
            if p and not self.stop.is_set():
                if p.get("fraction") is not None:     # levels: how far, 0..1
                    self.progress("server", float(p["fraction"]), 1.0)
                else:                                 # other work: the seconds so far
                    self.progress("server", p.get("seconds", 0.0), None)
        http.close()


class Client:
    """The daemon at `url`. `retries`: how often a 429/503 answer is retried after its
    Retry-After (capped at `max_wait` seconds each). `poll_interval`: seconds between looks at
    the session's progress while a request with a progress callback runs."""

    def __init__(self, url: str = "http://127.0.0.1:8080", *, timeout: float = 600,
                 retries: int = 0, max_wait: float = 10, poll_interval: float = 0.25,
                 http: Optional[requests.Session] = None) -> None:
        self.url = url.rstrip("/")
        self.poll_interval = poll_interval
        self.timeout = timeout
        self.retries = retries
        self.max_wait = max_wait
        self.http = http or requests.Session()

    def close(self) -> None:
        self.http.close()

    # ---- transport ------------------------------------------------------------------------

    def request(self, method: str, path: str, *, json_body: Any = None,
                data: Optional[bytes] = None, headers: Optional[Mapping[str, str]] = None,
                params: Optional[Mapping[str, Any]] = None, stream: bool = False,
                progress: Optional[Progress] = None, expect: Sequence[int] = (200,),
                timeout: Optional[float] = None) -> requests.Response:
        """One request; `path` is absolute ("/healthz") or a full URL. Raises the typed error
        for any status outside `expect`; returns the requests.Response."""
        url = path if path.startswith("http") else self.url + path
        h = dict(headers or {})
        body = None
        if json_body is not None:
            body = json.dumps(json_body, separators=(",", ":")).encode()
            h.setdefault("Content-Type", "application/json")
        elif data is not None:
            body = data
        for attempt in range(self.retries + 1):
            send = _Upload(body, progress) if (progress and body is not None) else body
            try:
                r = self.http.request(method, url, data=send, headers=h, params=params,
                                      stream=stream, timeout=timeout or self.timeout)
            except requests.RequestException as e:
                raise TransportError(f"{method} {url}: {e}") from e
            if r.status_code in expect:
                return r
            err = error_for(r)
            r.close()
            if r.status_code in (429, 503) and attempt < self.retries:
                time.sleep(min(err.retry_after or 1, self.max_wait))
                continue
            raise err
        raise AssertionError("unreachable")

    # ---- service ----------------------------------------------------------------------------

    def healthz(self) -> JSON:
        """GET /healthz: {"status": "ok"} while the daemon lives."""
        return self.request("GET", "/healthz").json()

    def livez(self) -> JSON:
        """GET /livez: the same as /healthz."""
        return self.request("GET", "/livez").json()

    def readyz(self) -> JSON:
        """GET /readyz: {"status": "ready", "memory": {"budget_bytes", "used_bytes"}}, or
        ServiceUnavailable while starting or stopping or with the memory budget in use."""
        return self.request("GET", "/readyz").json()

    def metrics(self) -> str:
        """GET /metrics: the Prometheus text."""
        return self.request("GET", "/metrics").text

    def openapi(self) -> JSON:
        """GET /v1/openapi.json."""
        return self.request("GET", "/v1/openapi.json").json()

    def error_page(self, slug: str) -> str:
        """GET /errors/<slug>: the Markdown page of a problem type (ProblemError.slug); NotFound
        for a slug the daemon does not have."""
        return self.request("GET", "/errors/" + slug).text

    def wait_ready(self, timeout: float = 10) -> JSON:
        """Poll /readyz until it answers 200 (TransportError after `timeout` seconds)."""
        deadline = time.time() + timeout
        while True:
            try:
                return self.readyz()
            except (TransportError, ProblemError):
                if time.time() > deadline:
                    raise
                time.sleep(0.05)

    # ---- sessions -----------------------------------------------------------------------------

    def create_session(self, ttl_s: Optional[int] = None, *, import_doc: Optional[JSON] = None) -> Session:
        """POST /v1/sessions: a new Session (deleted by `with ... as s` at the end of the block).
        `import_doc`, a document of Session.export(), recreates that session (new id and token,
        the version continuing from the document's, bit-identical levels)."""
        body: JSON = {} if ttl_s is None else {"ttl_s": ttl_s}
        if import_doc is not None:
            body["import"] = import_doc
        r = self.request("POST", "/v1/sessions", json_body=body, expect=(201,))
        j = r.json()
        s = Session(self, j["id"], j["token"])
        s.expires_at = j.get("expires_at")
        if import_doc is not None:
            s.version = j.get("version")
        return s

    def session(self, id: str, token: str) -> Session:
        """A Session object for an existing session (not deleted on exit)."""
        s = Session(self, id, token)
        s.owned = False
        return s


def _socket_of(response: requests.Response) -> Any:
    """The socket a streamed response reads from (urllib3 1.26 and 2), or None."""
    raw = getattr(response, "raw", None)
    sock = getattr(getattr(raw, "_connection", None), "sock", None)
    if sock is None:
        fp = getattr(getattr(raw, "_fp", None), "fp", None)
        sock = getattr(getattr(fp, "raw", None), "_sock", None)
    return sock if hasattr(sock, "shutdown") else None


class EventStream:
    """An open event stream (Session.events()): an iterator of the events, {"id", "event",
    "data"}; close() ends it whether or not it was read (also at the end of a `with` block)."""

    def __init__(self, response: requests.Response) -> None:
        self._r = response
        self._closed = self._ended = False
        self._sock = _socket_of(response)
        self._it = self._read()

    def __iter__(self) -> EventStream:
        return self

    def __next__(self) -> JSON:
        return next(self._it)

    def __enter__(self) -> EventStream:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        self._closed = True
        # A read blocked in another thread holds the response's buffer until a byte comes (the
        # next heartbeat): shutting the socket down wakes it at once, and it ends the iteration.
        if self._sock is not None and not self._ended:
            try:
                self._sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        try:
            self._it.close()
        except ValueError:  # being read in another thread: it ends with the connection
            pass
        self._r.close()

    def _read(self) -> Iterator[JSON]:
        r = self._r
        try:
            ev: JSON = {}
            data: List[str] = []
            try:
                for raw in r.iter_lines(chunk_size=1, decode_unicode=False):
                    line = raw.decode("utf-8")
                    if not line:
                        if data or ev:
                            ev["data"] = json.loads("\n".join(data)) if data else None
                            ev.setdefault("event", "message")
                            yield ev
                        ev, data = {}, []
                        continue
                    if line.startswith(":"):
                        continue
                    field, _, value = line.partition(":")
                    value = value[1:] if value.startswith(" ") else value
                    if field == "data":
                        data.append(value)
                    elif field == "id":
                        ev["id"] = int(value) if value.isdigit() else value
                    elif field == "event":
                        ev["event"] = value
            except Exception as e:
                if self._closed:  # close() from another thread: the iteration ends
                    return
                if isinstance(e, requests.RequestException):
                    raise TransportError(f"the event stream broke: {e}") from e
                raise
        finally:
            self._ended = True
            try:  # never back to the pool: close() may still shut this socket down
                r.raw.close()
            except Exception:
                pass
            r.close()


class Session:
    """One session of the daemon: `id`, `token`, and `version` (the last ETag seen)."""

    def __init__(self, client: Client, id: str, token: str) -> None:
        self.client = client
        self.id, self.token = id, token
        self.url = f"{client.url}/v1/sessions/{id}"
        self.version: Optional[int] = None
        self.expires_at: Optional[str] = None
        self.owned = True

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.owned:
            try:
                self.delete()
            except (ProblemError, TransportError):
                pass

    def headers(self, if_match: Union[bool, Version, None] = None,
                extra: Optional[Mapping[str, str]] = None) -> Dict[str, str]:
        h = {"Authorization": f"Bearer {self.token}"}
        if if_match is True:
            if self.version is None:
                self.info()
            h["If-Match"] = f'"{self.version}"'
        elif if_match not in (None, False):
            h["If-Match"] = f'"{int(if_match)}"' if str(if_match).isdigit() else str(if_match)
        h.update(extra or {})
        return h

    def _note(self, r):
        etag = r.headers.get("ETag", "").strip('"')
        if etag.isdigit():
            self.version = int(etag)
        return r

    def _call(self, method, path="", *, if_match=None, expect=(200,), **kw):
        r = self.client.request(method, self.url + path, headers=self.headers(if_match), expect=expect, **kw)
        return self._note(r)

    def _change(self, method, path, body, if_match, progress):
        with _ServerProgress(self, progress):
            j = self._call(method, path, json_body=body, if_match=if_match, progress=progress).json()
        self.version = j.get("version", self.version)
        return j

    # GET/PATCH/DELETE /v1/sessions/{id}
    def info(self) -> JSON:
        """GET /v1/sessions/{id}: version, levels_cached, memory_bytes, summary, progress."""
        j = self._call("GET").json()
        self.version = j.get("version", self.version)
        return j

    def set_ttl(self, ttl_s: int) -> JSON:
        """PATCH /v1/sessions/{id} {"ttl_s"}: a new idle TTL from now (capped at the daemon's
        --max-ttl): {"id", "ttl_s" granted, "expires_at", "version"}. The version is unchanged."""
        return self._call("PATCH", json_body={"ttl_s": ttl_s}).json()

    def delete(self) -> None:
        """DELETE /v1/sessions/{id}."""
        self._call("DELETE", expect=(204,))
        self.owned = False

    # the complex, tags and rules
    def put_complex(self, body: JSON, *, if_match: Union[bool, Version, None] = None,
                    progress: Optional[Progress] = None, repair: bool = False) -> JSON:
        """PUT /complex (vertices, simplices, attributes, diagonals, fill): {"version", "summary"}.
        `repair=True` drops degenerate, repeated-vertex and duplicate simplices instead of a 422;
        summary["repaired"] lists them ({"index", "reason"}, at most 1000; "repaired_count")."""
        if repair:
            body = dict(body, repair=True)
        return self._change("PUT", "/complex", body, if_match, progress)

    def get_complex(self) -> JSON:
        """GET /complex: the complex (with filled tetrahedra), classes, tags, rules, summary."""
        return self._call("GET", "/complex").json()

    def export(self) -> JSON:
        """GET /export: the session's control data as one document (complex with every diagonal
        and the stored orientation, details, tags, rules, version), for
        Client.create_session(import_doc=...)."""
        return self._call("GET", "/export").json()

    def put_tags(self, singular: Optional[Sequence[Sequence[int]]] = None, *,
                 petals: Optional[Sequence[JSON]] = None,
                 sharpness: Optional[Sequence[JSON]] = None, body: Optional[JSON] = None,
                 if_match: Union[bool, Version, None] = None,
                 crease_angle: Optional[float] = None,
                 normals: Optional[Sequence[JSON]] = None,
                 tangents: Optional[Sequence[JSON]] = None,
                 tangent_edges: Optional[Sequence[JSON]] = None) -> JSON:
        """PUT /tags with {"singular": singular, "petals": petals, "sharpness": sharpness} (or a
        whole `body`); petals: [{"vertex": v, "triangle": [a, b, c], "kind": "convex" |
        "concave" | "smooth"}]; sharpness: [{"simplex": [a, b] or [v], "value": s}].
        `crease_angle` (degrees, 0..180) also tags every surface edge whose dihedral angle
        exceeds it; the answer's "crease_angle" says {"degrees", "tagged"}. Tangent-plane
        constraints (003 Sec. 3, ying-zorin; docs/API.md "Tangent-plane constraints"): normals
        [{"vertex", "triangles": [[a, b, c], ...], "normal"?: [x, y, z]}], tangents [{"vertex",
        "triangle", "tangent"}], tangent_edges [{"edge": [a, b], "triangles"?: [t0, t1]}]."""
        if body is None:
            body = {"singular": singular or []}
            if petals is not None:
                body["petals"] = petals
            if sharpness is not None:
                body["sharpness"] = sharpness
            if crease_angle is not None:
                body["crease_angle"] = crease_angle
            for k, v in (("normals", normals), ("tangents", tangents),
                         ("tangent_edges", tangent_edges)):
                if v is not None:
                    body[k] = v
        return self._change("PUT", "/tags", body, if_match, None)

    def put_rules(self, rules: Optional[JSON] = None, *,
                  if_match: Union[bool, Version, None] = None) -> JSON:
        """PUT /rules: every preference at once (absent fields are the defaults)."""
        return self._change("PUT", "/rules", rules or {}, if_match, None)

    def refine(self, select: Any, depth: int = 1, positions: str = "subdivision", *,
               if_match: Union[bool, Version, None] = None) -> JSON:
        """POST /refine: red-green refinement of the control complex around `select`."""
        return self._change("POST", "/refine", {"select": select, "depth": depth, "positions": positions},
                            if_match, None)

    def edit(self, moves: Optional[Sequence[JSON]] = None, attributes: Optional[JSON] = None, *,
             if_match: Union[bool, Version, None] = True, delta: Optional[int] = None,
             delta_format: str = "bin",
             delta_attributes: Union[str, Sequence[str], None] = None,
             delta_parts: Union[str, Sequence[str], None] = None) -> JSON:
        """PATCH /control-points; If-Match is the session's known version unless given. A move
        is {"index", "position"} with an optional "level" (default 0): a point of a finer level
        moved there keeps a detail offset (GET /complex lists them as "details").
        With `delta=L` the answer carries the edit's delta of level L (PATCH ?delta=, one round
        trip): {"version", "updated_points", "delta"} where "delta" is what delta() returns for
        the version the edit was made on, or None when the daemon could not make it ("gone" then
        holds its problem: the edit stands; fetch the level). `delta_parts` as delta()'s
        `parts`."""
        body = {}
        if moves is not None:
            body["moves"] = moves
        if attributes is not None:
            body["attributes"] = attributes
        if delta is None:
            return self._change("PATCH", "/control-points", body, if_match, None)
        params, names = self._delta_params({"delta": int(delta)}, delta_format, delta_attributes,
                                           delta_parts)
        r = self._call("PATCH", "/control-points", json_body=body, if_match=if_match,
                       params=params)
        if r.headers.get("Content-Type", "").startswith("application/octet-stream"):
            d = self._parse_delta_bin(r, names)
            up = json.loads(r.headers.get("X-Updated-Points", "{}"))
            return {"version": d["version"], "updated_points": up, "delta": d}
        j = r.json()
        self.version = j.get("version", self.version)
        out = {"version": j["version"], "updated_points": j["updated_points"], "delta": None}
        d = j.get("delta")
        if d is not None and "indices" in d:
            out["delta"] = self._parse_delta_json(d, self._components(r))
        else:
            out["gone"] = d
        return out

    # levels
    def level(self, level: int, format: str = "glb", *, out: Optional[PathLike] = None,
              progress: Optional[Progress] = None, if_none_match: Optional[Version] = None,
              **options: Any) -> Union[bytes, int, None]:
        """GET /levels/{L}: the level in `format` with the options of docs/OUTPUTS.md (parts,
        slice, attributes, colormap, octahedra, names, compress, limit: True for every point at its
        limit position, docs/API.md "Limits and analysis"). With `out` (a path) it is streamed into the
        file (written as OUT.part, renamed when complete) and the byte count is returned;
        otherwise the bytes. With `if_none_match` (a version): None when unchanged (304)."""
        params = {"format": format}
        for k, v in options.items():
            if k not in LEVEL_OPTIONS:
                raise TypeError(f"unknown level option {k!r}; one of {', '.join(LEVEL_OPTIONS)}")
            if isinstance(v, bool):
                v = "true" if v else "false"
            if v is not None:
                params[k] = v
        extra = {"If-None-Match": f'"{if_none_match}"'} if if_none_match is not None else None
        with _ServerProgress(self, progress):
            r = self.client.request("GET", f"{self.url}/levels/{int(level)}", params=params,
                                    headers=self.headers(extra=extra), stream=True,
                                    expect=(200, 304))
        self._note(r)
        if r.status_code == 304:
            r.close()
            return None
        total = r.headers.get("Content-Length")
        total = int(total) if total and total.isdigit() else None
        done = 0
        sink = open(f"{out}.part", "wb") if out else io.BytesIO()
        try:
            try:
                for chunk in r.iter_content(1 << 16):
                    sink.write(chunk)
                    done += len(chunk)
                    if progress:
                        progress("download", done, total)
            except requests.RequestException as e:
                raise TransportError(f"the level stream broke after {done} bytes: {e}") from e
            if total is not None and done != total:
                raise TransportError(f"the level stream ended after {done} of {total} bytes")
            if out:
                sink.close()
                os.replace(f"{out}.part", out)
                return done
            return sink.getvalue()
        finally:
            r.close()
            if out and not sink.closed:
                sink.close()
            if out and os.path.exists(f"{out}.part"):
                os.unlink(f"{out}.part")

    def level_json(self, level: int, **options: Any) -> JSON:
        """The level as the JSON of docs/API.md (vertices, cells, attributes, rules, origin)."""
        return json.loads(self.level(level, format="json", **options))

    def level_arrays(self, level: int, **options: Any) -> JSON:
        """The level (GET /levels/{L}?format=json, with the level options of level()) as numpy
        arrays: {"level", "version", "positions" (n x 3 float64, the doubles of format=json),
        "cells": {"points" (k,), "edges" (k x 2), "triangles" (k x 3), "tetrahedra" (k x 4),
        "octahedra" (k x 6: p, q, a, a2, b, b2 — the major diagonal p-q first)} (int64 vertex
        indices; a part not asked for is an empty array of that shape), "attributes" {name: (n,)
        for one component, n x ncomp otherwise (float64)}, "rules" (one rule name per vertex)},
        and with the `slice` option "slice": {"vertices" (m x 3 float64), "triangles" (k x 3
        int64, indices into those vertices)}. Needs numpy (Debian: python3-numpy)."""
        import numpy as np
        j = self.level_json(level, **options)
        cells = {}
        for kind, width in _CELL_WIDTHS.items():
            cells[kind] = np.asarray(j["cells"].get(kind, []), dtype=np.int64).reshape(
                (-1,) if width == 1 else (-1, width))
        out = {"level": j["level"], "version": j.get("version"),
               "positions": np.asarray(j["vertices"], dtype=np.float64).reshape(-1, 3),
               "cells": cells,
               "attributes": {k: np.asarray(v, dtype=np.float64)
                              for k, v in j.get("attributes", {}).items()},
               "rules": list(j.get("rules", []))}
        if "slice" in j:
            out["slice"] = {"vertices": np.asarray(j["slice"]["vertices"],
                                                   dtype=np.float64).reshape(-1, 3),
                            "triangles": np.asarray(j["slice"]["triangles"],
                                                    dtype=np.int64).reshape(-1, 3)}
        return out

    def level_mesh(self, level: int, **options: Any) -> Any:
        """The level as a meshio.Mesh: points the level's vertices (float64), cell blocks
        "vertex" (isolated points), "line" (curve segments), "triangle" (surface triangles) and
        "tetra" (the tetrahedra, then every octahedron (p,q,a,a2,b,b2) split into the 4
        tetrahedra (q,p,a,b), (q,p,b,a2), (q,p,a2,b2), (q,p,b2,a) along its major diagonal p-q:
        meshio has no octahedron cell, and meshio 7's VTU reader refuses polyhedra mixed with
        other cells), empty blocks left out. This is the cell order and the split of the daemon's VTU
        (docs/OUTPUTS.md), so `meshio.read` of GET /levels/{L}?format=vtu gives the same points
        and cells. Point data: the attributes (float64; (n,) or n x ncomp). Cell data, as the
        VTU's: "kind" (0 point, 1 curve, 2 triangle, 3 tetrahedron, 4 octahedron) and
        "source_cell" (the index among the cells of that kind at this level; an octahedron's 4
        tetrahedra share it). Options: those of level() (e.g. parts="solids"); a `slice` is not
        in the mesh (the VTU's slice triangles are: see level_arrays()'s "slice"). Needs numpy
        and meshio (Debian: python3-numpy, python3-meshio)."""
        import meshio
        import numpy as np
        a = self.level_arrays(level, **options)
        c = a["cells"]
        oct_ = c["octahedra"]
        split = np.stack([oct_[:, [1, 0, a_, b_]] for a_, b_ in ((2, 4), (4, 3), (3, 5), (5, 2))],
                         axis=1).reshape(-1, 4)
        blocks = [("vertex", c["points"].reshape(-1, 1), 0, np.arange(len(c["points"]))),
                  ("line", c["edges"], 1, np.arange(len(c["edges"]))),
                  ("triangle", c["triangles"], 2, np.arange(len(c["triangles"])))]
        tets = np.concatenate([c["tetrahedra"], split])
        kind = np.concatenate([np.full(len(c["tetrahedra"]), 3), np.full(len(split), 4)])
        src = np.concatenate([np.arange(len(c["tetrahedra"])), np.repeat(np.arange(len(oct_)), 4)])
        blocks.append(("tetra", tets, kind, src))
        cells, kinds, sources = [], [], []
        for name, data, k, s in blocks:
            if len(data):
                cells.append((name, data))
                kinds.append(np.broadcast_to(np.asarray(k, dtype=np.uint8), (len(data),)).copy())
                sources.append(np.asarray(s, dtype=np.int32))
        return meshio.Mesh(a["positions"], cells, point_data=dict(a["attributes"]),
                           cell_data={"kind": kinds, "source_cell": sources})

    def delta(self, level: int, since: int, format: str = "bin",
              attributes: Union[str, Sequence[str], None] = None,
              parts: Union[str, Sequence[str], None] = None) -> JSON:
        """GET /levels/{L}/delta?since=V: the points of `level` that changed since version
        `since` (the version of the level you hold), as a dict: "level", "since", "version" (the
        version the delta brings you to) and numpy arrays "indices" (uint32: level vertex
        indices, i.e. rows of the GLB's POSITION accessor), "positions" (n x 3), "normals" (n x 3
        float32, or None when the level has no drawn triangles) and "attributes" {name: n x
        ncomp}. `format="bin"` reads the compact "SDD1" layout (positions float32, as the GLB),
        `format="json"` the JSON one (positions as doubles, as format=json). Raises Gone (410)
        when the delta is not available (a change since then was not an edit, the level is not
        computed, ...): fetch the level again. `parts`: those of the GLB you hold (level(...,
        parts=...)), whose normals are over its own drawn triangles; default all."""
        params, names = self._delta_params({"since": int(since)}, format, attributes, parts)
        r = self._call("GET", f"/levels/{int(level)}/delta", params=params)
        if format == "json":
            return self._parse_delta_json(r.json(), self._components(r))
        return self._parse_delta_bin(r, names)

    @staticmethod
    def _delta_params(params, format, attributes, parts=None):
        params["format"] = format
        if parts is not None:
            params["parts"] = parts if isinstance(parts, str) else ",".join(parts)
        names = []
        if attributes is not None:
            names = attributes.split(",") if isinstance(attributes, str) else list(attributes)
            params["attributes"] = ",".join(names)
        return params, names

    @staticmethod
    def _components(r):
        """X-Attribute-Components ("t=1,v=2") as {name: ncomp}."""
        return {k: int(v) for k, v in (c.split("=") for c in
                r.headers.get("X-Attribute-Components", "").split(",") if c)}

    @staticmethod
    def _parse_delta_json(j, comps=None):
        import numpy as np
        out = {k: j[k] for k in ("level", "since", "version")}
        out["indices"] = np.asarray(j["indices"], dtype=np.uint32)
        out["positions"] = np.asarray(j["positions"], dtype=np.float64).reshape(-1, 3)
        out["normals"] = (np.asarray(j["normals"], dtype=np.float32).reshape(-1, 3)
                          if "normals" in j else None)
        out["attributes"] = {}
        for name, vals in j["attributes"].items():
            a = np.asarray(vals, dtype=np.float64)
            n = len(out["indices"])  # an empty delta: the components from the header
            out["attributes"][name] = (a.reshape(n, -1) if n else
                                       a.reshape(0, (comps or {}).get(name, 1)))
        return out

    @staticmethod
    def _parse_delta_bin(r, names):
        import numpy as np
        data = r.content
        magic, level_, since_, version, n, flags = (data[:4],) + tuple(np.frombuffer(data, "<u4", 5, 4))
        if magic != b"SDD1":
            raise TransportError(f"not a delta (starts with {magic!r})")
        off = 24
        def take(count, dtype, shape):
            nonlocal off
            a = np.frombuffer(data, dtype, count, off).reshape(shape)
            off += a.nbytes
            return a
        out = {"level": int(level_), "since": int(since_), "version": int(version)}
        out["indices"] = take(n, "<u4", (n,))
        out["positions"] = take(3 * n, "<f4", (n, 3))
        out["normals"] = take(3 * n, "<f4", (n, 3)) if flags & 1 else None
        comps = Session._components(r)
        out["attributes"] = {name: take(n * comps[name], "<f4", (n, comps[name]))
                             for name in names if flags & 2}
        if off != len(data):
            raise TransportError(f"the delta has {len(data)} bytes, its header says {off}")
        return out

    # embedded models (free-form deformation, docs/API.md "Embedded models")
    def put_embedded(self, name: str, vertices: Any, triangles: Any = None, *, level: int = 2,
                     outside: str = "refuse", binary: Optional[bool] = None) -> JSON:
        """PUT /embedded/{name}: bind a model (vertices n x 3, optional triangles k x 3) to level
        `level` of the solid; `outside` "refuse" (422 naming the vertices outside), "fixed" or
        "nearest". Big models (or `binary=True`) go as the binary layout, not JSON. Returns
        {"version", "embedded": {...}}."""
        n = len(vertices)
        if binary is None:
            binary = n > 20000
        if binary:
            import struct
            flat = [float(c) for v in vertices for c in v]
            tri = [int(i) for t in (triangles or []) for i in t]
            body = struct.pack(f"<II{len(flat)}d{len(tri)}I", n, len(tri) // 3, *flat, *tri)
            r = self._note(self.client.request(
                "PUT", f"{self.url}/embedded/{name}", data=body,
                params={"level": level, "outside": outside},
                headers=self.headers(extra={"Content-Type": "application/octet-stream"})))
        else:
            doc: JSON = {"vertices": [list(map(float, v)) for v in vertices], "level": level,
                         "outside": outside}
            if triangles is not None:
                doc["triangles"] = [list(map(int, t)) for t in triangles]
            r = self._call("PUT", f"/embedded/{name}", json_body=doc)
        j = r.json()
        self.version = j.get("version", self.version)
        return j

    def embedded(self) -> List[JSON]:
        """GET /embedded: the session's embedded models (name, vertices, triangles, level,
        outside, outside_vertices)."""
        return self._call("GET", "/embedded").json()["embedded"]

    def get_embedded(self, name: str, format: str = "json") -> Any:
        """GET /embedded/{name}: the deformed model — a dict for json ({"name", "level",
        "version", "vertices", "triangles"}), text for obj, bytes for glb."""
        r = self._call("GET", f"/embedded/{name}", params={"format": format})
        return r.json() if format == "json" else r.text if format == "obj" else r.content

    def delete_embedded(self, name: str) -> None:
        """DELETE /embedded/{name}."""
        self._call("DELETE", f"/embedded/{name}", expect=(204,))

    def embedded_delta(self, name: str, since: int, format: str = "bin") -> JSON:
        """GET /embedded/{name}/delta?since=V: the model vertices that moved since version V,
        as delta() returns them ("indices", "positions"; normals and attributes None/{}).
        Raises Gone (410) when the model was bound after V, or as for levels."""
        r = self._call("GET", f"/embedded/{name}/delta", params={"since": int(since), "format": format})
        if format == "json":
            j = r.json()
            import numpy as np
            out = {k: j[k] for k in ("level", "since", "version")}
            out["indices"] = np.asarray(j["indices"], dtype=np.uint32)
            out["positions"] = np.asarray(j["positions"], dtype=np.float64).reshape(-1, 3)
            out["normals"], out["attributes"] = None, {}
            return out
        return self._parse_delta_bin(r, [])

    def events(self, last_event_id: Optional[Version] = None, *,
               timeout: Optional[float] = None) -> EventStream:
        """GET /events: the session's event stream, open when this returns (a refusal raises
        here: Unauthorized, NotFound, TooManyRequests beyond --max-listeners), so every change
        after the call comes, however late the iteration starts. Iterate it for the events as
        dicts {"id", "event", "data"} (data parsed as JSON): "version" after each change (data:
        version, kind, and for edits updated_points), "resync" when `last_event_id` is too old
        to replay, "deleted" when the session ends (the iteration ends with the stream).
        Heartbeat comments are skipped. `.close()` it (or use it in a `with` block) to stop,
        read or not. `timeout`: seconds without a byte (heartbeats come every --sse-heartbeat
        seconds) before TransportError."""
        extra = {"Accept": "text/event-stream"}
        if last_event_id is not None:
            extra["Last-Event-ID"] = str(last_event_id)
        r = self.client.request("GET", self.url + "/events", headers=self.headers(extra=extra),
                                stream=True, timeout=timeout or self.client.timeout)
        return EventStream(r)

    def level_stats(self, level: int) -> JSON:
        """GET /levels/{L}/stats: counts per cell kind, bytes per format, seconds."""
        return self._call("GET", f"/levels/{int(level)}/stats").json()

    def matrix(self, level: int, from_level: int = 0, format: str = "mtx", *,
               out: Optional[PathLike] = None) -> Union[str, JSON, int]:
        """GET /matrices/{L}?from=F: Matrix Market text, or the JSON CSR as a dict; with `out`
        written to that file (the byte count is returned)."""
        r = self._call("GET", f"/matrices/{int(level)}", params={"from": from_level, "format": format},
                       stream=True)
        data = b"".join(r.iter_content(1 << 16))
        r.close()
        if out:
            with open(out, "wb") as f:
                f.write(data)
            return len(data)
        return json.loads(data) if format == "json" else data.decode()

    def matrix_sparse(self, level: int, from_level: int = 0) -> Any:
        """GET /matrices/{L}?from=F&format=json as a scipy.sparse.csr_matrix of shape (rows of
        level L, points of level F): `P @ positions_F` is level L's positions (level_arrays()),
        and the same for every attribute. Without scipy (Debian: python3-scipy) the JSON CSR dict
        of matrix(format="json") ({"from", "to", "rows", "cols", "nnz", "rowptr", "col", "val"})."""
        j = self.matrix(level, from_level, format="json")
        try:
            import scipy.sparse
        except ImportError:
            return j
        return scipy.sparse.csr_matrix((j["val"], j["col"], j["rowptr"]),
                                       shape=(j["rows"], j["cols"]))

    def analysis(self, vertex: Optional[int] = None,
                 edge: Union[str, Sequence[int], None] = None) -> JSON:
        """GET /analysis?vertex=i or ?edge=i,j: local subdivision matrix and eigenvalues."""
        params = {}
        if vertex is not None:
            params["vertex"] = vertex
        if edge is not None:
            params["edge"] = ",".join(map(str, edge)) if not isinstance(edge, str) else edge
        return self._call("GET", "/analysis", params=params).json()


# The daemon's routes and the methods that serve them (a test compares this table with
# `subdivd --list-routes`).
ROUTES = {
    ("POST", "/v1/sessions"): "Client.create_session",
    ("GET", "/v1/sessions/{id}"): "Session.info",
    ("PATCH", "/v1/sessions/{id}"): "Session.set_ttl",
    ("DELETE", "/v1/sessions/{id}"): "Session.delete",
    ("PUT", "/v1/sessions/{id}/complex"): "Session.put_complex",
    ("GET", "/v1/sessions/{id}/complex"): "Session.get_complex",
    ("GET", "/v1/sessions/{id}/export"): "Session.export",
    ("PATCH", "/v1/sessions/{id}/control-points"): "Session.edit",
    ("POST", "/v1/sessions/{id}/refine"): "Session.refine",
    ("PUT", "/v1/sessions/{id}/tags"): "Session.put_tags",
    ("PUT", "/v1/sessions/{id}/rules"): "Session.put_rules",
    ("GET", "/v1/sessions/{id}/levels/{L}"): "Session.level",
    ("GET", "/v1/sessions/{id}/levels/{L}/stats"): "Session.level_stats",
    ("GET", "/v1/sessions/{id}/levels/{L}/delta"): "Session.delta",
    ("GET", "/v1/sessions/{id}/events"): "Session.events",
    ("GET", "/v1/sessions/{id}/embedded"): "Session.embedded",
    ("PUT", "/v1/sessions/{id}/embedded/{name}"): "Session.put_embedded",
    ("GET", "/v1/sessions/{id}/embedded/{name}"): "Session.get_embedded",
    ("DELETE", "/v1/sessions/{id}/embedded/{name}"): "Session.delete_embedded",
    ("GET", "/v1/sessions/{id}/embedded/{name}/delta"): "Session.embedded_delta",
    ("GET", "/v1/sessions/{id}/analysis"): "Session.analysis",
    ("GET", "/v1/sessions/{id}/matrices/{L}"): "Session.matrix",
    ("GET", "/healthz"): "Client.healthz",
    ("GET", "/livez"): "Client.livez",
    ("GET", "/readyz"): "Client.readyz",
    ("GET", "/metrics"): "Client.metrics",
    ("GET", "/v1/openapi.json"): "Client.openapi",
    ("GET", "/errors/{slug}"): "Client.error_page",
}
