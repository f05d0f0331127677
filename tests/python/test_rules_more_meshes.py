"""The rules on meshes the other suites do not use.

Expected values come from outside the code:
- OpenSubdiv 3.5 (tests/peers/osd_loop.cpp) for Loop surfaces with Loop's weights: perturbed
  planar triangulations with four boundary loops (three holes), boundary vertices of valence 2
  and interior vertices of valence 3, 4, 9 and 12, and a closed hull with poles of valence 12
  and 9; levels 1-4, semi-sharp chains whose sharpness varies along the chain (from the
  boundary through the valence-12 and valence-9 vertices to a dart end), fractional vertex
  sharpness at a valence-2 boundary vertex, a valence-3 vertex and on the chain; limit
  positions, normals and tangents;
- a Loop step written here (both weight choices, SPEC 3), compared level by level;
- SPEC 3's rules written here for non-manifold surfaces joined to curves (G2 default, cubic
  B-spline curves, fixed ends and junctions) and for solids (box and averaged masks, the
  solid-boundary Loop rules), on a cube tetrahedralised in five ways; the split counts of SPEC 2;
- the spectrum of the 1-ring block of a regular interior solid vertex: 1, 1/2 (3), 1/4 (6),
  1/8 (4), 1/16 (the polynomial generation of the box spline);
- the cubic B-spline's limit mask (1/6, 2/3, 1/6) and the dominant left eigenvector of a G2
  vertex's 1-ring block built here.
Where a step needs the previous level's cells (the major diagonals chosen by 001 Algorithm 2),
they are read from that level's output; every expected position is computed here from the
previous level's points with the rules above.
"""
import itertools
import math
import subprocess
from collections import Counter, defaultdict

import numpy as np
import pytest
from scipy.spatial import ConvexHull, Delaunay

from conftest import SDLEVEL

TOL = 1e-12


def run(cmd):
    return subprocess.run([str(c) for c in cmd], check=True, capture_output=True,
                          text=True).stdout


def parse(text):
    """Points, origins (('V', a), ('E', a, b), ('C', o), ('I',)), normals, cells by kind."""
    pts, orig, nrm, cells = [], [], [], defaultdict(list)
    for line in text.splitlines():
        f = line.split()
        if not f:
            continue
        if f[0] == "v":
            pts.append([float(x) for x in f[1:4]])
            if len(f) < 5 or f[4] == "I":
                orig.append(("I",))
            elif f[4] in ("V", "C"):
                orig.append((f[4], int(f[5])))
            else:
                orig.append(("E",) + tuple(sorted(int(x) for x in f[5:7])))
        elif f[0] == "n":
            nrm.append([float(x) for x in f[1:4]])
        elif f[0] in ("e", "t", "T", "O"):
            cells[f[0]].append(tuple(int(x) for x in f[1:]))
    return np.array(pts), orig, np.array(nrm), cells


def write(path, xyz, simplices, sharp=()):
    with open(path, "w") as f:
        for p in xyz:
            f.write("v %.17g %.17g %.17g\n" % tuple(p))
        for s in simplices:
            f.write("s " + " ".join(str(int(i)) for i in s) + "\n")
        for s in sharp:
            f.write("c " + " ".join(str(int(x)) for x in s[:-1]) + " %r\n" % s[-1])


def edge_count(tris):
    c = Counter()
    for t in tris:
        for i in range(3):
            c[tuple(sorted((t[i], t[(i + 1) % 3])))] += 1
    return c


def neighbours(tris):
    nb = defaultdict(set)
    for t in tris:
        for a, b in itertools.combinations(t, 2):
            nb[a].add(b)
            nb[b].add(a)
    return nb


# ---- meshes ------------------------------------------------------------------------------------

def _split13(xyz, tris, k):
    a, b, c = tris[k]
    v = len(xyz)
    xyz.append(tuple((np.array(xyz[a]) + xyz[b] + xyz[c]) / 3 + [0, 0, 0.01]))
    tris[k] = (a, b, v)
    tris += [(b, c, v), (c, a, v)]


def _split_edge(xyz, tris, a, b):
    """Split interior edge a-b at its midpoint: the new vertex has valence 4."""
    v = len(xyz)
    xyz.append(tuple((np.array(xyz[a]) + xyz[b]) / 2 + [0, 0, -0.01]))
    out = []
    for t in tris:
        if a in t and b in t:
            t1, t2 = list(t), list(t)
            t1[t.index(b)] = v
            t2[t.index(a)] = v
            out += [tuple(t1), tuple(t2)]
        else:
            out.append(t)
    tris[:] = out


