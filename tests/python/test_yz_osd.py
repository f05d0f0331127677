"""nonmanifold_surface = ying-zorin against OpenSubdiv, vertex by vertex (matched by origin).

The peer is tests/peers/osd_loop.cpp (Debian libosd-dev, Far::TopologyRefiner with the Loop
scheme built from the same triangles through TopologyDescriptor, PrimvarRefinerReal<double>,
boundaries VTX_BOUNDARY_EDGE_ONLY), run with --origins so that each of its points says which
vertex or edge of the previous level it comes from; ours come from build/sdlevel with
`-w loop -n ying-zorin`. Points are matched by those origins, never by position.

Where the rule sets coincide. OpenSubdiv makes every non-manifold edge an infinitely sharp
crease; a non-manifold vertex on exactly two non-manifold edges, with no boundary edge, follows
its crease rule (6/8, 1/8, 1/8 along them) and every other non-manifold vertex is made a corner
(it prints these tags with --rules, which the tests check). 003 Sec. 2 gives the same: singular
edges are creases (midpoints), simple singular vertices the cubic B-spline along their two
singular edges, complex ones are corners; regular vertices and edges away from singular
vertices are Loop's in both, and plain boundaries are B-splines in both.

Where they differ, on purpose:
  - the non-singular edges of petals at non-manifold vertices. OpenSubdiv keeps Loop's 3/8, 1/8;
    003 takes Fig. 4f's (3/4 - g) v + g w + 1/8 (c + d), g = 1/2 - cos(theta)/4, with theta =
    pi/k in an open petal of a simple vertex, alpha/k in a (convex) corner petal, 2 pi/k in a
    dart — Loop's only when theta = pi/3 — and in a closed petal the fixed-disk rule (Loop, then
    the flatness modification; never Loop's);
  - a simple singular vertex one of whose two singular edges is a boundary edge (a fin ending
    inside a sheet): 003 keeps the B-spline along the two edges, OpenSubdiv makes it a corner.
The tests predict these sets from the mesh alone (petals and angles computed here), assert
agreement to 1e-12 everywhere else, and assert that every predicted difference is real.

Test 1 builds three fins whose every petal rule happens to be Loop's (3 triangles per open petal
at the spine, corner petals with alpha/k = pi/3): the whole hierarchy then equals OpenSubdiv's at
levels 1, 2 and 3. Tests 2-3 compare one step at a time (OpenSubdiv refines our level l once and
the result is compared with our level l + 1) on meshes with petals of 2, 3 and 4 triangles,
darts and closed petals, at l = 0, 1, 2.
"""
import math
import subprocess
from collections import defaultdict

import numpy as np
import pytest

from conftest import OSD, SDLEVEL

S_FLAT = 0.75   # the flatness modification's s (docs/DECISIONS.md 27)


def parse(text):
    """Points, origins ((kind, ids...)) and triangles of a level printed by sdlevel / osd_loop."""
    P, O, T = [], [], []
    for line in text.splitlines():
        f = line.split()
        if not f:
            continue
        if f[0] == "v":
            P.append([float(x) for x in f[1:4]])
            O.append((f[4], *sorted(int(x) for x in f[5:])) if len(f) > 4 else None)
        elif f[0] == "t":
            T.append([int(x) for x in f[1:4]])
    return np.array(P), O, T


def write_mesh(path, P, T):
    path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in P) +
                    "".join(f"s {a} {b} {c}\n" for a, b, c in T))
    return path


def ours(path, L):
    out = subprocess.run([str(SDLEVEL), "-l", str(L), "-w", "loop", "-n", "ying-zorin", str(path)],
                         check=True, capture_output=True, text=True).stdout
    return parse(out)


def peer(path, L, rules=False):
    args = [str(OSD), "-l", str(L), "--origins"] + (["--rules"] if rules else []) + [str(path)]
    out = subprocess.run(args, check=True, capture_output=True, text=True).stdout
    return parse(out), out


def by_origin(O):
    return {o: i for i, o in enumerate(O)}


