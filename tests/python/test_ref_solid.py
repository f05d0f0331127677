"""Level-1 solid subdivision of tetrahedral meshes: the Python oracle and `build/sdlevel`.

Part (a) checks the oracle (`refimpl.py`) on its own: hand-built meshes with values worked
out on paper, rows summing to 1, refusal of non-manifold input, and the text-format reader.
Part (b) runs `build/sdlevel -l 1 --classes` on the TetGen-made cases in tests/cases/ and
compares every vertex point and edge point, the level-1 counts and the split topology with the
oracle.  `SDLEVEL` may point at another build (make sanitize does).

Run from the repository root:  /usr/bin/python3 -m pytest tests/python/test_ref_solid.py
"""

import functools
import math
import subprocess
import sys
from fractions import Fraction
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import refimpl  # noqa: E402
import sdtext  # noqa: E402

REPO = HERE.parent.parent
from conftest import SDLEVEL  # noqa: E402
CASES = ["tetgen_ball", "tetgen_cube"]
WEIGHTS = ["warren", "loop"]
TOL = 1e-12


def close(got, want, tol=1e-15):
    return np.max(np.abs(np.asarray(got, float) - np.asarray(want, float))) <= tol


# --------------------------------------------------------------------------------------------
# hand-built meshes


def single_tet():
    verts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.2, 0.3, 1.0]])
    return verts, [(0, 1, 2, 3)]


def star_octahedron():
    """An interior vertex 0 surrounded by the 8 tetrahedra of an (irregular) octahedron.

    Vertex 0 sits at (1/4, 0, 0); the octahedron's corners are 1 = (2,0,0), 2 = (-1,0,0),
    3 = (0,1,0), 4 = (0,-1,0), 5 = (0,0,1), 6 = (0,0,-3), one tetrahedron (0, x, y, z) per
    octant.  Boundary faces: the 8 outer triangles (x, y, z), so 0 and the 6 spokes [0, i] are
    interior and every corner and every outer edge is on the boundary.
    """
    verts = np.array([
        [0.25, 0.0, 0.0],
        [2.0, 0.0, 0.0], [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0], [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0], [0.0, 0.0, -3.0],
    ])
    tets = [(0, x, y, z) for x in (1, 2) for y in (3, 4) for z in (5, 6)]
    return verts, tets


def bipyramid(k):
    """k tetrahedra around the chord [0, 1]: apexes 0, 1 and a ring 2..k+1.

    The faces (0, r_i, r_i+1) and (1, r_i, r_i+1) are the boundary, so 0 and 1 are boundary
    vertices but the edge [0, 1] is in no boundary face: an interior edge with |rho(e)| = k.
    """
    verts = [[0.0, 0.0, -1.0], [0.0, 0.0, 2.0]]
    for i in range(k):
        t = 2.0 * math.pi * i / k + 0.1
        verts.append([math.cos(t), 1.3 * math.sin(t), 0.05 * i])
    tets = [(0, 1, 2 + i, 2 + (i + 1) % k) for i in range(k)]
    return np.array(verts), tets


def hand_meshes():
    return [single_tet(), star_octahedron()] + [bipyramid(k) for k in (3, 4, 5, 6, 7, 9)]


def case_mesh(case):
    return sdtext.read_input(REPO / "tests" / "cases" / case / "mesh.txt")


# --------------------------------------------------------------------------------------------
# (a) self-checks of the oracle


@pytest.mark.parametrize("weights", WEIGHTS)
def test_single_tet_is_all_boundary(weights):
    verts, tets = single_tet()
    r = refimpl.level1_tets(verts, tets, weights)
    mesh = r["mesh"]
    assert len(mesh["boundary_faces"]) == 4
    assert mesh["boundary_verts"] == {0, 1, 2, 3}
    assert mesh["boundary_edges"] == set(combinations(range(4), 2))
    # Loop edge rule: 3/8 (a+b) + 1/8 (c+d), c and d the two other corners
    for a, b in combinations(range(4), 2):
        c, d = (u for u in range(4) if u not in (a, b))
        want = 3 / 8 * (verts[a] + verts[b]) + 1 / 8 * (verts[c] + verts[d])
        assert close(r["edge_points"][(a, b)], want)
    # m = 3 boundary neighbours: Warren's c = 3/16; Loop's beta(3) = (1/3)(5/8 - (3/8 - 1/8)^2)
    # = (1/3)(9/16) = 3/16 as well, so both give 7/16 x + 3/16 (sum of the other three).
    for v in range(4):
        others = sum(verts[u] for u in range(4) if u != v)
        assert close(r["vertex_points"][v], 7 / 16 * verts[v] + 3 / 16 * others)
    assert r["counts"]["vertices"] == 10
    assert r["counts"]["tetrahedra"] == 4
    assert r["counts"]["octahedra"] == 1


