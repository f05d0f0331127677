"""The Python client (clients/python/subdiv) over HTTP against the real daemon: every endpoint,
every error status mapped to its typed exception with the problem+json, ETag/If-Match, progress."""
import http.server
import json
import subprocess
import sys
import threading

import pytest

from conftest import REPO
from daemon import SUBDIVD, Daemon

sys.path.insert(0, str(REPO / "clients" / "python"))
import subdiv  # noqa: E402
from subdiv import errors as E  # noqa: E402

MIXED = json.loads((REPO / "examples" / "mixed.json").read_text())


@pytest.fixture(scope="module")
def daemon():
    d = Daemon("--max-sessions", "100")
    yield d
    assert d.stop() == 0


@pytest.fixture
def client(daemon):
    c = subdiv.Client(daemon.url)
    yield c
    c.close()


def test_routes_table_matches_the_daemon():
    """ROUTES names a method for every route of `subdivd --list-routes`, and nothing else."""
    out = subprocess.run([str(SUBDIVD), "--list-routes"], capture_output=True, text=True, check=True).stdout
    routes = {tuple(line.split(" ", 1)) for line in out.splitlines() if line}
    assert routes == set(subdiv.ROUTES)
    for method in subdiv.ROUTES.values():
        cls, name = method.split(".")
        assert callable(getattr(getattr(subdiv, cls), name)), method


def test_every_endpoint(client, tmp_path):
    assert client.healthz() == {"status": "ok"}
    assert client.livez() == {"status": "ok"}
    ready = client.readyz()        # the memory budget is part of the answer
    assert ready["status"] == "ready" and ready["memory"]["budget_bytes"] > 0
    assert "subdivd_requests_total" in client.metrics()
    assert client.openapi()["openapi"] == "3.1.0"
    s = client.create_session(ttl_s=600)
    assert s.expires_at and s.version is None
    assert s.info()["version"] == 0 and s.version == 0
    assert s.put_rules({"solid_scheme": "averaged"})["version"] == 1 and s.version == 1
    a = s.put_complex(MIXED)
    assert a["version"] == 2 and a["summary"]["simplices"]["3"] == 1
    c = s.get_complex()
    assert c["vertices"] == [[float(x) for x in v] for v in MIXED["vertices"]]
    assert c["rules"]["solid_scheme"] == "averaged"
    assert s.put_tags([[3]])["version"] == 3
    assert s.get_complex()["tags"]["singular"] == [[3]]
    glb = s.level(1)
    assert glb[:4] == b"glTF"
    doc = s.export()
    assert doc["version"] == 3 and doc["tags"]["singular"] == [[3]]
    with client.create_session(import_doc=doc) as t:   # the same session, anew
        assert t.version == 3 and t.id != s.id and t.level(1) == glb
    n = s.level(2, format="vtu", out=tmp_path / "l2.vtu", parts="solids,curves")
    assert n == (tmp_path / "l2.vtu").stat().st_size and not (tmp_path / "l2.vtu.part").exists()
    assert s.level(1, if_none_match=s.version) is None          # 304: unchanged
    lj = s.level_json(1)
    assert lj["level"] == 1 and lj["vertices"]
    st = s.level_stats(2)
    assert (st["counts"]["tetrahedra"], st["counts"]["octahedra"]) == (24, 10)
    v = s.version
    e = s.edit(moves=[{"index": 7, "position": [3, 3, 3.5]}])
    assert e["version"] == v + 1 and s.version == v + 1 and "1" in e["updated_points"]
    mtx = s.matrix(1)
    assert mtx.startswith("%%MatrixMarket")
    csr = s.matrix(1, format="json")
    assert csr["rows"] == len(lj["vertices"]) and csr["cols"] == len(MIXED["vertices"])
    assert s.matrix(1, out=tmp_path / "s.mtx") == (tmp_path / "s.mtx").stat().st_size
    an = s.analysis(vertex=0)
    assert an["eigenvalues"] and an["rule"]
    assert s.analysis(edge=(0, 1))["eigenvalues"]
    r = s.refine({"simplices": [[0, 1, 2, 3]]}, depth=1)
    assert r["refined"]["red"] >= 1 and r["version"] == s.version
    s.delete()
    with pytest.raises(E.NotFound):
        s.info()


