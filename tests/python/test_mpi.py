"""subdivd-mpi (issue 21): a level refined by several MPI processes on loopback equals the level
one process computes.

The reference is the one-process level of the same mesh, tags and rules, written by `subdivd
refine` (the same api/ and core/ code in one process): every point a piece writes must be that
level's point with the same index (`global_id`) to 1e-12, the owned cells of all pieces together
must be that level's cells exactly once each (same vertices by global id, same kind and index),
the `owner` of a point the lowest rank among the pieces using it, and the .pvtu must open in
VTK's parallel reader with the level's counts. Cases: solids (both schemes), closed and open
surfaces (both weights), curves with junctions, a mixed complex with attributes, and non-manifold
complexes with singular tags, semi-sharp creases and per-simplex overrides; levels 1-3 on 2 and 3
ranks (3 oversubscribed). Halos thinner than the default are shown to be wrong (the comparison
sees it: no halo and one ring on solids, two rings on solids with pinched G2 edges), and
failures stop every rank with a message and a non-zero exit.
"""
import collections
import itertools
import json
import os
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

from conftest import REPO
from daemon import SUBDIVD

MPI = pathlib.Path(os.environ.get("SUBDIVD_MPI", str(REPO / "build" / "subdivd-mpi"))).resolve()
MPIRUN = shutil.which("mpirun")
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_btl="self,tcp,vader", OMPI_MCA_btl_tcp_if_include="lo",
           OMPI_MCA_oob_tcp_if_include="lo", OMPI_MCA_rmaps_base_oversubscribe="1")

pytestmark = pytest.mark.skipif(not MPIRUN or not MPI.exists(),
                                reason="needs Open MPI (tools/packages.txt) and build/subdivd-mpi")

vtk = pytest.importorskip("vtkmodules.vtkIOXML")
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402


# ---- meshes -----------------------------------------------------------------------------------

def jitter(v, seed, amount=0.08):
    rng = np.random.RandomState(seed)
    return (np.asarray(v, float) + rng.uniform(-amount, amount, np.shape(v))).tolist()


def cubes(n, seed=1):
    """n^3 cubes, 6 tetrahedra each (Kuhn), vertices jittered."""
    idx = lambda i, j, k: (i * (n + 1) + j) * (n + 1) + k
    v = [[i, j, k] for i in range(n + 1) for j in range(n + 1) for k in range(n + 1)]
    t = []
    perms = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    for i in range(n):
        for j in range(n):
            for k in range(n):
                for p in perms:
                    c = [i, j, k]
                    s = [idx(*c)]
                    for a in p:
                        c[a] += 1
                        s.append(idx(*c))
                    t.append(s)
    return jitter(v, seed), t


def grid(nu, nv, seed=2, z=0.0):
    """An open nu x nv patch of triangles (bumpy, with a boundary)."""
    idx = lambda i, j: i * (nv + 1) + j
    v = [[i, j, z + 0.3 * np.sin(i) * np.cos(j)] for i in range(nu + 1) for j in range(nv + 1)]
    f = []
    for i in range(nu):
        for j in range(nv):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            f += [[a, b, c], [a, c, d]] if (i + j) % 2 else [[a, b, d], [b, c, d]]
    return jitter(v, seed, 0.05), f