def test_star_octahedron_hand_values():
    verts, tets = star_octahedron()
    r = refimpl.level1_tets(verts, tets, "warren")
    mesh = r["mesh"]
    assert mesh["boundary_verts"] == {1, 2, 3, 4, 5, 6}
    assert all((0, i) not in mesh["boundary_edges"] for i in range(1, 7))

    # Interior vertex 0, rho = {1..6}, k = 6; sum rho = (2-1, 1-1, 1-3) = (1, 0, -2).
    #   9/16 (1/4, 0, 0) + 7/96 (1, 0, -2) = (9/64 + 7/96, 0, -14/96) = (41/192, 0, -7/48)
    assert close(r["vertex_points"][0], [41 / 192, 0, -7 / 48])

    # Interior spoke [0, 1], ring {3, 4, 5, 6} (k = 4, 001 eq. 3.5):
    #   8/32 ((1/4,0,0) + (2,0,0)) + 4/32 ((0,1,0) + (0,-1,0) + (0,0,1) + (0,0,-3))
    #   = (9/16, 0, 0) + (0, 0, -1/4) = (9/16, 0, -1/4)
    assert close(r["edge_points"][(0, 1)], [9 / 16, 0, -1 / 4])
    # Interior spoke [0, 6], ring {1, 2, 3, 4}:
    #   1/4 ((1/4,0,0) + (0,0,-3)) + 1/8 ((2,0,0) + (-1,0,0)) = (1/16 + 1/8, 0, -3/4)
    assert close(r["edge_points"][(0, 6)], [3 / 16, 0, -3 / 4])

    # Boundary vertex 1 = (2,0,0), surface neighbours {3, 4, 5, 6} (m = 4), Warren c = 3/32:
    #   (1 - 12/32) (2,0,0) + 3/32 (0, 0, 1-3) = (5/4, 0, -3/16)
    assert close(r["vertex_points"][1], [5 / 4, 0, -3 / 16])
    # Boundary edge [1, 3] in boundary faces (1,3,5) and (1,3,6):
    #   3/8 ((2,0,0) + (0,1,0)) + 1/8 ((0,0,1) + (0,0,-3)) = (3/4, 3/8, -1/4)
    assert close(r["edge_points"][(1, 3)], [3 / 4, 3 / 8, -1 / 4])

    # Loop's beta(4) = (1/4)(5/8 - (3/8 + cos(pi/2)/4)^2) = (1/4)(5/8 - 9/64) = 31/256:
    #   (1 - 124/256) (2,0,0) + 31/256 (0,0,-2) = (33/32, 0, -31/128)
    r = refimpl.level1_tets(verts, tets, "loop")
    assert close(r["vertex_points"][1], [33 / 32, 0, -31 / 128])
    # the solid rules do not depend on the surface weights
    assert close(r["vertex_points"][0], [41 / 192, 0, -7 / 48])


def test_chord_uses_the_solid_edge_rule():
    # k = 3 bipyramid with ring (1,0,0), (0,1,0), (-1,-1,1/2) and apexes (0,0,-1), (0,0,2):
    # [0, 1] joins two boundary vertices but is interior; 001 eq. 3.8 with k = 3:
    #   5/16 ((0,0,-1) + (0,0,2)) + 3/24 ((1,0,0) + (0,1,0) + (-1,-1,1/2))
    #   = (0, 0, 5/16) + (0, 0, 1/16) = (0, 0, 3/8)
    verts = np.array([[0, 0, -1], [0, 0, 2], [1, 0, 0], [0, 1, 0], [-1, -1, 0.5]], float)
    tets = [(0, 1, 2, 3), (0, 1, 3, 4), (0, 1, 4, 2)]
    r = refimpl.level1_tets(verts, tets)
    mesh = r["mesh"]
    assert {0, 1} <= mesh["boundary_verts"]
    assert (0, 1) not in mesh["boundary_edges"]
    assert close(r["edge_points"][(0, 1)], [0, 0, 3 / 8])