def test_put_tags_with_petals(client):
    """Three fins on a spine ending at vertex 0: a complex singular vertex with three open petals;
    one tagged concave through the client, echoed by GET /complex; a bad kind raises 422."""
    V = [[0, 0, 0], [0, 0, 1], [1, 0, 0], [1, 0, 1], [-.5, .8, 0], [-.5, .8, 1], [-.5, -.8, 0],
         [-.5, -.8, 1]]
    T = [[0, 1, a + 1] for a in (2, 4, 6)] + [[0, a + 1, a] for a in (2, 4, 6)]
    petal = {"vertex": 0, "triangle": [0, 3, 2], "kind": "concave"}
    with client.create_session() as s:
        s.put_complex({"vertices": V, "simplices": T})
        s.put_rules({"nonmanifold_surface": "ying-zorin"})
        s.put_tags(petals=[petal])
        assert s.get_complex()["tags"] == {"singular": [], "petals": [petal]}
        with pytest.raises(E.Unprocessable) as e:
            s.put_tags([[1]], petals=[dict(petal, kind="straight")])
        assert e.value.pointer == "/petals/0/kind"


def test_session_context_deletes(client):
    with client.create_session() as s:
        s.put_complex(MIXED)
        sid = s.id
    with pytest.raises(E.NotFound):
        client.session(sid, s.token).info()


def make_error(kind, client, daemon):
    """Provoke one error status; returns the callable that raises it."""
    s = client.create_session()
    if kind == 400:
        return lambda: s.put_complex({"vertices": 3, "simplices": []})
    if kind == 401:
        return lambda: client.session(s.id, "wrong-token").info()
    if kind == 404:
        s.delete()
        return lambda: s.info()
    if kind == 405:
        return lambda: client.request("POST", s.url + "/complex", headers=s.headers(), json_body={})
    if kind == 409:
        return lambda: s.get_complex()
    if kind == 412:
        s.put_complex(MIXED)
        return lambda: s.put_rules({}, if_match=99)
    if kind == 415:
        return lambda: client.request("PUT", s.url + "/complex", data=b"{}",
                                      headers=s.headers(extra={"Content-Type": "text/plain"}))
    if kind == 422:
        return lambda: s.put_complex({"vertices": [[0, 0, 0]], "simplices": [[0, 5]]})
    if kind == 428:
        s.put_complex(MIXED)
        return lambda: s.edit(moves=[{"index": 0, "position": [0, 0, 0]}], if_match=False)
    if kind == 501:   # a transfer coding the daemon does not implement
        return lambda: client.request("PUT", s.url + "/complex", data=b"{}", headers=s.headers(
            extra={"Content-Type": "application/json", "Transfer-Encoding": "gzip"}))
    raise AssertionError(kind)


@pytest.mark.parametrize("status,cls,pointer", [
    (400, E.BadRequest, "/vertices"), (401, E.Unauthorized, None), (404, E.NotFound, None),
    (405, E.MethodNotAllowed, None), (409, E.Conflict, None), (412, E.PreconditionFailed, None),
    (415, E.UnsupportedMediaType, None), (422, E.Unprocessable, "/simplices/0/1"),
    (428, E.PreconditionRequired, None), (501, E.NotImplementedByServer, None)])
def test_error_mapping(client, daemon, status, cls, pointer):
    call = make_error(status, client, daemon)
    with pytest.raises(cls) as ei:
        call()
    e = ei.value
    assert isinstance(e, E.ProblemError) and isinstance(e, E.SubdivError)
    assert e.status == status and e.problem["status"] == status
    assert e.type.startswith("/errors/") and e.slug and e.title and e.detail
    assert e.response is not None and e.response.headers["Content-Type"] == "application/problem+json"
    if pointer:
        assert e.pointer == pointer and e.errors[0]["message"]
    assert str(status) in str(e)
    assert e.exit_code == {400: 1, 409: 1, 412: 1, 415: 1, 422: 1, 428: 1, 501: 4}.get(status, 3)


