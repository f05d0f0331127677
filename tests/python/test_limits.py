"""Limit positions and limit normals (001 Sec. 4; docs/RULES.md "Limits"; core/limit.c).

Expected values come from outside the code:
- OpenSubdiv 3.5's Far::PrimvarRefinerReal<double>::Limit (tests/peers/osd_loop.cpp --limit) for
  Loop surfaces, closed, open and with infinitely sharp creases, with Loop's weights: limit
  positions to 1e-12 and limit normals (cross product of its limit tangents) to 1e-9, points
  matched by origin level by level;
- the cubic B-spline's limit mask (1/6, 2/3, 1/6) and Warren's closed form, derived here from the
  1-ring block written down in numpy;
- the dominant left eigenvector of the 1-ring block of a solid's interior vertex, built here from
  the tetrahedra with the box-spline rules of docs/RULES.md (not read from the core);
- convergence: |p_lim - p_{L+k}| falls like the block's subdominant eigenvalues, computed here.
"""
import math
import random
import subprocess

import numpy as np
import pytest

from conftest import SDLEVEL
from test_sharp_vs_osd import bipyramids, cube_tets, disc, torus, write


def run(cmd):
    return subprocess.run([str(c) for c in cmd], check=True, capture_output=True,
                          text=True).stdout


def parse(text):
    """Points, their origins ('V', a) / ('E', a, b) / ('I',), and normals if listed."""
    pts, orig, nrm = [], [], []
    for line in text.splitlines():
        f = line.split()
        if not f:
            continue
        if f[0] == "v":
            pts.append([float(x) for x in f[1:4]])
            if len(f) < 5 or f[4] == "I":
                orig.append(("I",))
            elif f[4] == "V":
                orig.append(("V", int(f[5])))
            else:
                orig.append((f[4],) + tuple(sorted(int(x) for x in f[5:])))
        elif f[0] == "n":
            nrm.append([float(x) for x in f[1:4]])
    return np.array(pts), orig, np.array(nrm)


def ours(path, L, limit=True, weights="loop", scheme="box"):
    args = [SDLEVEL, "-l", L, "-w", weights, "-s", scheme] + (["--limit"] if limit else []) + [path]
    return parse(run(args))


def osd(peer, path, L):
    return parse(run([peer, "-l", L, "--origins", "--limit", path]))


def match(peer, path, L):
    """Our level-L points' indices in OpenSubdiv's level L (by origin, level by level)."""
    m = None
    for l in range(0, L + 1):
        _, o, _ = ours(path, l, limit=False)
        _, r, _ = parse(run([peer, "-l", l, "--origins", path]))
        if l == 0:
            m = list(range(len(o)))
            continue
        index = {k: j for j, k in enumerate(r)}
        m = [index[("V", m[k[1]])] if k[0] == "V" else index[("E",) + tuple(sorted((m[k[1]], m[k[2]])))]
             for k in o]
        assert sorted(m) == list(range(len(r)))
    return m


def surface_case(name, rng):
    if name == "torus":
        xyz, tris = torus(9, 7, rng)
        return xyz, tris, []
    if name == "bipyramids":
        xyz, tris = bipyramids(rng)
        return xyz, tris, []
    if name == "disc-open":
        xyz, tris = disc(rng)
        return xyz, tris, []
    if name == "torus-creased":  # two infinitely sharp rings: crease vertices, no darts
        xyz, tris = torus(9, 7, rng)
        V = 7
        sharp = [(3 * V + j, 3 * V + (j + 1) % V, 10.0) for j in range(V)]
        sharp += [(i * V + 5, ((i + 1) % 9) * V + 5, 10.0) for i in range(9)]
        return xyz, tris, sharp
    if name == "disc-creased":  # a crease across the disc, boundary to boundary
        xyz, tris = disc(rng, rings=3, n=6)
        # the vertices on the x axis: rows r = 1..3 at angle 0 and pi, and the centre
        ring_start = [1, 7, 19]
        ids = [ring_start[2] + 9, ring_start[1] + 6, ring_start[0] + 3, 0, ring_start[0],
               ring_start[1], ring_start[2]]
        es = {tuple(sorted(e)) for t in tris for e in ((t[0], t[1]), (t[1], t[2]), (t[0], t[2]))}
        sharp = [(a, b, 10.0) for a, b in zip(ids, ids[1:]) if tuple(sorted((a, b))) in es]
        assert len(sharp) == 6
        return xyz, tris, sharp
    raise ValueError(name)


SURFACES = ["torus", "bipyramids", "disc-open", "torus-creased", "disc-creased"]


def crease_vertices(tris, sharp, n):
    """Vertices on a sharp edge that are not on the boundary (OpenSubdiv's crease vertices)."""
    on = set()
    for s in sharp:
        on.update(s[:2])
    return on


@pytest.mark.parametrize("case", SURFACES)
@pytest.mark.parametrize("L", [0, 1, 2])
def test_loop_limits_equal_opensubdiv(tmp_path, osd_loop, case, L):
    rng = random.Random(sum(map(ord, case)))
    xyz, tris, sharp = surface_case(case, rng)
    path = tmp_path / f"{case}.txt"
    write(path, xyz, tris, sharp)
    p, o, n = ours(path, L)
    q, r, m = osd(osd_loop, path, L)
    idx = match(osd_loop, path, L)
    assert p.shape == q.shape and n.shape == m.shape == p.shape
    assert np.abs(p - q[idx]).max() < 1e-12
    # the limit is not the level's point (the test would pass trivially otherwise)
    lv, _, _ = ours(path, L, limit=False)
    assert np.abs(lv - p).max() > 1e-3
    # normals: everywhere but on interior creases, where OpenSubdiv gives one side's (which it
    # picks by its own edge order) and we the unit sum of both sides'
    crease = set()
    if sharp:
        # the level-L points on the creases: children of crease vertices and of crease edges
        on0 = {s[0] for s in sharp} | {s[1] for s in sharp}
        cur = set(on0)
        edges = {tuple(sorted(s[:2])) for s in sharp}
        for l in range(1, L + 1):
            _, ol, _ = ours(path, l, limit=False)
            nxt, nedges = set(), set()
            for i, k in enumerate(ol):
                if k[0] == "V" and k[1] in cur:
                    nxt.add(i)
                elif k[0] == "E" and k[1:] in edges:
                    nxt.add(i)
            for i, k in enumerate(ol):
                if k[0] == "E" and k[1:] in edges:
                    nedges |= {tuple(sorted((i, k[1]))), tuple(sorted((i, k[2])))}
            cur, edges = nxt, nedges
        crease = cur
    keep = [i for i in range(len(p)) if i not in crease]
    assert np.abs(n[keep] - m[idx][keep]).max() < 1e-9
    assert np.allclose(np.linalg.norm(n, axis=1), 1)
    # on the creases: unit, and at right angles to the limit crease tangent, the cubic
    # B-spline's (q_b - q_a) / 2 over the two crease neighbours (found here from the level)
    if crease:
        lvp, _, _ = ours(path, L, limit=False)
        nb = {}
        for e in edges:
            for a, b in (e, e[::-1]):
                nb.setdefault(a, []).append(b)
        checked = 0
        for i in crease:
            if len(nb.get(i, [])) == 2:
                t = lvp[nb[i][1]] - lvp[nb[i][0]]
                assert abs(np.dot(t / np.linalg.norm(t), n[i])) < 1e-9
                checked += 1
        assert checked > 0