def _compact(xyz, tris):
    used = sorted({i for t in tris for i in t})
    new = {v: i for i, v in enumerate(used)}
    return [xyz[v] for v in used], [tuple(new[i] for i in t) for t in tris]


def holes(seed):
    """A jittered planar grid with fans of 12 and 9 around two points, Delaunay-triangulated,
    three holes cut out (four boundary loops), lifted to a bumpy height field; valence-3 and
    valence-4 vertices inserted. Vertices where two loops touch lose their smaller fan."""
    rng = np.random.default_rng(seed)
    pts = [(i + 0.3 * rng.uniform(-1, 1), j + 0.3 * rng.uniform(-1, 1))
           for i in range(9) for j in range(9)]
    pts = [p for p in pts if math.hypot(p[0] - 2, p[1] - 6) > 1.6
           and math.hypot(p[0] - 6, p[1] - 2) > 1.6]
    for cx, cy, k in ((2, 6, 12), (6, 2, 9)):
        pts.append((cx + 0.05, cy - 0.03))
        for i in range(k):
            a = 2 * math.pi * i / k + 0.1 * rng.uniform(-1, 1)
            pts.append((cx + 1.1 * math.cos(a), cy + 1.1 * math.sin(a)))
    P = np.array(pts)
    tris = [tuple(int(x) for x in t) for t in Delaunay(P).simplices]
    cut = [(5.5, 6.0, 1.0), (2.5, 2.5, 0.9), (4.5, 3.8, 0.6)]
    tris = [t for t in tris
            if all(math.hypot(*(P[list(t)].mean(0) - [x, y])) >= r for x, y, r in cut)]
    tris = [t if np.cross(P[t[1]] - P[t[0]], P[t[2]] - P[t[0]]) > 0 else (t[0], t[2], t[1])
            for t in tris]
    xyz = [(p[0], p[1], 0.3 * math.sin(p[0]) * math.cos(0.7 * p[1]) + 0.05 * rng.uniform(-1, 1))
           for p in P]
    for k in (5, 40, len(tris) // 2):
        _split13(xyz, tris, k)
    for n in (17, 101):
        inner = sorted(e for e, c in edge_count(tris).items() if c == 2)
        _split_edge(xyz, tris, *inner[n])
    while True:  # no vertex where two boundary loops touch
        bc = Counter(v for e, c in edge_count(tris).items() if c == 1 for v in e)
        bad = [v for v, c in bc.items() if c != 2]
        if not bad:
            break
        fan = [k for k, t in enumerate(tris) if bad[0] in t]
        comp = {k: k for k in fan}

        def root(k):
            while comp[k] != k:
                k = comp[k]
            return k
        for a, b in itertools.combinations(fan, 2):
            if len(set(tris[a]) & set(tris[b])) == 2:
                comp[root(a)] = root(b)
        groups = defaultdict(list)
        for k in fan:
            groups[root(k)].append(k)
        drop = set(min(groups.values(), key=len))
        tris = [t for k, t in enumerate(tris) if k not in drop]
    return _compact(xyz, tris)


def hull(seed):
    """A closed perturbed hull of random sphere points with poles of valence 12 and 9."""
    rng = np.random.default_rng(seed)

    def sph(th, ph):
        return (math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th))
    pts = []
    for _ in range(60):
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        if abs(v[2]) <= 0.75 and not (abs(v[0]) > 0.8 and v[1] > 0.3):
            pts.append(tuple(v))
    pts.append((0, 0, 1))
    pts += [sph(0.45, 2 * math.pi * i / 12) for i in range(12)]
    pts.append((0, 0, -1))
    pts += [sph(math.pi - 0.5, 2 * math.pi * i / 9 + 0.2) for i in range(9)]
    P = np.array(pts)
    h = ConvexHull(P)
    tris = []
    for s, eq in zip(h.simplices, h.equations):
        t = tuple(int(x) for x in s)
        if np.dot(np.cross(P[t[1]] - P[t[0]], P[t[2]] - P[t[0]]), eq[:3]) < 0:
            t = (t[0], t[2], t[1])
        tris.append(t)
    xyz = [tuple(p * (1 + 0.1 * rng.uniform(-1, 1))) for p in P]
    _split13(xyz, tris, 3)
    _split13(xyz, tris, 20)
    _split_edge(xyz, tris, *sorted(edge_count(tris))[30])
    return xyz, tris


