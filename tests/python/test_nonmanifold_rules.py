"""Non-manifold rules per simplex and by default (000 Sec. 3.5, Figs. 15-17; docs/RULES.md, docs/SERVICE.md "Rules").

The configuration of 000 Fig. 17: an octahedron made of 4 tetrahedra around its z diagonal
and two triangles T1, T2 hanging on two opposite equator edges (type-1 junctions). Expected
values are derived by hand from the stencils of docs/RULES.md (each derivation is in the test),
plus the paper's statements checked as relations between complexes:
  - N1 with dimension 3: "the boundary of the 3-simplex region does not change at all" — the
    solid subdivides exactly as the octahedron alone (000 Fig. 17c: as if the other cells were absent);
  - N1 with dimension 2: the triangles subdivide exactly as T1 and T2 alone;
  - G1: the singular vertex keeps its position at every level, a G1 edge is a crease;
  - G2 (default): the junction moves by the 3-simplex stencil with the relieved ring.
Then N2 at three fins sharing an edge, the default G1, the echo in GET /complex, and every
error path of the overrides.
"""
import numpy as np
import pytest

from daemon import Daemon, Session

# octahedron: 0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z; T1 on edge 0-2, T2 on edge 1-3
OCTA_V = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
OCTA_T = [[4, 5, 0, 2], [4, 5, 2, 1], [4, 5, 1, 3], [4, 5, 3, 0]]
FIG17_V = OCTA_V + [[1.5, 1.5, 0], [-1.5, -1.5, 0]]
FIG17_TRI = [[0, 2, 6], [1, 3, 7]]
FIG17 = {"vertices": FIG17_V, "simplices": OCTA_T + FIG17_TRI}
JUNCTION_V = [0, 1, 2, 3]
JUNCTION_E = [[0, 2], [1, 3]]


@pytest.fixture(scope="module")
def daemon():
    d = Daemon("--max-sessions", "1000")   # one session per configuration, none deleted
    yield d
    assert d.stop() == 0


def session(daemon, body, rules=None, tags=None):
    s = Session(daemon)
    r = s.put_complex(body)
    assert r.status_code == 200, r.text
    if rules is not None:
        r = s.req("PUT", "/rules", json=rules)
        assert r.status_code == 200, r.text
    if tags is not None:
        r = s.req("PUT", "/tags", json={"singular": tags})
        assert r.status_code == 200, r.text
    return s


def level(s, L):
    r = s.level(L, format="json")
    assert r.status_code == 200, r.text
    return r.json()


def n1(dim):
    return {"overrides": [{"simplex": [v], "rule": "N1", "dimension": dim} for v in JUNCTION_V] +
                         [{"simplex": e, "rule": "N1", "dimension": dim} for e in JUNCTION_E]}


def part_points(j, kinds):
    """Positions of the vertices used by cells of the given kinds, as a sorted array."""
    ids = sorted({i for k in kinds for c in j["cells"][k] for i in c})
    p = np.array(j["vertices"])[ids]
    return p[np.lexsort(p.T[::-1])]