def warren_block(n):
    """The 1-ring block of a smooth interior vertex of valence n with Warren's weights
    (docs/RULES.md: beta = 3/16 at n = 3, else 3/(8n); edges 3/8, 3/8, 1/8, 1/8)."""
    beta = 3 / 16 if n == 3 else 3 / (8 * n)
    M = np.zeros((n + 1, n + 1))
    M[0, 0] = 1 - n * beta
    M[0, 1:] = beta
    for i in range(n):
        M[1 + i, 0] = M[1 + i, 1 + i] = 3 / 8
        M[1 + i, 1 + (i - 1) % n] += 1 / 8
        M[1 + i, 1 + (i + 1) % n] += 1 / 8
    return M


def left_limit(M):
    w, vl = np.linalg.eig(M.T)
    j = int(np.argmin(abs(w - 1)))
    l = np.real(vl[:, j])
    return l / l.sum()


def test_warren_closed_form_is_the_eigenvector():
    """Warren's limit mask: 1/2 centre, 1/(2n) each neighbour for n > 3; 2/5, 1/5 at n = 3 —
    the closed form core/limit.c uses, against the block's left eigenvector."""
    for n in range(3, 13):
        l = left_limit(warren_block(n))
        want = [2 / 5] + [1 / 5] * 3 if n == 3 else [1 / 2] + [1 / (2 * n)] * n
        assert np.abs(l - want).max() < 1e-12


@pytest.mark.parametrize("case", ["torus", "bipyramids", "disc-open"])
def test_warren_limits(tmp_path, case):
    """With Warren's weights: interior vertices by the closed form above on their level-L
    1-ring (read from the level's triangles here), boundary vertices by (1/6, 2/3, 1/6)."""
    rng = random.Random(5)
    xyz, tris, _ = surface_case(case, rng)
    path = tmp_path / "w.txt"
    write(path, xyz, tris, [])
    p, _, _ = ours(path, 0, weights="warren")
    x = np.array(xyz)
    nbr, cnt = {}, {}
    for t in tris:
        for i in range(3):
            a, b = t[i], t[(i + 1) % 3]
            nbr.setdefault(a, set()).add(b)
            nbr.setdefault(b, set()).add(a)
            e = tuple(sorted((a, b)))
            cnt[e] = cnt.get(e, 0) + 1
    for v in range(len(xyz)):
        bnd = [u for u in nbr[v] if cnt[tuple(sorted((u, v)))] == 1]
        if bnd:
            want = 2 / 3 * x[v] + (x[bnd[0]] + x[bnd[1]]) / 6
        else:
            k = len(nbr[v])
            c0, c = (2 / 5, 1 / 5) if k == 3 else (1 / 2, 1 / (2 * k))
            want = c0 * x[v] + c * sum(x[u] for u in nbr[v])
        assert np.abs(p[v] - want).max() < 1e-12


def errors(path, L, K, weights="loop", vertices=None):
    """max over level-L points (or the given ones) of |p_lim - p_{L+k}|, k = 1..K."""
    p, _, _ = ours(path, L, weights=weights)
    sel = range(len(p)) if vertices is None else vertices
    out = []
    for k in range(1, K + 1):
        q, _, _ = ours(path, L + k, limit=False, weights=weights)
        out.append(max(np.linalg.norm(p[i] - q[i]) for i in sel))
    return np.array(out)


def assert_rate(e, lam, slack=0.03):
    """e_k falls like lam^k: every ratio at most lam (+ slack), and e_K within a factor 4 of
    e_1 lam^(K-1) from below (the rate is not faster than lam for no reason: e_K > 0)."""
    r = e[1:] / e[:-1]
    assert (r <= lam + slack).all(), (r, lam)
    assert e[-1] > 0
    assert e[-1] <= 4 * e[0] * lam ** (len(e) - 1), (e, lam)


def test_convergence_curve(tmp_path):
    """Cubic B-spline curves: a closed polygon and an open one (ends fixed). The limit is the
    (1/6, 2/3, 1/6) mask, ends themselves; the error at a vertex falls like 1/4^k (the block
    [[3/4,1/8,1/8],[1/2,1/2,0],[1/2,0,1/2]]'s eigenvalues 1, 1/2, 1/4: the 1/2 mode is odd and
    does not reach the centre)."""
    rng = random.Random(3)
    n = 9
    xyz = [(math.cos(2 * math.pi * k / n) * (1 + 0.2 * rng.uniform(-1, 1)),
            math.sin(2 * math.pi * k / n), 0.3 * rng.uniform(-1, 1)) for k in range(n)]
    closed = [(k, (k + 1) % n) for k in range(n)]
    opened = [(k, k + 1) for k in range(n - 1)]
    B = np.array([[3 / 4, 1 / 8, 1 / 8], [1 / 2, 1 / 2, 0], [1 / 2, 0, 1 / 2]])
    ev = sorted(abs(np.linalg.eigvals(B)))
    assert abs(left_limit(B) - [2 / 3, 1 / 6, 1 / 6]).max() < 1e-12
    x = np.array(xyz)
    for segs, ends in ((closed, []), (opened, [0, n - 1])):
        path = tmp_path / "c.txt"
        with open(path, "w") as f:
            for v in xyz:
                f.write("v %.17g %.17g %.17g\n" % v)
            for a, b in segs:
                f.write(f"s {a} {b}\n")
        p, _, _ = ours(path, 0)
        for v in range(n):
            want = x[v] if v in ends else 2 / 3 * x[v] + (x[(v - 1) % n] + x[(v + 1) % n]) / 6
            assert np.abs(p[v] - want).max() < 1e-14
        inner = [v for v in range(n) if v not in ends]
        assert_rate(errors(path, 0, 5, vertices=inner), ev[0])
        assert_rate(errors(path, 1, 5), ev[0])


def loop_block(n):
    """Loop's 1-ring block at an interior vertex (Loop's beta)."""
    beta = (5 / 8 - (3 / 8 + math.cos(2 * math.pi / n) / 4) ** 2) / n
    M = warren_block(n)
    M[0, 0] = 1 - n * beta
    M[0, 1:] = beta
    return M


def centre_rate(M):
    """The largest |eigenvalue| != 1 of block M whose right eigenvector reaches the centre
    (row 0): the rate at which a vertex point converges to its limit."""
    w, vr = np.linalg.eig(M)
    return max(abs(w[j]) for j in range(len(w))
               if abs(w[j] - 1) > 1e-9 and abs(vr[0, j]) > 1e-9)


