"""Ying-Zorin's tangent-plane constraints (003 Sec. 3): PUT /tags "normals", "tangents" and
"tangent_edges", and what they do to the limit surface.

Expected values are derived here from 003's statements, not from core/tangent.c:
  * the petal block of a simple singular vertex (003 Sec. 2: the B-spline rule on the curve,
    midpoints on its edges, Fig. 4f with theta = pi/k inside) is built with numpy, and its left
    eigenvector l^1 of the interior-tangent mode x^1_j = sin(j theta) (eigenvalue 1/2, dual to
    the curve-tangent mode) taken from numpy's eigen-decomposition; a_1 = (l^1, p) is a petal's
    interior tangent, a_2 = (q_0 - q_k)/2 the curve's;
  * a closed petal's tangent pair is 003 App. A's x^1, x^2 = sin, cos (2 pi j/k), l = 2/k x, with
    the eigenvalue lambda = 3/8 + cos(2 pi/k)/4 of the flattened fixed-disk rule; the Loop normal
    is a_1 x a_2;
  * Fig. 6(b): the shared normal is the unit average of the petals' normals; Fig. 6(c): each
    petal's interior tangent is projected onto the difference of the two; Fig. 6(a) and "we scale
    the prescribed tangents to have the same length as a_1 ... on the top level";
  * the tangent modification drives the petal's tangent plane to the one holding the curve and
    the prescribed tangent, with the rate 1 - s (s = 3/4); inserted vertices take the midpoint
    of their edge's ends' tangents, (T_a + T_b) / 4 at their level (003 App. B). A vertex's
    modification moves only its own 1-ring, a block S keeps, so a_1 / lambda^r tends to the target
    with the one mode (1 - s)^r and no part along the curve.
The limit of a_1 / lambda^r is read from the daemon's levels 2 .. 6 by Richardson steps (the
first gives it to rounding; the second, for a (1 - s)^2r mode, is kept as a check). Limits of
a_1 and normals compared to 1e-9.
"""
import math

import numpy as np
import pytest

from daemon import Daemon, Session

S_MOD = 0.75
LEVELS = range(2, 7)


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


# ---- meshes ------------------------------------------------------------------------------------

SHEETS = [(0.0, 1.0, 0.25), (0.15, -1.0, 0.6), (0.0, 0.2, 1.0)]
# sheet 1 on sheet 0's side and longer: a_1(0) . a_1(1) > |a_1(0)|^2, the projections of both
# onto their difference point the same way
SHEETS_SAME_SIDE = [(0.0, 1.0, 0.25), (0.1, 2.0, 1.2), (0.0, -0.3, 1.0)]


def tjunction(sheets=SHEETS):
    """A singular curve (ids 0..4, a parabola) where three sheets of two rows meet (003 Fig. 5(c):
    two of them are the halves of a surface, the third a fin). Vertices 1, 2, 3 are simple
    singular vertices with 3 triangles per petal; 0 and 4 are complex (the sheets' sides)."""
    V = [[float(x), 0.0, 0.1 * x * x] for x in range(-2, 3)]
    T = []
    for d in sheets:
        rows = [list(range(5))]
        for r in (1, 2):
            ids = []
            for i, x in enumerate(range(-2, 3)):
                c = V[i]
                ids.append(len(V))
                V.append([c[0] + r * d[0] + 0.05 * r * r * x, c[1] + r * d[1],
                          c[2] + r * d[2] + 0.07 * r * r])
            rows.append(ids)
        for r in range(2):
            a, b = rows[r], rows[r + 1]
            for i in range(4):
                T.append([a[i], a[i + 1], b[i + 1]])
                T.append([a[i], b[i + 1], b[i]])
    return V, T


def sheet_triangle(T, sheet, i):
    """The triangle of `sheet` on curve edge i - i+1."""
    return T[16 * sheet + 2 * i]


def fans():
    """Two closed fans sharing only their apex 0 (003 Fig. 5(a)): a complex singular vertex with
    two closed petals of 5 and 6 triangles."""
    V = [[0.0, 0.0, 0.0]]
    T = []
    for (k, axis, tilt, h) in ((5, 1, 0.3, 0.4), (6, -1, -0.2, 0.7)):
        first = len(V)
        for j in range(k):
            a = 2 * math.pi * j / k
            r = 1 + 0.2 * math.cos(2 * a)
            V.append([r * math.cos(a), r * math.sin(a) + tilt, axis * (h + 0.3 * math.sin(a))])
        for j in range(k):
            T.append([0, first + j, first + (j + 1) % k])
    return V, T


