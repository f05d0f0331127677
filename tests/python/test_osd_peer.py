"""The OpenSubdiv peer itself (tests/peers/osd_loop.cpp), checked against Loop's formulas.

Run with /usr/bin/python3 -m pytest. The peer is build/osd_loop (built with
`make -f tests/peers/Makefile.inc build/osd_loop` when missing or older than its source).
Comparisons of subdivd with the peer live elsewhere; here the peer is checked on its own:
counts, Loop's original vertex and edge rules computed independently, OpenSubdiv's vertex
order, the error paths and the --time line.
"""
import math
import re
import subprocess
from collections import defaultdict

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import make_mesh_file as mesh_file  # noqa: E402

TOL = 1e-12


def read_input(path):
    verts, tris = [], []
    for line in path.read_text().splitlines():
        f = line.split()
        if f and f[0] == "v":
            verts.append([float(x) for x in f[1:4]])
        elif f and f[0] == "s":
            tris.append(tuple(int(x) for x in f[1:]))
    return np.array(verts), tris


def parse_output(text):
    """(level, points, triangles) of the peer's output, checking its headers and counts."""
    lines = text.splitlines()
    m = [re.fullmatch(r"(level|vertices) (\d+)", s) for s in lines[:2]]
    assert m[0] and m[0][1] == "level" and m[1] and m[1][1] == "vertices", lines[:2]
    level, nv = int(m[0][2]), int(m[1][2])
    pts = np.array([[float(x) for x in s.split()[1:]] for s in lines[2:2 + nv]]).reshape(-1, 3)
    assert all(s.startswith("v ") and len(s.split()) == 4 for s in lines[2:2 + nv])
    assert re.fullmatch(r"triangles \d+", lines[2 + nv])
    nt = int(lines[2 + nv].split()[1])
    body = lines[3 + nv:]
    assert len(body) == nt and all(s.startswith("t ") and len(s.split()) == 4 for s in body)
    tris = [tuple(int(x) for x in s.split()[1:]) for s in body]
    assert all(0 <= i < nv for t in tris for i in t)
    return level, pts, tris


def run_peer(osd, path, level):
    out = subprocess.run([str(osd), "-l", str(level), str(path)], check=True,
                         capture_output=True, text=True)
    assert out.stderr == ""
    lv, pts, tris = parse_output(out.stdout)
    assert lv == level
    return pts, tris


def loop_beta(n):
    return (5 / 8 - (3 / 8 + math.cos(2 * math.pi / n) / 4) ** 2) / n


def loop_step(verts, tris):
    """One step of Loop's scheme (original weights) on a closed triangle mesh, independent of
    the peer: vertex points first (same index), then edge points in first-seen order."""
    nbrs = defaultdict(set)
    opposite = defaultdict(list)
    for t in tris:
        for i in range(3):
            a, b, c = t[i], t[(i + 1) % 3], t[(i + 2) % 3]
            nbrs[a].add(b)
            nbrs[b].add(a)
            opposite[(min(a, b), max(a, b))].append(c)
    new = []
    for v in range(len(verts)):
        n = len(nbrs[v])
        beta = loop_beta(n)
        new.append((1 - n * beta) * verts[v] + beta * verts[sorted(nbrs[v])].sum(0))
    edge_index = {}
    for t in tris:
        for i in range(3):
            e = (min(t[i], t[(i + 1) % 3]), max(t[i], t[(i + 1) % 3]))
            if e not in edge_index:
                c, d = opposite[e]
                edge_index[e] = len(new)
                new.append(3 / 8 * (verts[e[0]] + verts[e[1]]) + 1 / 8 * (verts[c] + verts[d]))
    out = []
    for a, b, c in tris:
        ab, bc, ca = (edge_index[(min(x, y), max(x, y))] for x, y in ((a, b), (b, c), (c, a)))
        out += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
    return np.array(new), out


def rotate_min_first(t):
    k = t.index(min(t))
    return t[k:] + t[:k]


def assert_closed_oriented(tris):
    half = defaultdict(int)
    for t in tris:
        for i in range(3):
            half[(t[i], t[(i + 1) % 3])] += 1
    assert all(c == 1 and half.get((b, a)) == 1 for (a, b), c in half.items())


# (a) counts
@pytest.mark.parametrize("level,nv,nt", [(0, 12, 20), (1, 42, 80), (2, 162, 320)])
def test_icosahedron_counts(tmp_path, osd_loop, level, nv, nt):
    path = mesh_file(tmp_path, "icosphere", 0)
    pts, tris = run_peer(osd_loop, path, level)
    assert len(pts) == nv and len(tris) == nt
    assert len({rotate_min_first(t) for t in tris}) == nt
    assert_closed_oriented(tris)


# (b) vertex points of the octahedron: Loop's original weights, n = 4
def test_octahedron_vertex_points(tmp_path, osd_loop):
    path = mesh_file(tmp_path, "octahedron")
    verts, faces = read_input(path)
    pts, _ = run_peer(osd_loop, path, 1)
    assert len(pts) == 6 + 12
    n = 4
    beta = (1 / n) * (5 / 8 - (3 / 8 + math.cos(2 * math.pi / n) / 4) ** 2)
    assert beta == pytest.approx(31 / 256, abs=1e-15)
    tree = cKDTree(pts)
    found = []
    for v in range(6):
        nb = sorted({w for t in faces if v in t for w in t if w != v})
        assert len(nb) == n
        want = (1 - n * beta) * verts[v] + beta * verts[nb].sum(0)
        d, j = tree.query(want)
        assert d < TOL, f"vertex {v}: nearest peer point at {d:.3g}"
        found.append(j)
    assert len(set(found)) == 6