@pytest.mark.parametrize("k", [3, 4, 5, 6, 7, 9])
def test_interior_edge_weights(k):
    _, tets = bipyramid(k)
    _, est, mesh = refimpl.level1_stencils(tets)
    assert mesh["edge_ring"][(0, 1)] == set(range(2, k + 2))
    if k == 6:
        end, each = Fraction(10, 32), Fraction(2, 32)        # 001 eq. 3.4
    elif k == 4:
        end, each = Fraction(8, 32), Fraction(4, 32)         # 001 eq. 3.5
    else:
        end, each = Fraction(5, 16), Fraction(3, 8 * k)      # 001 eq. 3.8
    row = est[(0, 1)]
    assert set(row) == set(range(k + 2))
    assert row[0] == row[1] == float(end)
    assert all(row[u] == float(each) for u in range(2, k + 2))
    assert 2 * end + k * each == 1


@pytest.mark.parametrize("m", range(3, 12))
def test_loop_weights(m):
    if m == 3:
        assert refimpl.loop_weight(3, "warren") == 3 / 16
    else:
        assert refimpl.loop_weight(m, "warren") == 3 / (8 * m)
    beta = (5 / 8 - (3 / 8 + math.cos(2 * math.pi / m) / 4) ** 2) / m
    assert refimpl.loop_weight(m, "loop") == pytest.approx(beta, abs=1e-16)
    if m == 6:  # the regular Loop weight is 1/16 under both choices
        assert refimpl.loop_weight(6, "loop") == pytest.approx(1 / 16, abs=1e-16)
        assert refimpl.loop_weight(6, "warren") == 1 / 16


def all_meshes():
    out = [(f"hand{i}", v, t) for i, (v, t) in enumerate(hand_meshes())]
    for case in CASES:
        m = case_mesh(case)
        out.append((case, m["verts"], m["tets"]))
    return out


@pytest.mark.parametrize("weights", WEIGHTS)
def test_rows_sum_to_one_and_constants_are_kept(weights):
    for name, verts, tets in all_meshes():
        vst, est, _ = refimpl.level1_stencils(tets, weights, nverts=len(verts))
        for row in list(vst.values()) + list(est.values()):
            assert abs(sum(row.values()) - 1.0) < 1e-14, name
            assert all(w > 0 for w in row.values()), name
        # a constant field (here a 2-column attribute) is reproduced
        field = np.tile([2.5, -7.0], (len(verts), 1))
        r = refimpl.level1_tets(field, tets, weights)
        for p in list(r["vertex_points"].values()) + list(r["edge_points"].values()):
            assert close(p, [2.5, -7.0], 1e-13), name


def test_tetgen_cases_exercise_the_rules():
    """The committed meshes contain what the comparison test is meant to cover."""
    for case in CASES:
        m = case_mesh(case)
        mesh = refimpl.analyse(m["tets"], len(m["verts"]))
        inner_v = [v for v in mesh["vertices"] if v not in mesh["boundary_verts"]]
        inner_e = [e for e in mesh["edges"] if e not in mesh["boundary_edges"]]
        rings = {len(mesh["edge_ring"][e]) for e in inner_e}
        valences = {len(mesh["vertex_nbrs"][v]) for v in inner_v}
        assert len(valences) >= 3, case
        assert {4, 6} <= rings and rings - {4, 6}, case
        assert any(a in mesh["boundary_verts"] and b in mesh["boundary_verts"]
                   for a, b in inner_e), case  # chords
        assert mesh["boundary_verts"], case