# ---- 003 Sec. 2, independently: singular vertices, petals, and where OpenSubdiv differs ----

def analyse(P, T):
    """Kinds of vertices and the predicted rule of every edge point under 003 and OpenSubdiv."""
    etri = defaultdict(list)
    for t in T:
        for i in range(3):
            etri[frozenset((t[i], t[(i + 1) % 3]))].append(t)
    sing = {e for e, ts in etri.items() if len(ts) != 2}
    vtri = defaultdict(list)
    for t in T:
        for v in t:
            vtri[v].append(t)

    def groups(v, across):
        ts = vtri[v]
        par = list(range(len(ts)))

        def find(i):
            while par[i] != i:
                i = par[i]
            return i
        for i in range(len(ts)):
            for j in range(i + 1, len(ts)):
                sh = set(ts[i]) & set(ts[j])
                if len(sh) == 2 and across(frozenset(sh)):
                    par[find(i)] = find(j)
        g = defaultdict(list)
        for i, t in enumerate(ts):
            g[find(i)].append(t)
        return list(g.values())

    kind, petals = {}, {}
    for v in vtri:
        sedges = [e for e in etri if v in e and e in sing]
        nflowers = len(groups(v, lambda e: True))
        nonman = nflowers > 1 or any(len(etri[e]) > 2 for e in sedges)
        if not nonman:
            kind[v] = "boundary" if sedges else "interior"
            continue
        kind[v] = "simple" if nflowers == 1 and len(sedges) == 2 else "complex"
        petals[v] = groups(v, lambda e: e not in sing)
    return etri, sing, kind, petals


def petal_edge_rule(P, v, pet, sing, kind):
    """003's rule at end v for the non-singular edges of petal `pet`: ("gamma", g) or ("disk", ring)."""
    k = len(pet)
    pedges = {frozenset((v, u)) for t in pet for u in t if u != v}
    s_ends = [next(iter(e - {v})) for e in pedges if e in sing]
    if not s_ends:        # closed petal: the ring in order
        ring, t = [], pet[0]
        a = next(u for u in t if u != v)
        ring.append(a)
        cur = t
        while True:
            b = next(u for u in cur if u not in (v, ring[-1]))
            if b == ring[0]:
                break
            ring.append(b)
            cur = next(x for x in pet if x is not cur and v in x and b in x)
        return ("disk", ring)
    if len(s_ends) == 1:
        theta = 2 * math.pi / k
    elif kind[v] == "complex":
        a, b = P[s_ends[0]] - P[v], P[s_ends[1]] - P[v]
        theta = math.acos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)) / k
    else:
        theta = math.pi / k
    return ("gamma", 0.5 - math.cos(theta) / 4)


def predicted(P, T):
    """003's value of every edge point at a non-manifold end, and the sets of points whose rule
    differs from OpenSubdiv's: {("E", a, b)} and {("V", v)}."""
    etri, sing, kind, petals = analyse(P, T)
    value, differ = {}, set()
    for e, ts in etri.items():
        if e in sing:
            continue
        a, b = sorted(e)
        sides = []
        for v, w in ((a, b), (b, a)):
            if v not in petals:
                continue
            pet = next(p for p in petals[v] if any(set(t) >= set(e) for t in p))
            r = petal_edge_rule(P, v, pet, sing, kind)
            if r[0] == "gamma":
                c, d = [next(x for x in t if x not in e) for t in ts]
                g = r[1]
                sides.append(((0.75 - g) * P[v] + g * P[w] + (P[c] + P[d]) / 8, abs(g - 3 / 8) > 1e-12))
            else:
                ring = r[1]
                k = len(ring)
                i0 = ring.index(w)
                E = [3 / 8 * (P[v] + P[ring[j]]) + (P[ring[j - 1]] + P[ring[(j + 1) % k]]) / 8
                     for j in range(k)]
                flat = P[v] + 2 / k * sum(math.cos(2 * math.pi * (i0 - j) / k) * E[j] for j in range(k))
                sides.append(((1 - S_FLAT) * E[i0] + S_FLAT * flat, True))
        if sides:
            value[("E", a, b)] = sum(s[0] for s in sides) / len(sides)
            if any(s[1] for s in sides):
                differ.add(("E", a, b))
    for v, kd in kind.items():
        if kd == "simple" and any(len(etri[e]) == 1 for e in etri if v in e):
            differ.add(("V", v))      # OpenSubdiv: a corner (a boundary edge at a non-manifold vertex)
    return value, differ, kind