def icosphere(n):
    p = (1 + 5 ** 0.5) / 2
    v = [(-1, p, 0), (1, p, 0), (-1, -p, 0), (1, -p, 0), (0, -1, p), (0, 1, p), (0, -1, -p),
         (0, 1, -p), (p, 0, -1), (p, 0, 1), (-p, 0, -1), (-p, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    v = [list(q) for q in v]
    for _ in range(n):
        mid, nf = {}, []

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                v.append([(v[a][i] + v[b][i]) / 2 for i in range(3)])
                mid[k] = len(v) - 1
            return mid[k]
        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = nf
    v = [[x / np.linalg.norm(q) * (1 + 0.1 * np.sin(3 * q[0] + q[2])) for x in q] for q in v]
    return jitter(v, 3, 0.02), [list(t) for t in f]


def curves_net(n=6):
    """A net of polylines on an n x n grid: junctions of valence 4 and 3, open ends."""
    idx = lambda i, j: i * (n + 1) + j
    v = [[i, j, 0.2 * np.sin(i + 2 * j)] for i in range(n + 1) for j in range(n + 1)]
    c = [[idx(i, j), idx(i + 1, j)] for i in range(n) for j in range(0, n + 1, 2)]
    c += [[idx(i, j), idx(i, j + 1)] for i in range(0, n + 1, 3) for j in range(n)]
    used = sorted({x for s in c for x in s})
    ren = {o: k for k, o in enumerate(used)}
    return jitter([v[o] for o in used], 4, 0.05), [[ren[a], ren[b]] for a, b in c]


def mixed():
    """A tet block with a triangle fin on one face's edge, a curve from a corner, an isolated
    point, and an attribute."""
    v, t = cubes(3, seed=5)
    n = len(v)
    # fin: a strip of triangles on the block's edge x = 0, z = 0 (vertices (0, j, 0))
    base = [4 * j for j in range(4)]  # the block's vertices (0, j, 0)
    fin = []
    for j in range(4):
        v.append([-1.0, j + 0.1 * j, -0.5 - 0.05 * j])
    for j in range(3):
        a, b, c, d = base[j], base[j + 1], n + j + 1, n + j
        fin += [[a, b, c], [a, c, d]]
    m = len(v)
    v += [[3.5, 3.6, 3.4], [4.2, 4.0, 4.5], [5.0, 4.4, 5.2], [9.0, 9.0, 9.0]]
    cur = [[63, m], [m, m + 1], [m + 1, m + 2]]
    pt = [[m + 3]]
    height = [float(p[2]) for p in v]
    body = {"vertices": v, "simplices": t + fin + cur + pt,
            "attributes": {"height": height, "uv": [[p[0], p[1] * 0.5] for p in v]}}
    return body


def book(pages=3, n=4, block=True):
    """`pages` triangle strips sharing one spine (non-manifold edges and vertices), plus (with
    `block`) a tet block glued to the spine's end vertex."""
    v = [[0, 0, j] for j in range(n + 1)]
    f = []
    for p in range(pages):
        ang = 2 * np.pi * p / pages + 0.3
        row0 = list(range(n + 1))
        for r in range(1, 3):
            row = []
            for j in range(n + 1):
                v.append([r * np.cos(ang) + 0.05 * j, r * np.sin(ang), j + 0.1 * r])
                row.append(len(v) - 1)
            for j in range(n):
                f += [[row0[j], row0[j + 1], row[j + 1]], [row0[j], row[j + 1], row[j]]]
            row0 = row
    if not block:
        return jitter(v, 7, 0.03), f
    cv, ct = cubes(2, seed=6)
    off = len(v)
    top = n  # the spine's top vertex (0, 0, n) is glued to the block's corner 0
    cv = [[x + 0.0, y + 0.0, z + n] for x, y, z in cv]
    ren = {0: top}
    k = off
    for i in range(1, len(cv)):
        ren[i] = k
        k += 1
    v += cv[1:]
    t = [[ren[a] for a in s] for s in ct]
    return jitter(v, 7, 0.03), f + t


PINCHED = REPO / "tests" / "cases" / "mpi_pinched_block" / "mesh.json"


def cases():
    out = {}
    v, t = cubes(4)
    out["solid-box"] = ({"vertices": v, "simplices": t}, None, None)
    out["solid-averaged"] = ({"vertices": v, "simplices": t}, None, {"solid_scheme": "averaged"})
    # a sharp triangle inside the solid (a face of two cells), a semi-sharp boundary edge and
    # vertex, a singular boundary crease
    out["solid-sharp"] = ({"vertices": v, "simplices": t},
                          {"singular": [[0, 5], [5, 10]],
                           "sharpness": [{"simplex": [31, 61, 62], "value": 2.5},
                                         {"simplex": [0, 1], "value": 1.5},
                                         {"simplex": [124], "value": 2.0}]}, None)
    v, f = icosphere(2)
    out["sphere-loop"] = ({"vertices": v, "simplices": f}, None, {"surface_weights": "loop"})
    v, f = grid(8, 7)
    out["open-surface-creases"] = (
        {"vertices": v, "simplices": f},
        {"singular": [[8 * 3 + j, 8 * 3 + j + 1] for j in range(3)] + [[40]],
         "sharpness": [{"simplex": [8 * 5 + j, 8 * 5 + j + 1], "value": 1.5 + j}
                       for j in range(4)] + [{"simplex": [50], "value": 2.0}]},
        {"crease_method": "chaikin"})
    v, c = curves_net()
    out["curves"] = ({"vertices": v, "simplices": c}, {"singular": [[5]]}, None)
    out["mixed"] = (mixed(), {"singular": [[63]]}, None)
    v, s = book()
    out["nonmanifold-g2"] = ({"vertices": v, "simplices": s}, {"singular": [[1]]}, None)
    out["nonmanifold-overrides"] = (
        {"vertices": v, "simplices": s}, None,
        {"nonmanifold_default": "G1",
         "overrides": [{"simplex": [2], "rule": "G2"}, {"simplex": [0, 1], "rule": "G1"},
                       {"simplex": [4], "rule": "N1", "dimension": 3},
                       {"simplex": [1, 2], "rule": "N2", "pair": [[1, 2, 7], [1, 2, 17]]}]})
    out["nonmanifold-ying-zorin"] = ({"vertices": v, "simplices": s}, None,
                                     {"nonmanifold_surface": "ying-zorin"})
    v, s = book(pages=4, n=6, block=False)   # triangles only, non-manifold: two rings of halo
    out["sheets-chang-qin"] = ({"vertices": v, "simplices": s}, {"singular": [[3]]}, None)
    out["sheets-ying-zorin"] = (
        {"vertices": v, "simplices": s},
        {"singular": [[0]], "petals": [{"vertex": 6, "triangle": [5, 6, 13], "kind": "concave"}]},
        {"nonmanifold_surface": "ying-zorin"})
    # a G2 edge ring that reads beyond the edge's star: the spine 0-1 of three sheets and a
    # vertex 5 joined to both ends by other triangles (its class decides whether the ring keeps
    # it, so one ring of halo is not enough)
    out["g2-edge-ring"] = ({"vertices": [[0, 0, 0], [0, 0, 1], [1, 0, 0.5], [-0.5, 0.87, 0.5],
                                         [-0.5, -0.87, 0.5], [0.5, 0.5, 0.6], [1, 1.2, -0.5],
                                         [1.2, 1, 1.5], [0, -1, -1], [1, -1, -1.2]],
                            "simplices": [[0, 8, 9], [0, 1, 2], [0, 1, 3], [0, 1, 4], [0, 5, 6],
                                          [1, 5, 7]]}, None, None)
    # non-manifold (pinched) solid edges following G2 next to tetrahedra: three rings of halo
    out["pinched-block"] = (json.loads(PINCHED.read_text()), None, None)
    return out


CASES = cases()


# ---- running ----------------------------------------------------------------------------------

def write_case(d, name):
    body, tags, rules = CASES[name]
    d = pathlib.Path(d)
    (d / "mesh.json").write_text(json.dumps(body))
    extra = []
    if tags:
        (d / "tags.json").write_text(json.dumps(tags))
        extra += ["--tags", str(d / "tags.json")]
    if rules:
        (d / "rules.json").write_text(json.dumps(rules))
        extra += ["--rules", str(d / "rules.json")]
    return d / "mesh.json", extra


def mpirun(n, *args, timeout=300):
    return subprocess.run([MPIRUN, "-n", str(n), "--oversubscribe", str(MPI), *map(str, args)],
                          capture_output=True, text=True, env=ENV, timeout=timeout)


def read(path):
    r = (vtk.vtkXMLPUnstructuredGridReader() if str(path).endswith(".pvtu")
         else vtk.vtkXMLUnstructuredGridReader())
    r.SetFileName(str(path))
    r.Update()
    return r.GetOutput()


def arr(g, name, cell=False):
    a = (g.GetCellData() if cell else g.GetPointData()).GetArray(name)
    assert a is not None, name
    return vtk_to_numpy(a)


def cells_of(g):
    conn = vtk_to_numpy(g.GetCells().GetConnectivityArray())
    offs = vtk_to_numpy(g.GetCells().GetOffsetsArray())
    types = vtk_to_numpy(g.GetCellTypesArray())
    return [(int(types[i]), tuple(conn[offs[i]:offs[i + 1]])) for i in range(len(types))]


_refs = {}
_ref_rules = {}


def reference(tmp_path_factory, name, level):
    """The one-process level: points (index = global id) and cells, from `subdivd refine`."""
    key = (name, level)
    if key not in _refs:
        d = tmp_path_factory.mktemp(f"ref-{name}-{level}")
        mesh, extra = write_case(d, name)
        out = d / "ref.vtu"
        r = subprocess.run([str(SUBDIVD), "refine", str(mesh), "--level", str(level), "-o",
                            str(out), *extra], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        g = read(out)
        _ref_rules[key] = arr(g, "rule").copy()
        _refs[key] = (vtk_to_numpy(g.GetPoints().GetData()).copy(), cells_of(g),
                      vtk_to_numpy(g.GetCellData().GetArray("kind")).copy()
                      if g.GetCellData().GetArray("kind") is not None else None)
    return _refs[key]


def reference_rules(tmp_path_factory, name, level):
    """The one-process level's per-point rule ids (its VTU's "rule" array)."""
    reference(tmp_path_factory, name, level)
    return _ref_rules[(name, level)]


def pieces_of(pvtu, n):
    stem = str(pvtu)[:-5]
    return [read(f"{stem}_{r}.vtu") for r in range(n)]


# ---- the acceptance tests --------------------------------------------------------------------

@pytest.mark.parametrize("nranks", [2, 3])
@pytest.mark.parametrize("name", sorted(CASES))
def test_pieces_equal_the_one_process_level(tmp_path, tmp_path_factory, name, nranks):
    mesh, extra = write_case(tmp_path, name)
    for level in (1, 2, 3):
        ref_pts, ref_cells, _ = reference(tmp_path_factory, name, level)
        out = tmp_path / f"l{level}.pvtu"
        stats = tmp_path / f"l{level}.json"
        r = mpirun(nranks, "refine", mesh, "--level", level, "-o", out, "--stats", stats, *extra)
        assert r.returncode == 0, r.stderr
        # progress per rank on stderr
        for k in range(nranks):
            assert f"subdivd-mpi: rank {k}/{nranks}: level {level}:" in r.stderr, r.stderr
        pieces = pieces_of(out, nranks)
        seen_cells = []
        users = {}
        for k, g in enumerate(pieces):
            pts = vtk_to_numpy(g.GetPoints().GetData()) if g.GetNumberOfPoints() else np.zeros((0, 3))
            gid = arr(g, "global_id") if g.GetNumberOfPoints() else np.zeros(0, int)
            assert len(set(gid.tolist())) == len(gid), "a piece lists a point twice"
            assert (gid >= 0).all() and (gid < len(ref_pts)).all()
            err = np.abs(pts - ref_pts[gid]).max() if len(gid) else 0.0
            assert err <= 1e-12, f"{name} level {level} rank {k}: max error {err}"
            if len(gid):   # every written point follows the one-process level's rule
                ref_rule = reference_rules(tmp_path_factory, name, level)
                assert (arr(g, "rule") == ref_rule[gid]).all(), f"{name} level {level} rank {k}"
            for x in gid.tolist():
                users.setdefault(x, set()).add(k)
            if g.GetNumberOfCells():
                cid = arr(g, "cell_id", cell=True)
                kind = arr(g, "kind", cell=True)
                for (t, vs), c, kk in zip(cells_of(g), cid, kind):
                    seen_cells.append((int(kk), int(c), t, tuple(int(gid[i]) for i in vs)))
            owner = arr(g, "owner") if g.GetNumberOfPoints() else []
            for x, o in zip(gid.tolist(), list(owner)):
                users.setdefault(x, set()).add(k)
        # every point of the level is written, with the lowest user as owner
        assert sorted(users) == list(range(len(ref_pts)))
        for k, g in enumerate(pieces):
            if g.GetNumberOfPoints():
                for x, o in zip(arr(g, "global_id").tolist(), arr(g, "owner").tolist()):
                    assert o == min(users[x]), (x, o, users[x])
        # the owned cells partition the level: every cell once, with the one-process vertices
        assert len(seen_cells) == len(ref_cells)
        assert sorted((t, vs) for _, _, t, vs in seen_cells) == sorted(ref_cells)
        times = collections.Counter((kk, c) for kk, c, _, _ in seen_cells)
        assert all(n == (4 if kk == 4 else 1) for (kk, c), n in times.items())   # 4 per octahedron
        # the parallel reader sees the whole level
        whole = read(out)
        assert whole.GetNumberOfCells() == len(ref_cells)
        assert whole.GetNumberOfPoints() == sum(p.GetNumberOfPoints() for p in pieces)
        s = json.loads(stats.read_text())
        assert s["ranks"] == nranks and s["level"] == level
        assert s["level_counts"]["points"] == len(ref_pts)
        assert sum(p["owned_simplices"] for p in s["per_rank"]) == \
            len(CASES[name][0]["simplices"]) - absorbed(CASES[name][0])
        # the whole complex's level-0 classes reached every piece, agreed with what the piece
        # holds whole, and every rank follows the whole complex's rules there
        for p in s["per_rank"]:
            if p["owned_simplices"]:
                assert p["classes_shipped"] > 0 and p["rules_checked"] > 0, p
            assert p["classes_differing"] == 0, p
        assert "level-0 classes:" in r.stderr


@pytest.mark.parametrize("nranks", [4, 8])
@pytest.mark.parametrize("name", ["nonmanifold-g2", "nonmanifold-ying-zorin", "sheets-ying-zorin",
                                  "g2-edge-ring"])
def test_many_small_pieces_of_nonmanifold_complexes(tmp_path, tmp_path_factory, name, nranks):
    """Parts of a few simplices put most of every piece near its rim, where G2's rows read
    their neighbours' classes and Ying-Zorin's petal edges their ends' rules: the default halo
    keeps every owned point exact and every checked rule the whole complex's."""
    test_pieces_equal_the_one_process_level(tmp_path, tmp_path_factory, name, nranks)


@pytest.mark.parametrize("nranks", [4, 5])
def test_solids_with_g2_need_three_rings(tmp_path, tmp_path_factory, nranks):
    """tests/cases/mpi_pinched_block: a Delaunay box whose dropped boundary slivers leave pinched
    solid edges (G2, non-manifold type 3) among tetrahedra, with triangle fins and curves. A G2
    edge ring one ring out reads a vertex two rings out (its class is the piece's own there), and
    an octahedron's diagonal joins an owned edge's level-1 point to that edge's: with two rings, 4
    and 5 ranks write a level-2 point wrong by 2e-3 without a word. The default (three rings with
    tetrahedra and a non-manifold simplex, DECISIONS 44) is exact, to level 3."""
    mesh, extra = write_case(tmp_path, "pinched-block")
    ref_pts, _, _ = reference(tmp_path_factory, "pinched-block", 2)
    out = tmp_path / "h2.pvtu"
    r = mpirun(nranks, "refine", mesh, "--level", 2, "-o", out, "--halo", 2, "-q")
    assert r.returncode == 0, r.stderr
    assert max_error(out, nranks, ref_pts) > 1e-3
    for level in (2, 3):
        ref_pts, ref_cells, _ = reference(tmp_path_factory, "pinched-block", level)
        out = tmp_path / f"l{level}.pvtu"
        r = mpirun(nranks, "refine", mesh, "--level", level, "-o", out, "--stats",
                   tmp_path / "s.json")
        assert r.returncode == 0, r.stderr
        assert "in 3 halo rings" in r.stderr
        assert json.loads((tmp_path / "s.json").read_text())["halo"] == 3
        assert max_error(out, nranks, ref_pts) <= 1e-12
        assert read(out).GetNumberOfCells() == len(ref_cells)


def test_chaikin_creases_take_two_rings(tmp_path):
    """Chaikin's child of a semi-sharp edge reads the other semi-sharp edges at its end
    (docs/RULES.md): with one ring a rim vertex lacks one, and an open surface (a column of
    semi-sharp edges crossing the parts) came out wrong by 1.6e-3 at level 2 on 3 ranks, exit 0.
    The default halo with Chaikin and a semi-sharp edge is two rings."""
    v, f = grid(10, 10)
    tags = {"sharpness": [{"simplex": [j * 11 + 3, (j + 1) * 11 + 3], "value": 0.7 + 0.4 * j}
                          for j in range(10)]}
    (tmp_path / "m.json").write_text(json.dumps({"vertices": v, "simplices": f}))
    (tmp_path / "t.json").write_text(json.dumps(tags))
    (tmp_path / "r.json").write_text(json.dumps({"crease_method": "chaikin"}))
    extra = ["--tags", tmp_path / "t.json", "--rules", tmp_path / "r.json"]
    r = subprocess.run([str(SUBDIVD), "refine", str(tmp_path / "m.json"), "--level", "2", "-o",
                        str(tmp_path / "ref.vtu"), *map(str, extra)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    ref = vtk_to_numpy(read(tmp_path / "ref.vtu").GetPoints().GetData())
    r = mpirun(3, "refine", tmp_path / "m.json", "--level", 2, "-o", tmp_path / "o.pvtu", *extra,
               "--stats", tmp_path / "s.json", "-q")
    assert r.returncode == 0, r.stderr
    assert max_error(tmp_path / "o.pvtu", 3, ref) <= 1e-12
    assert json.loads((tmp_path / "s.json").read_text())["halo"] == 2


def test_a_halo_too_thin_for_g2_stops(tmp_path):
    """One ring around the part owning the sheet [0, 8, 9] misses the triangle [1, 5, 7], so the
    G2 ring of the spine 0-1 (common neighbours of its ends, 5 among them in the whole complex)
    is another: the run stops naming the edge instead of writing wrong points."""
    mesh, extra = write_case(tmp_path, "g2-edge-ring")
    r = mpirun(6, "refine", mesh, "--level", 2, "-o", tmp_path / "o.pvtu", "--halo", 1, "-q")
    assert r.returncode == 3, r.stderr
    assert "are not the whole complex's at edge 0-1: G2 (valence 3) there, G2 (valence 4)" in \
        r.stderr and "a halo of 1 ring is too thin" in r.stderr, r.stderr


def absorbed(body):
    """Posted simplices that are faces of others (the core absorbs them): none in these cases."""
    return 0


@pytest.mark.parametrize("name", ["mixed", "nonmanifold-overrides", "solid-box"])
def test_merged_vtu_is_the_one_process_vtu(tmp_path, tmp_path_factory, name):
    """--merge: rank 0 assembles one VTU with the one-process points in order and cells in the
    one-process order (that of subdivd refine's VTU)."""
    mesh, extra = write_case(tmp_path, name)
    ref_pts, ref_cells, ref_kind = reference(tmp_path_factory, name, 2)
    out = tmp_path / "merged.vtu"
    r = mpirun(3, "refine", mesh, "--level", 2, "-o", out, *extra)
    assert r.returncode == 0, r.stderr
    g = read(out)
    pts = vtk_to_numpy(g.GetPoints().GetData())
    assert pts.shape == ref_pts.shape
    assert np.abs(pts - ref_pts).max() <= 1e-12
    assert (arr(g, "global_id") == np.arange(len(ref_pts))).all()
    assert (arr(g, "rule") == reference_rules(tmp_path_factory, name, 2)).all()
    assert cells_of(g) == ref_cells
    if ref_kind is not None:
        assert (arr(g, "kind", cell=True) == ref_kind).all()
    if name == "mixed":   # attributes travel with the points
        assert g.GetPointData().GetArray("height") is not None
        assert g.GetPointData().GetArray("uv").GetNumberOfComponents() == 2


@pytest.mark.parametrize("nranks", [1, 3])
def test_merge_keeps_the_vertices_of_no_simplex(tmp_path, nranks):
    """A posted vertex of no simplex is a point of every level, carried unchanged (DECISIONS 41):
    the merged VTU has it at its one-process index, as subdivd refine's VTU has; no piece's cells
    use it, so the merge used to stop with "no rank sent point 5" and exit 3."""
    v, t = cubes(2, seed=7)
    body = {"vertices": v[:5] + [[9, 9, 9]] + v[5:] + [[-3, 2, 1]],
            "simplices": [[i + (i >= 5) for i in s] for s in t],
            "attributes": {"h": list(range(len(v) + 2))}}
    mesh = tmp_path / "m.json"
    mesh.write_text(json.dumps(body))
    ref = tmp_path / "ref.vtu"
    r = subprocess.run([str(SUBDIVD), "refine", str(mesh), "--level", "2", "-o", str(ref)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    g0 = read(ref)
    out = tmp_path / "merged.vtu"
    r = mpirun(nranks, "refine", mesh, "--level", 2, "-o", out)
    assert r.returncode == 0, r.stderr
    g = read(out)
    pts, ref_pts = vtk_to_numpy(g.GetPoints().GetData()), vtk_to_numpy(g0.GetPoints().GetData())
    assert pts.shape == ref_pts.shape
    assert np.abs(pts - ref_pts).max() <= 1e-12
    assert pts[5].tolist() == [9, 9, 9] and pts[len(v) + 1].tolist() == [-3, 2, 1]
    assert (arr(g, "global_id") == np.arange(len(ref_pts))).all()
    assert (arr(g, "rule") == arr(g0, "rule")).all()
    assert np.abs(arr(g, "h") - arr(g0, "h")).max() <= 1e-12
    assert cells_of(g) == cells_of(g0)
    # the pieces still write only the points their cells use, and equal the one-process points
    r = mpirun(nranks, "refine", mesh, "--level", 2, "-o", tmp_path / "o.pvtu")
    assert r.returncode == 0, r.stderr
    assert max_error(tmp_path / "o.pvtu", nranks, ref_pts) <= 1e-12
    assert sum(p.GetNumberOfCells() for p in pieces_of(tmp_path / "o.pvtu", nranks)) == \
        g0.GetNumberOfCells()


def one_process_and_pieces(tmp_path, body, level, attributes, out="o.pvtu"):
    """`body` refined to `level` by `subdivd refine` (with those attributes) and by 2 ranks into
    `out` (pieces and a .pvtu, or one merged .vtu): the one-process VTU and out's path."""
    mesh = tmp_path / "m.json"
    mesh.write_text(json.dumps(body))
    ref = tmp_path / "ref.vtu"
    r = subprocess.run([str(SUBDIVD), "refine", str(mesh), "--level", str(level), "-o", str(ref),
                        "--attributes", attributes], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    out = tmp_path / out
    r = mpirun(2, "refine", mesh, "--level", level, "-o", out)
    assert r.returncode == 0, r.stderr
    return read(ref), out


def test_attributes_match_one_process(tmp_path):
    g0, out = one_process_and_pieces(tmp_path, mixed(), 2, "height,uv")
    for g in pieces_of(out, 2):
        gid = arr(g, "global_id")
        for a in ("height", "uv"):
            want = vtk_to_numpy(g0.GetPointData().GetArray(a))[gid]
            assert np.abs(arr(g, a) - want).max() <= 1e-12


def test_an_attribute_called_rule_moves_the_rule_array(tmp_path):
    """The pieces name the rule array as subdivd refine's VTU does: "rule_2" when an attribute
    is called "rule" (docs/OUTPUTS.md), the attribute keeping its name."""
    body = mixed()
    body["attributes"] = {"rule": body["attributes"]["height"]}
    g0, out = one_process_and_pieces(tmp_path, body, 1, "rule")
    assert '<PDataArray type="UInt8" Name="rule_2"' in out.read_text()
    for g in pieces_of(out, 2):
        gid = arr(g, "global_id")
        assert (arr(g, "rule_2") == vtk_to_numpy(g0.GetPointData().GetArray("rule_2"))[gid]).all()
        want = vtk_to_numpy(g0.GetPointData().GetArray("rule"))[gid]
        assert np.abs(arr(g, "rule") - want).max() <= 1e-12


@pytest.mark.parametrize("out", ["o.pvtu", "m.vtu"])
def test_attributes_called_global_id_and_owner_move_those_arrays(tmp_path, out):
    """Attributes called "global_id", "owner" and "global_id_2": the id and owner arrays become
    "global_id_3" and "owner_2" (as the rule array does, docs/OUTPUTS.md), so no two point arrays
    share a name (VTK's parallel reader and meshio keep one of a name: the ids were lost behind
    the attribute), and the attributes keep theirs."""
    v = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1.2]]
    body = {"vertices": v, "simplices": [[0, 1, 2, 3], [1, 2, 3, 4]],
            "attributes": {"global_id": [10.0, 11, 12, 13, 14], "owner": [5.0] * 5,
                           "global_id_2": [1.0] * 5}}
    g0, path = one_process_and_pieces(tmp_path, body, 2, "global_id,owner,global_id_2", out)
    want_attr = vtk_to_numpy(g0.GetPointData().GetArray("global_id"))
    graphs = [read(path)] if out.endswith(".vtu") else pieces_of(path, 2)
    if out.endswith(".pvtu"):
        graphs.append(read(path))  # the parallel reader, all pieces as one
    for g in graphs:
        pd = g.GetPointData()
        names = [pd.GetArrayName(i) for i in range(pd.GetNumberOfArrays())]
        assert len(names) == len(set(names)), names
        assert sorted(names) == ["global_id", "global_id_2", "global_id_3", "owner", "owner_2",
                                 "rule"], names
        gid = arr(g, "global_id_3")
        assert pd.GetArray("global_id_3").GetDataTypeAsString() in ("long", "long long")
        assert np.abs(arr(g, "global_id") - want_attr[gid]).max() <= 1e-12
        assert (arr(g, "owner") == 5).all() and set(arr(g, "owner_2").tolist()) <= {0, 1}


@pytest.mark.parametrize("halo,level,nranks", [(0, 2, 2), (1, 3, 3)])
def test_thinner_halos_are_wrong_for_solids(tmp_path, tmp_path_factory, halo, level, nranks):
    """Without a halo the pieces' rims are false boundaries, and one ring is too thin for the
    tetrahedron-octahedron split by level 3 (DECISIONS 44): the comparison must see both, so the
    tests above would catch a halo that is too thin. The default (two rings) is exact."""
    mesh, extra = write_case(tmp_path, "solid-box")
    ref_pts, _, _ = reference(tmp_path_factory, "solid-box", level)
    out = tmp_path / "h.pvtu"
    r = mpirun(nranks, "refine", mesh, "--level", level, "-o", out, "--halo", halo, "-q")
    if halo == 0 and r.returncode:   # the owned entities' rules, or the numbering, see the rim
        assert r.returncode == 3, r.stderr
        assert ("are not the whole complex's at" in r.stderr and "too thin" in r.stderr) or \
            ("internal: " in r.stderr and "in the piece" in r.stderr), r.stderr
        return
    assert r.returncode == 0, r.stderr
    worst = 0.0
    for g in pieces_of(out, nranks):
        gid = arr(g, "global_id")
        worst = max(worst, np.abs(vtk_to_numpy(g.GetPoints().GetData()) - ref_pts[gid]).max())
    assert worst > 1e-4


def test_one_rank_is_the_one_process_level(tmp_path, tmp_path_factory):
    mesh, extra = write_case(tmp_path, "mixed")
    ref_pts, ref_cells, _ = reference(tmp_path_factory, "mixed", 3)
    out = tmp_path / "one.pvtu"
    stats = tmp_path / "one.json"
    r = mpirun(1, "refine", mesh, "--level", 3, "-o", out, "--stats", stats, *extra)
    assert r.returncode == 0, r.stderr
    # one piece holds every star: every level-0 vertex, edge and face gets the whole complex's
    # class, and every vertex's and edge's rule is checked (counted here from the mesh)
    simplices = CASES["mixed"][0]["simplices"]
    verts = {v for s_ in simplices for v in s_}
    edges = {tuple(sorted(e)) for s_ in simplices for e in itertools.combinations(s_, 2)}
    faces = {tuple(sorted(f)) for s_ in simplices for f in itertools.combinations(s_, 3)}
    (p,) = json.loads(stats.read_text())["per_rank"]
    assert p["classes_shipped"] == len(verts) + len(edges) + len(faces)
    assert p["rules_checked"] == len(verts) + len(edges)
    assert p["classes_differing"] == 0
    (g,) = pieces_of(out, 1)
    assert (arr(g, "global_id") == np.arange(len(ref_pts))).all()   # the level's own order
    assert np.abs(vtk_to_numpy(g.GetPoints().GetData()) - ref_pts).max() <= 1e-12
    assert cells_of(g) == ref_cells
    assert (arr(g, "owner") == 0).all()


# ---- failures ---------------------------------------------------------------------------------

def test_refused_mesh_stops_every_rank(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"vertices": [[0, 0, 0], [1, 0, 0]], "simplices": [[0, 5]]}))
    r = mpirun(3, "refine", bad, "--level", 1, "-o", tmp_path / "o.pvtu")
    assert r.returncode == 1, r.stderr
    assert "subdivd-mpi: rank 0/3:" in r.stderr and "refused (422)" in r.stderr
    assert "/simplices/0/1" in r.stderr
    assert not list(tmp_path.glob("o*"))


def test_detail_offsets_are_refused(tmp_path):
    """PUT /complex's "details" (offsets of level-l points, docs/API.md) are not applied by the
    pieces: refused with a message naming them (exit 1, nothing written), where they used to be
    dropped without a word and every level >= 1 came out without the offsets, exit 0."""
    v, t = cubes(2, seed=7)
    mesh = tmp_path / "m.json"
    mesh.write_text(json.dumps({"vertices": v, "simplices": t, "details": [
        {"level": 1, "index": 5, "offset": [0.3, 0.2, 0.1]}]}))
    for out in ("o.pvtu", "o.vtu"):
        r = mpirun(2, "refine", mesh, "--level", 2, "-o", tmp_path / out)
        assert r.returncode == 1, r.stderr
        assert "detail offsets" in r.stderr and "subdivd refine" in r.stderr, r.stderr
        assert not list(tmp_path.glob("o*"))


def test_a_failing_rank_stops_all(tmp_path):
    """A memory cap per rank that the level does not fit in: the ranks that hit it say so, the
    run stops before writing and exits 3."""
    mesh, extra = write_case(tmp_path, "solid-box")
    r = mpirun(2, "refine", mesh, "--level", 3, "-o", tmp_path / "o.pvtu", "--max-memory",
               2_000_000)
    assert r.returncode == 3, r.stderr
    assert "level 3 failed" in r.stderr or "refused" in r.stderr, r.stderr
    assert "subdivd-mpi: rank" in r.stderr
    assert not list(tmp_path.glob("o*.vtu")) and not (tmp_path / "o.pvtu").exists()


@pytest.mark.parametrize("nth", [1, 5])
def test_one_failing_rank_stops_the_others(tmp_path, nth):
    """Rank 1 alone runs out of memory (the test hook SUBDIVD_MPI_FAIL_AT fails its nth
    allocation): it says so, rank 0 says the run stopped because of rank 1, nothing is written,
    and mpirun exits 3."""
    out = tmp_path / "o.pvtu"
    r = subprocess.run([MPIRUN, "-n", "3", "--oversubscribe", str(MPI), "refine",
                        str(REPO / "examples" / "mixed.json"), "--level", "3", "-o", str(out)],
                       capture_output=True, text=True, timeout=300,
                       env=dict(ENV, SUBDIVD_MPI_FAIL_AT=f"1:{nth}"))
    assert r.returncode == 3, r.stderr
    assert "subdivd-mpi: rank 1/3: out of memory" in r.stderr, r.stderr
    assert "subdivd-mpi: stopped (refining) after a failure on rank 1" in r.stderr
    assert "rank 0/3: out of memory" not in r.stderr and "rank 2/3: out of memory" not in r.stderr
    assert not list(tmp_path.glob("o*"))


@pytest.mark.parametrize("args,msg", [
    ([], "INPUT, --level L and -o OUT are required"),
    (["m.json", "--level", "1", "-o", "x.vtk"], "-o must end in .pvtu"),
    (["m.json", "--level", "x", "-o", "x.pvtu"], "--level takes a whole number"),
    (["m.json", "--level", "1", "-o", "x.pvtu", "--bogus"], "unknown option --bogus"),
    (["m.json", "--level", "1", "-o", "x.pvtu", "--merge"], "--merge writes one .vtu"),
])
def test_usage_errors(tmp_path, args, msg):
    r = mpirun(2, "refine", *args)
    assert r.returncode == 2
    assert msg in r.stderr and r.stderr.count(msg) == 1   # said once, by rank 0


def test_missing_file(tmp_path):
    r = mpirun(2, "refine", tmp_path / "none.json", "--level", 1, "-o", tmp_path / "o.pvtu")
    assert r.returncode == 2
    assert "cannot open" in r.stderr


def test_stats_not_written_is_a_failure(tmp_path):
    """--stats S.json that cannot be written: a message and exit 2 (a file), where the run said
    "cannot write" and exited 0, so a script reading S.json next found none or an old one."""
    mesh, extra = write_case(tmp_path, "curves")
    (tmp_path / "s.json").mkdir()   # its directory takes files; the name does not (a directory)
    r = mpirun(2, "refine", mesh, "--level", 1, "-o", tmp_path / "o.pvtu", *extra,
               "--stats", tmp_path / "s.json")
    assert r.returncode == 2, r.stderr
    assert "cannot write" in r.stderr and "s.json" in r.stderr


def test_a_piece_not_written_leaves_no_pieces(tmp_path):
    """Rank 1 cannot write its piece (a directory stands at its name): the run stops with exit 3
    and the other ranks remove the pieces they wrote, so no partial result is left."""
    (tmp_path / "o_1.vtu").mkdir()
    r = mpirun(3, "refine", REPO / "examples" / "mixed.json", "--level", 2, "-o",
               tmp_path / "o.pvtu", "-q")
    assert r.returncode == 3, r.stderr
    assert "subdivd-mpi: rank 1/3: cannot rename" in r.stderr
    assert "stopped (writing the pieces) after a failure on rank 1" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o_1.vtu"]
    assert (tmp_path / "o_1.vtu").is_dir()


def test_a_failed_run_leaves_no_index_of_an_earlier_one(tmp_path):
    """A complete result of an earlier run at the same name, then a run whose rank 1 cannot
    write its piece (a directory stands at its temporary name): the earlier o.pvtu must not stay
    behind naming pieces that were removed or belong to the other run (VTK would open it as a
    result, or fail on its missing pieces); nothing of either run is left."""
    mesh = REPO / "examples" / "mixed.json"
    r = mpirun(3, "refine", mesh, "--level", 1, "-o", tmp_path / "o.pvtu", "-q")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.pvtu", "o_0.vtu", "o_1.vtu",
                                                          "o_2.vtu"]
    (tmp_path / "o_1.vtu.part").mkdir()
    r = mpirun(3, "refine", mesh, "--level", 2, "-o", tmp_path / "o.pvtu", "-q")
    assert r.returncode == 3, r.stderr
    assert "stopped (writing the pieces) after a failure on rank 1" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o_1.vtu.part"]


# ---- other inputs -----------------------------------------------------------------------------

def sdlevel_points(path, level):
    """The level's points as build/sdlevel prints them (the core alone, no api/)."""
    from conftest import SDLEVEL
    out = subprocess.run([str(SDLEVEL), "-l", str(level), str(path)], capture_output=True,
                         text=True, check=True).stdout
    return np.array([[float(x) for x in l.split()[1:4]] for l in out.splitlines()
                     if l.startswith("v ")])


def max_error(pvtu, n, ref):
    worst = 0.0
    for g in pieces_of(pvtu, n):
        if g.GetNumberOfPoints():
            gid = arr(g, "global_id")
            worst = max(worst, np.abs(vtk_to_numpy(g.GetPoints().GetData()) - ref[gid]).max())
    return worst


def test_text_format_input(tmp_path):
    """INPUT.txt (docs/TEXT_FORMAT.md) with sharpness lines, against sdlevel's level."""
    from conftest import MAKE_MESH
    for name, args, extra in (("torus", ["torus", 12, 9], "c 0 1 2.5\nc 5 1.5\n"),
                              ("block", ["cubes", 3], "")):
        text = subprocess.run(["/usr/bin/python3", str(MAKE_MESH), *map(str, args)],
                              capture_output=True, text=True, check=True).stdout
        path = tmp_path / f"{name}.txt"
        path.write_text(text + extra)
        out = tmp_path / f"{name}.pvtu"
        r = mpirun(2, "refine", path, "--level", 2, "-o", out, "-q")
        assert r.returncode == 0, r.stderr
        ref = sdlevel_points(path, 2)
        assert max_error(out, 2, ref) <= 1e-12
        assert read(out).GetNumberOfCells() > 0


def test_text_diagonal_lines_are_posted_diagonals(tmp_path):
    """`d t k` lines become PUT /complex "diagonals" (the others chosen against them, as the
    API does): the level equals subdivd refine's of that JSON body."""
    v, t = cubes(3, seed=9)
    lines = ["v %.17g %.17g %.17g" % tuple(p) for p in v] + ["s " + " ".join(map(str, s)) for s in t]
    (tmp_path / "b.txt").write_text("\n".join(lines + ["d 0 1", "d 7 2", "d 30 0"]) + "\n")
    body = {"vertices": v, "simplices": t, "diagonals": [[0, 1], [7, 2], [30, 0]]}
    (tmp_path / "b.json").write_text(json.dumps(body))
    r = subprocess.run([str(SUBDIVD), "refine", str(tmp_path / "b.json"), "--level", "2", "-o",
                        str(tmp_path / "ref.vtu")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    ref = vtk_to_numpy(read(tmp_path / "ref.vtu").GetPoints().GetData())
    r = mpirun(3, "refine", tmp_path / "b.txt", "--level", 2, "-o", tmp_path / "o.pvtu", "-q")
    assert r.returncode == 0, r.stderr
    assert max_error(tmp_path / "o.pvtu", 3, ref) <= 1e-12


def test_cli_mpi_converts_and_runs(tmp_path):
    """`subdiv refine MESH --mpi N`: the mesh file converted as `subdiv convert` does, refined by
    N processes; the same level as subdivd refine of the converted body."""
    subdiv = REPO / "build" / "subdiv"
    mesh = REPO / "examples" / "block.msh"
    env = dict(ENV, SUBDIVD_MPI=str(MPI))
    r = subprocess.run([str(subdiv), "convert", str(mesh), "-o", str(tmp_path / "b.json"),
                        "--tags-out", str(tmp_path / "t.json")], capture_output=True, text=True,
                       env=env)
    assert r.returncode == 0, r.stderr
    r = subprocess.run([str(SUBDIVD), "refine", str(tmp_path / "b.json"), "--level", "2",
                        "--tags", str(tmp_path / "t.json"), "-o", str(tmp_path / "ref.vtu")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    g0 = read(tmp_path / "ref.vtu")
    ref = vtk_to_numpy(g0.GetPoints().GetData())
    r = subprocess.run([str(subdiv), "refine", str(mesh), "--level", "2", "-o",
                        str(tmp_path / "o.pvtu"), "--mpi", "2"], capture_output=True, text=True,
                       env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "subdivd-mpi: rank 1/2: level 2:" in r.stderr
    assert max_error(tmp_path / "o.pvtu", 2, ref) <= 1e-12
    assert read(tmp_path / "o.pvtu").GetNumberOfCells() == g0.GetNumberOfCells()
    r = subprocess.run([str(subdiv), "refine", str(mesh), "--level", "2", "-o",
                        str(tmp_path / "o.glb"), "--mpi", "2"], capture_output=True, text=True,
                       env=env)
    assert r.returncode == 2 and "--mpi writes one output" in r.stderr
    # -q: no result lines (docs: "errors still"), rank 0's summary included; the output is made
    r = subprocess.run([str(subdiv), "refine", str(mesh), "--level", "1", "-o",
                        str(tmp_path / "q.pvtu"), "--mpi", "2", "-q"], capture_output=True,
                       text=True, env=env, timeout=300)
    assert r.returncode == 0 and r.stderr == "" and r.stdout == "", (r.stdout, r.stderr)
    assert read(tmp_path / "q.pvtu").GetNumberOfCells() > 0


def test_more_ranks_than_simplices(tmp_path, tmp_path_factory):
    """examples/mixed.json has 5 simplices: on 7 ranks two get none and write empty pieces; the
    .pvtu still holds the whole level, and --merge the one-process VTU."""
    mesh = REPO / "examples" / "mixed.json"
    ref = tmp_path / "ref.vtu"
    r = subprocess.run([str(SUBDIVD), "refine", str(mesh), "--level", "2", "-o", str(ref)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    g0 = read(ref)
    ref_pts = vtk_to_numpy(g0.GetPoints().GetData())
    r = mpirun(7, "refine", mesh, "--level", 2, "-o", tmp_path / "o.pvtu", "-q")
    assert r.returncode == 0, r.stderr
    pieces = pieces_of(tmp_path / "o.pvtu", 7)
    assert sum(p.GetNumberOfCells() == 0 for p in pieces) == 2
    assert read(tmp_path / "o.pvtu").GetNumberOfCells() == g0.GetNumberOfCells()
    assert max_error(tmp_path / "o.pvtu", 7, ref_pts) <= 1e-12
    r = mpirun(7, "refine", mesh, "--level", 2, "-o", tmp_path / "m.vtu", "-q")
    assert r.returncode == 0, r.stderr
    g = read(tmp_path / "m.vtu")
    assert np.abs(vtk_to_numpy(g.GetPoints().GetData()) - ref_pts).max() <= 1e-12
    assert cells_of(g) == cells_of(g0)


def test_level_4_solid_averaged(tmp_path, tmp_path_factory):
    """Two rings stay enough at level 4 (DECISIONS 44: the front's advance is a geometric
    series): the averaged solid scheme on 3 ranks."""
    mesh, extra = write_case(tmp_path, "solid-averaged")
    ref_pts, ref_cells, _ = reference(tmp_path_factory, "solid-averaged", 4)
    out = tmp_path / "l4.pvtu"
    r = mpirun(3, "refine", mesh, "--level", 4, "-o", out, "-q", *extra)
    assert r.returncode == 0, r.stderr
    assert max_error(out, 3, ref_pts) <= 1e-12
    assert read(out).GetNumberOfCells() == len(ref_cells)


@pytest.mark.parametrize("out,stats", [("none/o.pvtu", None), ("none/o.vtu", None),
                                       ("o.pvtu", "none/s.json")])
def test_an_unwritable_output_is_found_before_the_work(tmp_path, out, stats):
    """-o (pieces or merged) or --stats in a directory that is not there: exit 2 (a file) with a
    message naming the directory, before anything is read or refined (no summary line, no
    files), where the run used to compute the whole level and fail when writing (exit 3)."""
    extra = ["--stats", tmp_path / stats] if stats else []
    r = mpirun(2, "refine", REPO / "examples" / "mixed.json", "--level", 2, "-o", tmp_path / out,
               *extra)
    assert r.returncode == 2, r.stderr
    assert f"cannot write into {tmp_path / 'none'}: No such file or directory" in r.stderr
    assert "read " not in r.stderr and "level 2 on 2 ranks" not in r.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("out", ["afile/o.pvtu", "afile/o.vtu"])
def test_an_output_under_a_file_says_not_a_directory(tmp_path, out):
    """-o under a path that is a regular file: exit 2 before the work, saying it is not a
    directory (access() on a file without the search bit said "Permission denied", which is not
    what is wrong, least of all to root)."""
    (tmp_path / "afile").write_text("")
    r = mpirun(2, "refine", REPO / "examples" / "mixed.json", "--level", 2, "-o", tmp_path / out)
    assert r.returncode == 2, r.stderr
    assert f"cannot write into {tmp_path / 'afile'}: Not a directory" in r.stderr, r.stderr
    assert "level 2 on 2 ranks" not in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]