# (c) edge points of the octahedron: 3/8 (a + b) + 1/8 (c + d)
def test_octahedron_edge_points(tmp_path, osd_loop):
    path = mesh_file(tmp_path, "octahedron")
    verts, faces = read_input(path)
    pts, _ = run_peer(osd_loop, path, 1)
    tree = cKDTree(pts)
    edges = {tuple(sorted((t[i], t[(i + 1) % 3]))) for t in faces for i in range(3)}
    assert len(edges) == 12
    found = []
    for a, b in sorted(edges):
        c, d = [w for t in faces if a in t and b in t for w in t if w not in (a, b)]
        want = 3 / 8 * (verts[a] + verts[b]) + 1 / 8 * (verts[c] + verts[d])
        dist, j = tree.query(want)
        assert dist < TOL, f"edge {a}-{b}: nearest peer point at {dist:.3g}"
        found.append(j)
    assert len(set(found)) == 12


# Vertex order of OpenSubdiv's refined levels (default UniformOptions): the child of vertex i
# of level l is vertex i of level l+1; the edge points follow.
@pytest.mark.parametrize("shape", [("octahedron",), ("bumpy", 1), ("torus", 5, 4)])
def test_vertex_points_come_first_in_parent_order(tmp_path, osd_loop, shape):
    path = mesh_file(tmp_path, *shape)
    verts, faces = read_input(path)
    want, _ = loop_step(verts, faces)
    pts, _ = run_peer(osd_loop, path, 1)
    assert np.abs(pts[:len(verts)] - want[:len(verts)]).max() < TOL


# Several levels on meshes without symmetry and with valences 4, 5, 6: positions equal the
# independent Loop steps to 1e-12 (matched one-to-one by position) and so do the triangles
# (with orientation) under that matching. This also covers the level-by-level primvar buffers.
@pytest.mark.parametrize("shape,level", [(("octahedron",), 3), (("bumpy", 0), 3),
                                         (("bumpy", 1), 2), (("torus", 7, 5), 2)])
def test_levels_equal_independent_loop(tmp_path, osd_loop, shape, level):
    path = mesh_file(tmp_path, *shape)
    verts, tris = read_input(path)
    for _ in range(level):
        verts, tris = loop_step(verts, tris)
    pts, ptris = run_peer(osd_loop, path, level)
    assert pts.shape == verts.shape and len(ptris) == len(tris)
    d, j = cKDTree(pts).query(verts)
    assert d.max() < TOL, f"max distance {d.max():.3g}"
    assert len(set(j.tolist())) == len(verts), "matching is not one-to-one"
    mapped = {rotate_min_first(tuple(int(j[i]) for i in t)) for t in tris}
    assert mapped == {rotate_min_first(t) for t in ptris}


@pytest.mark.parametrize("text", [
    "v 0 0 0\nv 1 0 0\ns 0 1\n",                                    # a curve edge
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\ns 0 1 2 3\n",              # a tetrahedron
    "v 0 0 0\nv 1 0 0\nv 0 1 0\ns 0 1 2\nd 0 0\n",                  # a diagonal line
    "v 0 0 0\nv 1 0 0\nv 0 1 0\ns 0 1 2\nx 1\n",                    # an unknown line
    "v 0 0 0\nv 1 0 0\nv 0 1 0\ns 0 1 3\n",                         # index out of range
    "v 0 0 0\nv 1 0 0\nv 0 1 0\ns 0 1 1\n",                         # repeated index
    "v 0 0\nv 1 0 0\nv 0 1 0\ns 0 1 2\n",                           # short vertex line
    "v 0 0 0\n",                                                    # no triangles
])
def test_refuses_other_input(tmp_path, osd_loop, text):
    p = tmp_path / "bad.txt"
    p.write_text(text)
    r = subprocess.run([str(osd_loop), "-l", "1", str(p)], capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == "" and r.stderr.startswith("osd_loop: ")


@pytest.mark.parametrize("args", [["--warren"], ["-l", "11"], ["-l", "x"], ["--time", "0"], []])
def test_refuses_bad_arguments(tmp_path, osd_loop, args):
    path = mesh_file(tmp_path, "octahedron")
    r = subprocess.run([str(osd_loop), *args] + ([str(path)] if args else []),
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == "" and r.stderr.startswith("osd_loop: ")


def test_time_line(tmp_path, osd_loop):
    path = mesh_file(tmp_path, "icosphere", 1)
    r = subprocess.run([str(osd_loop), "--time", "4", "-l", "2", str(path)], check=True,
                       capture_output=True, text=True)
    m = re.fullmatch(r"osd_loop level=2 faces_in=80 faces_out=1280 "
                     r"seconds_best=([0-9]+\.[0-9]+) seconds_median=([0-9]+\.[0-9]+)\n", r.stdout)
    assert m, r.stdout
    assert 0 <= float(m[1]) <= float(m[2])