def test_limit_and_busy_and_server_errors(tmp_path):
    """413 with the limit, 429 with Retry-After, 500 from a missing TetGen helper."""
    d = Daemon("--max-vertices", "10", "--max-sessions", "1", "--tetgen", str(tmp_path / "none"))
    try:
        c = subdiv.Client(d.url)
        s = c.create_session()
        with pytest.raises(E.ContentTooLarge) as ei:
            s.put_complex({"vertices": [[i, 0, 0] for i in range(11)], "simplices": [[0]]})
        assert (ei.value.limit_name, ei.value.limit, ei.value.requested) == ("max_vertices", 10, 11)
        tet = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
        s.put_complex({"vertices": tet, "simplices": [[0, 1, 2, 3]]})  # else it is evictable
        with pytest.raises(E.TooManyRequests) as ei:
            c.create_session()
        assert ei.value.retry_after > 0 and ei.value.slug == "too-many-sessions"
        with pytest.raises(E.ServerError) as ei:
            s.put_complex({"vertices": tet, "fill": [{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]}]})
        assert ei.value.status == 500 and ei.value.slug == "fill-failed"
        assert type(ei.value) is E.ServerError
        s.delete()
    finally:
        assert d.stop() == 0


class _Fake(http.server.BaseHTTPRequestHandler):
    """Answers 503 problem+json twice, then 200; any other path: an HTML 502."""
    hits = 0

    def do_GET(self):
        if self.path == "/readyz":
            _Fake.hits += 1
            if _Fake.hits <= 2:
                body = json.dumps({"type": "/errors/not-ready", "title": "Service Unavailable",
                                   "status": 503, "detail": "starting"}).encode()
                self.send_response(503)
                self.send_header("Content-Type", "application/problem+json")
                self.send_header("Retry-After", "1")
            else:
                body = b'{"status":"ready"}'
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
        else:
            body = b"<html>bad gateway</html>"
            self.send_response(502)
            self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *a):
        pass


def test_503_retry_html_errors_and_transport():
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Fake)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{srv.server_address[1]}"
    try:
        with pytest.raises(E.ServiceUnavailable) as ei:
            subdiv.Client(url).readyz()
        assert ei.value.retry_after == 1 and ei.value.slug == "not-ready"
        assert subdiv.Client(url, retries=2, max_wait=0.05).readyz() == {"status": "ready"}
        with pytest.raises(E.ServerError) as ei:
            subdiv.Client(url).healthz()
        assert ei.value.status == 502 and "bad gateway" in ei.value.detail
    finally:
        srv.shutdown()
    with pytest.raises(E.TransportError):
        subdiv.Client("http://127.0.0.1:1", timeout=2).healthz()


def test_if_match_between_two_writers(client):
    a = client.create_session()
    a.put_complex(MIXED)
    b = client.session(a.id, a.token)
    b.info()
    a.put_rules({"surface_weights": "loop"}, if_match=True)        # a is current: accepted
    with pytest.raises(E.PreconditionFailed):
        b.put_rules({"solid_scheme": "averaged"}, if_match=True)  # b saw an older version
    b.info()
    assert b.put_rules({"solid_scheme": "averaged"}, if_match=True)["version"] == a.version + 1
    with pytest.raises(E.PreconditionFailed):
        a.edit(moves=[{"index": 0, "position": [0, 0, 0]}])        # edits always send If-Match
    a.delete()


def test_progress_events(client):
    from test_fill import surface
    events = []
    cb = lambda kind, done, total: events.append((kind, done, total))
    c = subdiv.Client(client.url, poll_interval=0.02)
    s = c.create_session()
    v, f = surface("icosphere", 2)
    s.put_complex({"vertices": v, "fill": [{"surface": f, "max_volume": 4e-5}]}, progress=cb)
    up = [e for e in events if e[0] == "upload"]
    assert up[0][1] == 0 and up[-1][1] == up[-1][2] > 0
    assert [e for e in events if e[0] == "server"], "TetGen's fill shows as server-side work"
    events.clear()
    data = s.level(1, format="vtu", progress=cb)
    down = [e for e in events if e[0] == "download"]
    assert down[-1][1] == down[-1][2] == len(data)
    assert all(x[1] <= y[1] for x, y in zip(down, down[1:]))
    s.delete()


