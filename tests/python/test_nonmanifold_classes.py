"""Classes and level-1 junction positions on complexes the other suites do not use, against an
independent reading of the papers (not the program's output).

The classifier below is written from 000 Sec. 2.2-2.4 (C_k, boundary simplices and dC, types 1-4)
with the type-3 test of 002 Sec. 5.2 (the link has two or more connected components;
DECISIONS 4); it works on octahedra [p, q, a, a2, b, b2] too, so levels 1 and 2 are classified from
scratch. G2's row is 000 eq. 17-18 with the relieved ring of DECISIONS 5 (every vertex joined by
an edge or major diagonal, less those strictly inside a solid unless the junction itself is
inside one), the edge's special |rho| = 4 and 6 masks of 001 eq. 3.4-3.5. N1, N2, G1 and tags are
derived per case in the test from the stencils of docs/RULES.md.
"""
from collections import defaultdict
from itertools import combinations

import numpy as np
import pytest

from daemon import Daemon, Session


@pytest.fixture(scope="module")
def daemon():
    d = Daemon("--max-sessions", "1000")
    yield d
    assert d.stop() == 0


def cell_faces(c):
    """dim -> set of faces (frozensets) of a maximal cell, itself included."""
    if len(c) == 6:
        p, q, a, a2, b, b2 = c
        eq = [a, b, a2, b2]
        return {3: {frozenset(c)},
                2: {frozenset((x, eq[i], eq[(i + 1) % 4])) for x in (p, q) for i in range(4)},
                1: {frozenset((x, e)) for x in (p, q) for e in eq} |
                   {frozenset((eq[i], eq[(i + 1) % 4])) for i in range(4)},
                0: {frozenset((v,)) for v in c}}
    return {r - 1: {frozenset(x) for x in combinations(c, r)} for r in range(1, len(c) + 1)}


def classify(cells):
    """(family bits, dC, non-manifold type) of every simplex of the complex of maximal cells."""
    C, cof, dim, up, below = defaultdict(set), defaultdict(list), {}, defaultdict(set), defaultdict(set)
    for c in cells:
        fs = cell_faces(c)
        k = 3 if len(c) == 6 else len(c) - 1
        for d, ss in fs.items():
            for s in ss:
                C[k].add(s)
                cof[s].append((frozenset(c), k))
                dim[s] = d
                for d2 in range(d):
                    below[s] |= {t for t in fs[d2] if t < s}
                if d:
                    for t in fs[d - 1]:
                        if t < s:
                            up[t].add(s)
    fam = {s: sum(1 << k for k in range(4) if s in C[k]) for s in cof}
    # boundary simplex: a (k-1)-face of a maximal k-cell and a subsimplex of nothing else
    bnd = set()
    for s in cof:
        others = {c for c, k in cof[s] if c != s}
        if len(others) == 1:
            (c,) = others
            k = [k for cc, k in cof[s] if cc == c][0]
            if dim[s] == k - 1 and up[s] == {c}:
                bnd.add(s)
    dC = set(bnd).union(*(below[b] for b in bnd)) if bnd else set()
    nm = {}
    for s in cof:
        ks = [k for k in range(4) if s in C[k]]
        if len(ks) > 1:
            nm[s] = 1
        elif dim[s] == ks[0] - 1 and len({c for c, k in cof[s] if k == ks[0]}) >= 3:
            nm[s] = 2

    def components(s, k):
        parent = {}

        def root(x):
            while parent[x] != x:
                x = parent[x]
            return x
        for c, kk in cof[s]:
            if kk != k or c == s:
                continue
            fs = cell_faces(tuple(c) if len(c) != 6 else [x for x in cells if frozenset(x) == c][0])
            link = [w for w in c if w not in s and (s | {w}) in fs[dim[s] + 1]]
            for w in link:
                parent.setdefault(w, w)
            for w in link[1:]:
                parent[root(w)] = root(link[0])
        return len({root(w) for w in parent})
    t3 = {s for s in cof if s not in nm and bin(fam[s]).count("1") == 1
          and dim[s] < fam[s].bit_length() - 2 and components(s, fam[s].bit_length() - 1) >= 2}
    bad = set(nm) | t3
    for s in cof:
        k = fam[s].bit_length() - 1
        if s in nm or bin(fam[s]).count("1") != 1 or dim[s] >= k - 1:
            continue
        if any(s < t for t in bad):
            nm[s] = 4
        elif s in t3:
            nm[s] = 3
    return fam, dC, nm