def test_fig17_level1_by_hand(daemon):
    """Level-1 positions of junction vertex 0 and junction edge 0-2 under each rule.
    p0 = (1,0,0); its neighbours: 2, 3 (equator), 4, 5 (poles), 6 (T1's tip (1.5,1.5,0))."""
    cases = {
        # N1(3): Loop on the octahedron's boundary, m = 4 (2,3,4,5), Warren c = 3/32:
        #   (1 - 4*3/32) p0 + 3/32 (p2+p3+p4+p5) = 5/8 p0 + 0 = (0.625, 0, 0).
        # edge 0-2 on the boundary surface, opposite 4 and 5: 3/8 (p0+p2) + 1/8 (p4+p5).
        "N1-3": (n1(3), [0.625, 0, 0], [0.375, 0.375, 0]),
        # N1(2): boundary of T1, B-spline along 2 and 6: (6 p0 + p2 + p6)/8 = (0.9375, 0.3125, 0);
        # edge 0-2 a boundary edge of T1: midpoint.
        "N1-2": (n1(2), [0.9375, 0.3125, 0], [0.5, 0.5, 0]),
        # G1 on the vertices: 0-mask; the edge keeps the default G2 (see below).
        "G1-vertices": ({"overrides": [{"simplex": [v], "rule": "G1"} for v in JUNCTION_V]},
                        [1, 0, 0], [0.5, 0.5, 0]),
        # G1 on the edges: creases; vertex 0 ends one crease (a corner): fixed; edge: midpoint.
        "G1-edges": ({"overrides": [{"simplex": e, "rule": "G1"} for e in JUNCTION_E]},
                     [1, 0, 0], [0.5, 0.5, 0]),
        # G2: 9/16 p0 + 7/(16*5) (p2+p3+p4+p5+p6) = (0.5625 + 7/80*1.5, 7/80*1.5, 0);
        # edge 0-2: ring = common neighbours {4,5,6}, k = 3: 5/16 (p0+p2) + 1/8 (p4+p5+p6)
        #   = (5/16 + 3/16, 5/16 + 3/16, 0) = (0.5, 0.5, 0).
        "G2": ({}, [0.5625 + 7 / 80 * 1.5, 7 / 80 * 1.5, 0], [0.5, 0.5, 0]),
    }
    for name, (rules, v0, e02) in cases.items():
        s = session(daemon, FIG17, rules)
        j = level(s, 1)
        p = np.array(j["vertices"])
        np.testing.assert_allclose(p[0], v0, atol=1e-14, err_msg=name)
        (mid,) = [i for i, e in enumerate(j["origin"]["edge_of"]) if e and sorted(e) == [0, 2]]
        np.testing.assert_allclose(p[mid], e02, atol=1e-14, err_msg=name)
        # the far pole and T1's tip follow their own manifold rules whatever the junction does:
        # pole 4: Loop on the boundary, 5/8 p4 + 3/32 (p0+p1+p2+p3) = (0, 0, 0.625);
        # tip 6: boundary of T1, (6 p6 + p0 + p2)/8 = (1.25, 1.25, 0)
        np.testing.assert_allclose(p[4], [0, 0, 0.625], atol=1e-14, err_msg=name)
        np.testing.assert_allclose(p[6], [1.25, 1.25, 0], atol=1e-14, err_msg=name)


def test_fig17_reported_rules(daemon):
    expect = {"N1-3": (n1(3), "N1"), "N1-2": (n1(2), "N1"), "G2": ({}, "G2"),
              "G1": ({"nonmanifold_default": "G1"}, "G1")}
    for name, (rules, rule) in expect.items():
        s = session(daemon, FIG17, rules)
        c = s.req("GET", "/complex").json()
        for v in JUNCTION_V:
            assert c["classes"]["vertices"][v]["rule"] == rule, name
            assert c["classes"]["vertices"][v]["nonmanifold"] == 1
        junction = [e for e in c["classes"]["edges"] if sorted(e["vertices"]) in JUNCTION_E]
        assert len(junction) == 2 and all(e["rule"] == rule for e in junction), name
        assert c["classes"]["vertices"][4]["rule"] == "solid-boundary"
        assert c["classes"]["vertices"][6]["rule"] == "loop-boundary"
        # children keep the choice: the edge point of a junction edge at level 1
        j = level(s, 1)
        (mid,) = [i for i, e in enumerate(j["origin"]["edge_of"]) if e and sorted(e) == [0, 2]]
        assert j["rules"][mid] == rule and j["rules"][0] == rule, name


def test_fig17c_n1_solid_subdivides_as_if_alone(daemon):
    """N1 with dimension 3 (Fig. 17c): the solid's points equal those of the octahedron alone."""
    mixed = session(daemon, FIG17, n1(3))
    alone = session(daemon, {"vertices": OCTA_V, "simplices": OCTA_T})
    for L in (1, 2, 3):
        a = part_points(level(mixed, L), ["tetrahedra", "octahedra"])
        b = part_points(level(alone, L), ["tetrahedra", "octahedra"])
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, atol=1e-12)
    # ... which the default G2 does not do (the fins pull the junction)
    g2 = session(daemon, FIG17)
    a = part_points(level(g2, 1), ["tetrahedra", "octahedra"])
    assert np.abs(a - part_points(level(alone, 1), ["tetrahedra", "octahedra"])).max() > 0.05