@pytest.mark.parametrize("weights", ["loop", "warren"])
@pytest.mark.parametrize("case", ["bipyramids", "disc-open", "torus-creased"])
def test_convergence_loop(tmp_path, case, weights):
    """Loop surfaces (closed, open, creased; Loop's and Warren's weights): at every level-L
    vertex the error falls like the slowest centre rate among the blocks that occur — interior:
    computed from loop_block(n) / warren_block(n) for the valences of the mesh; boundary and
    crease vertices: the curve's 1/4."""
    rng = random.Random(sum(map(ord, case)))
    xyz, tris, sharp = surface_case(case, rng)
    path = tmp_path / "s.txt"
    write(path, xyz, tris, sharp)
    val = {}
    for t in tris:
        for i in range(3):
            val.setdefault(t[i], set()).update((t[(i + 1) % 3], t[(i + 2) % 3]))
    block = loop_block if weights == "loop" else warren_block
    lam = max([centre_rate(block(len(s))) for s in val.values()] + [0.25])
    assert_rate(errors(path, 0, 5, weights=weights, vertices=range(len(xyz))), lam)


def tet_rings(tets):
    nb, ering = {}, {}
    for t in tets:
        for i in range(4):
            for j in range(4):
                if i != j:
                    nb.setdefault(t[i], set()).add(t[j])
                    ering.setdefault((t[i], t[j]), set()).update(
                        t[k] for k in range(4) if k not in (i, j))
    return nb, ering


def box_block(v, nb, ering):
    """The 1-ring block of an interior solid vertex v at level 0 with the box-spline rules of
    docs/RULES.md (001 eqs. 3.3-3.8): vertex 9/16 v + 7/(16k) each neighbour; edge [v, x] with
    ring rho(e) (the other vertices of the tetrahedra around it): |rho| = 6: 10/32 (v + x) +
    2/32 each, = 4: 8/32, 4/32, else 5/16 (v + x) + 3/(8 |rho|) each. Level 0 has no
    octahedra, and one level later v's star is the same (its corner tetrahedra)."""
    ring = sorted(nb[v])
    pts = [v] + ring
    at = {u: i for i, u in enumerate(pts)}
    k = len(ring)
    M = np.zeros((k + 1, k + 1))
    M[0, 0] = 9 / 16
    M[0, 1:] = 7 / (16 * k)
    for i, x in enumerate(ring):
        r = ering[(v, x)]
        m = len(r)
        a, c = (10 / 32, 2 / 32) if m == 6 else (8 / 32, 4 / 32) if m == 4 else (5 / 16, 3 / (8 * m))
        M[1 + i, 0] += a
        M[1 + i, at[x]] += a
        for u in r:
            M[1 + i, at[u]] += c
    assert np.allclose(M.sum(axis=1), 1)
    return pts, M


def write_solid(path, xyz, cells):
    with open(path, "w") as f:
        for p in xyz:
            f.write("v %.17g %.17g %.17g\n" % tuple(p))
        for t in cells:
            f.write("s " + " ".join(map(str, t)) + "\n")


def star(n, rng):
    """A bipyramid over an n-gon split into 2n tetrahedra around its axis, with a vertex inside
    the axis: the centre (index 0) is interior with valence n + 2."""
    xyz = [(0.02 * rng.uniform(-1, 1), 0.02 * rng.uniform(-1, 1), 0.0)]
    for k in range(n):
        a = 2 * math.pi * k / n
        xyz.append((math.cos(a), math.sin(a), 0.1 * rng.uniform(-1, 1)))
    xyz += [(0.0, 0.0, 1.0), (0.0, 0.0, -1.1)]
    top, bot = n + 1, n + 2
    tets = []
    for k in range(n):
        a, b = 1 + k, 1 + (k + 1) % n
        tets += [(0, a, b, top), (0, b, a, bot)]
    return xyz, tets


@pytest.mark.parametrize("n", [4, 5, 7])
def test_solid_interior_is_the_eigenvector(tmp_path, n):
    """The limit of an interior solid vertex is the dominant left eigenvector of its 1-ring block,
    built here from the tetrahedra, applied to its 1-ring (1e-9)."""
    rng = random.Random(n)
    xyz, tets = star(n, rng)
    path = tmp_path / "star.txt"
    write_solid(path, xyz, tets)
    nb, ering = tet_rings(tets)
    pts, M = box_block(0, nb, ering)
    l = left_limit(M)
    want = l @ np.array(xyz)[pts]
    p, _, _ = ours(path, 0)
    assert np.abs(p[0] - want).max() < 1e-9
    assert np.abs(p[0] - np.array(xyz[0])).max() > 1e-4 or n == 4


def test_solid_interior_cube(tmp_path):
    """The same for the interior vertex of 2^3 cubes of 6 tetrahedra (valence 14)."""
    rng = random.Random(11)
    xyz, tets = cube_tets(2, rng)
    path = tmp_path / "cube.txt"
    write_solid(path, xyz, tets)
    nb, ering = tet_rings(tets)
    centre = 13  # (1, 1, 1)
    pts, M = box_block(centre, nb, ering)
    assert len(pts) == 15
    want = left_limit(M) @ np.array(xyz)[pts]
    p, _, _ = ours(path, 0)
    assert np.abs(p[centre] - want).max() < 1e-9


def test_convergence_solid(tmp_path):
    """Solid interior and boundary: the error of the level-0 vertices falls like the slowest
    centre rate of their blocks (interior: box_block here; boundary: the Loop blocks of the
    boundary surface, and the curve's 1/4 does not occur), over k = 1..4 (level 5 of a solid
    is large for a shared machine)."""
    rng = random.Random(2)
    xyz, tets = star(5, rng)
    path = tmp_path / "star.txt"
    write_solid(path, xyz, tets)
    nb, ering = tet_rings(tets)
    lam_in = centre_rate(box_block(0, nb, ering)[1])
    e_in = errors(path, 0, 4, vertices=[0])
    assert_rate(e_in, lam_in, slack=0.05)
    bval = {}
    count = {}
    for t in tets:
        for k in range(4):
            f = tuple(sorted(t[:k] + t[k + 1:]))
            count[f] = count.get(f, 0) + 1
    for f, c in count.items():
        if c == 1:
            for v in f:
                bval.setdefault(v, set()).update(u for u in f if u != v)
    lam_b = max(centre_rate(loop_block(len(s))) for s in bval.values())
    assert_rate(errors(path, 0, 4, vertices=sorted(bval)), lam_b, slack=0.05)