def valences(tris):
    return {v: len(s) for v, s in neighbours(tris).items()}


SURFACES = {"holes0": lambda: holes(0), "holes5": lambda: holes(5),
            "hull1": lambda: hull(1), "hull2": lambda: hull(2)}


def test_meshes_have_what_they_claim():
    for name in ("holes0", "holes5"):
        xyz, tris = SURFACES[name]()
        ec = edge_count(tris)
        assert max(ec.values()) == 2
        bnd = [e for e, c in ec.items() if c == 1]
        # four boundary loops: components of the boundary edges
        comp = {}

        def root(v):
            while comp.setdefault(v, v) != v:
                v = comp[v]
            return v
        for a, b in bnd:
            comp[root(a)] = root(b)
        assert len({root(v) for e in bnd for v in e}) == 4
        bv = {v for e in bnd for v in e}
        inner = {n for v, n in valences(tris).items() if v not in bv}
        assert {3, 4, 9, 12} <= inner
        assert 2 in {n for v, n in valences(tris).items() if v in bv}
    xyz, tris = SURFACES["hull1"]()
    assert set(edge_count(tris).values()) == {2}
    assert {3, 4, 9, 12} <= set(valences(tris).values())


# ---- Loop against OpenSubdiv -------------------------------------------------------------------

def against_osd(osd, path, levels, ours=(), theirs=(), limit=False):
    """Max distance to OpenSubdiv per level, points matched by origin level by level; with
    `limit`, the last level's limit positions and normals (up to sign) too."""
    prev, worst = None, []
    for L in range(1, levels + 1):
        lim = ["--limit"] if limit and L == levels else []
        p, o, n, _ = parse(run([SDLEVEL, "-l", L, "-w", "loop", *ours, *lim, path]))
        q, r, m, _ = parse(run([osd, "-l", L, "--origins", *theirs, *lim, path]))
        assert p.shape == q.shape
        index = {k: j for j, k in enumerate(r)}
        prev = prev if prev is not None else list(range(len(p)))
        idx = [index[("V", prev[k[1]])] if k[0] == "V"
               else index[("E",) + tuple(sorted((prev[k[1]], prev[k[2]])))] for k in o]
        assert sorted(idx) == list(range(len(q)))
        prev = idx
        worst.append(float(np.abs(p - q[idx]).max()))
        if lim:
            nd = np.minimum(np.abs(n - m[idx]).max(1), np.abs(n + m[idx]).max(1))
            worst.append(float(nd.max()))
    return worst


@pytest.mark.parametrize("name", sorted(SURFACES))
def test_loop_levels_and_limits_equal_opensubdiv(tmp_path, osd_loop, name):
    xyz, tris = SURFACES[name]()
    path = tmp_path / f"{name}.txt"
    write(path, xyz, tris)
    assert max(against_osd(osd_loop, path, 4)) < TOL
    pos, nrm = against_osd(osd_loop, path, 2, limit=True)[-2:]
    assert pos < TOL and nrm < 1e-9


def sharp_chain(xyz, tris):
    """A chain from the boundary through the valence-12 vertex to a valence-9 one (a dart end),
    its sharpness rising 0.2, 0.57, 0.94 ... along it; vertex sharpness 1.6 on the valence-12
    vertex, 0.8 on valence-2 boundary vertices, 2.35 on a valence-3 vertex."""
    nb = neighbours(tris)
    val = {v: len(s) for v, s in nb.items()}
    bv = {v for e, c in edge_count(tris).items() if c == 1 for v in e}
    hi = max(val, key=lambda v: val[v])
    nine = min(v for v in val if val[v] == 9 and v not in bv)
    three = min(v for v in val if val[v] == 3 and v not in bv)

    def path(a, b):
        prev, queue = {a: None}, [a]
        for u in queue:
            for w in sorted(nb[u]):
                if w not in prev and (w not in bv or w == b):
                    prev[w] = u
                    queue.append(w)
        p = [b]
        while prev[p[-1]] is not None:
            p.append(prev[p[-1]])
        return p[::-1]
    start = min(bv, key=lambda v: np.linalg.norm(np.array(xyz[v]) - xyz[hi]))
    chain = path(start, hi) + path(hi, nine)[1:]
    sharp = [(a, b, round(0.2 + 0.37 * i, 3)) for i, (a, b) in enumerate(zip(chain, chain[1:]))]
    sharp += [(hi, 1.6), (three, 2.35)] + [(v, 0.8) for v in sorted(val) if val[v] == 2][:2]
    return sharp