# ---- 003's petal analysis, numerically ---------------------------------------------------------

def l1_open(k):
    """l^1 of the open petal block of a simple singular vertex (order: v, q_0 .. q_k)."""
    th = math.pi / k
    g = 0.5 - math.cos(th) / 4
    n = k + 2
    S = np.zeros((n, n))
    S[0, 0], S[0, 1], S[0, k + 1] = 0.75, 0.125, 0.125
    S[1, 0] = S[1, 1] = S[k + 1, 0] = S[k + 1, k + 1] = 0.5
    for j in range(1, k):
        S[j + 1, 0] += 0.75 - g
        S[j + 1, j + 1] += g
        S[j + 1, j] += 0.125
        S[j + 1, j + 2] += 0.125
    w, X = np.linalg.eig(S)
    L = np.real(np.linalg.inv(X))
    half = [i for i in range(n) if abs(w[i] - 0.5) < 1e-9]
    assert len(half) == 2                                       # 1/2 is double
    rest = sorted((abs(w[i]) for i in range(n) if i not in half), reverse=True)
    assert rest[0] == pytest.approx(1, abs=1e-12)               # the centre's eigenvalue 1
    assert rest[1] < 0.5 - 1e-9                                 # the rest below 1/2
    x1 = np.array([0.0] + [math.sin(j * th) for j in range(k + 1)])
    x2 = np.array([0.0, 1.0] + [math.cos(j * th) for j in range(1, k)] + [-1.0])
    Lh = L[half, :]
    assert np.allclose(S @ x1, 0.5 * x1, atol=1e-12) and np.allclose(S @ x2, 0.5 * x2, atol=1e-12)
    # l^1 = c Lh with (l^1, x^1) = 1, (l^1, x^2) = 0: rows of the system are Lh x^1, Lh x^2
    c = np.linalg.solve(np.array([Lh @ x1, Lh @ x2]), np.array([1.0, 0.0]))
    l1 = c @ Lh
    assert np.allclose(l1 @ S, 0.5 * l1, atol=1e-12)
    assert abs(l1 @ x1 - 1) < 1e-12 and abs(l1 @ x2) < 1e-12
    return l1


def unit(x):
    return np.asarray(x) / np.linalg.norm(x)


def level(s, L, V=None, T=None):
    if L == 0:
        return np.array(V, float), T
    j = s.level(L, format="json").json()
    c = j["cells"]
    return np.array(j["vertices"], float), c["triangles"] if isinstance(c, dict) else c


def petals_at(tris, v):
    """The petals of v: its triangles joined across edges v-u of exactly two triangles, each as
    the ring of its other vertices in order (open: from one singular edge's end to the other's;
    closed: k of them)."""
    cnt = {}
    for t in tris:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            cnt[frozenset((a, b))] = cnt.get(frozenset((a, b)), 0) + 1
    star = [tuple(t) for t in tris if v in t]
    parent = {t: t for t in star}

    def find(x):
        while parent[x] != x:
            x = parent[x]
        return x
    by_u = {}
    for t in star:
        for u in t:
            if u != v:
                by_u.setdefault(u, []).append(t)
    for u, ts in by_u.items():
        if cnt[frozenset((v, u))] == 2 and len(ts) == 2:
            parent[find(ts[0])] = find(ts[1])
    groups = {}
    for t in star:
        groups.setdefault(find(t), []).append(t)
    rings = []
    for ts in groups.values():
        adj = {}
        for t in ts:
            a, b = [u for u in t if u != v]
            adj.setdefault(a, []).append(b)
            adj.setdefault(b, []).append(a)
        ends = sorted(u for u in adj if len(adj[u]) == 1)
        start = ends[0] if ends else min(adj)
        ring, prev = [start], None
        while True:
            nxt = [y for y in adj[ring[-1]] if y != prev]
            if not nxt or nxt[0] == start:
                break
            prev = ring[-1]
            ring.append(nxt[0])
        rings.append(ring)
    return rings


def sheet_ring(X, tris, v, sh):
    """The petal of v in sheet `sh`, read from the topology: a level's triangles come in the order
    of their level-0 ancestors (face f's descendants are 4^L f .. 4^L (f + 1) - 1), so each sheet
    is a third of them."""
    span = len(tris) // 3
    rings = petals_at([t for t in tris[sh * span:(sh + 1) * span] if v in t], v)
    assert len(rings) == 1 and len(rings[0]) >= 3
    return rings[0]