@pytest.mark.parametrize("tets,why", [
    ([(0, 1, 2, 3), (0, 4, 5, 6)], "meet only at a vertex"),
    ([(0, 1, 2, 3), (0, 1, 4, 5)], "meet only along an edge"),
    ([(0, 1, 2, 3), (0, 1, 2, 4), (0, 1, 2, 5)], "three tetrahedra on one face"),
    ([(0, 1, 2, 2)], "repeated vertex"),
    ([(0, 1, 2, 3), (3, 2, 1, 0)], "same tetrahedron twice"),
])
def test_refuses_non_manifold(tets, why):
    with pytest.raises(refimpl.NotManifoldError):
        refimpl.analyse(tets)


def test_refuses_unused_vertex():
    verts, tets = single_tet()
    with pytest.raises(refimpl.NotManifoldError):
        refimpl.level1_tets(np.vstack([verts, [[5, 5, 5]]]), tets)


def test_input_round_trip(tmp_path):
    verts = np.array([[0.1, 1 / 3, -2e-17], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    simplices = [(0, 1, 2, 3), (1, 2, 3, 4), (4,), (0, 4), (1, 2, 4)]
    path = tmp_path / "in.txt"
    sdtext.write_input(path, verts, simplices, diagonals={1: 2}, comment="two tets")
    m = sdtext.read_input(path)
    assert np.array_equal(m["verts"], verts)  # %.17g round-trips exactly
    assert m["simplices"] == simplices
    assert m["tets"].tolist() == [[0, 1, 2, 3], [1, 2, 3, 4]]
    assert m["diagonals"] == {1: 2}


def test_parse_level_output():
    text = """\
level 1
vertices 5   # comment
v 0 0 0 V 0
v 1 0 0 V 1
v 0.5 0 0 E 1 0
v 0.25 0.25 0 C 3
v 1e-3 2 3 I

points 1
p 4
edges 1
e 0 2
triangles 0
tetrahedra 1
T 0 1 2 3
octahedra 1
O 0 1 2 3 4 0
vclass 0 8 1 0 loop 14
eclass 0 2 8 0 0 solid 6
row 2 2 0 0.5 1 0.5
"""
    out = sdtext.parse_level_text(text)
    assert out["level"] == 1
    assert out["verts"].shape == (5, 3)
    assert out["origins"] == [("V", 0), ("V", 1), ("E", 1, 0), ("C", 3), ("I",)]
    assert out["points"].tolist() == [[4]]
    assert out["edges"].tolist() == [[0, 2]]
    assert out["triangles"].shape == (0, 3)
    assert out["tetrahedra"].tolist() == [[0, 1, 2, 3]]
    assert out["octahedra"].shape == (1, 6)
    assert out["vclass"][0] == {"family": 8, "boundary": 1, "nmtype": 0, "rule": "loop",
                                "valence": 14}
    assert out["eclass"][(0, 2)]["ringsize"] == 6
    cols, w = out["rows"][2]
    assert cols.tolist() == [0, 1] and w.tolist() == [0.5, 0.5]


@pytest.mark.parametrize("text", [
    "vertices 1\nv 0 0 0 V 0\n",                 # no level line
    "level 1\nvertices 2\nv 0 0 0 V 0\n",         # short block
    "level 1\nvertices 1\nv 0 0 0 X 0\n",         # unknown tag
    "level 1\nvertices 1\nv 0 0 0 E 0\n",         # E needs two indices
    "level 1\nvertices 1\nv 0 0 0 V 0\ntetrahedra 1\nT 0 0 0\n",   # 3 indices
    "level 1\nvertices 1\nv 0 0 0 V 0\nedges 1\ne 0 1\n",          # index out of range
    "level 1\nvertices 1\nv 0 0 0 V 0\nrow 0 2 0 1\n",             # row too short
])
def test_parse_level_rejects_malformed(text):
    with pytest.raises(sdtext.FormatError):
        sdtext.parse_level_text(text)


# --------------------------------------------------------------------------------------------
# (b) build/sdlevel against the oracle

def needs_sdlevel(fn):
    """The comparison needs the tool: a missing binary is a failure, never a skip."""
    return fn


@functools.lru_cache(maxsize=None)
def run_sdlevel(case, weights):
    cmd = [str(SDLEVEL), "-l", "1", "--classes"]
    if weights != "warren":
        cmd += ["-w", weights]
    cmd.append(f"tests/cases/{case}/mesh.txt")
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"{' '.join(cmd)} failed:\n{proc.stderr}"
    return sdtext.parse_level_text(proc.stdout, f"sdlevel {case} {weights}")


@functools.lru_cache(maxsize=None)
def oracle(case, weights):
    m = case_mesh(case)
    return refimpl.level1_tets(m["verts"], m["tets"], weights)


@needs_sdlevel
@pytest.mark.parametrize("weights", WEIGHTS)
@pytest.mark.parametrize("case", CASES)
def test_sdlevel_points_match_oracle(case, weights):
    out = run_sdlevel(case, weights)
    ref = oracle(case, weights)
    assert out["level"] == 1

    worst, worst_at = 0.0, None
    seen_v, seen_e = set(), set()
    for i, (origin, x) in enumerate(zip(out["origins"], out["verts"])):
        tag = origin[0]
        if tag == "V":
            a = origin[1]
            assert i == a, f"vertex point of {a} printed at index {i}"
            assert a in ref["vertex_points"], f"V {a}: no such level-0 vertex"
            assert a not in seen_v, f"V {a} printed twice"
            seen_v.add(a)
            want = ref["vertex_points"][a]
        elif tag == "E":
            e = (min(origin[1:]), max(origin[1:]))
            assert e in ref["edge_points"], f"E {e}: no such level-0 edge"
            assert e not in seen_e, f"E {e} printed twice"
            seen_e.add(e)
            want = ref["edge_points"][e]
        else:
            pytest.fail(f"level-1 vertex {i} has origin {origin}; expected only V and E")
        d = float(np.max(np.abs(x - want)))
        if d > worst:
            worst, worst_at = d, (i, origin)
    assert seen_v == set(ref["vertex_points"]), "missing vertex points"
    assert seen_e == set(ref["edge_points"]), "missing edge points"
    assert worst < TOL, f"max |sdlevel - oracle| = {worst:.3g} at level-1 vertex {worst_at}"


@needs_sdlevel
@pytest.mark.parametrize("weights", WEIGHTS)
@pytest.mark.parametrize("case", CASES)
def test_sdlevel_counts_and_cells(case, weights):
    out = run_sdlevel(case, weights)
    ref = oracle(case, weights)
    counts = ref["counts"]
    assert len(out["verts"]) == counts["vertices"]
    for block in ("points", "edges", "triangles", "tetrahedra", "octahedra"):
        assert len(out[block]) == counts[block], block

    # Name every level-1 vertex by its parent simplex: ('V', a) or ('E', a, b) with a < b.
    def name(i):
        o = out["origins"][i]
        return o if o[0] == "V" else ("E", min(o[1:]), max(o[1:]))

    def E(a, b):
        return ("E", min(a, b), max(a, b))

    # docs/RULES.md "Splitting": each tetrahedron -> 4 corner tetrahedra + 1 octahedron on its edge points.
    want_tets, want_octs = set(), set()
    for t in ref["mesh"]["tets"]:
        for v in t:
            want_tets.add(frozenset([("V", v)] + [E(v, u) for u in t if u != v]))
        want_octs.add(frozenset(E(a, b) for a, b in combinations(t, 2)))
    got_tets = [frozenset(name(i) for i in cell) for cell in out["tetrahedra"]]
    assert len(set(got_tets)) == len(got_tets), "a corner tetrahedron is printed twice"
    assert set(got_tets) == want_tets

    got_octs = []
    for cell in out["octahedra"]:
        p, q, a, a2, b, b2 = (name(i) for i in cell)
        # the three pairs are opposite vertices: midpoints of opposite (disjoint) parent edges
        for u, w in ((p, q), (a, a2), (b, b2)):
            assert u[0] == w[0] == "E" and not set(u[1:]) & set(w[1:]), (u, w)
        got_octs.append(frozenset((p, q, a, a2, b, b2)))
    assert len(set(got_octs)) == len(got_octs), "an octahedron is printed twice"
    assert set(got_octs) == want_octs