@pytest.mark.parametrize("chaikin", [False, True], ids=["uniform", "chaikin"])
@pytest.mark.parametrize("name", ["holes0", "holes5"])
def test_varying_chain_equals_opensubdiv(tmp_path, osd_loop, name, chaikin):
    xyz, tris = SURFACES[name]()
    sharp = sharp_chain(xyz, tris)
    path = tmp_path / f"{name}.txt"
    write(path, xyz, tris, sharp)
    flag = ["--chaikin"] if chaikin else []
    assert max(against_osd(osd_loop, path, 4, flag, flag)) < TOL
    # the limit, taken where every sharpness has expired (docs/DECISIONS.md 45 (b))
    E = math.ceil(max(s[-1] for s in sharp))
    pos, nrm = against_osd(osd_loop, path, E, flag, flag, limit=True)[-2:]
    assert pos < TOL and nrm < 1e-9


# ---- Loop's step written here, both weights ----------------------------------------------------

def loop_step(P, tris, weights):
    """One step of SPEC 3's 2-simplex rules (boundary: the cubic B-spline), keyed by origin."""
    opp, nb, bnb = defaultdict(list), neighbours(tris), defaultdict(list)
    for t in tris:
        for i in range(3):
            opp[tuple(sorted((t[i], t[(i + 1) % 3])))].append(t[(i + 2) % 3])
    for e, o in opp.items():
        if len(o) == 1:
            bnb[e[0]].append(e[1])
            bnb[e[1]].append(e[0])
    new = {}
    for v, ring in nb.items():
        if v in bnb:
            a, b = bnb[v]
            new["V", v] = (6 * P[v] + P[a] + P[b]) / 8
            continue
        m = len(ring)
        if weights == "loop":
            c = (5 / 8 - (3 / 8 + math.cos(2 * math.pi / m) / 4) ** 2) / m
        else:
            c = 3 / 16 if m == 3 else 3 / (8 * m)
        new["V", v] = (1 - m * c) * P[v] + c * sum(P[u] for u in ring)
    for (a, b), o in opp.items():
        new["E", a, b] = ((P[a] + P[b]) / 2 if len(o) == 1
                          else 3 / 8 * (P[a] + P[b]) + 1 / 8 * (P[o[0]] + P[o[1]]))
    return new


def by_origin(new, prev_pts, prev_cells, origins):
    """`new` (keyed by origin in the previous level) in the order of `origins`."""
    out = []
    for k in origins:
        out.append(new[k] if k[0] != "E" else new[("E",) + tuple(sorted(k[1:]))])
    return np.array(out)


@pytest.mark.parametrize("weights", ["warren", "loop"])
@pytest.mark.parametrize("name", ["holes5", "hull2"])
def test_loop_both_weights_equal_the_rules(tmp_path, name, weights):
    xyz, tris = SURFACES[name]()
    path = tmp_path / f"{name}.txt"
    write(path, xyz, tris)
    prev, _, _, cells = parse(run([SDLEVEL, "-l", 0, "-w", weights, path]))
    for L in range(1, 5):
        p, o, _, nxt = parse(run([SDLEVEL, "-l", L, "-w", weights, path]))
        want = by_origin(loop_step(prev, cells["t"], weights), prev, cells, o)
        assert np.abs(p - want).max() < TOL, L
        prev, cells = p, nxt


# ---- non-manifold surfaces joined to curves ----------------------------------------------------

