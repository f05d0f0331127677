"""GET /analysis against 001 Appendix B: the bipyramid centre's 1-ring block M equals B.1's
printed 6x6 matrix and has the paper's eigenvalues; an edge's block L is (2k+3)x(2k+3), affine
(rows sum to 1) and has the dominant eigenvalue 1."""
import math

import numpy as np
import pytest

from daemon import Daemon, Session


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


def bipyramid():
    v = [[0, 0, 0], [0, 0, 1]]
    v += [[math.cos(2 * math.pi * i / 3), math.sin(2 * math.pi * i / 3), 0.05 * i] for i in range(3)]
    v.append([0.1, 0, -1])
    s = []
    for i in range(3):
        a, b = 2 + i, 2 + (i + 1) % 3
        s += [[0, 1, a, b], [0, 5, a, b]]
    return {"vertices": v, "simplices": s}


def edge_star(k):
    v = [[0, 0, 1], [0, 0, -1]] + [[math.cos(2 * math.pi * i / k), math.sin(2 * math.pi * i / k), 0]
                                    for i in range(k)]
    return {"vertices": v, "simplices": [[0, 1, 2 + i, 2 + (i + 1) % k] for i in range(k)]}


def test_appendix_b1_vertex(daemon):
    s = Session(daemon)
    assert s.put_complex(bipyramid()).status_code == 200
    r = s.req("GET", "/analysis", params={"vertex": 0})
    assert r.status_code == 200, r.text
    j = r.json()
    assert j["rule"] == "solid" and j["size"] == 6 and j["closed"] is True
    ids = j["points"]["ids"]
    # the block acts on the control points: the centre, then its 5 neighbours (B.1's order is
    # centre, apex 1, the three ring vertices 2, 3, 4, apex 5)
    assert j["points"]["level"] == 0 and ids[0] == 0 and sorted(ids[1:]) == [1, 2, 3, 4, 5]
    M = np.array(j["matrix"])
    s16, e, q, f, w = 1 / 16, 1 / 8, 1 / 4, 5 / 16, 7 / 80
    B1 = np.array([[9 * s16, w, w, w, w, w], [f, f, e, e, e, 0], [q, e, q, e, e, e],
                   [q, e, e, q, e, e], [q, e, e, e, q, e], [f, 0, e, e, e, f]])
    order = [ids.index(v) for v in range(6)]
    np.testing.assert_allclose(M[np.ix_(order, order)], B1, atol=1e-15)
    want = sorted([1, 5 / 16, (15 + math.sqrt(70)) / 80, 1 / 8, 1 / 8, (15 - math.sqrt(70)) / 80],
                  key=lambda x: -abs(x))
    np.testing.assert_allclose(j["eigenvalues"], want, atol=1e-9)


@pytest.mark.parametrize("k", [3, 4, 5, 6])
def test_edge_block(daemon, k):
    s = Session(daemon)
    assert s.put_complex(edge_star(k)).status_code == 200
    r = s.req("GET", "/analysis", params={"edge": "0,1"})
    assert r.status_code == 200, r.text
    j = r.json()
    # (2k+3) points for skew diagonals (001 Fig. 23); Algorithm 2 may point some diagonals at the
    # edge, which gives the midpoint more neighbours
    assert j["size"] >= 2 * k + 3 and j["rule"] == "solid"
    L = np.array(j["matrix"])
    assert L.shape == (j["size"], j["size"])
    np.testing.assert_allclose(L.sum(axis=1), 1, atol=1e-14)
    ev = j["eigenvalues"]
    assert abs(ev[0] - 1) < 1e-12
    mags = [abs(complex(*x)) if isinstance(x, list) else abs(x) for x in ev]
    assert mags == sorted(mags, reverse=True) and mags[1] < 1


@pytest.mark.parametrize("params,status,slug", [
    ({"vertex": "x"}, 400, "bad-parameter"), ({"vertex": "-1"}, 400, "bad-parameter"),
    ({"edge": "0,x"}, 400, "bad-parameter"), ({"vertex": "1.0"}, 400, "bad-parameter"),
    ({"vertex": "4294967296"}, 422, "out-of-range"),
    ({"vertex": "99999999999999999999"}, 422, "out-of-range"),
    ({"edge": "0,99999999999999999999"}, 422, "out-of-range")])
def test_analysis_query_values(daemon, params, status, slug):
    """vertex= and edge= are query parameters: a value that is not an index is a 400
    bad-parameter (docs/SERVICE.md "Errors"; it was wrong-type, the slug of a body of the wrong
    shape), and an index past every vertex is a 422 out-of-range whether or not it fits in a
    machine integer (20 digits were a 400)."""
    s = Session(daemon)
    assert s.put_complex(bipyramid()).status_code == 200
    r = s.req("GET", "/analysis", params=params)
    assert r.status_code == status and r.json()["type"] == "/errors/" + slug, r.text
    assert r.json()["errors"][0]["pointer"] == next(iter(params)), r.text