def a1_a2(X, v, ring):
    k = len(ring) - 1
    pts = np.vstack([X[v]] + [X[u] for u in ring])
    return l1_open(k) @ pts, (X[ring[0]] - X[ring[-1]]) / 2


def richardson(seq, rate):
    """The limit of seq[r] = b + c rate^r + d rate^2r (two steps; the spread of the last two
    estimates returned too)."""
    r1 = [(seq[i + 1] - rate * seq[i]) / (1 - rate) for i in range(len(seq) - 1)]
    r2 = [(r1[i + 1] - rate * rate * r1[i]) / (1 - rate * rate) for i in range(len(r1) - 1)]
    return r2[-1], max(np.linalg.norm(r2[i + 1] - r2[i]) for i in range(len(r2) - 1))


def session(daemon, V, T, tags=None):
    s = Session(daemon)
    assert s.put_complex({"vertices": V, "simplices": T}).status_code == 200
    r = s.req("PUT", "/rules", json={"nonmanifold_surface": "ying-zorin"})
    assert r.status_code == 200, r.text
    if tags is not None:
        r = s.req("PUT", "/tags", json=tags)
        assert r.status_code == 200, r.text
    return s


def interior_limits(s, vertices, sheets, origin_level=0):
    """For each (vertex, sheet): the limit of a_1 2^r (level-`origin_level` units) and the curve
    tangent, from the daemon's levels."""
    seqs = {}
    for L in LEVELS:
        X, tris = level(s, L)
        for v in vertices:
            for sh in sheets:
                ring = sheet_ring(X, tris, v, sh)
                a1, a2 = a1_a2(X, v, ring)
                seqs.setdefault((v, sh), []).append((a1 * 2.0 ** (L - origin_level), a2))
    out = {}
    for key, seq in seqs.items():
        b, spread = richardson([x[0] for x in seq], 1 - S_MOD)
        assert spread < 1e-11 * np.linalg.norm(b), (key, spread)
        out[key] = (b, seq[-1][1])
    return out


def limit_normal(b, a2):
    return unit(np.cross(a2, b))


def same_plane(n0, n1, tol=1e-9):
    return np.linalg.norm(np.cross(n0, n1)) < tol


# ---- the curve: Fig. 6(c) and 6(a) -------------------------------------------------------------

def curve_vertices_level1(s, V, T):
    """The level-1 vertices on the curve between 1-2 and 2-3 (the midpoints' images)."""
    X1, tris1 = level(s, 1)
    nv0 = len(V)
    cnt = {}
    for t in tris1:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            cnt[frozenset((a, b))] = cnt.get(frozenset((a, b)), 0) + 1
    mids = []
    for end in ((1, 2), (2, 3)):
        m = [u for u in range(nv0, len(X1)) if cnt.get(frozenset((end[0], u)), 0) == 3 and
             cnt.get(frozenset((end[1], u)), 0) == 3]
        assert len(m) == 1
        mids.append((m[0], end))
    return mids