def test_public_api_has_type_hints():
    """Every public method of Client and Session annotates its parameters and its result."""
    import inspect
    import typing
    for cls in (subdiv.Client, subdiv.Session):
        for name, f in inspect.getmembers(cls, inspect.isfunction):
            if name.startswith("_") and name != "__init__":
                continue
            hints = typing.get_type_hints(f)
            params = [p for p in inspect.signature(f).parameters.values()
                      if p.name != "self" and p.kind is not p.VAR_POSITIONAL]
            missing = [p.name for p in params if p.name not in hints]
            assert not missing and "return" in hints, (cls.__name__, name, missing)


# ---- numpy, meshio and scipy answers ---------------------------------------------------------

CUBE = REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt"


def _with_attributes(body):
    """The body with a scalar and a 2-vector attribute (point data to carry through)."""
    n = len(body["vertices"])
    return dict(body, attributes={"t": [float(i % 5) for i in range(n)],
                                  "uv": [[float(i), 0.5 * i] for i in range(n)]})


def _mesh_bodies():
    from daemon import complex_from_text
    return {"mixed": _with_attributes({k: MIXED[k] for k in ("vertices", "simplices")}),
            "cube": _with_attributes(complex_from_text(CUBE))}


@pytest.mark.parametrize("mesh", ["mixed", "cube"])
def test_level_arrays_match_the_json(client, mesh):
    """level_arrays(): the arrays hold exactly what GET ?format=json (read here with requests,
    not through the client) says, with the documented shapes and dtypes."""
    import numpy as np
    import requests
    with client.create_session() as s:
        s.put_complex(_mesh_bodies()[mesh])
        for L in (0, 2):
            a = s.level_arrays(L)
            j = requests.get(f"{s.url}/levels/{L}", params={"format": "json"},
                             headers={"Authorization": f"Bearer {s.token}"}, timeout=60).json()
            assert (a["level"], a["version"]) == (j["level"], j["version"]) == (L, s.version)
            assert a["positions"].dtype == np.float64 and a["positions"].shape == (len(j["vertices"]), 3)
            assert a["positions"].tolist() == j["vertices"]
            widths = {"points": 1, "edges": 2, "triangles": 3, "tetrahedra": 4, "octahedra": 6}
            assert set(a["cells"]) == set(widths) == set(j["cells"])
            for kind, w in widths.items():
                c = a["cells"][kind]
                assert c.dtype == np.int64 and c.shape[1:] == (() if w == 1 else (w,))
                assert c.tolist() == j["cells"][kind], kind
            assert a["attributes"]["t"].shape == (len(j["vertices"]),)
            assert a["attributes"]["uv"].shape == (len(j["vertices"]), 2)
            assert {k: v.tolist() for k, v in a["attributes"].items()} == j["attributes"]
            assert a["rules"] == j["rules"]
        assert len(s.level_arrays(2)["cells"]["octahedra"]) > 0
        solids = s.level_arrays(1, parts="solids")["cells"]
        assert solids["edges"].shape == (0, 2) and solids["points"].shape == (0,)
        assert "slice" not in s.level_arrays(1)
        sl = s.level_arrays(1, slice="0,0,1,0.5")["slice"]
        j = s.level_json(1, slice="0,0,1,0.5")["slice"]
        assert len(j["triangles"]) > 0
        assert sl["vertices"].tolist() == j["vertices"] and sl["triangles"].tolist() == j["triangles"]
        assert sl["vertices"].shape[1:] == (3,) and sl["triangles"].shape[1:] == (3,)