@pytest.mark.parametrize("params,status,pointer", [
    ({}, 400, "vertex"), ({"vertex": 0, "edge": "0,1"}, 400, "vertex"), ({"vertex": "x"}, 400, "vertex"),
    ({"vertex": 99}, 422, "vertex"), ({"edge": "0"}, 400, "edge"), ({"edge": "1,2,3"}, 400, "edge"),
    ({"edge": "1,5"}, 422, "edge"),
    ({"edge": "0,99"}, 422, "edge"), ({"node": 1}, 400, "node")])
def test_analysis_errors(daemon, params, status, pointer):
    s = Session(daemon)
    assert s.put_complex(bipyramid()).status_code == 200
    r = s.req("GET", "/analysis", params=params)
    assert r.status_code == status, r.text
    assert r.headers["Content-Type"] == "application/problem+json"
    pointers = [e["pointer"] for e in r.json()["errors"]]
    assert pointers[0] == pointer, r.text
    if "vertex" in params and "edge" in params or not params:   # both named: one of each is wrong
        assert pointers == ["vertex", "edge"], r.text
        # query parameters, not body fields: neither is a missing parameter, both a bad one
        want = "missing-parameter" if not params else "bad-parameter"
        assert r.json()["type"] == f"/errors/{want}", r.text
    if params.get("edge") == "1,2,3":
        assert "two vertex indices" in r.json()["detail"], r.text


def test_analysis_needs_complex(daemon):
    r = Session(daemon).req("GET", "/analysis", params={"vertex": 0})
    assert r.status_code == 409


def test_appendix_b2_edge_skew_diagonals(daemon):
    """001 B.2: the valence-4 edge with skew diagonals (Fig. 23, first row) — pair 1 of each
    tetrahedron (p0, p2, c_i, c_i+1) is p0-c_i | p2-c_i+1 — has the printed eigenvalues."""
    s = Session(daemon)
    body = edge_star(4)
    body["diagonals"] = [[i, 1] for i in range(4)]
    assert s.put_complex(body).status_code == 200
    assert s.req("GET", "/complex").json()["diagonals"] == body["diagonals"]
    j = s.req("GET", "/analysis", params={"edge": "0,1"}).json()
    assert j["size"] == 11 and j["closed"] and j["points"]["level"] == 1
    r2 = math.sqrt(2)
    want = sorted([1, (45 + math.sqrt(985)) / 160, (25 + 6 * r2) / 80, (25 + 6 * r2) / 80, 19 / 80,
                   (25 - 6 * r2) / 80, (25 - 6 * r2) / 80, 3 / 16, 13 / 80, 13 / 80,
                   (45 - math.sqrt(985)) / 160], key=lambda x: -abs(x))
    np.testing.assert_allclose(j["eigenvalues"], want, atol=1e-9)


def test_edge_with_diagonals_toward_it_is_regular(daemon):
    """All diagonals at the edge (pair 0): its midpoint is a regular octet-truss vertex, so the
    block has the regular box-spline spectrum {1, 1/2 x3, 1/4 x6, 1/8 x4, 1/16}
    (docs/DECISIONS.md 2)."""
    s = Session(daemon)
    body = edge_star(4)
    body["diagonals"] = [[i, 0] for i in range(4)]
    assert s.put_complex(body).status_code == 200
    j = s.req("GET", "/analysis", params={"edge": "0,1"}).json()
    want = [1] + [0.5] * 3 + [0.25] * 6 + [0.125] * 4 + [1 / 16]
    np.testing.assert_allclose(sorted(j["eigenvalues"], reverse=True), want, atol=1e-9)


@pytest.mark.parametrize("k", [4, 5])
def test_averaged_edge_block_is_closed_for_every_diagonal(daemon, k):
    """The averaged scheme's vertex rows read the vertices opposite across octahedra (all three
    pairs, not only the major diagonal), and its masks do not depend on which pair is the major
    diagonal: the edge's block (its midpoint at level 1, which lies in octahedra) holds those
    octahedra's cell points, is closed, has the simple dominant eigenvalue 1, and has one spectrum
    for every choice of diagonals."""
    spectra = []
    for pair in (0, 1, 2):
        s = Session(daemon)
        body = edge_star(k)
        body["diagonals"] = [[i, pair] for i in range(k)]
        assert s.put_complex(body).status_code == 200
        assert s.req("PUT", "/rules", json={"solid_scheme": "averaged"}).status_code == 200
        j = s.req("GET", "/analysis", params={"edge": "0,1"}).json()
        assert j["closed"] is True, pair
        L = np.array(j["matrix"])
        np.testing.assert_allclose(L.sum(axis=1), 1, atol=1e-14)
        ev = sorted(np.linalg.eigvals(L), key=lambda z: (-abs(z), -z.real, -z.imag))
        assert abs(ev[0] - 1) < 1e-12 and abs(ev[1]) < 1 - 1e-6
        spectra.append(np.array(ev))
        assert j["limit"]["method"] == "eigenvector"
        assert len(j["limit_mask"]) == j["size"] and abs(sum(j["limit_mask"]) - 1) < 1e-12
    for sp in spectra[1:]:
        np.testing.assert_allclose(sp, spectra[0], atol=1e-9)