def test_fig17b_n1_triangles_subdivide_as_if_alone(daemon):
    mixed = session(daemon, FIG17, n1(2))
    alone = session(daemon, {"vertices": FIG17_V, "simplices": FIG17_TRI})
    for L in (1, 2, 3):
        a = part_points(level(mixed, L), ["triangles"])
        b = part_points(level(alone, L), ["triangles"])
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, atol=1e-12)


def test_fig17d_g1_vertex_keeps_its_position(daemon):
    s = session(daemon, FIG17, {"overrides": [{"simplex": [0], "rule": "G1"}]})
    for L in (1, 2, 3):
        j = level(s, L)
        np.testing.assert_array_equal(j["vertices"][0], FIG17_V[0])   # vertex points keep ids
        assert j["rules"][0] == "G1"
    # vertex 2 has no override: it moves (G2)
    assert np.abs(np.array(level(s, 1)["vertices"][2]) - FIG17_V[2]).max() > 0.05


def test_fig17e_g1_edges_are_straight_creases(daemon):
    s = session(daemon, FIG17, {"overrides": [{"simplex": e, "rule": "G1"} for e in JUNCTION_E]})
    for L in (1, 2, 3):
        j = level(s, L)
        p = np.array(j["vertices"])
        np.testing.assert_array_equal(p[:4], np.array(FIG17_V[:4], dtype=float))
        # the ends of each crease are corners (one crease edge each), the 2^L - 1 points
        # inside each crease polygon follow it
        assert [j["rules"][v] for v in range(4)] == ["corner"] * 4
        on = [i for i, r in enumerate(j["rules"]) if r == "G1"]
        assert len(on) == 2 * (2 ** L - 1)
        for i in on:                                  # on segment 0-2 or 1-3: |x| + |y| = 1, z = 0
            assert abs(abs(p[i][0]) + abs(p[i][1]) - 1) < 1e-12 and abs(p[i][2]) < 1e-15


def test_g1_default(daemon):
    """nonmanifold_default G1: every non-manifold edge a crease, the vertices on them follow the
    creases (here each junction is one edge, so its ends are corners)."""
    s = session(daemon, FIG17, {"nonmanifold_default": "G1"})
    c = s.req("GET", "/complex").json()
    assert c["rules"]["nonmanifold_default"] == "G1"
    j = level(s, 2)
    p = np.array(j["vertices"])
    np.testing.assert_array_equal(p[:4], np.array(FIG17_V[:4], dtype=float))
    # an explicit G2 takes vertex 0 out of the default: it moves as in test_fig17_level1_by_hand
    s = session(daemon, FIG17, {"nonmanifold_default": "G1",
                                "overrides": [{"simplex": [0], "rule": "G2"}]})
    c = s.req("GET", "/complex").json()
    assert c["classes"]["vertices"][0]["rule"] == "G2" and c["classes"]["vertices"][2]["rule"] == "G1"
    assert np.abs(np.array(level(s, 1)["vertices"][0]) - FIG17_V[0]).max() > 0.05


# three fins sharing edge 0-1 (a type-2 edge; its ends are type 4)
FINS_V = [[0, 0, 0], [0, 0, 1], [1, 0, 0.5], [-0.5, 0.8, 0.5], [-0.5, -0.8, 0.5]]
FINS_T = [[0, 1, 2], [0, 1, 3], [0, 1, 4]]
FINS = {"vertices": FINS_V, "simplices": FINS_T}