def book(seed):
    """Three pages (strips of two rows of triangles) on a spine of 4 edges, a fourth page (one
    triangle) on the middle spine edge; a curve from a page's interior vertex with a junction of
    three curve edges, a branch that closes back onto the curve, a branch with a free end; a
    curve from the spine's end; a closed curve loop apart."""
    rng = np.random.default_rng(seed)
    xyz, tris, curves = [], [], []

    def add(p):
        xyz.append(tuple(np.array(p, float) + 0.04 * rng.uniform(-1, 1, 3)))
        return len(xyz) - 1
    spine = [add((i, 0, 0)) for i in range(5)]
    for page, ang in enumerate((0.3, 2.2, 4.1)):
        d = np.array([0, math.cos(ang), math.sin(ang)])
        r1 = [add(np.array([i + 0.5, 0, 0]) + d) for i in range(4)]
        r2 = [add(np.array([i, 0, 0]) + 2 * d) for i in range(5)]
        tris += [(spine[i], spine[i + 1], r1[i]) for i in range(4)]
        tris += [(spine[i + 1], r1[i + 1], r1[i]) for i in range(3)]
        tris += [(r1[i], r2[i + 1], r2[i]) for i in range(4)]
        tris += [(r1[i], r1[i + 1], r2[i + 1]) for i in range(3)]
        if page == 0:
            anchor = r1[1]
    tris.append((spine[2], spine[3], add((2.5, -0.2, -0.9))))

    def curve(start, pts):
        ids, prev = [], start
        for p in pts:
            v = add(p)
            curves.append((prev, v))
            prev = v
            ids.append(v)
        return ids
    base = np.array(xyz[anchor])
    c1 = curve(anchor, [base + (0, 0.3, 0.8 * k) for k in range(1, 5)])
    j = np.array(xyz[c1[1]])
    curve(c1[1], [j + (0.7 * k, 0.1, 0) for k in range(1, 4)])
    br = curve(c1[1], [j + (-0.6 * k, 0, 0.2 * k) for k in range(1, 3)])
    curves.append((br[-1], c1[3]))
    s4 = np.array(xyz[spine[4]])
    curve(spine[4], [s4 + (0.8 * k, 0.1 * k, 0) for k in range(1, 4)])
    ring = [add((2 + math.cos(2 * math.pi * k / 6), 5 + math.sin(2 * math.pi * k / 6), 0))
            for k in range(6)]
    curves += [(ring[k], ring[(k + 1) % 6]) for k in range(6)]
    return xyz, tris, curves


def box_edge(k):
    return {4: (8 / 32, 4 / 32), 6: (10 / 32, 2 / 32)}.get(k, (5 / 16, 3 / (8 * k)))


def surface_curve_step(P, tris, curves):
    """SPEC 3 without solids: G2 (type 1: on a curve and a surface; type 2 edges and their
    vertices; type 3: a disconnected link) by the 3-simplex masks over every edge neighbour
    (vertices) and the triangles' third vertices (edges); curves B-spline, ends and junctions
    fixed, edge points midpoints; surfaces Loop (Warren) with B-spline boundaries."""
    opp, snb, cnb = defaultdict(list), neighbours(tris), defaultdict(set)
    for t in tris:
        for i in range(3):
            opp[tuple(sorted((t[i], t[(i + 1) % 3])))].append(t[(i + 2) % 3])
    for a, b in curves:
        cnb[a].add(b)
        cnb[b].add(a)

    def fans(v):
        ts = [t for t in tris if v in t]
        comp = list(range(len(ts)))

        def root(i):
            while comp[i] != i:
                i = comp[i]
            return i
        for i, j in itertools.combinations(range(len(ts)), 2):
            if len(set(ts[i]) & set(ts[j])) == 2:
                comp[root(i)] = root(j)
        return len({root(i) for i in range(len(ts))})
    new, rule = {}, {}
    on_surface, on_curve = set(snb), set(cnb)
    for v in on_surface | on_curve:
        ring = snb[v] | cnb[v]
        if v in on_surface and v in on_curve:
            r = "G2"
        elif v in on_curve:
            r = "curve" if len(cnb[v]) == 2 else "fixed"
        elif any(len(opp[tuple(sorted((v, u)))]) > 2 for u in snb[v]) or fans(v) > 1:
            r = "G2"
        else:
            bn = [u for u in snb[v] if len(opp[tuple(sorted((v, u)))]) == 1]
            r = "boundary" if bn else "loop"
        rule[v] = r
        if r == "G2":
            new["V", v] = 9 / 16 * P[v] + 7 / (16 * len(ring)) * sum(P[u] for u in ring)
        elif r == "fixed":
            new["V", v] = P[v]
        elif r in ("curve", "boundary"):
            a, b = cnb[v] if r == "curve" else bn
            new["V", v] = (6 * P[v] + P[a] + P[b]) / 8
        else:
            m = len(ring)
            c = 3 / 16 if m == 3 else 3 / (8 * m)
            new["V", v] = (1 - m * c) * P[v] + c * sum(P[u] for u in ring)
    for (a, b), o in opp.items():
        if len(o) == 1:
            new["E", a, b] = (P[a] + P[b]) / 2
        elif len(o) == 2:
            new["E", a, b] = 3 / 8 * (P[a] + P[b]) + 1 / 8 * (P[o[0]] + P[o[1]])
        else:
            wa, wo = box_edge(len(o))
            new["E", a, b] = wa * (P[a] + P[b]) + wo * sum(P[u] for u in o)
    for a, b in curves:
        new[("E",) + tuple(sorted((a, b)))] = (P[a] + P[b]) / 2
    return new, rule


