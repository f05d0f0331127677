"""PUT /tags "crease_angle" (docs/API.md "Tags", DECISIONS 42): surface edges (maximal triangles'
and solid boundaries') whose dihedral angle is strictly greater than the threshold become
singular tags. Expected edges and positions come from the shapes' geometry: a tetrahedralized
2x2x2 cube keeps its 12 edge lines straight and its 8 corners fixed; a cube surface of 12
triangles tags its 12 edges (90 degrees) and none of its face diagonals (0 degrees); a smooth
icosphere tags nothing at 60 degrees; the range is checked."""
import itertools
import json
import math
import subprocess

import numpy as np
import pytest

from daemon import SUBDIVD, Daemon, Session
from meshes import icosphere


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


# the unit cube as 6 tetrahedra around its main diagonal 0-7 (corner id = x + 2y + 4z): every
# face is split along the diagonal through the corner nearest 0, so translated copies conform
CELL_T = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]]


def tet_cube(n=2):
    """An n x n x n grid of unit cells, 6 tetrahedra each, over [0, n]^3."""
    vid = {}
    verts = []
    for z, y, x in itertools.product(range(n + 1), repeat=3):
        vid[(x, y, z)] = len(verts)
        verts.append([float(x), float(y), float(z)])
    tets = []
    for x, y, z in itertools.product(range(n), repeat=3):
        corner = [vid[(x + (c & 1), y + (c >> 1 & 1), z + (c >> 2 & 1))] for c in range(8)]
        tets += [[corner[i] for i in t] for t in CELL_T]
    return verts, tets


def cube_edge_segments(verts, n):
    """The edges of the grid that lie on the cube's 12 edge lines: 12 n segments."""
    out = set()
    idx = {tuple(v): i for i, v in enumerate(verts)}
    for v in verts:
        for k in range(3):
            w = list(v)
            w[k] += 1
            if tuple(w) not in idx:
                continue
            others = [v[j] for j in range(3) if j != k]
            if all(c in (0, n) for c in others):
                out.add(tuple(sorted((idx[tuple(v)], idx[tuple(w)]))))
    return out


def on_edge_line(p, n):
    return sum(abs(c) < 1e-12 or abs(c - n) < 1e-12 for c in p) >= 2


def test_tet_cube_keeps_edges_and_corners(daemon):
    n = 2
    verts, tets = tet_cube(n)
    s = Session(daemon)
    assert s.put_complex({"vertices": verts, "simplices": tets}).status_code == 200
    r = s.req("PUT", "/tags", json={"crease_angle": 30})
    assert r.status_code == 200, r.text
    expect = cube_edge_segments(verts, n)
    assert len(expect) == 24
    assert r.json()["crease_angle"] == {"degrees": 30, "tagged": 24}
    c = s.req("GET", "/complex").json()
    assert {tuple(sorted(e)) for e in c["tags"]["singular"]} == expect
    assert c["tags"]["crease_angle"] == {"degrees": 30, "tagged": 24}
    corners = [[x, y, z] for z in (0, n) for y in (0, n) for x in (0, n)]
    for level in (1, 2, 3):
        p = np.array(s.level(level, format="json").json()["vertices"])
        for q in corners:  # the corners are level points at their places
            assert np.min(np.linalg.norm(p - q, axis=1)) == 0.0
        # every point that started on an edge line stays on it: the points on the lines are
        # exactly those of the edge segments' subdivision, 12 n 2^level + 1 per line, in total
        online = [i for i in range(len(p)) if on_edge_line(p[i], n)]
        assert len(online) == 12 * (n * 2 ** level - 1) + 8
    # without the crease angle the corners move
    t = Session(daemon)
    assert t.put_complex({"vertices": verts, "simplices": tets}).status_code == 200
    p = np.array(t.level(1, format="json").json()["vertices"])
    assert not any(np.min(np.linalg.norm(p - q, axis=1)) == 0.0 for q in corners)


def test_tet_cube_straight_edges_exact(daemon):
    """The points on the edge lines lie on them up to rounding and move only along them."""
    n = 2
    verts, tets = tet_cube(n)
    s = Session(daemon)
    assert s.put_complex({"vertices": verts, "simplices": tets}).status_code == 200
    assert s.req("PUT", "/tags", json={"crease_angle": 89.9}).status_code == 200
    for level in (1, 2, 3):
        j = s.level(level, format="json").json()
        p = np.array(j["vertices"])
        crease = [i for i, r in enumerate(j["rules"]) if r == "curve"]
        assert len(crease) == 12 * (n * 2 ** level - 1)  # every point inside an edge line
        for i in crease:
            assert on_edge_line(p[i], n), p[i]