def neighbours(cells):
    """Vertices joined by an edge or a major diagonal (an octahedron's p-q)."""
    nb = defaultdict(set)
    for c in cells:
        skip = [{c[2], c[3]}, {c[4], c[5]}] if len(c) == 6 else []
        for x, y in combinations(c, 2):
            if {x, y} not in skip:
                nb[x].add(y)
                nb[y].add(x)
    return nb


def g2_rows(cells, P):
    """Expected G2 vertex points {v: p} and edge points {(a, b): p} of every non-manifold vertex
    and edge (but junctions of 3+ curves, fixed by docs/RULES.md "Fixed points")."""
    fam, dC, nm = classify(cells)
    nb = neighbours(cells)

    def inside(x):
        return fam[x] == 8 and x not in dC
    verts, edges = {}, {}
    for s, t in nm.items():
        if t == 2 and fam[s] == 2:
            continue
        keep_all = bool(fam[s] & 8) and s not in dC
        if len(s) == 1:
            (v,) = s
            rho = [u for u in nb[v] if keep_all or not inside(frozenset((u,)))]
            verts[v] = 9 / 16 * P[v] + 7 / (16 * len(rho)) * P[rho].sum(0)
        elif len(s) == 2:
            a, b = sorted(s)
            ring = [u for u in nb[a] & nb[b] if keep_all or not inside(frozenset((u,)))]
            k = len(ring)
            wa, wr = (8 / 32, 4 / 32) if k == 4 else (10 / 32, 2 / 32) if k == 6 else (5 / 16, 3 / (8 * k))
            edges[(a, b)] = wa * (P[a] + P[b]) + wr * P[ring].sum(0)
    return verts, edges


K = 6
HEX = [[0, 0, 0]] + [[np.cos(2 * np.pi * i / K), np.sin(2 * np.pi * i / K), 0] for i in range(K)]
UP = [[np.cos(np.pi * i / 2), np.sin(np.pi * i / 2), 1] for i in range(4)]
DOWN = [[np.cos(np.pi * i / 2 + 0.3), np.sin(np.pi * i / 2 + 0.3), -1.5] for i in range(4)]
COMPLEXES = {
    # two tetrahedra sharing only vertex 0 (type 3) / only edge 0-1 (type 3, its ends type 4)
    "tets-vertex": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -2]],
                    [[0, 1, 2, 3], [0, 4, 5, 6]]),
    "tets-edge": ([[0, 0, 0], [0, 0, 1], [1, 0, 0.3], [1, 1, 0.6], [-1, 0, 0.3], [-1, -1, 0.6]],
                  [[0, 1, 2, 3], [0, 1, 4, 5]]),
    # a fan of three triangles meeting a tetrahedron along edge 0-1 (type 1)
    "fan-solid": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, -1, -0.5], [1, -1, 0.2], [0, -1, 0.5]],
                  [[0, 1, 2, 3], [0, 1, 4], [0, 4, 5], [0, 5, 6]]),
    # three sheets of two triangles on edge 0-1 (type 2)
    "three-sheets": ([[0, 0, 0], [0, 0, 1], [1, 0, 0], [1, 0, 1], [-0.5, 0.8, 0], [-0.5, 0.8, 1],
                      [-0.5, -0.8, 0], [-0.5, -0.8, 1]],
                     [[0, 1, 2], [1, 2, 3], [0, 1, 4], [1, 4, 5], [0, 1, 6], [1, 6, 7]]),
    # a curve 8-0-7-9 piercing a closed hexagonal fan at its centre 0 (type 1, off dC)
    "curve-pierce": (HEX + [[0.1, 0, 1], [0, 0.2, -1], [0.3, 0.1, 2]],
                     [[0, 1 + i, 1 + (i + 1) % K] for i in range(K)] + [[7, 0], [0, 8], [7, 9]]),
    # a surface pinched at vertex 0: two cones with the same apex (type 3, off dC)
    "pinch": ([[0, 0, 0]] + UP + DOWN,
              [[0, 1 + i, 1 + (i + 1) % 4] for i in range(4)] + [[0, 5 + i, 5 + (i + 1) % 4] for i in range(4)]),
    # a tetrahedron with a dangling curve 3-4-5 and an isolated point 6
    "solid-curve-point": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.2, 0.3, 2], [0.5, 0.1, 3], [5, 5, 5]],
                          [[0, 1, 2, 3], [3, 4], [4, 5], [6]]),
    # three tetrahedra on triangle 0-1-2 (type 2; its edges and vertices type 4)
    "three-tets": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 1], [0.3, 0.3, -1], [-1, -1, 0.2]],
                   [[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 2, 5]]),
    # every type: tets sharing vertex 3 (3), a triangle on tet edge 1-2 (1), fins on 8-9 (2, 4),
    # a curve 0-8 (1), a junction of three curves at 13 (2), triangles touching at 17 (3), tets
    # sharing edge 22-23 (3, 4)
    "mixed": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.2, 0.1, 2], [1, 0.3, 1.5], [0.1, 1, 1.6],
               [1.2, 1.2, -0.3], [3, 0, 0], [3, 0, 1], [4, 0, 0.5], [2.5, 0.8, 0.5], [2.5, -0.8, 0.5],
               [6, 0, 0], [7, 0, 0], [6, 1, 0], [6, 0, 1.2], [9, 0, 0], [10, 0, 0], [9, 1, 0], [8, 0, 0.5],
               [8.5, -1, 0], [12, 0, 0], [12, 0, 1], [13, 0, 0.3], [13, 1, 0.6], [11, 0, 0.3], [11, -1, 0.6]],
              [[0, 1, 2, 3], [3, 4, 5, 6], [1, 2, 7], [8, 9, 10], [8, 9, 11], [8, 9, 12], [0, 8],
               [13, 14], [13, 15], [13, 16], [17, 18, 19], [17, 20, 21], [22, 23, 24, 25], [22, 23, 26, 27]]),
}
# the types each complex must show (so the classifier above is not vacuous)
TYPES = {"tets-vertex": {3}, "tets-edge": {3, 4}, "fan-solid": {1}, "three-sheets": {2, 4},
         "curve-pierce": {1}, "pinch": {3}, "solid-curve-point": {1}, "three-tets": {4},
         "mixed": {1, 2, 3, 4}}