@pytest.mark.parametrize("seed", [0, 1])
def test_surfaces_joined_to_curves_follow_the_rules(tmp_path, seed):
    xyz, tris, curves = book(seed)
    path = tmp_path / "book.txt"
    write(path, xyz, tris + curves)
    prev, _, _, cells = parse(run([SDLEVEL, "-l", 0, path]))
    _, rule = surface_curve_step(prev, cells["t"], cells["e"])
    # the spine (5) and the page vertex a curve starts from; two pages' inner vertices and the
    # third's (one is the anchor); every page's outer row and sides and the fourth page's tip;
    # 3 + 2 + 2 + 2 + 6 curve vertices; the junction and the two free ends
    assert Counter(rule.values()) == {"G2": 6, "loop": 5, "boundary": 22, "curve": 15,
                                      "fixed": 3}
    for L in range(1, 4):
        p, o, _, nxt = parse(run([SDLEVEL, "-l", L, path]))
        new, _ = surface_curve_step(prev, cells["t"], cells["e"])
        assert np.abs(p - by_origin(new, prev, cells, o)).max() < TOL, L
        prev, cells = p, nxt


@pytest.mark.parametrize("L", [0, 2])
def test_curve_and_junction_limits(tmp_path, L):
    """Curve vertices: (a + 4x + b)/6 (their 3-point block is closed whatever the neighbours'
    rules); ends and junctions stay; a G2 vertex: the dominant left eigenvector of its 1-ring
    block, the block's rows written here."""
    xyz, tris, curves = book(0)
    path = tmp_path / "book.txt"
    write(path, xyz, tris + curves)
    p, _, _, cells = parse(run([SDLEVEL, "-l", L, path]))
    lim = parse(run([SDLEVEL, "-l", L, "--limit", path]))[0]
    cnb = defaultdict(set)
    for a, b in cells["e"]:
        cnb[a].add(b)
        cnb[b].add(a)
    on_surface = {v for t in cells["t"] for v in t}
    n = 0
    for v, ring in cnb.items():
        if v in on_surface:
            continue
        a, b = sorted(ring) if len(ring) == 2 else (v, v)
        want = (p[a] + 4 * p[v] + p[b]) / 6 if len(ring) == 2 else p[v]
        assert np.abs(lim[v] - want).max() < TOL
        n += 1
    assert n > 15
    if L:
        return
    # G2 vertices at level 0: S's rows on unit coordinates give the block
    basis = np.eye(len(p))
    new, rule = surface_curve_step(basis, cells["t"], cells["e"])
    g2 = [v for v, r in rule.items() if r == "G2"]
    assert len(g2) == 6
    for v in g2:
        ring = sorted(({u for t in cells["t"] if v in t for u in t}
                       | {u for e in cells["e"] if v in e for u in e}) - {v})
        pts = [v] + ring
        M = np.array([new["V", v][pts] if u == v else new[("E",) + tuple(sorted((u, v)))][pts]
                      for u in pts])
        assert np.allclose(M.sum(1), 1)  # closed
        w, vec = np.linalg.eig(M.T)
        left = vec[:, np.argmin(abs(w - 1))].real
        left /= left.sum()
        assert np.abs(lim[v] - left @ p[pts]).max() < TOL


# ---- solids: a cube tetrahedralised in five ways -----------------------------------------------