@pytest.mark.parametrize("sheets", [SHEETS, SHEETS_SAME_SIDE], ids=["apart", "same-side"])
def test_inferred_tangent_plane_along_curve(daemon, sheets):
    """003 Fig. 6(c): the two halves of the surface (sheets 0 and 1) made tangent along the curve
    with no tangent given: at every vertex of the curve the limit normals of the two sheets are
    equal (1e-9) and the projections of the level-0 interior tangents onto their difference are
    tangent to both, the inserted vertices' interpolated ones too, and the fin (sheet 2) keeps
    its own tangent plane."""
    V, T = tjunction(sheets)
    edges = [{"edge": [i, i + 1], "triangles": [sheet_triangle(T, 0, i), sheet_triangle(T, 1, i)]}
             for i in range(4)]
    s = session(daemon, V, T, {"tangent_edges": edges})
    X0 = np.array(V, float)
    want = {}
    for v in (1, 2, 3):
        # "t and -t" along d = a_1(sheet 1) - a_1(sheet 0): sheet 0 takes -unit(d), sheet 1
        # +unit(d), each at its own level-0 length (003's scaling)
        a = [a1_a2(X0, v, sheet_ring(X0, T, v, sh))[0] for sh in (0, 1)]
        if sheets is SHEETS_SAME_SIDE:
            assert a[0] @ a[1] > a[0] @ a[0]
        d = unit(a[1] - a[0])
        want[(v, 0)] = -np.linalg.norm(a[0]) * d
        want[(v, 1)] = np.linalg.norm(a[1]) * d
    lim = interior_limits(s, (1, 2, 3), (0, 1, 2))
    for v in (1, 2, 3):
        n0 = limit_normal(*lim[(v, 0)])
        n1 = limit_normal(*lim[(v, 1)])
        assert same_plane(n0, n1), (v, n0, n1)
        for sh in (0, 1):                                        # the projection is tangent
            assert abs(n0 @ unit(want[(v, sh)])) < 1e-9, (v, sh)
            # and is a_1's limit itself: direction, sign and length, nothing along the curve
            assert np.linalg.norm(lim[(v, sh)][0] - want[(v, sh)]) < \
                1e-9 * np.linalg.norm(want[(v, sh)]), (v, sh, lim[(v, sh)][0], want[(v, sh)])
        assert unit(lim[(v, 0)][0]) @ unit(lim[(v, 1)][0]) == pytest.approx(-1, abs=1e-9)
        fin = a1_a2(X0, v, sheet_ring(X0, T, v, 2))[0]
        assert np.allclose(lim[(v, 2)][0], fin, atol=1e-10)     # untouched: a_1 scales by 1/2
    # the vertices inserted on the tagged edges: midpoint interpolation (003 App. B)
    for m, (a, b) in curve_vertices_level1(s, V, T):
        lm = interior_limits(s, (m,), (0, 1), origin_level=1)
        n0, n1 = limit_normal(*lm[(m, 0)]), limit_normal(*lm[(m, 1)])
        assert same_plane(n0, n1)
        for sh in (0, 1):
            assert abs(n0 @ unit(want[(a, sh)] + want[(b, sh)])) < 1e-9
            # the midpoint rule with App. B's factor: T = (T_a + T_b) / 4 at level 1, whose
            # units the limit is read in; the ends' level-1 targets are T_a / 2, T_b / 2
            mid = (want[(a, sh)] + want[(b, sh)]) / 4
            assert np.linalg.norm(lm[(m, sh)][0] - mid) < 1e-9 * np.linalg.norm(mid), \
                (m, sh, lm[(m, sh)][0], mid)
    s.delete()


def test_prescribed_opposite_tangents(daemon):
    """003 Fig. 6(a): opposite interior tangents t and -t for the two halves at every vertex of
    the curve, interpolated along the tagged edges: one tangent plane, containing t."""
    V, T = tjunction()
    t = np.array([0.05, 1.0, 0.4])
    tangents = []
    for v in (1, 2, 3):
        for sh, sign in ((0, 1), (1, -1)):
            tri = sheet_triangle(T, sh, v)
            tangents.append({"vertex": v, "triangle": tri, "tangent": list(sign * t)})
    tags = {"tangents": tangents, "tangent_edges": [{"edge": [1, 2]}, {"edge": [2, 3]}]}
    s = session(daemon, V, T, tags)
    X0 = np.array(V, float)
    lim = interior_limits(s, (1, 2, 3), (0, 1))
    for v in (1, 2, 3):
        n0, n1 = limit_normal(*lim[(v, 0)]), limit_normal(*lim[(v, 1)])
        assert same_plane(n0, n1)
        assert abs(n0 @ unit(t)) < 1e-9                          # the plane holds t
        for sh, sign in ((0, 1), (1, -1)):   # a_1 2^r -> the given direction at |a_1 level 0|
            want = sign * np.linalg.norm(a1_a2(X0, v, sheet_ring(X0, T, v, sh))[0]) * unit(t)
            assert np.linalg.norm(lim[(v, sh)][0] - want) < 1e-9 * np.linalg.norm(want), \
                (v, sh, lim[(v, sh)][0], want)
    # the tagged edges' inserted vertices: one plane too
    for m, _ in curve_vertices_level1(s, V, T):
        lm = interior_limits(s, (m,), (0, 1), origin_level=1)
        assert same_plane(limit_normal(*lm[(m, 0)]), limit_normal(*lm[(m, 1)]))
    s.delete()