def cube_surface():
    v = [[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    tris = []
    for q in quads:
        tris += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    return v, tris


def test_cube_surface_exact_count(daemon):
    v, tris = cube_surface()
    edges = [(a, b) for a in range(8) for b in range(a + 1, 8) if (a ^ b) in (1, 2, 4)]
    s = Session(daemon)
    assert s.put_complex({"vertices": v, "simplices": tris}).status_code == 200
    r = s.req("PUT", "/tags", json={"crease_angle": 45})
    assert r.status_code == 200 and r.json()["crease_angle"]["tagged"] == 12
    got = {tuple(sorted(e)) for e in s.req("GET", "/complex").json()["tags"]["singular"]}
    assert got == set(edges)  # the 12 edges, none of the 6 face diagonals
    # strictly greater: at 90 degrees nothing; one listed edge is not added twice
    r = s.req("PUT", "/tags", json={"crease_angle": 90})
    assert r.json()["crease_angle"]["tagged"] == 0
    r = s.req("PUT", "/tags", json={"crease_angle": 0, "singular": [[1, 0]]})
    assert r.json()["crease_angle"]["tagged"] == 12
    sing = s.req("GET", "/complex").json()["tags"]["singular"]
    assert len(sing) == 12 and sing[0] == [1, 0]
    # flipped triangles (inconsistent orientation) give the same angles
    t = Session(daemon)
    flipped = [tri[::-1] if i % 3 == 0 else tri for i, tri in enumerate(tris)]
    assert t.put_complex({"vertices": v, "simplices": flipped}).status_code == 200
    assert t.req("PUT", "/tags", json={"crease_angle": 45}).json()["crease_angle"]["tagged"] == 12
    # tags of a later PUT /tags without crease_angle replace them (no re-evaluation)
    assert s.req("PUT", "/tags", json={"singular": []}).status_code == 200
    assert s.req("GET", "/complex").json()["tags"] == {"singular": []}


def test_sphere_tags_nothing(daemon):
    v, f = icosphere(2)
    # the largest dihedral angle of the sphere, from its geometry: under 60 degrees
    x = np.array(v)
    normal = {}
    for i, (a, b, c) in enumerate(f):
        normal[i] = np.cross(x[b] - x[a], x[c] - x[a])
    by_edge = {}
    for i, tri in enumerate(f):
        for j in range(3):
            by_edge.setdefault(tuple(sorted((tri[j], tri[(j + 1) % 3]))), []).append(i)
    worst = max(math.degrees(math.acos(np.dot(normal[p], normal[q]) /
                                       np.linalg.norm(normal[p]) / np.linalg.norm(normal[q])))
                for p, q in by_edge.values())
    assert 5 < worst < 60
    s = Session(daemon)
    assert s.put_complex({"vertices": v, "simplices": f}).status_code == 200
    r = s.req("PUT", "/tags", json={"crease_angle": 60})
    assert r.status_code == 200 and r.json()["crease_angle"] == {"degrees": 60, "tagged": 0}
    assert s.req("GET", "/complex").json()["tags"]["singular"] == []
    # and below the sphere's angles, every edge
    r = s.req("PUT", "/tags", json={"crease_angle": worst / 10})
    assert r.json()["crease_angle"]["tagged"] == len(by_edge) == 30 * 16


def test_open_and_nonmanifold_edges_skipped(daemon):
    # three triangles on one edge (0,1) at 120 degrees: non-manifold; the rest are open edges
    v = [[0, 0, 0], [0, 0, 1], [1, 0, 0], [-0.5, 0.8660254037844386, 0],
         [-0.5, -0.8660254037844386, 0]]
    s = Session(daemon)
    assert s.put_complex({"vertices": v, "simplices": [[0, 1, 2], [0, 1, 3], [0, 1, 4]]}).status_code == 200
    r = s.req("PUT", "/tags", json={"crease_angle": 0})
    assert r.status_code == 200 and r.json()["crease_angle"]["tagged"] == 0


@pytest.mark.parametrize("value,status", [(-1, 422), (180.5, 422), ("45", 400), (None, 400),
                                          (True, 400), ([45], 400)])
def test_crease_angle_validation(daemon, value, status):
    v, tris = cube_surface()
    s = Session(daemon)
    assert s.put_complex({"vertices": v, "simplices": tris}).status_code == 200
    assert s.req("PUT", "/tags", json={"singular": [[0, 1]]}).status_code == 200
    r = s.req("PUT", "/tags", json={"crease_angle": value})
    assert r.status_code == status and r.headers["Content-Type"].startswith("application/problem+json")
    assert r.json()["errors"][0]["pointer"] == "/crease_angle"
    # all-or-nothing: the tags are as before
    assert s.req("GET", "/complex").json()["tags"] == {"singular": [[0, 1]]}
    assert s.req("GET").json()["version"] == 2


def test_crease_angle_just_outside_names_the_value(daemon):
    """A value just above 180 is refused with the value as sent, not rounded onto the bound."""
    v, tris = cube_surface()
    s = Session(daemon)
    assert s.put_complex({"vertices": v, "simplices": tris}).status_code == 200
    r = s.req("PUT", "/tags", json={"crease_angle": 180.0000001})
    assert r.status_code == 422
    assert r.json()["detail"].endswith("not 180.0000001")


def test_crease_angle_before_a_complex(daemon):
    s = Session(daemon)
    r = s.req("PUT", "/tags", json={"crease_angle": 30})
    assert r.status_code == 409 and r.json()["errors"][0]["pointer"] == "/crease_angle"


def test_offline_crease_angle(tmp_path):
    verts, tets = tet_cube(2)
    src = tmp_path / "cube.json"
    src.write_text(json.dumps({"vertices": verts, "simplices": tets}))
    out = tmp_path / "l1.json"
    r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "1", "--crease-angle", "45",
                        "-o", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "24 edges tagged" in r.stderr
    p = np.array(json.loads(out.read_text())["vertices"])
    assert np.min(np.linalg.norm(p - [2, 2, 2], axis=1)) == 0.0
    r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "1", "--crease-angle", "x",
                        "-o", str(out)], capture_output=True, text=True)
    assert r.returncode == 2
    r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "1", "--crease-angle", "181",
                        "-o", str(out)], capture_output=True, text=True)
    assert r.returncode == 1 and "/crease_angle" in r.stderr
    # a value strtod reads but JSON cannot carry is refused, not silently dropped
    for bad in ("nan", "inf", "-inf", "1e999"):
        r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "1", "--crease-angle", bad,
                            "-o", str(out)], capture_output=True, text=True)
        assert r.returncode == 2 and "--crease-angle" in r.stderr, (bad, r.returncode, r.stderr)