@pytest.mark.parametrize("mesh", ["mixed", "cube"])
@pytest.mark.parametrize("options", [{}, {"parts": "solids"}])
def test_level_mesh_matches_meshio_reading_the_vtu(client, tmp_path, mesh, options):
    """level_mesh(): meshio reading the daemon's VTU of the same level (octahedra as 4 tetrahedra,
    its default) gives the same points, the same cell blocks (types, counts, vertices), the same
    kind and source_cell cell data and the same attribute point data."""
    import meshio
    import numpy as np
    with client.create_session() as s:
        s.put_complex(_mesh_bodies()[mesh])
        for L in (1, 2):
            m = s.level_mesh(L, **options)
            assert isinstance(m, meshio.Mesh)
            vtu = tmp_path / f"{mesh}_{L}.vtu"
            s.level(L, format="vtu", out=vtu, **options)
            ref = meshio.read(str(vtu))
            assert m.points.dtype == np.float64
            assert np.array_equal(m.points, ref.points)
            assert [(b.type, len(b.data)) for b in m.cells] == [(b.type, len(b.data)) for b in ref.cells]
            for b, r in zip(m.cells, ref.cells):
                assert np.array_equal(b.data, r.data), b.type
            for name in ("kind", "source_cell"):
                for x, y in zip(m.cell_data[name], ref.cell_data[name]):
                    assert np.array_equal(x, y), name
            assert set(m.point_data) == {"t", "uv"} and set(ref.point_data) == {"t", "uv", "rule"}
            for name, v in m.point_data.items():
                assert np.array_equal(v.reshape(len(m.points), -1),
                                      ref.point_data[name].reshape(len(m.points), -1)), name
            counts = s.level_stats(L)["counts"]
            tets = sum(len(b.data) for b in m.cells if b.type == "tetra")
            assert tets == counts["tetrahedra"] + 4 * counts["octahedra"]
            if options:
                assert [b.type for b in m.cells] == ["tetra"]


@pytest.mark.parametrize("mesh", ["mixed", "cube"])
def test_matrix_sparse_reproduces_levels(client, mesh, monkeypatch):
    """matrix_sparse(): a scipy CSR matrix with P @ (level F positions) = level L positions and
    P @ (level F attribute) = level L attribute, to 1e-12, the levels being the daemon's JSON;
    without scipy the JSON CSR dict."""
    import numpy as np
    import scipy.sparse
    with client.create_session() as s:
        s.put_complex(_mesh_bodies()[mesh])
        levels = [s.level_json(L) for L in range(3)]
        for frm, to in ((0, 1), (1, 2), (0, 2)):
            P = s.matrix_sparse(to, from_level=frm)
            assert isinstance(P, scipy.sparse.csr_matrix)
            src, dst = np.array(levels[frm]["vertices"]), np.array(levels[to]["vertices"])
            assert P.shape == (len(dst), len(src))
            np.testing.assert_allclose(P @ src, dst, rtol=0, atol=1e-12)
            np.testing.assert_allclose(P @ np.array(levels[frm]["attributes"]["uv"]),
                                       levels[to]["attributes"]["uv"], rtol=0, atol=1e-12)
        monkeypatch.setitem(sys.modules, "scipy", None)
        monkeypatch.setitem(sys.modules, "scipy.sparse", None)
        j = s.matrix_sparse(2, from_level=1)
        assert isinstance(j, dict) and j == s.matrix(2, 1, format="json")
        assert (j["rows"], j["cols"]) == (len(levels[2]["vertices"]), len(levels[1]["vertices"]))