def test_given_tangent_kept_the_other_petal_takes_its_opposite(daemon):
    """003 Fig. 6(a) with one tangent given: a tagged edge's pair of petals where only sheet 0's
    petal has a tangent t; it keeps t and sheet 1's petal takes -t, each at its level-0 length."""
    V, T = tjunction()
    t = np.array([0.05, 1.0, 0.4])
    tangents = [{"vertex": v, "triangle": sheet_triangle(T, 0, v), "tangent": list(t)}
                for v in (1, 2, 3)]
    edges = [{"edge": [i, i + 1], "triangles": [sheet_triangle(T, 0, i), sheet_triangle(T, 1, i)]}
             for i in (1, 2)]
    s = session(daemon, V, T, {"tangents": tangents, "tangent_edges": edges})
    X0 = np.array(V, float)
    lim = interior_limits(s, (1, 2, 3), (0, 1))
    for v in (1, 2, 3):
        for sh, sign in ((0, 1), (1, -1)):
            want = sign * np.linalg.norm(a1_a2(X0, v, sheet_ring(X0, T, v, sh))[0]) * unit(t)
            assert np.linalg.norm(lim[(v, sh)][0] - want) < 1e-9 * np.linalg.norm(want), \
                (v, sh, lim[(v, sh)][0], want)
    s.delete()


def test_three_patches_share_one_plane(daemon):
    """Any number of patches can be made tangential along a curve (003 Sec. 3, Fig. 5(b)): the
    fin too gets a tangent, -t, folding it onto the side of sheet 1; all three limit normals
    are one."""
    V, T = tjunction()
    t = np.array([0.05, 1.0, 0.4])
    tangents = [{"vertex": v, "triangle": sheet_triangle(T, sh, v), "tangent": list(sign * t)}
                for v in (1, 2, 3) for sh, sign in ((0, 1), (1, -1), (2, -1))]
    tags = {"tangents": tangents, "tangent_edges": [{"edge": [1, 2]}, {"edge": [2, 3]}]}
    s = session(daemon, V, T, tags)
    lim = interior_limits(s, (1, 2, 3), (0, 1, 2))
    for v in (1, 2, 3):
        n = [limit_normal(*lim[(v, sh)]) for sh in (0, 1, 2)]
        assert same_plane(n[0], n[1]) and same_plane(n[0], n[2]), (v, n)
    s.delete()


def test_without_constraints_the_sheets_keep_their_planes(daemon):
    """The control: with no tangent tags a_1 2^r is the level-0 a_1 at every level (l^1 is a left
    eigenvector of the rules), so the halves meet at their own angle."""
    V, T = tjunction()
    s = session(daemon, V, T)
    X0 = np.array(V, float)
    X, tris = level(s, 3)
    for v in (1, 2, 3):
        n = []
        for sh in (0, 1):
            a0 = a1_a2(X0, v, sheet_ring(X0, T, v, sh))
            a3 = a1_a2(X, v, sheet_ring(X, tris, v, sh))
            assert np.allclose(a3[0] * 8, a0[0], atol=1e-12)
            n.append(limit_normal(a0[0], a0[1]))
        assert np.linalg.norm(np.cross(n[0], n[1])) > 0.5
    s.delete()


# ---- the vertex: Fig. 5(a) and 6(b) ------------------------------------------------------------

def closed_a(X, v, ring):
    k = len(ring)
    a1 = sum(math.sin(2 * math.pi * j / k) * (X[u] - X[v]) for j, u in enumerate(ring)) * 2 / k
    a2 = sum(math.cos(2 * math.pi * j / k) * (X[u] - X[v]) for j, u in enumerate(ring)) * 2 / k
    return a1, a2


def gram_limits(s):
    """Per closed petal of vertex 0 (by its size k): G_r = A A^T / lambda^2r over levels 1 .. 6,
    A = [a_1 a_2] (lambda = 3/8 + cos(2 pi/k)/4, App. A). G does not depend on where the ring
    starts or which way it turns (A changes by an orthogonal 2 x 2 factor)."""
    seqs = {}
    for L in range(1, 7):
        X, tris = level(s, L)
        for ring in petals_at(tris, 0):
            k = len(ring)
            lam = 3 / 8 + math.cos(2 * math.pi / k) / 4
            A = np.column_stack(closed_a(X, 0, ring))
            seqs.setdefault(k, []).append(A @ A.T / lam ** (2 * L))
    return seqs