def test_solid_boundary_normals_are_its_surface_loop_normals(tmp_path, osd_loop):
    """The box-spline solid's boundary follows Loop over its boundary surface (001 Sec. 3.6), so
    at level 1 its boundary points' limit positions and normals equal OpenSubdiv's Loop limits
    of that surface (outward), matched by origin."""
    rng = random.Random(7)
    xyz, tets = cube_tets(2, rng)
    x = np.array(xyz)
    faces = {}
    for t in tets:
        vol = np.dot(np.cross(x[t[1]] - x[t[0]], x[t[2]] - x[t[0]]), x[t[3]] - x[t[0]])
        for k in range(4):
            f = [t[j] for j in range(4) if j != k]
            # outward: the face seen from outside, away from the opposite vertex
            nrm = np.cross(x[f[1]] - x[f[0]], x[f[2]] - x[f[0]])
            if np.dot(nrm, x[t[k]] - x[f[0]]) > 0:
                f = [f[0], f[2], f[1]]
            key = tuple(sorted(f))
            faces.setdefault(key, []).append(f)
        assert abs(vol) > 0
    bnd = [fs[0] for fs in faces.values() if len(fs) == 1]
    used = sorted({v for f in bnd for v in f})
    new = {v: i for i, v in enumerate(used)}
    solid, surf = tmp_path / "solid.txt", tmp_path / "surf.txt"
    write_solid(solid, xyz, tets)
    write(surf, [xyz[v] for v in used], [[new[v] for v in f] for f in bnd], [])
    for L in (1, 2):
        p, o, n = ours(solid, L)
        q, r, m = osd(osd_loop, surf, L)
        # the solid's level-L boundary points by origin, followed from level 0 (old -> new ids)
        mp = {v: new[v] for v in used}
        for l in range(1, L + 1):
            _, ol, _ = ours(solid, l, limit=False)
            _, rl, _ = parse(run([osd_loop, "-l", l, "--origins", surf]))
            index = {k: j for j, k in enumerate(rl)}
            nm = {}
            for i, k in enumerate(ol):
                if k[0] == "V" and k[1] in mp:
                    nm[i] = index[("V", mp[k[1]])]
                elif k[0] == "E" and k[1] in mp and k[2] in mp:
                    key = ("E",) + tuple(sorted((mp[k[1]], mp[k[2]])))
                    if key in index:
                        nm[i] = index[key]
            mp = nm
        assert len(mp) == len(q)
        ids = sorted(mp)
        j = [mp[i] for i in ids]
        assert np.abs(p[ids] - q[j]).max() < 1e-12
        assert np.abs(n[ids] - m[j]).max() < 1e-9


@pytest.mark.parametrize("chaikin", [False, True], ids=["uniform", "chaikin"])
@pytest.mark.parametrize("case", ["torus-chains", "disc-open"])
def test_semi_sharp_limit_is_taken_where_sharpness_has_expired(tmp_path, osd_loop, case, chaikin):
    """Semi-sharp creases (0.3 - 3.7, edges and vertices): the limit of a level-0 vertex is
    taken at level E = ceil(max sharpness), where every sharpness has expired; it equals
    OpenSubdiv's Limit at its level E (smooth masks there) of the same vertex (vertex children
    keep their index in both) to 1e-12, and level-0 errors fall like the Loop centre rate."""
    from test_sharp_vs_osd import make_case
    rng = random.Random(sum(map(ord, case)))
    xyz, tris, sharp = make_case(case, rng)
    keys = [tuple(sorted(s[:-1])) for s in sharp]
    sharp = [s for i, s in enumerate(sharp) if keys.index(keys[i]) == i]
    path = tmp_path / "sh.txt"
    write(path, xyz, tris, sharp)
    E = math.ceil(max(s[-1] for s in sharp))
    extra = ["--chaikin"] if chaikin else []
    p = parse(run([SDLEVEL, "-l", 0, "-w", "loop", "--limit", *extra, path]))[0]
    q = parse(run([osd_loop, "-l", E, "--limit", *extra, path]))[0]
    nv = len(xyz)
    assert np.abs(p - q[:nv]).max() < 1e-12
    # at level 0 the sharpness still matters: OpenSubdiv's level-0 limit masks differ
    q0 = parse(run([osd_loop, "-l", 0, "--limit", *extra, path]))[0]
    assert np.abs(p - q0).max() > 1e-3


# ---- through the daemon: ?limit=true, limit_mask, detail offsets --------------------------------

@pytest.fixture(scope="module")
def daemon():
    from daemon import Daemon
    d = Daemon()
    yield d
    assert d.stop() == 0


def session(daemon, body, rules=None):
    from daemon import Session
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    if rules:
        r = s.req("PUT", "/rules", json=rules)
        assert r.status_code == 200, r.text
    return s


def b1_bipyramid():
    """001 Appendix B.1's triangular bipyramid (centre 0, poles 1 and 5, ring 2 3 4)."""
    from test_http_analysis import bipyramid
    return bipyramid()


def test_limit_mask_of_appendix_b1(daemon):
    """The bipyramid centre of 001 Appendix B.1: limit_mask is the dominant left eigenvector of
    the paper's printed 6x6 block (its order: centre, apex 1, ring 2 3 4, apex 5), and the level's
    ?limit=true point is that mask on the control points."""
    s = session(daemon, b1_bipyramid())
    j = s.req("GET", "/analysis", params={"vertex": 0}).json()
    s16, e, q, f, w = 1 / 16, 1 / 8, 1 / 4, 5 / 16, 7 / 80
    B1 = np.array([[9 * s16, w, w, w, w, w], [f, f, e, e, e, 0], [q, e, q, e, e, e],
                   [q, e, e, q, e, e], [q, e, e, e, q, e], [f, 0, e, e, e, f]])
    want = left_limit(B1)
    ids = j["points"]["ids"]
    got = np.array(j["limit_mask"])
    assert len(got) == len(ids)
    np.testing.assert_allclose(got[[ids.index(v) for v in range(6)]], want, atol=1e-12)
    assert j["limit"]["method"] == "eigenvector" and j["limit"]["level"] == 1
    assert j["limit"]["outside"] == []
    x = np.array(b1_bipyramid()["vertices"])
    lim = s.level(0, format="json", limit="true").json()["vertices"]
    np.testing.assert_allclose(lim[0], want @ x[[0, 1, 2, 3, 4, 5]], atol=1e-12)
    plain = s.level(0, format="json").json()["vertices"]
    assert np.abs(np.array(lim) - plain).max() > 1e-3


def surface_body(case, seed):
    xyz, tris, sharp = surface_case(case, random.Random(seed))
    return {"vertices": [list(p) for p in xyz], "simplices": [list(t) for t in tris]}, sharp


def test_loop_limit_mask_and_tangents(daemon):
    """A Loop vertex of valence n: limit_mask = (1 - n chi, chi ...) with chi = 1/(n + 3/(8 beta))
    (Loop's beta), tangents cos / sin (2 pi i / n) over its ring in the triangles' order."""
    body, _ = surface_body("bipyramids", 1)
    s = session(daemon, body, {"surface_weights": "loop"})
    for v in range(3, 13):  # the apex of the n-gon bipyramid: index of its top
        top = sum(k + 2 for k in range(3, v)) + v
        j = s.req("GET", "/analysis", params={"vertex": top}).json()
        n = len(j["points"]["ids"]) - 1
        assert n == v
        beta = (5 / 8 - (3 / 8 + math.cos(2 * math.pi / n) / 4) ** 2) / n
        chi = 1 / (n + 3 / (8 * beta))
        np.testing.assert_allclose(j["limit_mask"], [1 - n * chi] + [chi] * n, atol=1e-15)
        assert j["limit"]["method"] == "loop" and j["limit"]["level"] == 0
        t1, t2 = (np.array(t) for t in j["limit"]["tangents"])
        assert abs(t1[0]) < 1e-15 and abs(t2[0]) < 1e-15
        # the ring's weights are cos/sin of equally spaced angles: |(t1, t2)_i| = 1, and
        # consecutive ones (in the ring's order found here) are 2 pi / n apart
        np.testing.assert_allclose(np.hypot(t1[1:], t2[1:]), 1, atol=1e-12)
        ang = np.sort(np.mod(np.arctan2(t2[1:], t1[1:]), 2 * math.pi))
        np.testing.assert_allclose(np.diff(ang), 2 * math.pi / n, atol=1e-9)