def session(daemon, name, rules=None, tags=None):
    V, T = COMPLEXES[name]
    s = Session(daemon)
    r = s.put_complex({"vertices": V, "simplices": T})
    assert r.status_code == 200, r.text
    for path, body in (("/rules", rules), ("/tags", tags)):
        if body is not None:
            r = s.req("PUT", path, json=body)
            assert r.status_code == 200, r.text
    return s


def level(s, L):
    r = s.level(L, format="json")
    assert r.status_code == 200, r.text
    return r.json()


def level_cells(j):
    c = j["cells"]
    return [tuple(x) for k in ("edges", "triangles", "tetrahedra", "octahedra") for x in c[k]] + \
        [(x,) for x in c["points"]]


def edge_point(j, a, b):
    (m,) = [i for i, e in enumerate(j["origin"]["edge_of"]) if e and sorted(e) == sorted([a, b])]
    return np.array(j["vertices"][m])


@pytest.mark.parametrize("name", COMPLEXES)
def test_classes_and_g2_against_the_definitions(daemon, name):
    V, T = COMPLEXES[name]
    s = session(daemon, name)
    c = s.req("GET", "/complex").json()["classes"]
    fam, dC, nm = classify([tuple(t) for t in T])
    assert {t for x, t in nm.items() if len(x) <= 2} == TYPES[name]

    def expect(x):
        return {"family": [k for k in range(4) if fam[x] >> k & 1], "boundary": x in dC,
                "nonmanifold": nm.get(x, 0)}
    for i, v in enumerate(c["vertices"]):
        assert {k: v[k] for k in ("family", "boundary", "nonmanifold")} == expect(frozenset((i,))), (name, i)
    assert len(c["edges"]) == sum(1 for x in fam if len(x) == 2)
    for e in c["edges"]:
        assert {k: e[k] for k in ("family", "boundary", "nonmanifold")} == expect(frozenset(e["vertices"])), (name, e)
    # G2 (the default) at every non-manifold vertex and edge, levels 0 -> 1 -> 2 -> 3, each level
    # classified from scratch; valences at level 0 are the ring sizes
    nb = neighbours([tuple(t) for t in T])
    for i, v in enumerate(c["vertices"]):
        if v["rule"] == "G2":
            keep = bool(fam[frozenset((i,))] & 8) and frozenset((i,)) not in dC
            assert v["valence"] == sum(1 for u in nb[i] if keep or not (fam[frozenset((u,))] == 8 and
                                                                          frozenset((u,)) not in dC))
    cells, P = [tuple(t) for t in T], np.array(V, dtype=float)
    for L in (1, 2, 3):
        j = level(s, L)
        verts, edges = g2_rows(cells, P)
        assert verts or edges or name == "mixed"
        Q = np.array(j["vertices"])
        for v, p in verts.items():
            np.testing.assert_allclose(Q[v], p, atol=1e-12, err_msg=f"{name} level {L} vertex {v}")
            assert j["rules"][v] == "G2"
        for (a, b), p in edges.items():
            np.testing.assert_allclose(edge_point(j, a, b), p, atol=1e-12, err_msg=f"{name} level {L} edge {a}-{b}")
        cells, P = level_cells(j), Q