@pytest.mark.parametrize("mode", ["given", "shared"])
def test_normal_at_complex_vertex(daemon, mode):
    """003 Sec. 3's normal modification on the two closed petals of a complex vertex: with a
    normal given (Fig. 5(a)) or shared as the average of the petals' Loop normals (Fig. 6(b)).
    Writing a_i / lambda^r = P_i + c^r Q_i, the part along n shrinks by c = 1 - s per level and
    the rest stays; the limit tangent plane, the range of lim G, is normal to n (1e-9)."""
    V, T = fans()
    X0 = np.array(V, float)
    if mode == "given":
        n = unit([0.2, -0.3, 1.0])
        tags = {"normals": [{"vertex": 0, "triangles": [T[0], T[5]], "normal": list(n)}]}
    else:
        ns = [unit(np.cross(*closed_a(X0, 0, r))) for r in petals_at(T, 0)]
        ns = [x if x @ ns[0] >= 0 else -x for x in ns]
        n = unit(sum(ns))
        tags = {"normals": [{"vertex": 0, "triangles": [T[0], T[5]]}]}
    s = session(daemon, V, T, tags)
    seqs = gram_limits(s)
    assert sorted(seqs) == [5, 6]
    c = 1 - S_MOD
    for k, G in seqs.items():
        along = [n @ g @ n for g in G]
        for r in range(1, len(G)):
            assert along[r] == pytest.approx(c * c * along[r - 1], rel=1e-9, abs=1e-14)
        # G_r = G + c^r C_1 + c^2r C_2: two Richardson steps
        r1 = [(G[i + 1] - c * G[i]) / (1 - c) for i in range(len(G) - 1)]
        r2 = [(r1[i + 1] - c * c * r1[i]) / (1 - c * c) for i in range(len(r1) - 1)]
        assert np.abs(r2[-1] - r2[-2]).max() < 1e-11
        w, U = np.linalg.eigh(r2[-1])
        assert w[1] > 1e-3 * w[2]                   # a plane: rank 2
        assert same_plane(U[:, 0], n), (k, U[:, 0], n)
    s.delete()


# ---- the API: echo, round trip, edits, refusals ------------------------------------------------

def test_echo_export_import_and_edit(daemon):
    V, T = tjunction()
    tags = {"tangents": [{"vertex": 2, "triangle": sheet_triangle(T, 0, 2),
                          "tangent": [0, 1, 0.5]}],
            "tangent_edges": [{"edge": [1, 2], "triangles": [sheet_triangle(T, 0, 1),
                                                             sheet_triangle(T, 1, 1)]},
                              {"edge": [2, 3]}]}
    s = session(daemon, V, T, tags)
    got = s.req("GET", "/complex").json()["tags"]
    assert got["tangents"] == tags["tangents"]
    assert got["tangent_edges"] == tags["tangent_edges"]
    lv = s.level(3, format="json").json()["vertices"]
    doc = s.req("GET", "/export").json()
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 201, r.text
    j = r.json()
    t = Session.__new__(Session)
    t.d, t.http, t.id, t.token = daemon, s.http, j["id"], j["token"]
    t.base, t.auth = f"{daemon.url}/v1/sessions/{t.id}", {"Authorization": f"Bearer {t.token}"}
    assert t.level(3, format="json").json()["vertices"] == lv
    # an edit recomputes the constrained levels as a new complex with the moved point gives
    ver = s.req("GET", "/complex").headers["ETag"]
    moved = [V[11][0], V[11][1] + 0.2, V[11][2] - 0.1]
    r = s.req("PATCH", "/control-points", headers={"If-Match": ver},
              json={"moves": [{"index": 11, "position": moved}]})
    assert r.status_code == 200, r.text
    V2 = [list(p) for p in V]
    V2[11] = moved
    u = session(daemon, V2, T, tags)
    got, want = (x.level(3, format="json").json()["vertices"] for x in (s, u))
    assert got == want
    # a move at level 1 of a modified point: where asked, and kept by the export's offsets
    X1, tris1 = level(s, 1)
    ring = sheet_ring(X1, tris1, 2, 0)
    q = ring[1]
    ver = s.req("GET", "/complex").headers["ETag"]
    to = list(X1[q] + np.array([0.0, 0.05, 0.1]))
    r = s.req("PATCH", "/control-points", headers={"If-Match": ver},
              json={"moves": [{"level": 1, "index": int(q), "position": to}]})
    assert r.status_code == 200, r.text
    assert np.allclose(level(s, 1)[0][q], to, atol=1e-12)
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": s.req("GET", "/export").json()})
    assert r.status_code == 201, r.text
    j = r.json()
    w = Session.__new__(Session)
    w.d, w.http, w.id, w.token = daemon, s.http, j["id"], j["token"]
    w.base, w.auth = f"{daemon.url}/v1/sessions/{w.id}", {"Authorization": f"Bearer {w.token}"}
    got, want = (x.level(3, format="json").json()["vertices"] for x in (s, w))
    assert got == want
    for x in (s, t, u, w):
        x.delete()