def compare_step(tmp_path, src, name, L):
    """OpenSubdiv refines our level L of `src` once; compare with our level L + 1."""
    P, _, T = ours(src, L)
    lvl = write_mesh(tmp_path / f"{name}_l{L}.txt", P, T)
    (Q, O, _), out = peer(lvl, 1, rules=True)
    R, RO, _ = ours(src, L + 1)
    value, differ, kind = predicted(P, T)
    # OpenSubdiv's own tags agree with the analysis above
    osd_rule = {int(f[1]): f[2] for f in (l.split() for l in out.splitlines()) if f and f[0] == "vrule"}
    for v, kd in kind.items():
        if kd == "complex" or ("V", v) in differ:
            assert osd_rule[v] == "corner", (v, kd, osd_rule[v])
        elif kd == "simple":
            assert osd_rule[v] == "crease", (v, kd, osd_rule[v])
    theirs = by_origin(O)
    assert len(RO) == len(O)
    same_d, diff_d, n_same, n_diff = 0.0, math.inf, 0, 0
    for i, o in enumerate(RO):
        d = np.abs(R[i] - Q[theirs[o]]).max()
        if o in differ:
            n_diff += 1
            diff_d = min(diff_d, d)
        else:
            n_same += 1
            same_d = max(same_d, d)
        if o in value:   # 003's value, re-derived here
            np.testing.assert_allclose(R[i], value[o], atol=1e-12, err_msg=str(o))
    assert same_d < 1e-12, f"level {L}: max difference where the rules coincide {same_d:.3g}"
    if n_diff:
        assert diff_d > 1e-9, f"level {L}: a predicted difference is not there ({diff_d:.3g})"
    return n_same, n_diff, same_d


# ---- meshes -----------------------------------------------------------------------------

def regular_fins(nz=5, nf=3):
    """A spine on the z axis and nf fins of 2 columns, every quad split along (c,z)-(c+1,z+1):
    each interior spine vertex has 3 triangles per fin. The fins' bottom rows leave the spine at
    120 degrees to it and their top rows at 60 degrees, so the corner petals at the spine's ends
    (2 triangles at the bottom, 1 at the top) have alpha/k = pi/3: Loop's edge rule."""
    V = [[0.0, 0.0, float(z)] for z in range(nz)]
    T = []
    for f in range(nf):
        a = 2 * math.pi * f / nf + 0.3 * f
        d = np.array([math.cos(a), math.sin(a), 0.0])
        base = len(V)
        for c in (1, 2):
            for z in range(nz):
                # bottom row slants down (120 deg to the spine), top row up (60 deg)
                dz = -c * math.tan(math.pi / 6) if z == 0 else c * math.tan(math.pi / 6) if z == nz - 1 \
                    else 0.15 * c * math.sin(z + f)
                p = d * c * (1 + 0.1 * math.cos(z)) + [0, 0, z + dz]
                if z in (0, nz - 1):
                    p = d * c + [0, 0, z + dz]
                V.append([float(x) for x in p])
        col = lambda c, z: z if c == 0 else base + nz * (c - 1) + z  # noqa: E731
        for c in (0, 1):
            for z in range(nz - 1):
                T += [[col(c, z), col(c + 1, z + 1), col(c + 1, z)],
                      [col(c, z), col(c, z + 1), col(c + 1, z + 1)]]
    return V, T