def test_client_imports_without_numpy_scipy_meshio():
    """numpy, scipy and meshio are imported only by the methods that return their objects."""
    code = ("import sys\n"
            "for m in ('numpy', 'scipy', 'scipy.sparse', 'meshio'): sys.modules[m] = None\n"
            f"sys.path.insert(0, {str(REPO / 'clients' / 'python')!r})\n"
            "import subdiv, subdiv.cli, subdiv.meshes\n"
            "print(subdiv.Session.level_mesh.__name__)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == "level_mesh", r.stderr


def test_meshes_read_unreadable_file_is_mesh_error(tmp_path, capsys):
    """Every file meshio cannot read raises MeshError (docs: clients/README.md), also the ones
    meshio refuses with its ReadError, for which meshio.read prints and calls sys.exit(1)."""
    from subdiv import meshes
    for name, text in (("bad.vtk", "this is not a VTK file\n"), ("bad.vtu", "<not xml\n"),
                       ("bad.msh", "$MeshFormat\nnonsense\n"), ("bad.stl", "garbage\n")):
        (tmp_path / name).write_text(text)
        with pytest.raises(meshes.MeshError, match=name):
            meshes.read(tmp_path / name)
    assert capsys.readouterr().out == ""      # meshio's message is in the MeshError, not printed


def test_meshes_read_obj_and_off_records(tmp_path):
    """OBJ points, polylines and polygons and OFF polygons are posted (clients/README.md:
    vertices, lines, triangles and tetrahedra as they are, quads and polygons split into
    triangles around their first vertex), in file order; bad indices are MeshErrors."""
    from subdiv import meshes
    obj = tmp_path / "a.obj"
    obj.write_text("# points, a polyline, a triangle, a pentagon\n"
                   "v 0 0 0\nv 1 0 0\nv 1 1 0 1.0\nv 0 1 0\nv 0 0 1 0.5 0.5 0.5\n"
                   "vn 0 0 1\nvt 0 0\ng part\nusemtl m\ns off\n"
                   "p 5 -4\nl 1 5 -2\nf 1/1 2/1/1 3//1\nf -1 -2 -3 -4 -5\n")
    body, tags = meshes.read(obj)
    assert tags is None and set(body) == {"vertices", "simplices"}
    assert body["vertices"] == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]]
    assert body["simplices"] == [[4], [1], [0, 4], [4, 3], [0, 1, 2],
                                 [4, 3, 2], [4, 2, 1], [4, 1, 0]]
    body, _ = meshes.read(obj, fill={})           # every 2-D cell, the pentagon split, is the surface
    assert body["fill"] == [{"surface": [[0, 1, 2], [4, 3, 2], [4, 2, 1], [4, 1, 0]]}]
    assert body["simplices"] == [[4], [1], [0, 4], [4, 3]]
    off = tmp_path / "a.off"
    off.write_text("OFF # a header comment\n\n# counts\n5 5 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n"
                   "0 0 1\n4 0 1 2 3\n3 0 1 4 1.0 0.0 0.0\n5 0 1 2 3 4\n2 2 4\n1 4\n")
    body, _ = meshes.read(off)
    assert body["vertices"] == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]]
    assert body["simplices"] == [[0, 1, 2], [0, 2, 3], [0, 1, 4], [0, 1, 2], [0, 2, 3],
                                 [0, 3, 4], [2, 4], [4]]
    off.write_text("COFF\n3 1\n0 0 0 1 0 0 1\n1 0 0 1 0 0 1\n0 1 0 1 0 0 1\n3 0 1 2\n")
    assert meshes.read(off)[0] == {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "simplices": [[0, 1, 2]]}
    for name, text, msg in (
            ("b.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\n", "line 3: vertex index 3"),
            ("c.obj", "v 0 0 0\nl 1\n", "at least 2"),
            ("d.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "vertex index 0"),
            ("e.obj", "v 0 0\n", "line 1"),
            # a record continued with a backslash: errors name the line a record starts on
            ("f.obj", "v 0 0 \\\n0\nv 1 0 0\nv 0 1 0\nf 1 2 \\\n 3\nf 1 2 4\n",
             "line 7: vertex index 4"),
            ("b.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "line 6"),
            ("c.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "2 faces announced"),
            ("d.off", "OFF BINARY\n", "binary"),
            ("e.off", "ply\n", "not an OFF file")):
        (tmp_path / name).write_text(text)
        with pytest.raises(meshes.MeshError, match=msg):
            meshes.read(tmp_path / name)


def test_meshes_read_tetgen_and_cut_short_files(tmp_path):
    """TetGen files are read here (meshio's reader loops forever on a .node or .ele without a
    header line): comments anywhere, 1-based numbering, counts checked against the lines; a
    binary .msh cut short, which meshio reads into a tetra block of 2-index rows, is a MeshError."""
    from subdiv import meshes
    (tmp_path / "a.node").write_text("# points\n4 3 0 1\n1 0 0 0 5  # marker\n2 1 0 0 5\n"
                                     "3 0 1 0 5\n4 0 0 1 5\n")
    (tmp_path / "a.ele").write_text("1 4 0\n1 1 2 4 3\n")
    assert meshes.read(tmp_path / "a.ele")[0] == {
        "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 3, 2]]}
    (tmp_path / "a.ele").write_text("# no header\n\n")
    r = subprocess.run([str(REPO / "build" / "subdiv"), "convert", str(tmp_path / "a.node"), "-o",
                        str(tmp_path / "a.json")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "a.ele: no header line" in r.stderr, r.stderr
    (tmp_path / "a.ele").write_text("2 4 0\n1 1 2 3 4\n")
    with pytest.raises(meshes.MeshError, match="2 tetrahedra announced, the file has 1"):
        meshes.read(tmp_path / "a.node")
    import meshio
    import numpy as np
    msh = tmp_path / "t.msh"
    meshio.write(str(msh), meshio.Mesh(np.eye(4), [("tetra", np.array([[0, 1, 2, 3], [3, 2, 1, 0]]))]),
                 file_format="gmsh", binary=True)
    msh.write_bytes(msh.read_bytes()[:-40])      # into the second tetrahedron
    with pytest.raises(meshes.MeshError, match="tetra cell 0 has 2 point indices"):
        meshes.read(msh)


def test_meshes_read_returns_what_its_docstring_says(tmp_path):
    """meshes.read: (body, tags) — vertices in file order, quads split into triangles, point data
    as attributes, tags None without chosen groups; with fill the 2-D cells move into "fill"."""
    from subdiv import meshes
    obj = tmp_path / "q.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nf 1 2 3 4\nf 1 2 5\n")
    body, tags = meshes.read(obj)
    assert tags is None and set(body) == {"vertices", "simplices"}
    assert body["vertices"] == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]]
    assert body["simplices"] == [[0, 1, 2], [0, 2, 3], [0, 1, 4]]
    body, tags = meshes.read(obj, fill={"max_volume": 0.1})   # every 2-D cell -> the surface
    assert tags is None and "simplices" not in body
    assert body["fill"] == [{"max_volume": 0.1, "surface": [[0, 1, 2], [0, 2, 3], [0, 1, 4]]}]
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    body, _ = meshes.read(obj, fill={})
    assert "simplices" not in body and len(body["fill"][0]["surface"]) == 4
    import meshio
    import numpy as np
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    m = meshio.Mesh(pts, [("tetra", [[0, 1, 2, 3]]), ("line", [[0, 1]]), ("vertex", [[3]])],
                    point_data={"t": np.arange(4.0), "uvw": np.ones((4, 3))},
                    cell_data={"gmsh:physical": [[1], [2], [3]], "gmsh:geometrical": [[1], [2], [3]]},
                    field_data={"solid": np.array([1, 3]), "crease_a": np.array([2, 1]),
                                "corner": np.array([3, 0])})
    msh = tmp_path / "g.msh"
    meshio.write(str(msh), m, file_format="gmsh22", binary=False)
    body, tags = meshes.read(msh)
    assert body["simplices"] == [[0, 1, 2, 3], [0, 1], [3]]
    assert body["attributes"] == {"t": [0.0, 1.0, 2.0, 3.0], "uvw": [[1.0, 1.0, 1.0]] * 4}
    assert sorted(tags) == [[0, 1], [3]]
    assert meshes.read(msh, singular_groups=["solid"])[1] == []      # chosen, no such cells
    assert meshes.read(msh, singular_groups=[])[1] is None


def test_events_close_from_another_thread(client):
    """clients/README.md: `.close()` stops an event stream, "read or not". A thread blocked in
    the iteration (no event, the next heartbeat 15 s away) ends its loop at once, without an
    exception, and close() itself does not wait for the heartbeat either."""
    import time
    s = client.create_session()
    s.put_complex(MIXED)
    ev = s.events()
    seen, errors = [], []

    def read():
        try:
            for e in ev:
                seen.append(e)
        except BaseException as e:  # noqa: B902 - any exception is the failure
            errors.append(e)

    t = threading.Thread(target=read, daemon=True)
    t.start()
    time.sleep(0.3)
    t0 = time.time()
    ev.close()
    t.join(5)
    assert not t.is_alive(), "the reading thread is still blocked after close()"
    assert time.time() - t0 < 2, "close() waited for the next heartbeat"
    assert errors == [] and seen == []
    # a stream read to its end ("deleted"), then closed: the client's other requests go on
    other = client.create_session()
    ev = other.events()
    other.delete()
    assert [e["event"] for e in ev] == ["deleted"]
    assert client.healthz() == {"status": "ok"}
    ev.close()
    for _ in range(3):
        assert client.healthz() == {"status": "ok"}
        assert s.info()["version"] == 1
    s.delete()