def test_n2_edge_and_vertices(daemon):
    """N2 chooses fins 2 and 3: the edge follows Loop between them, its ends the boundary of the
    two-triangle surface — exactly what fins [0,1,2] and [0,1,3] give alone."""
    pair = [[0, 1, 2], [0, 1, 3]]
    ov = [{"simplex": [0, 1], "rule": "N2", "pair": pair},
          {"simplex": [0], "rule": "N2", "pair": pair},
          {"simplex": [1], "rule": "N2", "pair": pair}]
    s = session(daemon, FINS, {"overrides": ov})
    c = s.req("GET", "/complex").json()
    assert c["rules"]["overrides"] == ov
    assert [c["classes"]["vertices"][v]["rule"] for v in (0, 1)] == ["N2", "N2"]
    j = level(s, 1)
    p = np.array(j["vertices"])
    P = np.array(FINS_V, dtype=float)
    (mid,) = [i for i, e in enumerate(j["origin"]["edge_of"]) if e and sorted(e) == [0, 1]]
    np.testing.assert_allclose(p[mid], 3 / 8 * (P[0] + P[1]) + 1 / 8 * (P[2] + P[3]), atol=1e-14)
    np.testing.assert_allclose(p[0], (6 * P[0] + P[2] + P[3]) / 8, atol=1e-14)
    np.testing.assert_allclose(p[1], (6 * P[1] + P[2] + P[3]) / 8, atol=1e-14)
    alone = session(daemon, {"vertices": FINS_V, "simplices": pair})
    for L in (1, 2, 3):
        a = level(s, L)
        b = level(alone, L)
        # every point of the two chosen fins alone appears in the three-fin complex
        pa = np.array(a["vertices"])
        for q in part_points(b, ["triangles"]):
            assert np.min(np.linalg.norm(pa - q, axis=1)) < 1e-12
    # the default G2 blends all three fins instead
    g2 = level(session(daemon, FINS), 1)
    assert np.abs(np.array(g2["vertices"][mid]) - p[mid]).max() > 1e-3


def test_n2_curves(daemon):
    """Three curves meeting at vertex 0 (type 2): N2 with two of them makes 0 a B-spline point of
    the chosen pair; without it the junction is a corner."""
    body = {"vertices": [[0, 0, 0], [1, 0, 0], [-1, 0.5, 0], [0, -1, 1]],
            "simplices": [[0, 1], [0, 2], [0, 3]]}
    s = session(daemon, body, {"overrides": [{"simplex": [0], "rule": "N2", "pair": [[0, 1], [2, 0]]}]})
    p = np.array(level(s, 1)["vertices"])
    np.testing.assert_allclose(p[0], (6 * np.array([0, 0, 0]) + [1, 0, 0] + [-1, 0.5, 0]) / 8, atol=1e-15)
    np.testing.assert_array_equal(np.array(level(session(daemon, body), 1)["vertices"][0]), [0, 0, 0])


def test_overrides_survive_tags_not_a_new_complex(daemon):
    s = session(daemon, FIG17, {"overrides": [{"simplex": [0], "rule": "G1"}]})
    assert s.req("PUT", "/tags", json={"singular": [[4]]}).status_code == 200
    c = s.req("GET", "/complex").json()
    assert c["rules"]["overrides"] == [{"simplex": [0], "rule": "G1"}]
    assert c["classes"]["vertices"][0]["rule"] == "G1"
    assert s.put_complex(FIG17).status_code == 200
    c = s.req("GET", "/complex").json()
    assert c["rules"]["overrides"] == [] and c["classes"]["vertices"][0]["rule"] == "G2"


