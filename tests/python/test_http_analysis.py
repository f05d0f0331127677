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


@pytest.mark.parametrize("params,status,pointer", [
    ({}, 400, None), ({"vertex": 0, "edge": "0,1"}, 400, None), ({"vertex": "x"}, 400, "vertex"),
    ({"vertex": 99}, 422, "vertex"), ({"edge": "0"}, 400, "edge"), ({"edge": "1,5"}, 422, "edge"),
    ({"edge": "0,99"}, 422, "edge"), ({"node": 1}, 400, "node")])
def test_analysis_errors(daemon, params, status, pointer):
    s = Session(daemon)
    assert s.put_complex(bipyramid()).status_code == 200
    r = s.req("GET", "/analysis", params=params)
    assert r.status_code == status, r.text
    assert r.headers["Content-Type"] == "application/problem+json"
    if pointer:
        assert r.json()["errors"][0]["pointer"] == pointer


def test_analysis_needs_complex(daemon):
    r = Session(daemon).req("GET", "/analysis", params={"vertex": 0})
    assert r.status_code == 409