def test_fan_meeting_a_solid_n1_each_dimension(daemon):
    """Type-1 edge 0-1 (a tetrahedron and a fan). N1 3: Loop over the tetrahedron's boundary
    (m = 3, Warren 3/16), the edge 3/8, 1/8 across its boundary faces; N1 2: the fan's boundary
    (B-spline along 1, 6 at vertex 0 and along 0, 4 at vertex 1, the edge a midpoint). The part
    not chosen keeps its own rules either way."""
    P = np.array(COMPLEXES["fan-solid"][0], dtype=float)
    junction = [[0], [1], [0, 1]]
    for d, v0, v1, e01 in (
            (3, 7 / 16 * P[0] + 3 / 16 * (P[1] + P[2] + P[3]), 7 / 16 * P[1] + 3 / 16 * (P[0] + P[2] + P[3]),
             3 / 8 * (P[0] + P[1]) + 1 / 8 * (P[2] + P[3])),
            (2, (6 * P[0] + P[1] + P[6]) / 8, (6 * P[1] + P[0] + P[4]) / 8, (P[0] + P[1]) / 2)):
        s = session(daemon, "fan-solid", {"overrides": [{"simplex": x, "rule": "N1", "dimension": d}
                                                        for x in junction]})
        j = level(s, 1)
        np.testing.assert_allclose(j["vertices"][0], v0, atol=1e-14)
        np.testing.assert_allclose(j["vertices"][1], v1, atol=1e-14)
        np.testing.assert_allclose(edge_point(j, 0, 1), e01, atol=1e-14)
        # the fan's boundary vertex 4, its inner edge 0-4, the solid's vertex 2
        np.testing.assert_allclose(j["vertices"][4], (6 * P[4] + P[1] + P[5]) / 8, atol=1e-14)
        np.testing.assert_allclose(edge_point(j, 0, 4), 3 / 8 * (P[0] + P[4]) + 1 / 8 * (P[1] + P[5]), atol=1e-14)
        np.testing.assert_allclose(j["vertices"][2], 7 / 16 * P[2] + 3 / 16 * (P[0] + P[1] + P[3]), atol=1e-14)
    s = session(daemon, "fan-solid")
    r = s.req("PUT", "/rules", json={"overrides": [{"simplex": [0, 1], "rule": "N2",
                                                    "pair": [[0, 1, 4], [0, 1, 2]]}]})
    assert r.status_code == 422 and "type 1" in r.json()["detail"]


def test_three_sheets_n2_takes_whole_petals(daemon):
    """N2 on edge 0-1 and both ends with sheets A (0,1,2 + 1,2,3) and B (0,1,4 + 1,4,5): the edge
    follows Loop between A and B, vertex 1 the B-spline along the union's boundary (3, 5), vertex 0
    along (2, 4); the third sheet keeps its own rules (boundary vertex 7, inner edge 1-6)."""
    P = np.array(COMPLEXES["three-sheets"][0], dtype=float)
    pair = [[0, 1, 2], [0, 1, 4]]
    s = session(daemon, "three-sheets", {"overrides": [{"simplex": x, "rule": "N2", "pair": pair}
                                                       for x in ([0, 1], [0], [1])]})
    j = level(s, 1)
    np.testing.assert_allclose(edge_point(j, 0, 1), 3 / 8 * (P[0] + P[1]) + 1 / 8 * (P[2] + P[4]), atol=1e-14)
    np.testing.assert_allclose(j["vertices"][0], (6 * P[0] + P[2] + P[4]) / 8, atol=1e-14)
    np.testing.assert_allclose(j["vertices"][1], (6 * P[1] + P[3] + P[5]) / 8, atol=1e-14)
    np.testing.assert_allclose(j["vertices"][7], (6 * P[7] + P[1] + P[6]) / 8, atol=1e-14)
    np.testing.assert_allclose(edge_point(j, 1, 6), 3 / 8 * (P[1] + P[6]) + 1 / 8 * (P[0] + P[7]), atol=1e-14)