# every error path of the overrides: (body, status, pointer, words in the detail)
BAD = [
    ({"overrides": [{"simplex": [4], "rule": "G1"}]}, 422, "/overrides/0/simplex", "manifold"),
    ({"overrides": [{"simplex": [0, 1, 2], "rule": "G1"}]}, 422, "/overrides/0/simplex", "triangle"),
    ({"overrides": [{"simplex": [], "rule": "G1"}]}, 422, "/overrides/0/simplex", "vertex or edge"),
    ({"overrides": [{"simplex": [0, 1], "rule": "G1"}]}, 422, "/overrides/0/simplex", "not an edge"),
    ({"overrides": [{"simplex": [0, 0], "rule": "G1"}]}, 422, "/overrides/0/simplex", "twice"),
    ({"overrides": [{"simplex": [8], "rule": "G1"}]}, 422, "/overrides/0/simplex/0", None),
    ({"overrides": [{"simplex": [-1], "rule": "G1"}]}, 422, "/overrides/0/simplex/0", None),
    ({"overrides": [{"simplex": [1.0], "rule": "G1"}]}, 400, "/overrides/0/simplex/0", None),
    ({"overrides": [{"simplex": 1, "rule": "G1"}]}, 400, "/overrides/0/simplex", None),
    ({"overrides": [{"rule": "G1"}]}, 400, "/overrides/0/simplex", None),
    ({"overrides": [{"simplex": [0]}]}, 400, "/overrides/0/rule", None),
    ({"overrides": [{"simplex": [0], "rule": "N3"}]}, 422, "/overrides/0/rule", None),
    ({"overrides": [{"simplex": [0], "rule": "G1"}, {"simplex": [0], "rule": "G2"}]}, 422,
     "/overrides/1/simplex", "already"),
    ({"overrides": [{"simplex": [0], "rule": "N1"}]}, 400, "/overrides/0/dimension", None),
    ({"overrides": [{"simplex": [0], "rule": "N1", "dimension": 1}]}, 422, "/overrides/0/dimension", "no part of dimension 1"),
    ({"overrides": [{"simplex": [0], "rule": "N1", "dimension": 4}]}, 422, "/overrides/0/dimension", None),
    ({"overrides": [{"simplex": [0], "rule": "N1", "dimension": "3"}]}, 400, "/overrides/0/dimension", None),
    ({"overrides": [{"simplex": [0], "rule": "G1", "dimension": 3}]}, 422, "/overrides/0/dimension", "only N1"),
    ({"overrides": [{"simplex": [0], "rule": "N2", "pair": [[0, 2, 6], [0, 2, 4]]}]}, 422, "/overrides/0/rule", "type-2"),
    ({"overrides": [{"simplex": [0], "rule": "N2"}]}, 400, "/overrides/0/pair", None),
    ({"overrides": [{"simplex": [0], "rule": "G2", "pair": [[0, 1], [0, 2]]}]}, 422, "/overrides/0/pair", "only N2"),
    ({"overrides": [{"simplex": [0], "rule": "G1", "x": 1}]}, 400, "/overrides/0/x", None),
    ({"overrides": ["G1"]}, 400, "/overrides/0", None),
    ({"overrides": {}}, 400, "/overrides", None),
]
BAD_FINS = [
    # N1 at a type-2 edge / type-4 vertex
    ({"overrides": [{"simplex": [0, 1], "rule": "N1", "dimension": 2}]}, 422, "/overrides/0/rule", "type-1"),
    ({"overrides": [{"simplex": [0, 1], "rule": "N2", "pair": [[0, 1, 2]]}]}, 422, "/overrides/0/pair", "two simplices"),
    ({"overrides": [{"simplex": [0, 1], "rule": "N2", "pair": [[0, 1], [0, 1]]}]}, 422, "/overrides/0/pair", "two triangles"),
    ({"overrides": [{"simplex": [0, 1], "rule": "N2", "pair": [[0, 1, 2], [0, 1]]}]}, 422, "/overrides/0/pair/1", None),
    ({"overrides": [{"simplex": [0, 1], "rule": "N2", "pair": [[0, 1, 2], [0, 2, 3]]}]}, 422, "/overrides/0/pair/1", "not a triangle"),
    ({"overrides": [{"simplex": [0, 1], "rule": "N2", "pair": [[0, 1, 2], [0, 1, 2]]}]}, 422, "/overrides/0/pair/1", "same simplex"),
    ({"overrides": [{"simplex": [0, 1], "rule": "N2", "pair": [[0, 1, 2], [0, 1, 9]]}]}, 422, "/overrides/0/pair/1/2", None),
    ({"overrides": [{"simplex": [0, 1], "rule": "N2", "pair": "x"}]}, 400, "/overrides/0/pair", None),
    ({"overrides": [{"simplex": [0, 1], "rule": "N2", "pair": [7, [0, 1, 2]]}]}, 400, "/overrides/0/pair/0", None),
    # two N2 choices that contradict each other: the edge picks fins 2, 3; vertex 0 picks 3, 4
    ({"overrides": [{"simplex": [0, 1], "rule": "N2", "pair": [[0, 1, 2], [0, 1, 3]]},
                    {"simplex": [0], "rule": "N2", "pair": [[0, 1, 3], [0, 1, 4]]}]}, 422, "/overrides/0/pair", "conflicts"),
]