@pytest.mark.parametrize("diag,status,pointer", [
    ([[0, 3]], 422, "/diagonals/0/1"), ([[9, 0]], 422, "/diagonals/0/0"),
    ([[0, 1], [0, 2]], 422, "/diagonals/1/0"), ([[0]], 400, "/diagonals/0"),
    ("x", 400, "/diagonals")])
def test_diagonal_errors(daemon, diag, status, pointer):
    s = Session(daemon)
    body = edge_star(4)
    body["diagonals"] = diag
    r = s.put_complex(body)
    assert r.status_code == status and r.json()["errors"][0]["pointer"] == pointer


def test_diagonal_on_a_triangle(daemon):
    s = Session(daemon)
    body = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "simplices": [[0, 1, 2]], "diagonals": [[0, 0]]}
    r = s.put_complex(body)
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/diagonals/0/0"


def disk_fan(k):
    """A flat disk of k triangles around vertex 0: its 1-ring block has k + 1 points (Loop)."""
    v = [[0, 0, 0]] + [[math.cos(2 * math.pi * i / k), math.sin(2 * math.pi * i / k), 0]
                       for i in range(k)]
    return {"vertices": v, "simplices": [[0, 1 + i, 1 + (i + 1) % k] for i in range(k)]}


def test_analysis_size_is_bounded_before_the_work(daemon):
    """docs/API.md: a block of more than 256 points is a 422 naming the vertex, refused before any
    matrix is made; at 256 points it is answered, its Loop block being (k+1)x(k+1) with the
    dominant eigenvalue 1, and "full" (the 2-ring, over 256 points) is null."""
    s = Session(daemon)
    assert s.put_complex(disk_fan(255)).status_code == 200
    r = s.req("GET", "/analysis", params={"vertex": 0})
    assert r.status_code == 200, r.text
    j = r.json()
    assert j["size"] == 256 and j["rule"] == "loop"
    assert abs(j["eigenvalues"][0] - 1) < 1e-9
    assert j["full"] is None
    s2 = Session(daemon)
    assert s2.put_complex(disk_fan(400)).status_code == 200
    r = s2.req("GET", "/analysis", params={"vertex": 0})
    assert r.status_code == 422, r.text
    p = r.json()
    assert p["type"].endswith("/not-analysable") and p["errors"][0]["pointer"] == "vertex", p
    assert "401 points" in p["detail"] and "256" in p["detail"]
    # refused before the finer levels the limit mask and the full matrix read were made: levels 0
    # and 1 only (the block's own)
    assert s2.req("GET", "").json()["levels_cached"] == 2
    # the session is untouched: a rim vertex of it (a boundary vertex: itself and its two boundary
    # neighbours) is still analysable
    r = s2.req("GET", "/analysis", params={"vertex": 1})
    assert r.status_code == 200, r.text
    assert r.json()["size"] == 3 and r.json()["rule"] == "loop-boundary", r.text


def kuhn_block(n):
    """n^3 cubes of 6 tetrahedra around their main diagonals (vertex id x + (n+1) y + (n+1)^2 z)."""
    m = n + 1
    v = [[x, y, z] for z in range(m) for y in range(m) for x in range(m)]
    perms = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    s = []
    for z in range(n):
        for y in range(n):
            for x in range(n):
                for p in perms:
                    c = [x, y, z]
                    t = [c[0] + m * c[1] + m * m * c[2]]
                    for k in p:
                        c[k] += 1
                        t.append(c[0] + m * c[1] + m * m * c[2])
                    s.append(t)
    return {"vertices": v, "simplices": s}


def test_analysis_over_the_session_memory_is_413():
    """The session's memory limit reached while the analysis computes is the limit it is (413
    limit-exceeded naming it), not a block that cannot be analysed."""
    d = Daemon("--max-session-bytes", "1048576")
    try:
        s = Session(d)
        assert s.put_complex(kuhn_block(5)).status_code == 200
        r = s.req("GET", "/analysis", params={"edge": "37,38"})
        assert r.status_code == 413, r.text
        assert r.json()["type"].endswith("/limit-exceeded"), r.text
    finally:
        assert d.stop() == 0