def test_python_client_and_cli(daemon, tmp_path):
    import sys
    from conftest import REPO
    sys.path.insert(0, str(REPO / "clients" / "python"))
    from subdiv import Client
    v, tris = cube_surface()
    with Client(daemon.url).create_session() as s:
        s.put_complex({"vertices": v, "simplices": tris})
        assert s.put_tags(crease_angle=45)["crease_angle"] == {"degrees": 45, "tagged": 12}
        assert len(s.get_complex()["tags"]["singular"]) == 12
    src = tmp_path / "cube.json"
    src.write_text(json.dumps({"vertices": v, "simplices": tris}))
    r = subprocess.run([str(REPO / "build" / "subdiv"), "refine", str(src), "--url", daemon.url,
                        "--level", "1", "--crease-angle", "45", "-o", str(tmp_path / "a.json")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "cube.json: crease angle 45: 12 edges tagged" in r.stderr
    for bad in ("nan", "inf"):  # refused before anything is sent
        r = subprocess.run([str(REPO / "build" / "subdiv"), "refine", str(src), "--url", daemon.url,
                            "--level", "1", "--crease-angle", bad, "-o", str(tmp_path / "b.json")],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and "crease_angle" in r.stderr, (bad, r.returncode, r.stderr)
        assert not (tmp_path / "b.json").exists()
    p = np.array(json.loads((tmp_path / "a.json").read_text())["vertices"])
    np.testing.assert_array_equal(p[:8], np.array(v, dtype=float))  # corners fixed