@pytest.mark.parametrize("body,status,pointer,words", BAD + [(b, s, p, w) for b, s, p, w in BAD_FINS])
def test_override_errors(daemon, body, status, pointer, words):
    fins = any(x in BAD_FINS for x in [(body, status, pointer, words)])
    s = session(daemon, FINS if fins else FIG17)
    r = s.req("PUT", "/rules", json=body)
    assert r.status_code == status, r.text
    assert r.headers["Content-Type"].startswith("application/problem+json")
    p = r.json()
    assert [e["pointer"] for e in p["errors"]] == [pointer], p
    if words:
        assert words in p["detail"], p["detail"]
    # all-or-nothing: the session is unchanged
    assert s.req("GET", "/complex").json()["rules"]["overrides"] == []
    assert r.status_code != 200


def test_overrides_need_a_complex(daemon):
    s = Session(daemon)
    r = s.req("PUT", "/rules", json={"overrides": [{"simplex": [0], "rule": "G1"}]})
    assert r.status_code == 409 and r.json()["errors"][0]["pointer"] == "/overrides"


def test_refine_carries_tags(daemon):
    """POST /refine: children of tagged simplices stay tagged (docs/RULES.md "Conventions"). The cube of 6 tets
    with its 12 edges tagged, refined red at a corner tet to depth 2: the tagged edges still
    cover exactly the 12 unit edges of the cube, and the corners and creases stay put at level 2
    of the refined complex."""
    from test_http_tags import CUBE_V, CUBE_T, CUBE_EDGES, on_cube_edge
    s = session(daemon, {"vertices": CUBE_V, "simplices": CUBE_T}, tags=CUBE_EDGES)
    r = s.req("POST", "/refine", json={"select": {"simplices": [CUBE_T[0]]}, "depth": 2,
                                       "positions": "subdivision"})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    tagged = c["tags"]["singular"]
    assert len(tagged) > 12 and all(len(t) == 2 for t in tagged)
    P = np.array(c["vertices"])
    total = 0.0
    for a, b in tagged:
        assert on_cube_edge(P[a]) and on_cube_edge(P[b]) and on_cube_edge((P[a] + P[b]) / 2)
        total += np.linalg.norm(P[a] - P[b])
    assert abs(total - 12) < 1e-12
    j = level(s, 2)
    p = np.array(j["vertices"])
    np.testing.assert_array_equal(p[:8], np.array(CUBE_V, dtype=float))
    assert all(on_cube_edge(p[i]) for i, r in enumerate(j["rules"]) if r == "curve")


def test_refine_carries_triangle_tags_and_overrides(daemon):
    """A tagged triangle becomes its children (same total area); an N1 junction edge's halves and
    midpoint keep N1 with the same dimension."""
    s = session(daemon, FIG17, n1(3), tags=[[1, 2, 4]])
    r = s.req("POST", "/refine", json={"select": {"sphere": {"center": [0, 0, 0], "radius": 10}},
                                       "positions": "midpoint"})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    P = np.array(c["vertices"])
    tris = c["tags"]["singular"]
    assert len(tris) == 4 and all(len(t) == 3 for t in tris)
    area = sum(np.linalg.norm(np.cross(P[b] - P[a], P[t] - P[a])) / 2 for a, b, t in tris)
    assert abs(area - np.sqrt(3) / 2) < 1e-12          # the face (-1,0,0),(0,1,0),(0,0,1)
    mid = next(i for i, x in enumerate(P) if np.allclose(x, [0.5, 0.5, 0]))
    ov = {tuple(o["simplex"]): o for o in c["rules"]["overrides"]}
    assert ov[(mid,)] == {"simplex": [mid], "rule": "N1", "dimension": 3}
    assert ov[(0, mid)]["rule"] == "N1" and ov[(2, mid)]["dimension"] == 3
    assert c["classes"]["vertices"][mid]["rule"] == "N1"