def glb_normals(data):
    from test_live import glb_arrays
    g = glb_arrays(data)
    return g["POSITION"], g["NORMAL"]


@pytest.mark.parametrize("L", [0, 2])
def test_limit_on_every_format(daemon, tmp_path, osd_loop, L):
    """?limit=true on json, vtk and glb: the points are OpenSubdiv's limits (json to 1e-12; the
    formats' float32 positions and normals to 1e-6), glTF normals its limit normals."""
    body, _ = surface_body("disc-open", 3)
    s = session(daemon, body, {"surface_weights": "loop"})
    path = tmp_path / "d.txt"
    write(path, body["vertices"], body["simplices"], [])
    q, _, m = osd(osd_loop, path, L)
    idx = match(osd_loop, path, L)
    j = s.level(L, format="json", limit="true").json()
    np.testing.assert_allclose(np.array(j["vertices"]), q[idx], atol=1e-12)
    r = s.level(L, format="glb", limit="true")
    assert r.status_code == 200
    pos, nrm = glb_normals(r.content)
    np.testing.assert_allclose(pos, q[idx], atol=1e-6)
    np.testing.assert_allclose(nrm, m[idx], atol=1e-6)
    plain = glb_normals(s.level(L, format="glb").content)[1]
    assert np.abs(plain - nrm).max() > 1e-3  # area-weighted normals are not the limit's
    vtk = s.level(L, format="vtk", limit="true")
    assert vtk.status_code == 200 and vtk.content != s.level(L, format="vtk").content


@pytest.mark.parametrize("value", ["yes", "1", ""])
def test_limit_bad_value(daemon, value):
    s = session(daemon, b1_bipyramid())
    r = s.level(0, format="json", limit=value)
    assert r.status_code == 422
    assert r.headers["Content-Type"].startswith("application/problem+json")
    assert r.json()["errors"][0]["pointer"] == "limit"


def test_limit_includes_detail_offsets(daemon):
    """A detail offset at level 2: ?limit=true at level 1 takes the limit from level 2 (the
    finest level with offsets), so a level-1 vertex's limit equals that of the same vertex at
    level 2, and the offset moves it; GET /analysis's limit mask and tangents carry the offset's
    part as constant terms."""
    body, _ = surface_body("torus", 4)
    s = session(daemon, body, {"surface_weights": "loop"})
    before = np.array(s.level(1, format="json", limit="true").json()["vertices"])
    etag = s.req("GET", "/complex").headers.get("ETag")
    edit = {"moves": [{"level": 2, "index": 5, "position": [0.5, 0.5, 0.9]}]}
    r = s.req("PATCH", "/control-points", json=edit, headers={"If-Match": etag} if etag else {})
    assert r.status_code == 200, r.text
    l1 = np.array(s.level(1, format="json", limit="true").json()["vertices"])
    l2 = np.array(s.level(2, format="json", limit="true").json()["vertices"])
    np.testing.assert_allclose(l1, l2[:len(l1)], atol=1e-12)
    assert np.abs(l1[5] - before[5]).max() > 1e-3
    # the limit is Loop's closed form at level 2 (the limit level) on level 2's points, the
    # offset among them; GET /analysis's mask on the control points plus its offset is that
    lv2 = s.level(2, format="json").json()
    p2 = np.array(lv2["vertices"])
    ring = sorted({v for tri in lv2["cells"]["triangles"] if 5 in tri for v in tri} - {5})
    n = len(ring)
    beta = (5 / 8 - (3 / 8 + math.cos(2 * math.pi / n) / 4) ** 2) / n
    chi = 1 / (n + 3 / (8 * beta))
    want = (1 - n * chi) * p2[5] + chi * p2[ring].sum(axis=0)
    np.testing.assert_allclose(l2[5], want, atol=1e-12)
    j = s.req("GET", "/analysis", params={"vertex": 5}).json()
    assert j["limit"]["level"] == 2 and j["points"]["level"] == 0
    x0 = np.array(body["vertices"])
    got = np.array(j["limit_mask"]) @ x0[j["points"]["ids"]]
    got += sum((o["weight"] * x0[o["id"]] for o in j["limit"]["outside"]), np.zeros(3))
    assert np.abs(j["limit"]["offset"]).max() > 1e-3
    np.testing.assert_allclose(got + j["limit"]["offset"], want, atol=1e-12)
    # the tangents likewise: their cross product is along the limit normal ?limit=true serves
    t1, t2 = (np.array(w) @ x0[j["points"]["ids"]] + np.array(o)
              for w, o in zip(j["limit"]["tangents"], j["limit"]["tangent_offsets"]))
    from test_live import glb_arrays
    nrm = glb_arrays(s.level(0, limit="true").content)["NORMAL"][5]
    cr = np.cross(t1, t2)
    np.testing.assert_allclose(cr / np.linalg.norm(cr), nrm, atol=1e-6)


@pytest.mark.parametrize("scheme", ["box", "averaged"])
def test_convergence_solid_finer_levels(tmp_path, scheme):
    """Every point of levels 1 and 2 of a solid (vertex, edge and cell points, interior and
    boundary): the error falls geometrically at most like the slowest rate of the level-0 blocks
    here (interior: box_block; boundary: the Loop blocks), plus slack for the new points'
    configurations (valence 12 + 2 diagonals and their boundary counterparts). The averaged
    scheme's rows also read the vertices opposite across octahedra (not only the major
    diagonals'), so its blocks at levels >= 1 hold those octahedra's cell points: a point left
    where it is (a block taken as not closed) has an error that tends to a constant."""
    rng = random.Random(1)
    xyz, tets = star(5, rng)
    path = tmp_path / "star.txt"
    write_solid(path, xyz, tets)
    for L in (1, 2):
        p, _, _ = ours(path, L, scheme=scheme)
        es = []
        for k in range(1, 6 - L + 1):
            q, _, _ = ours(path, L + k, limit=False, scheme=scheme)
            es.append(np.linalg.norm(p - q[:len(p)], axis=1).max())
        es = np.array(es)
        r = es[1:] / es[:-1]
        assert (r < 0.4).all(), r
        assert es[-1] < 0.4 ** (len(es) - 1) * es[0]


def test_convergence_nonmanifold(tmp_path):
    """A solid with a fin of three triangles on one of its boundary edges (a G2 edge, G2
    vertices) and a curve from its apex: the limits there are the eigenvectors of blocks with no
    closed form. The error of every control point falls geometrically (ratio at most 0.6, over
    k = 1..6), which a wrong limit cannot do (its error tends to a nonzero constant)."""
    rng = random.Random(1)
    xyz, tets = star(5, rng)
    cells = [list(t) for t in tets]
    n0 = len(xyz)
    xyz += [(1.6, 0.6, 0.3), (1.7, 0.9, -0.4), (0.1, 0.2, 1.8), (0.3, -0.2, 2.5), (-0.2, 0.1, 3.1)]
    cells += [[1, 2, n0], [1, 2, n0 + 1], [n0, 2, n0 + 1]]
    cells += [[6, n0 + 2], [n0 + 2, n0 + 3], [n0 + 3, n0 + 4]]
    path = tmp_path / "nm.txt"
    write_solid(path, xyz, cells)
    p, _, _ = ours(path, 0)
    es = []
    for k in range(1, 7):
        q, _, _ = ours(path, k, limit=False)
        es.append(np.linalg.norm(p - q[:len(p)], axis=1))
    es = np.array(es)
    moving = es[0] > 1e-12  # fixed points (the curve's end) have no error at all
    r = es[2:, moving] / es[1:-1, moving]
    assert (r <= 0.6).all(), r.max()
    assert es[-1].max() < 0.6 ** 5 * es[0].max()