def cube(kind, seed):
    rng = np.random.default_rng(seed)
    corner = [np.array([(i >> 2) & 1, (i >> 1) & 1, i & 1], float) for i in range(8)]
    faces = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    V = list(corner)
    if kind == "kuhn6":  # around the main diagonal 0-7
        T = []
        for perm in itertools.permutations((4, 2, 1)):
            a, path = 0, [0]
            for b in perm:
                a |= b
                path.append(a)
            T.append(tuple(path))
    elif kind == "five":  # a central tetrahedron and four corners
        T = [(0, 3, 5, 6)] + [(v, v ^ 1, v ^ 2, v ^ 4) for v in (7, 1, 2, 4)]
    elif kind.startswith("twelve"):  # the centre (8) over each face cut in two
        V.append(np.full(3, 0.5))
        alt = kind.endswith("alt")
        T = []
        for k, (a, b, c, d) in enumerate(faces):
            T += ([(8, a, b, c), (8, a, c, d)] if (k % 2 == 0) != alt
                  else [(8, a, b, d), (8, b, c, d)])
    elif kind == "twentyfour":  # the centre over each face cut in four at its centre
        V.append(np.full(3, 0.5))
        T = []
        for k, f in enumerate(faces):
            V.append(np.mean([corner[i] for i in f], 0))
            T += [(8, 9 + k, f[i], f[(i + 1) % 4]) for i in range(4)]
    V = [v + 0.06 * rng.uniform(-1, 1, 3) for v in V]

    def vol(t):
        return np.linalg.det(np.array([V[t[1]] - V[t[0]], V[t[2]] - V[t[0]], V[t[3]] - V[t[0]]]))
    return V, [t if vol(t) > 0 else (t[0], t[1], t[3], t[2]) for t in T]


KINDS = ["kuhn6", "five", "twelve", "twelve-alt", "twentyfour"]


def solid_step(P, tets, octs, scheme):
    """SPEC 3 for a pure solid (octahedra as `O p q a a2 b b2`, major diagonal p-q): interior
    box or averaged masks, solid-boundary Loop (Warren) over the boundary faces, cell points."""
    faces = Counter()
    for t in tets:
        faces.update(tuple(sorted(f)) for f in itertools.combinations(t, 3))
    opposite = {}
    for o in octs:
        p, q, a, a2, b, b2 = o
        faces.update(tuple(sorted((x, y, z))) for x in (p, q) for y in (a, a2) for z in (b, b2))
        for x, y in ((p, q), (a, a2), (b, b2)):
            opposite[o, x], opposite[o, y] = y, x
    bopp, bnb = defaultdict(list), defaultdict(set)
    for f, c in faces.items():
        if c == 1:
            for i in range(3):
                e = tuple(sorted((f[i], f[(i + 1) % 3])))
                bopp[e].append(f[(i + 2) % 3])
                bnb[e[0]].add(e[1])
                bnb[e[1]].add(e[0])
    diag = {tuple(sorted(o[:2])) for o in octs}
    dnb = defaultdict(set)
    subtets = list(tets)
    for o in octs:
        p, q, a, a2, b, b2 = o
        eq = (a, b, a2, b2)
        subtets += [(p, q, eq[i], eq[(i + 1) % 4]) for i in range(4)]
        dnb[p].add(q)
        dnb[q].add(p)
    ring, enb = defaultdict(set), defaultdict(set)
    for t in subtets:
        for e in itertools.combinations(sorted(t), 2):
            if e not in diag:
                ring[e] |= set(t) - set(e)
                enb[e[0]].add(e[1])
                enb[e[1]].add(e[0])
    fring, onb, dring = defaultdict(set), defaultdict(set), defaultdict(set)
    for f in faces:
        for e in itertools.combinations(f, 2):
            fring[e] |= set(f) - set(e)
    for o in octs:
        for x in o:
            onb[x].add(opposite[o, x])
        for x, y in itertools.combinations(sorted(o), 2):
            if opposite[o, x] != y:
                dring[x, y] |= {opposite[o, x], opposite[o, y]}
    new = {}
    for v in enb:
        if v in bnb:
            m = len(bnb[v])
            c = 3 / 16 if m == 3 else 3 / (8 * m)
            new["V", v] = (1 - m * c) * P[v] + c * sum(P[u] for u in bnb[v])
        elif scheme == "box":
            rho = enb[v] | dnb[v]
            new["V", v] = 9 / 16 * P[v] + 7 / (16 * len(rho)) * sum(P[u] for u in rho)
        else:
            s = 3 * sum(P[u] for u in enb[v]) + sum((P[u] for u in onb[v]), np.zeros(3))
            new["V", v] = 9 / 16 * P[v] + 7 / 16 * s / (3 * len(enb[v]) + len(onb[v]))
    for e, r in ring.items():
        a, b = e
        if e in bopp:
            c, d = bopp[e]
            new["E", a, b] = 3 / 8 * (P[a] + P[b]) + 1 / 8 * (P[c] + P[d])
        elif scheme == "box":
            wa, wo = box_edge(len(r))
            new["E", a, b] = wa * (P[a] + P[b]) + wo * sum(P[u] for u in r)
        else:
            s = 4 * sum(P[u] for u in fring[e]) + sum((P[u] for u in dring[e]), np.zeros(3))
            new["E", a, b] = (7 / 24 * (P[a] + P[b])
                              + 5 / 12 * s / (4 * len(fring[e]) + len(dring[e])))
    for i, o in enumerate(octs):
        new["C", i] = (sum(P[u] for u in o) / 6 if scheme == "averaged"
                       else (P[o[0]] + P[o[1]]) / 4 + sum(P[u] for u in o[2:]) / 8)
    return new, len(ring)