def test_refine_says_it_drops_the_constraints(daemon):
    """POST /refine does not carry tangent-plane constraints (DECISIONS 47 (f)): the answer
    counts the entries dropped, and the refined complex lists none."""
    V, T = tjunction()
    tags = {"tangents": [{"vertex": 2, "triangle": sheet_triangle(T, 0, 2),
                          "tangent": [0, 1, 0.5]}],
            "tangent_edges": [{"edge": [1, 2]}, {"edge": [2, 3]}]}
    s = session(daemon, V, T, tags)
    ver = s.req("GET", "/complex").headers["ETag"]
    r = s.req("POST", "/refine", headers={"If-Match": ver},
              json={"select": {"simplices": [T[0]]}})
    assert r.status_code == 200, r.text
    assert r.json()["tangent_tags_dropped"] == 3
    got = s.req("GET", "/complex").json().get("tags", {})
    assert not got.get("tangents") and not got.get("tangent_edges") and not got.get("normals")
    plain = session(daemon, V, T)
    ver = plain.req("GET", "/complex").headers["ETag"]
    r = plain.req("POST", "/refine", headers={"If-Match": ver},
                  json={"select": {"simplices": [T[0]]}})
    assert r.status_code == 200 and "tangent_tags_dropped" not in r.json(), r.text
    for x in (s, plain):
        x.delete()


def test_subnormal_directions_are_directions(daemon):
    """A given normal or tangent is a direction (any finite vector of non-zero length is taken):
    with subnormal components it makes the same level as the same direction at unit scale (its
    length was once taken from the subnormals, so (5e-324, 5e-324, 0) became (1, 1, 0), not unit,
    and a subnormal tangent was refused as along the curve)."""
    def level3(V, T, tags):
        s = session(daemon, V, T, tags)
        X, _ = level(s, 3)
        s.delete()
        return X

    V, T = fans()
    want = level3(V, T, {"normals": [{"vertex": 0, "triangles": [T[0], T[5]],
                                      "normal": [1.0, 1.0, 0.0]}]})
    got = level3(V, T, {"normals": [{"vertex": 0, "triangles": [T[0], T[5]],
                                     "normal": [5e-324, 5e-324, 0.0]}]})
    assert np.abs(got - want).max() < 1e-12
    V, T = tjunction()
    tri = sheet_triangle(T, 0, 2)
    want = level3(V, T, {"tangents": [{"vertex": 2, "triangle": tri, "tangent": [0.0, 1.0, 1.0]}]})
    got = level3(V, T, {"tangents": [{"vertex": 2, "triangle": tri,
                                      "tangent": [0.0, 5e-324, 5e-324]}]})
    assert np.abs(got - want).max() < 1e-12


def refuse(s, body, status, pointer):
    r = s.req("PUT", "/tags", json=body)
    assert r.status_code == status, (body, r.text)
    j = r.json()
    assert j["errors"][0]["pointer"] == pointer, (body, j)
    return j