def test_offline_client_and_cli(daemon, tmp_path):
    """The offline mode (`subdivd refine --limit`), the Python client (`level(..., limit=True)`)
    and `subdiv refine --limit true` give the daemon's ?limit=true level (the JSON's version
    aside), on examples/mixed.json (a solid, a fin, a curve, a point)."""
    import json
    import sys
    from conftest import REPO
    from daemon import SUBDIVD
    body = json.loads((REPO / "examples" / "mixed.json").read_text())
    s = session(daemon, body)
    want = s.level(1, format="json", limit="true").json()
    plain = s.level(1, format="json").json()
    assert np.abs(np.array(want["vertices"]) - plain["vertices"]).max() > 1e-3
    src = tmp_path / "mixed.json"
    src.write_text(json.dumps(body))
    out = tmp_path / "l1.json"
    r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "1", "--limit", "-o", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    got = json.loads(out.read_text())
    assert got["vertices"] == want["vertices"] and got["cells"] == want["cells"]
    sys.path.insert(0, str(REPO / "clients" / "python"))
    import subdiv
    c = subdiv.Client(daemon.url)
    cs = c.session(s.id, s.token)
    assert json.loads(cs.level(1, format="json", limit=True))["vertices"] == want["vertices"]
    assert json.loads(cs.level(1, format="json", limit=False))["vertices"] == plain["vertices"]
    c.close()
    env = dict(__import__("os").environ, SUBDIVD=str(SUBDIVD))
    out2 = tmp_path / "cli.json"
    r = subprocess.run([str(REPO / "build" / "subdiv"), "refine", str(src), "--level", "1",
                        "--limit", "true", "-o", str(out2), "--url", daemon.url],
                       capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    assert json.loads(out2.read_text())["vertices"] == want["vertices"]


# ---- full invariant-neighbourhood matrices (001 Sec. 4.1, Appendix B) ---------------------------

# 001 Appendix B's printed matrices, row by row as column:fraction (the paper's point order).
B1_PRINTED = [
    "0:9/16 1:7/80 2:7/80 3:7/80 4:7/80 5:7/80",
    "0:5/16 1:5/16 2:1/8 3:1/8 4:1/8",
    "0:1/4 1:1/8 2:1/4 3:1/8 4:1/8 5:1/8",
    "0:1/4 1:1/8 2:1/8 3:1/4 4:1/8 5:1/8",
    "0:1/4 1:1/8 2:1/8 3:1/8 4:1/4 5:1/8",
    "0:5/16 2:1/8 3:1/8 4:1/8 5:5/16",
    "0:7/128 1:9/16 2:7/128 3:7/128 4:7/128 6:7/128 7:7/128 8:7/128 9:7/128",
    "0:1/16 1:5/16 2:5/16 3:1/16 4:1/16 7:1/16 10:1/16 12:1/16",
    "0:1/16 1:5/16 2:1/16 3:5/16 4:1/16 8:1/16 12:1/16 14:1/16",
    "0:1/16 1:5/16 2:1/16 3:1/16 4:5/16 9:1/16 10:1/16 14:1/16",
    "0:3/40 1:3/40 2:5/16 4:5/16 5:3/40 10:3/40 16:3/40",
    "0:7/160 1:7/160 2:9/16 3:7/160 4:7/160 5:7/160 7:7/160 10:7/160 11:7/160 12:7/160 16:7/160",
    "0:3/40 1:3/40 2:5/16 3:5/16 5:3/40 12:3/40 17:3/40",
    "0:7/160 1:7/160 2:7/160 3:9/16 4:7/160 5:7/160 8:7/160 12:7/160 13:7/160 14:7/160 17:7/160",
    "0:3/40 1:3/40 3:5/16 4:5/16 5:3/40 14:3/40 18:3/40",
    "0:7/160 1:7/160 2:7/160 3:7/160 4:9/16 5:7/160 9:7/160 10:7/160 14:7/160 15:7/160 18:7/160",
    "0:3/40 2:5/16 3:3/40 4:3/40 5:5/16 16:3/40 17:3/40",
    "0:3/40 2:3/40 3:5/16 4:3/40 5:5/16 17:3/40 18:3/40",
    "0:3/40 2:3/40 3:3/40 4:5/16 5:5/16 16:3/40 18:3/40",
    # the printed matrix has 19 columns: the 20th, which only this row reads (its own point, the
    # row then sums to 1), is lost (SPEC 3.1); restored here as 19:7/128
    "0:7/128 2:7/128 3:7/128 4:7/128 5:9/16 16:7/128 17:7/128 18:7/128 19:7/128",
]
B2_PRINTED = [
    "0:9/16 1:7/160 2:7/160 3:7/160 4:7/160 5:7/160 6:7/160 7:7/160 8:7/160 9:7/160 10:7/160",
    "0:1/4 1:1/4 3:1/8 4:1/8 5:1/8 6:1/8",
    "0:1/4 2:1/4 7:1/8 8:1/8 9:1/8 10:1/8",
    "0:5/16 1:3/40 3:5/16 4:3/40 6:3/40 7:3/40 8:3/40",
    "0:5/16 1:3/40 3:3/40 4:5/16 5:3/40 8:3/40 9:3/40",
    "0:5/16 1:3/40 4:3/40 5:5/16 6:3/40 9:3/40 10:3/40",
    "0:5/16 1:3/40 3:3/40 5:3/40 6:5/16 7:3/40 10:3/40",
    "0:5/16 2:3/40 3:3/40 6:3/40 7:5/16 8:3/40 10:3/40",
    "0:5/16 2:3/40 3:3/40 4:3/40 7:3/40 8:5/16 9:3/40",
    "0:5/16 2:3/40 4:3/40 5:3/40 8:3/40 9:5/16 10:3/40",
    "0:5/16 2:3/40 5:3/40 6:3/40 7:3/40 9:3/40 10:5/16",
    "0:1/16 3:5/16 6:1/16 7:5/16 8:1/16 11:1/16 12:1/16 18:1/16",
    "0:1/8 3:1/4 4:1/8 7:1/8 8:1/4 12:1/8",
    "0:1/16 3:1/16 4:5/16 8:5/16 9:1/16 12:1/16 13:1/16 14:1/16",
    "0:1/8 4:1/4 5:1/8 8:1/8 9:1/4 14:1/8",
    "0:1/16 4:1/16 5:5/16 9:5/16 10:1/16 14:1/16 15:1/16 16:1/16",
    "0:1/8 5:1/4 6:1/8 9:1/8 10:1/4 16:1/8",
    "0:1/16 5:1/16 6:5/16 7:1/16 10:5/16 16:1/16 17:1/16 18:1/16",
    "0:1/8 3:1/8 6:1/4 7:1/4 10:1/8 18:1/8",
]


def printed(rows):
    from fractions import Fraction
    n = len(rows)
    M = np.zeros((n, n))
    for i, r in enumerate(rows):
        for item in r.split():
            j, f = item.split(":")
            M[i, int(j)] = float(Fraction(f))
    return M


def same_up_to_permutation(F, P, fixed):
    """A permutation perm (paper index -> ours) with F[perm i, perm j] = P[i, j] for all i, j,
    extending `fixed`, by backtracking; None if there is none."""
    n = len(P)
    perm, used = dict(fixed), set(fixed.values())
    order = [i for i in range(n) if i not in perm]

    def ok(i):
        return all(abs(F[perm[i], q] - P[i, j]) < 1e-12 and abs(F[q, perm[i]] - P[j, i]) < 1e-12
                   for j, q in perm.items())

    def rec(k):
        if k == len(order):
            return True
        i = order[k]
        for c in range(n):
            if c not in used:
                perm[i] = c
                used.add(c)
                if ok(i) and rec(k + 1):
                    return True
                del perm[i]
                used.discard(c)
        return False
    return perm if rec(0) else None


def edge_star_body(k, pair):
    v = [[0, 0, 1], [0, 0, -1]] + [[math.cos(2 * math.pi * i / k), math.sin(2 * math.pi * i / k), 0]
                                    for i in range(k)]
    return {"vertices": v, "simplices": [[0, 1, 2 + i, 2 + (i + 1) % k] for i in range(k)],
            "diagonals": [[i, pair] for i in range(k)]}


def test_full_appendix_b2_is_the_printed_matrix(daemon):
    """001 B.2, the valence-4 edge with skew diagonals (pair 1, Fig. 23 first row): `full` is the
    printed 19 x 19 (4k + 3) exactly, up to the order of its points (the centre first in both),
    and its 11 largest eigenvalues are the paper's list (with 1/8 the 11th)."""
    s = session(daemon, edge_star_body(4, 1))
    j = s.req("GET", "/analysis", params={"edge": "0,1"}).json()
    f = j["full"]
    assert f["size"] == 19 and f["points"]["level"] == 1
    F = np.array(f["matrix"])
    assert same_up_to_permutation(F, printed(B2_PRINTED), {0: 0}) is not None
    r2 = math.sqrt(2)
    want = [1, (45 + math.sqrt(985)) / 160, (25 + 6 * r2) / 80, (25 + 6 * r2) / 80, 19 / 80,
            (25 - 6 * r2) / 80, (25 - 6 * r2) / 80, 3 / 16, 13 / 80, 13 / 80, 1 / 8]
    np.testing.assert_allclose(f["eigenvalues"][:11], want, atol=1e-12)
    # the block's own 11th eigenvalue is (45 - sqrt 985)/160, not 1/8 (SPEC 3.1)
    assert abs(j["eigenvalues"][10] - (45 - math.sqrt(985)) / 160) < 1e-12


def test_full_appendix_b2_diagonals_toward_the_edge(daemon):
    """Diagonals toward the edge (pair 0): the midpoint is a regular octet-truss vertex
    (DECISIONS 2), so the full matrix has the regular lattice's leading spectrum: B.2's
    1, 1/2, 1/2, 1/2 and then 1/4 (its garbled S'_e gives (25 + sqrt 385)/160 there)."""
    s = session(daemon, edge_star_body(4, 0))
    f = s.req("GET", "/analysis", params={"edge": "0,1"}).json()["full"]
    np.testing.assert_allclose(f["eigenvalues"][:11], [1, .5, .5, .5] + [.25] * 6 + [.125],
                               atol=1e-12)


def test_full_appendix_b1(daemon):
    """001 B.1, the bipyramid centre (k = 5, 5k - 5 = 20), each tetrahedron's major diagonal at an
    equator spoke (pair 2 of (0, pole, a, b)): the top-left 6 x 6 is the printed one with zeros
    beside it; 17 of the 20 printed rows are rows of ours (as weights), the other 3 being the
    vertex points of the equator spokes' midpoints, which the paper gives 10 neighbours (edges
    only) and 001 Def. 3.3 12 (2 major diagonals: 9/16 and 7/192 each); and the spectrum holds the
    paper's list {1, 5/16, (15 + sqrt 70)/80, 3/20, 1/8, 1/8} (3/20 twice here)."""
    body = b1_bipyramid()
    body["diagonals"] = [[i, 2] for i in range(6)]
    s = session(daemon, body)
    j = s.req("GET", "/analysis", params={"vertex": 0}).json()
    f = j["full"]
    assert f["size"] == 20
    F = np.array(f["matrix"])
    P = printed(B1_PRINTED)
    blk = j["points"]["ids"]
    order = [blk.index(v) for v in range(6)]
    np.testing.assert_allclose(F[np.ix_(order, order)], P[:6, :6], atol=1e-15)
    assert not F[:6, 6:].any()
    sig = lambda r: tuple(sorted(round(x, 12) for x in r if x))  # noqa: E731
    ours = [sig(r) for r in F]
    left = []
    for r in P:
        if sig(r) in ours:
            ours.remove(sig(r))
        else:
            left.append(sig(r))
    assert len(left) == 3 and all(r == sig([7 / 160] * 10 + [9 / 16]) for r in left)
    assert len(ours) == 3 and all(r == sig([7 / 192] * 12 + [9 / 16]) for r in ours)
    ev = [x for x in f["eigenvalues"] if not isinstance(x, list)]
    for w in [1, 5 / 16, (15 + math.sqrt(70)) / 80, 3 / 20, 1 / 8, 1 / 8]:
        k = int(np.argmin([abs(x - w) for x in ev]))
        assert abs(ev[k] - w) < 1e-12
        ev.pop(k)


def test_full_appendix_b1_configuration(daemon):
    """001 B.1 point by point. The printed rows name their points (row/column i: the centre 0,
    the spoke midpoints 1-5 in the 6 x 6's order, then pole 1, m(1,a) m(1,b) m(1,c), m(a,c), a,
    m(a,b), b, m(b,c), c, m(5,a) m(5,b) m(5,c), pole 5: read off the rows' 5/16 and 9/16), and
    their edge rows fix the major diagonals: the rings of [m(0,1), m(0,x)] hold m(a,b)-type
    points, so each upper tetrahedron (0, 1, a, b) has pair 0 (diagonal [m(0,1), m(a,b)]), and
    those of [m(0,a), m(0,c)] hold m(5,a), so each lower one (0, 5, a, b) has pair 1 (diagonal
    [m(0,b), m(5,a)]). With these diagonals 16 of the 20 rows are the printed ones entry for
    entry, and the full spectrum starts with the printed list in its order (3/20 simple). The 4
    others are the vertex points of the spoke midpoints that carry diagonals (m(0,1) three, each
    equator spoke one): the paper gives them their edge neighbours only (8 and 10: 7/128, 7/160),
    001 Def. 3.3 and eq. 3.3 (14 = 12 + 2) count the diagonals' ends too (11: 7/176 each, the
    printed support plus those ends). The printed vertex rows count edges only while its edge
    rows see the diagonals, so no choice of diagonals gives all 20 rows: a defect of the print
    (docs/DECISIONS.md 45 (g))."""
    from fractions import Fraction
    body = b1_bipyramid()
    body["diagonals"] = [[i, i % 2] for i in range(6)]  # upper tetrahedra pair 0, lower pair 1
    s = session(daemon, body)
    j = s.req("GET", "/analysis", params={"vertex": 0}).json()
    F = np.array(j["full"]["matrix"])
    ids = j["full"]["points"]["ids"]
    o = s.req("GET", "/levels/1", params={"format": "json"}).json()["origin"]
    at = {}
    for i, (vo, eo) in enumerate(zip(o["vertex_of"], o["edge_of"])):
        at[("v", vo) if vo >= 0 else ("m",) + tuple(sorted(eo))] = i
    V = lambda x: ("v", x)  # noqa: E731
    M = lambda x, y: ("m",) + tuple(sorted((x, y)))  # noqa: E731
    c, p1, a, b, cc, p5 = 0, 1, 2, 3, 4, 5
    names = [V(c), M(c, p1), M(c, a), M(c, b), M(c, cc), M(c, p5), V(p1), M(p1, a), M(p1, b),
             M(p1, cc), M(a, cc), V(a), M(a, b), V(b), M(b, cc), V(cc), M(p5, a), M(p5, b),
             M(p5, cc), V(p5)]
    idx = [ids.index(at[n]) for n in names]
    Q = F[np.ix_(idx, idx)]
    P = printed(B1_PRINTED)
    differ = [i for i in range(20) if np.abs(Q[i] - P[i]).max() > 1e-15]
    assert differ == [6, 11, 13, 15]
    diag_ends = {6: {10, 12, 14}, 11: {17}, 13: {18}, 15: {16}}  # m(a,b)-type; m(5,x)
    for i in differ:
        centre = int(np.argmax(P[i]))
        assert P[i, centre] == Q[i, centre] == 9 / 16
        support = set(np.flatnonzero(P[i])) - {centre}
        assert set(np.flatnonzero(Q[i])) - {centre} == support | diag_ends[i]
        assert len(support | diag_ends[i]) == 11
        np.testing.assert_allclose(Q[i][sorted(support | diag_ends[i])], 7 / 176, atol=1e-15)
    ev = sorted(np.linalg.eigvals(F), key=lambda z: (-abs(z), -z.real))
    want = [1, 5 / 16, (15 + math.sqrt(70)) / 80, 3 / 20, 1 / 8, 1 / 8]
    np.testing.assert_allclose(np.real(ev[:6]), want, atol=1e-12)
    assert np.abs(np.imag(ev[:6])).max() < 1e-12 and abs(ev[6]) < 1 / 8 - 1e-6
    assert Fraction(float(Q[6, 10])).limit_denominator(1000) == Fraction(7, 176)


@pytest.mark.parametrize("rules", ["chang-qin", "ying-zorin"])
def test_convergence_nonmanifold_surface(tmp_path, rules):
    """Three fins of triangles around one edge (a non-manifold edge with its two ends), under
    Chang-Qin's G2 and Ying-Zorin's rules: the error of every control point falls geometrically
    (ratio at most 0.6 over the last three of k = 1..7: at the G2 edge's ends the error first
    dips, two modes of opposite sign crossing, then falls at about 1/2), so the limits
    (eigenvectors, B-spline along the Ying-Zorin crease) are the fixed points."""
    xyz = [(0, 0, 0), (0, 0, 1)]
    tris = []
    for f in range(3):
        a = 2 * math.pi * f / 3
        base = len(xyz)
        for j in range(3):
            r = 1 + 0.1 * j
            xyz.append((r * math.cos(a + 0.2 * (j - 1)), r * math.sin(a + 0.2 * (j - 1)),
                        0.5 * (j - 1) + 0.5 + 0.05 * f))
        tris += [(0, 1, base + 1), (0, base + 1, base), (1, base + 2, base + 1)]
    path = tmp_path / "fins.txt"
    write(path, xyz, tris, [])

    def level(L, lim):
        return parse(run([SDLEVEL, "-l", L, "-n", rules] + (["--limit"] if lim else []) + [path]))[0]
    p = level(0, True)
    es = np.array([np.linalg.norm(p - level(k, False)[:len(p)], axis=1) for k in range(1, 8)])
    moving = es[0] > 1e-12
    r = es[-3:, moving] / es[-4:-1, moving]
    assert (r <= 0.6).all(), r.max()
    assert es[-1].max() < 0.01 * es[0].max()


def test_analysis_tangents_reach_outside_the_block(daemon, tmp_path, osd_loop):
    """GET /analysis's tangents on an open surface with a corner tag: a boundary vertex's block
    is the B-spline one (v and its two boundary neighbours), but OpenSubdiv's across-tangent mask
    also reads the interior neighbours, and a corner's masks read its first two neighbours; those
    weights are in `limit.outside[].tangents`. The limit normal t1 x t2 taken from both equals
    Far::PrimvarRefinerReal<double>::Limit's (tests/peers/osd_loop.cpp) at every vertex that has
    tangents, boundary and corner ones among them."""
    rng = random.Random(7)
    N = 4
    xyz = [(i + rng.uniform(-.15, .15), j + rng.uniform(-.15, .15),
            0.3 * math.sin(0.9 * i) * math.cos(0.7 * j) + rng.uniform(-.1, .1))
           for i in range(N + 1) for j in range(N + 1)]
    at = lambda i, j: i * (N + 1) + j
    tris = []
    for i in range(N):
        for j in range(N):
            a, b, c, d = at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)
            tris += [(a, b, c), (a, c, d)]
    corner = at(0, 2)  # a boundary vertex of three triangles, tagged as a corner
    path = tmp_path / "patch.txt"
    write(path, xyz, tris, [(corner, 10.0)])
    _, _, want = parse(run([osd_loop, "-l", 0, "--limit", path]))
    body = {"vertices": [list(p) for p in xyz], "simplices": [list(t) for t in tris]}
    s = session(daemon, body, {"surface_weights": "loop"})
    assert s.req("PUT", "/tags", json={"singular": [[corner]]}).status_code == 200
    x = np.array(xyz)
    seen = set()
    for v in range(len(xyz)):
        j = s.req("GET", "/analysis", params={"vertex": v}).json()
        lim = j["limit"]
        assert "tangents" in lim, v
        t = [np.array(w) @ x[j["points"]["ids"]] for w in lim["tangents"]]
        for o in lim["outside"]:
            for k in range(2):
                t[k] = t[k] + o.get("tangents", [0, 0])[k] * x[o["id"]]
        n = np.cross(t[0], t[1])
        np.testing.assert_allclose(n / np.linalg.norm(n), want[v], atol=1e-9, err_msg=f"vertex {v}")
        if lim["outside"]:
            seen.add(lim["method"])
    assert seen == {"bspline", "fixed"}