@pytest.mark.parametrize("scheme", ["box", "averaged"])
@pytest.mark.parametrize("kind", KINDS)
def test_cube_tetrahedralisations(tmp_path, kind, scheme):
    V, T = cube(kind, 0)
    path = tmp_path / f"{kind}.txt"
    write(path, V, T)
    prev, _, _, cells = parse(run([SDLEVEL, "-l", 0, "-s", scheme, path]))
    assert len(cells["T"]) == len(T)
    for L in range(1, 4):
        p, o, _, nxt = parse(run([SDLEVEL, "-l", L, "-s", scheme, path]))
        new, nedges = solid_step(prev, cells["T"], cells["O"], scheme)
        # SPEC 2: tetrahedron -> 4 + 1 octahedron, octahedron -> 6 + 8 tetrahedra
        assert len(nxt["T"]) == 4 * len(cells["T"]) + 8 * len(cells["O"])
        assert len(nxt["O"]) == len(cells["T"]) + 6 * len(cells["O"])
        assert len(p) == len(prev) + nedges + len(cells["O"])
        assert np.abs(p - by_origin(new, prev, cells, o)).max() < TOL, L
        prev, cells = p, nxt


def test_regular_interior_vertex_spectrum(tmp_path):
    """Eight cubes of six tetrahedra: at level 3 every interior vertex has 14 neighbours
    (SPEC 2's invariant); the 1-ring block of the one nearest the middle that ends major
    diagonals, read from S_4's rows, is closed and has the box spline's spectrum."""
    n, rng = 2, np.random.default_rng(5)
    vid = {c: i for i, c in enumerate(itertools.product(range(n + 1), repeat=3))}
    V = [np.array(c, float) + 0.05 * rng.uniform(-1, 1, 3) for c in vid]
    T = []
    for c in itertools.product(range(n), repeat=3):
        for perm in itertools.permutations(np.eye(3, dtype=int)):
            q, path = np.array(c), [vid[c]]
            for d in perm:
                q = q + d
                path.append(vid[tuple(q)])
            T.append(tuple(path))
    path = tmp_path / "grid.txt"
    write(path, V, T)
    p3, _, _, c3 = parse(run([SDLEVEL, "-l", 3, path]))
    text = run([SDLEVEL, "-l", 4, "--matrix", path])
    _, o4, _, _ = parse(text)
    rows = {}
    for line in text.splitlines():
        if line.startswith("row "):
            f = line.split()
            rows[int(f[1])] = {int(f[3 + 2 * k]): float(f[4 + 2 * k]) for k in range(int(f[2]))}
    ends = {v for o in c3["O"] for v in o[:2]}
    order = np.argsort(np.linalg.norm(p3 - p3.mean(0), axis=1))
    centre = int(next(v for v in order if v in ends))
    enb, dnb = set(), set()
    for t in c3["T"]:
        if centre in t:
            enb |= set(t)
    for o in c3["O"]:
        if centre in o:
            i = o.index(centre)
            other = o[i ^ 1]
            enb |= set(o) - {other}
            if i < 2:
                dnb.add(other)
    enb.discard(centre)
    assert len(enb) + len(dnb) == 14 and dnb
    pts = [centre] + sorted(enb) + sorted(dnb)
    index = {k: i for i, k in enumerate(o4)}
    newpts = [centre] + [index[("E",) + tuple(sorted((centre, u)))] for u in sorted(enb)]
    newpts += [index["C", next(j for j, o in enumerate(c3["O"]) if set(o[:2]) == {centre, q})]
               for q in sorted(dnb)]
    M = np.zeros((15, 15))
    for i, r in enumerate(newpts):
        for c, w in rows[r].items():
            M[i, pts.index(c)] = w  # raises if the block is not closed
    ev = np.sort(np.linalg.eigvals(M).real)[::-1]
    want = [1] + [1 / 2] * 3 + [1 / 4] * 6 + [1 / 8] * 4 + [1 / 16]
    np.testing.assert_allclose(ev, want, atol=1e-12)