def test_hostile_tangent_tags(daemon):
    V, T = tjunction()
    s = session(daemon, V, T)
    A1, B1 = sheet_triangle(T, 0, 1), sheet_triangle(T, 1, 1)
    ok_t = {"vertex": 2, "triangle": sheet_triangle(T, 0, 2), "tangent": [0, 1, 0]}
    cases = [
        ({"tangents": {}}, 400, "/tangents"),
        ({"tangents": [3]}, 400, "/tangents/0"),
        ({"tangents": [{"vertex": 2, "triangle": A1}]}, 400, "/tangents/0/tangent"),
        ({"tangents": [dict(ok_t, extra=1)]}, 400, "/tangents/0/extra"),
        ({"tangents": [dict(ok_t, vertex=999)]}, 422, "/tangents/0/vertex"),
        ({"tangents": [dict(ok_t, tangent=[0, 1])]}, 422, "/tangents/0/tangent"),
        ({"tangents": [dict(ok_t, tangent=[0, "a", 1])]}, 400, "/tangents/0/tangent/1"),
        ({"tangents": [dict(ok_t, tangent=[0, 0, 0])]}, 422, "/tangents/0/tangent"),
        ({"tangents": [dict(ok_t, tangent=[-2, 0, 0])]}, 422,
         "/tangents/0/tangent"),                                      # along the curve
        ({"tangents": [dict(ok_t, vertex=0, triangle=sheet_triangle(T, 0, 0))]}, 422,
         "/tangents/0/vertex"),                                       # complex vertex
        ({"tangents": [dict(ok_t, vertex=7)]}, 422, "/tangents/0/triangle"),  # not holding it
        ({"tangents": [dict(ok_t, vertex=7, triangle=[7, 8, 13])]}, 422, "/tangents/0/vertex"),
        ({"tangents": [ok_t, ok_t]}, 422, "/tangents/1/triangle"),    # one entry per petal
        ({"tangents": [dict(ok_t, triangle=[2, 2, 7])]}, 422, "/tangents/0/triangle/1"),
        ({"normals": [{"vertex": 2, "triangles": [A1], "normal": [0, 0, 1]}]}, 422,
         "/normals/0/vertex"),                                        # a simple vertex
        ({"normals": [{"vertex": 0, "triangles": []}]}, 422, "/normals/0/triangles"),
        ({"tangent_edges": [{"edge": [5, 6]}]}, 422, "/tangent_edges/0/edge"),   # not singular
        ({"tangent_edges": [{"edge": [1, 9]}]}, 422, "/tangent_edges/0/edge"),   # not an edge
        ({"tangent_edges": [{"edge": [1, 1]}]}, 422, "/tangent_edges/0/edge"),
        ({"tangent_edges": [{"edge": [1, 2]}, {"edge": [2, 1]}]}, 422, "/tangent_edges/1/edge"),
        ({"tangent_edges": [{"edge": [1, 2], "triangles": [A1]}]}, 422,
         "/tangent_edges/0/triangles"),
        ({"tangent_edges": [{"edge": [1, 2], "triangles": [A1, A1]}]}, 422,
         "/tangent_edges/0/triangles/1"),
        ({"tangent_edges": [{"edge": [1, 2], "triangles": [A1, sheet_triangle(T, 1, 2)]}]}, 422,
         "/tangent_edges/0/triangles/1"),
        ({"tangent_edges": [{"edge": [1, 2], "triangles": [A1, [1, 2, 99]]}]}, 422,
         "/tangent_edges/0/triangles/1/2"),
        ({"tangent_edges": [{"edge": [1, 2]}] * 600}, 422, "/tangent_edges"),  # > nv + 10 ns
    ]
    # the petals of all normals together are bounded too (nv + 10 ns), before allocating: two
    # entries each at the bound are refused at the second one's list
    most = len(V) + 10 * len(T)
    cases.append(({"normals": [{"vertex": 0, "triangles": [T[0]] * most}] * 2}, 422,
                  "/normals/1/triangles"))
    for body, status, ptr in cases:
        refuse(s, body, status, ptr)
    assert "tangents" not in s.req("GET", "/complex").json()["tags"]   # nothing applied
    s.delete()
    V, T = fans()
    s = session(daemon, V, T)
    for body, status, ptr in [
        ({"normals": [{"vertex": 0, "triangles": [T[0]]}]}, 422, "/normals/0/triangles"),
        ({"normals": [{"vertex": 0, "triangles": [T[0], T[1]]}]}, 422, "/normals/0/triangles/1"),
        ({"normals": [{"vertex": 0, "triangles": [T[0]], "normal": [0, 0, 0]}]}, 422,
         "/normals/0/normal"),
        ({"normals": [{"vertex": 1, "triangles": [T[0]], "normal": [0, 0, 1]}]}, 422,
         "/normals/0/vertex"),
        ({"tangents": [{"vertex": 0, "triangle": T[0], "tangent": [1, 0, 0]}]}, 422,
         "/tangents/0/vertex"),
    ]:
        refuse(s, body, status, ptr)
    s.delete()
    e = Session(daemon)
    refuse(e, {"tangents": [{"vertex": 0, "triangle": [0, 1, 2], "tangent": [1, 0, 0]}]}, 409,
           "/tangents")
    e.delete()