def test_fig16_type3_vertex_g1_and_g2(daemon):
    """000 Fig. 16: two solids meeting at one vertex A (type 3). G1 keeps A; G2 (default) moves it
    by 9/16 A + 7/(16k) sum of its k = 6 neighbours: A = 0, neighbours summing to (0, 0, -1)
    -> (0, 0, -7/96)."""
    body = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -2]],
            "simplices": [[0, 1, 2, 3], [0, 4, 5, 6]]}
    g2 = session(daemon, body)
    c = g2.req("GET", "/complex").json()["classes"]["vertices"][0]
    assert c["nonmanifold"] == 3 and c["rule"] == "G2"
    np.testing.assert_allclose(level(g2, 1)["vertices"][0], [0, 0, -7 / 96], atol=1e-15)
    g1 = session(daemon, body, {"overrides": [{"simplex": [0], "rule": "G1"}]})
    for L in (1, 2, 3):
        assert level(g1, L)["vertices"][0] == [0, 0, 0]


def test_fig15a_curve_meets_solid_g2(daemon):
    """000 Fig. 15(a): a curve leaving a tetrahedron at vertex v = (0,0,1) (type 1), rule G2:
    k = 4 neighbours (three tet vertices and the curve's next point (0,0,2)):
    9/16 (0,0,1) + 7/64 ((1,1,0) + (0,0,2)) = (7/64, 7/64, 9/16 + 14/64)."""
    body = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 2]],
            "simplices": [[0, 1, 2, 3], [3, 4]]}
    s = session(daemon, body)
    assert s.req("GET", "/complex").json()["classes"]["vertices"][3]["rule"] == "G2"
    np.testing.assert_allclose(level(s, 1)["vertices"][3], [7 / 64, 7 / 64, 9 / 16 + 14 / 64], atol=1e-15)


def test_g2_junction_inside_a_solid_keeps_the_solid_ring(daemon):
    """A curve from the centre 0 of an octahedron of 8 tets to p7 = (0.2, 0.3, 0.1): vertex 0 is a
    type-1 junction inside the solid, off dC, so G2's relief (which drops points strictly inside
    a solid only where the junction lies on dC, DECISIONS 5) leaves its ring whole at every level.
    Level 1: the solid edges (0, i) have 4 tets around them, so their points are 1/4 p_i + 1/8 of
    the 4 others, = p_i / 4 (the octahedron's vertices sum to 0); the curve's point is p7 / 2;
    vertex 0 = 9/16 * 0 + 7/(16*7) (sum p_i + p7) = p7 / 16. Level 2: vertex 0's ring is those 7
    points: 9/16 p7/16 + 1/16 (0 + p7/2) = 17/256 p7 (dropping the 6 solid points, as the ring did
    when only a junction in C_3 alone counted as inside, gave 9/256 + 7/32 = 65/256 p7)."""
    p7 = [0.2, 0.3, 0.1]
    body = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1],
                         [0, 0, -1], p7],
            "simplices": [[0, 1, 2, 5], [0, 2, 3, 5], [0, 3, 4, 5], [0, 4, 1, 5],
                          [0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 4, 6], [0, 4, 1, 6], [0, 7]]}
    s = session(daemon, body)
    c = s.req("GET", "/complex").json()["classes"]["vertices"][0]
    assert c["nonmanifold"] == 1 and not c["boundary"] and c["rule"] == "G2"
    np.testing.assert_allclose(level(s, 1)["vertices"][0], np.array(p7) / 16, atol=1e-15)
    j = level(s, 2)
    assert j["rules"][0] == "G2"
    np.testing.assert_allclose(j["vertices"][0], np.array(p7) * 17 / 256, atol=1e-15)


def test_fig15b_four_surfaces_on_a_line_g2(daemon):
    """000 Fig. 15(b): four surfaces meeting along edge 0-1 (type 2), rule G2. Edge: its ring is
    the 4 tips, so 1/4 (a+b) + 1/8 each (docs/RULES.md: |rho(e)| = 4): 1/4 (0,0,1) + 1/8 (0,-1,2).
    Vertex 0 (type 4): 5 neighbours, 9/16 * 0 + 7/80 ((0,0,1) + (0,-1,2))."""
    tips = [[1, 0, 0.5], [-1, 0, 0.5], [0, 1, 0.5], [0, -2, 0.5]]
    body = {"vertices": [[0, 0, 0], [0, 0, 1]] + tips, "simplices": [[0, 1, k] for k in range(2, 6)]}
    s = session(daemon, body)
    j = level(s, 1)
    (mid,) = [i for i, e in enumerate(j["origin"]["edge_of"]) if e and sorted(e) == [0, 1]]
    np.testing.assert_allclose(j["vertices"][mid], [0, -0.125, 0.5], atol=1e-15)
    np.testing.assert_allclose(j["vertices"][0], [0, -7 / 80, 21 / 80], atol=1e-15)