def test_curve_piercing_a_surface(daemon):
    """Vertex 0: centre of a closed hexagonal fan and an inner point of curve 8-0-7. N1 2: Loop,
    m = 6, Warren 1/16: 5/8 p0 + 1/16 (the hexagon, summing to 0) = 0; N1 1: (6 p0 + p7 + p8)/8;
    G1: fixed; a tagged crease 1-0-4 through it: B-spline along it; a crease 1-0 ending there
    (and at the boundary vertex 1): both ends fixed."""
    P = np.array(COMPLEXES["curve-pierce"][0], dtype=float)
    cases = [({"overrides": [{"simplex": [0], "rule": "N1", "dimension": 2}]}, None, P[0] * 0),
             ({"overrides": [{"simplex": [0], "rule": "N1", "dimension": 1}]}, None, (6 * P[0] + P[7] + P[8]) / 8),
             ({"overrides": [{"simplex": [0], "rule": "G1"}]}, None, P[0]),
             ({"nonmanifold_default": "G1"}, None, P[0]),
             (None, {"singular": [[1, 0], [0, 4]]}, (6 * P[0] + P[1] + P[4]) / 8),
             (None, {"singular": [[1, 0]]}, P[0])]
    for rules, tags, p0 in cases:
        j = level(session(daemon, "curve-pierce", rules, tags), 1)
        np.testing.assert_allclose(j["vertices"][0], p0, atol=1e-14, err_msg=str((rules, tags)))
        # the curve's inner point 7 keeps the curve rule
        np.testing.assert_allclose(j["vertices"][7], (6 * P[7] + P[0] + P[9]) / 8, atol=1e-14)
    j = level(session(daemon, "curve-pierce", None, {"singular": [[1, 0]]}), 1)
    np.testing.assert_array_equal(j["vertices"][1], P[1])


@pytest.mark.parametrize("name,simplex,override,words", [
    ("pinch", [0], {"rule": "N1", "dimension": 2}, "type 3"),
    ("pinch", [0], {"rule": "N2", "pair": [[0, 1, 2], [0, 5, 6]]}, "type 3"),
    ("tets-edge", [0, 1], {"rule": "N1", "dimension": 3}, "type 3"),
    ("tets-edge", [0], {"rule": "N1", "dimension": 3}, "type 4"),
    ("three-sheets", [1], {"rule": "N1", "dimension": 2}, "type 4"),
])
def test_n_rules_refused_where_they_do_not_apply(daemon, name, simplex, override, words):
    s = session(daemon, name)
    r = s.req("PUT", "/rules", json={"overrides": [dict(override, simplex=simplex)]})
    assert r.status_code == 422, r.text
    assert words in r.json()["detail"]


def test_g1_default_fixes_the_junctions(daemon):
    """Under the G1 default the junction edges are creases (midpoints) whose ends are corners, and
    the pinch and the type-3 vertex of two tetrahedra stay put."""
    for name, fixed, creases in (("tets-edge", [0, 1], [[0, 1]]), ("three-sheets", [0, 1], [[0, 1]]),
                                 ("fan-solid", [0, 1], [[0, 1]]), ("pinch", [0], []), ("tets-vertex", [0], [])):
        P = np.array(COMPLEXES[name][0], dtype=float)
        j = level(session(daemon, name, {"nonmanifold_default": "G1"}), 1)
        for v in fixed:
            np.testing.assert_array_equal(j["vertices"][v], P[v])
        for a, b in creases:
            np.testing.assert_allclose(edge_point(j, a, b), (P[a] + P[b]) / 2, atol=1e-15)


def test_solid_with_a_curve_and_a_point(daemon):
    """Vertex 3 (tetrahedron and curve, type 1) under N1 3: Loop on the boundary, m = 3; the curve's
    inner point 4 the curve rule, its end 5 and the isolated point 6 fixed, each reported as a
    corner with valence 0."""
    P = np.array(COMPLEXES["solid-curve-point"][0], dtype=float)
    s = session(daemon, "solid-curve-point", {"overrides": [{"simplex": [3], "rule": "N1", "dimension": 3}]})
    j = level(s, 1)
    np.testing.assert_allclose(j["vertices"][3], 7 / 16 * P[3] + 3 / 16 * (P[0] + P[1] + P[2]), atol=1e-14)
    np.testing.assert_allclose(j["vertices"][4], (6 * P[4] + P[3] + P[5]) / 8, atol=1e-14)
    np.testing.assert_array_equal(j["vertices"][5], P[5])
    np.testing.assert_array_equal(j["vertices"][6], P[6])
    c = s.req("GET", "/complex").json()["classes"]["vertices"]
    assert [(c[i]["rule"], c[i]["valence"]) for i in (5, 6)] == [("corner", 0), ("corner", 0)]
    assert c[6]["family"] == [0] and not c[6]["boundary"]