def irregular_fins():
    """Four fins with alternating diagonals: petals of 2, 3 and 4 triangles at the spine."""
    V = [[0.1 * z * z, 0, z] for z in range(4)]
    T = []
    for f, ang in enumerate((0.0, 1.4, 3.0, 4.6)):
        d = np.array([math.cos(ang), math.sin(ang), 0])
        base = len(V)
        for c in (1, 2):
            for z in range(4):
                p = d * c * (1 + 0.15 * z) + [0, 0, z + 0.2 * c * (f - 1)]
                V.append([float(x) for x in p])
        col = lambda c, z: z if c == 0 else base + 4 * (c - 1) + z  # noqa: E731
        for c in (0, 1):
            for z in range(3):
                a, b, cc, dd = col(c, z), col(c, z + 1), col(c + 1, z), col(c + 1, z + 1)
                if (z + c + f) % 2:
                    T += [[a, b, dd], [a, dd, cc]]
                else:
                    T += [[a, b, cc], [b, dd, cc]]
    return V, T


def closed_and_dart():
    """Two closed surfaces touching at vertex 0 (a tetrahedron's and a closed square pyramid's:
    closed petals of 3 and 4 triangles, fixed disks), and a sheet (a hexagonal fan around vertex
    11) with a fin on its edge 11-12: a dart petal at 11, whose singular edges are 11-12 (three
    triangles) and the fin's boundary edge."""
    V = [[0, 0, 0], [1, 0, .8], [-.5, .9, 1], [-.4, -.8, 1.1],
         [1, .1, -1], [.1, 1, -1.1], [-1, 0, -.9], [0, -1, -1]]
    T = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]
    T += [[0, 4 + i, 4 + (i + 1) % 4] for i in range(4)] + [[4, 7, 6], [4, 6, 5]]
    c = len(V)
    V.append([5, 0, 0])
    for i in range(6):
        a = 2 * math.pi * i / 6
        V.append([5 + math.cos(a), math.sin(a), 0.1 * math.sin(3 * a)])
    T += [[c, c + 1 + i, c + 1 + (i + 1) % 6] for i in range(6)]
    V.append([5.5, 0.2, 1.0])
    T += [[c, c + 1, len(V) - 1]]
    return V, T


def test_regular_fins_whole_hierarchy_equals_opensubdiv(tmp_path, osd_loop):
    V, T = regular_fins()
    src = write_mesh(tmp_path / "regular_fins.txt", V, T)
    _, differ, kind = predicted(np.array(V), T)
    assert not differ and list(kind.values()).count("simple") == 3
    assert list(kind.values()).count("complex") == 2
    ours_map = {i: i for i in range(len(V))}       # OpenSubdiv's id -> ours, level by level
    worst = 0.0
    for L in (1, 2, 3):
        R, RO, _ = ours(src, L)
        (Q, O, _), _ = peer(src, L)
        assert len(Q) == len(R)
        mine = by_origin(RO)
        new_map = {}
        for i, o in enumerate(O):
            key = (o[0], *sorted(ours_map[x] for x in o[1:]))
            new_map[i] = mine[key]
        assert sorted(new_map.values()) == list(range(len(R)))     # one to one
        d = max(np.abs(R[new_map[i]] - Q[i]).max() for i in range(len(Q)))
        worst = max(worst, d)
        assert d < 1e-12, f"level {L}: {d:.3g}"
        ours_map = new_map
    print(f"regular fins: levels 1-3, {len(R)} points at level 3, max difference {worst:.3g}")


@pytest.mark.parametrize("mesh", [irregular_fins, closed_and_dart])
def test_one_step_equals_opensubdiv_where_the_rules_coincide(tmp_path, osd_loop, mesh):
    V, T = mesh()
    src = write_mesh(tmp_path / f"{mesh.__name__}.txt", V, T)
    totals = []
    for L in (0, 1, 2):
        totals.append(compare_step(tmp_path, src, mesh.__name__, L))
    n_same = sum(t[0] for t in totals)
    n_diff = sum(t[1] for t in totals)
    assert n_diff > 0 and n_same > n_diff
    print(f"{mesh.__name__}: {n_same} points equal to OpenSubdiv's (max "
          f"{max(t[2] for t in totals):.3g}), {n_diff} differ as predicted")