# N1 only decides a rule where the chosen part is itself manifold (DECISIONS 23): two solids
# touching at vertex 0 plus a curve there (vertex 0 is type 1, and type 3 within the solids), and
# three fins on edge 0-1 plus a curve at vertex 0.
FIG16_V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -2]]
FIG16_T = [[0, 1, 2, 3], [0, 4, 5, 6]]


@pytest.mark.parametrize("body,override,words", [
    ({"vertices": FIG16_V + [[5, 5, 5]], "simplices": FIG16_T + [[0, 7]]},
     {"simplex": [0], "rule": "N1", "dimension": 3}, "solids are themselves non-manifold"),
    ({"vertices": FINS_V + [[0, 0, -3]], "simplices": FINS_T + [[0, 5]]},
     {"simplex": [0], "rule": "N1", "dimension": 2}, "more than one fan"),
])
def test_n1_needs_a_manifold_part(daemon, body, override, words):
    s = session(daemon, body)
    r = s.req("PUT", "/rules", json={"overrides": [override]})
    assert r.status_code == 422, r.text
    assert r.json()["errors"][0]["pointer"] == "/overrides/0/dimension"
    assert words in r.json()["detail"]
    # the other dimension is fine there: the curve alone makes vertex 0 a curve end (fixed)
    r = s.req("PUT", "/rules", json={"overrides": [dict(override, dimension=1)]})
    assert r.status_code == 200, r.text
    assert level(s, 1)["vertices"][0] == body["vertices"][0]
    assert s.req("GET", "/complex").json()["classes"]["vertices"][0]["rule"] == "corner"


def test_n2_pair_in_one_petal_is_refused(daemon):
    """A closed fan around vertex 0 plus a fin on edge 0-1: two triangles of the fan are one
    petal, so they are not a pair of two sheets."""
    K = 6
    V = [[0, 0, 0]] + [[np.cos(2 * np.pi * i / K), np.sin(2 * np.pi * i / K), 0] for i in range(K)] \
        + [[0.5, 0, 1]]
    T = [[0, 1 + i, 1 + (i + 1) % K] for i in range(K)] + [[0, 1, K + 1]]
    s = session(daemon, {"vertices": V, "simplices": T})
    r = s.req("PUT", "/rules", json={"overrides": [{"simplex": [0], "rule": "N2", "pair": [T[0], T[2]]}]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/overrides/0/pair/1"
    assert "same petal" in r.json()["detail"]
    # a triangle of the fan and the fin: two petals, accepted
    r = s.req("PUT", "/rules", json={"overrides": [{"simplex": [0], "rule": "N2", "pair": [T[0], T[K]]}]})
    assert r.status_code == 200, r.text


def test_g1_default_makes_a_shared_triangle_a_surface(daemon):
    """Three tetrahedra sharing triangle 0-1-2 (type 2): under the G1 default the triangle is a
    2-singularity (an embedded surface) and its children stay singular at every level: no point
    follows G2, and the triangle's points stay in its plane z = 0."""
    V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 1], [0.3, 0.3, -1], [-1, -1, 0.2]]
    T = [[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 2, 5]]
    s = session(daemon, {"vertices": V, "simplices": T}, {"nonmanifold_default": "G1"})
    for L in (1, 2, 3):
        j = level(s, L)
        assert "G2" not in j["rules"]
        p = np.array(j["vertices"])
        inside = [i for i, r in enumerate(j["rules"]) if r in ("loop", "loop-boundary")]
        assert inside and all(abs(p[i][2]) < 1e-15 for i in inside)
    g2 = level(session(daemon, {"vertices": V, "simplices": T}), 2)
    assert "G2" in g2["rules"]
