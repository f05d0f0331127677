"""Ying-Zorin (003 Sec. 2): the flatness modification at dart petals and concave corners, and
the petal tags that choose convex, concave or smooth corners (PUT /tags "petals").

Expected values are computed here from 003's statements alone, numerically, not from the
closed forms of core/yz.c:
  * the petal's first-stage subdivision matrix S on (v, p_0, ...): v fixed (a complex singular
    vertex is a corner), a singular edge's point its midpoint, any other edge 003 Fig. 4f,
    (3/4 - g) v + g p_i + 1/8 (p_{i-1} + p_{i+1}), g = 1/2 - cos(theta)/4, theta = 2 pi/k at a
    dart, (2 pi - alpha)/k at a concave corner, alpha/k convex, pi/k smooth;
  * its eigen-decomposition by numpy (right eigenvectors X, left ones the rows of X^-1);
  * the modification p <- (1 - s) p + s (a_0 x^0 + a_1 x^1 + a_2 x^2) applied to the new points,
    keeping the eigenvalue 1 and the eigenvalue-1/2 pair (the tangent plane of the dart chart
    and of the corner: the characteristic map of the pair is the regular k-gon for a dart and the
    wedge of angle k theta for a corner; docs/DECISIONS.md 28), s = 3/4.
The test also checks what the modification is for: after it the petal's matrix has 1, then 1/2
twice, then only smaller eigenvalues (before it, a larger one: the dart's half-angle mode
sin(pi i/k), the concave corner's first Dirichlet mode), so the petal is C1 at its centre.
"""
import math

import numpy as np
import pytest

from daemon import Daemon, Session

S_FLAT = 0.75


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


def first_stage(k, theta, singular, closed):
    """003's first stage on (v, p_0 .. p_{n-1}); `singular`: ring indices whose edge is singular;
    closed: the ring wraps around (dart) or not (open corner petal, p_0 and p_{n-1} singular)."""
    n = k if closed else k + 1
    S = np.zeros((n + 1, n + 1))
    S[0, 0] = 1
    g = 0.5 - math.cos(theta) / 4
    for i in range(n):
        r = i + 1
        if i in singular:
            S[r, 0] = S[r, r] = 0.5
            continue
        S[r, 0] += 0.75 - g
        S[r, r] += g
        for j in (i - 1, i + 1):
            S[r, (j % n if closed else j) + 1] += 0.125
    return S


def flattened(S, keep=(1.0, 0.5), s=S_FLAT):
    w, X = np.linalg.eig(S)
    assert np.linalg.cond(X) < 1e8          # diagonalizable: left eigenvectors are X^-1's rows
    L = np.linalg.inv(X)
    kept = [i for i in range(len(w)) if any(abs(w[i] - q) < 1e-9 for q in keep)]
    P = np.real(X[:, kept] @ L[kept, :])
    return (1 - s) * S + s * P @ S, w


def spectrum(M):
    return sorted(np.abs(np.linalg.eigvals(M)), reverse=True)


def ours(daemon, V, T, L=1, petals=None, singular=()):
    s = Session(daemon)
    assert s.put_complex({"vertices": V, "simplices": T}).status_code == 200
    r = s.req("PUT", "/rules", json={"nonmanifold_surface": "ying-zorin", "surface_weights": "loop"})
    assert r.status_code == 200, r.text
    if petals is not None:
        r = s.req("PUT", "/tags", json={"singular": list(singular), "petals": petals})
        assert r.status_code == 200, r.text
    out = [s.level(l, format="json").json() for l in range(1, L + 1)]
    c = s.req("GET", "/complex").json()
    s.delete()
    return out, c


def edge_point(j, a, b):
    """The point of level j on the edge a-b of the level before."""
    for i, e in enumerate(j["origin"]["edge_of"]):
        if e and sorted(e) == sorted([a, b]):
            return np.array(j["vertices"][i])
    raise KeyError((a, b))


def edge_rules(c):
    return {tuple(sorted(e["vertices"])): e["rule"] for e in c["classes"]["edges"]}


# ---- a dart petal at a complex singular vertex ---------------------------------------------

def dart_mesh(k=5):
    """A fan of k triangles around vertex 0 (ring 1..k, not flat) and two fins on edge 0-1: the
    edge 0-1 is non-manifold, the fins' edges 0-6 and 0-7 boundary, so vertex 0 has three
    singular edges (complex) and the fan is a dart petal (one singular edge, 0-1)."""
    V = [[0, 0, 0]] + [[math.cos(2 * math.pi * i / k), math.sin(2 * math.pi * i / k),
                        0.3 * math.sin(3.0 * i)] for i in range(k)]
    V += [[0.6, 0.1, 1], [0.5, -0.2, -1]]
    T = [[0, 1 + i, 1 + (i + 1) % k] for i in range(k)] + [[0, 1, k + 1], [0, 1, k + 2]]
    return V, T


@pytest.mark.parametrize("k", [3, 4, 5, 7])
def test_dart_flatness(daemon, k):
    V, T = dart_mesh(k)
    (j,), c = ours(daemon, V, T)
    assert c["classes"]["vertices"][0]["rule"] == "ying-zorin-corner"
    rules = edge_rules(c)
    assert rules[(0, 1)] == "ying-zorin-crease"
    assert all(rules[(0, 1 + i)] == "ying-zorin-dart" for i in range(1, k))
    ring = list(range(1, k + 1))                          # p_0 = 1: the singular edge 0-1
    S = first_stage(k, 2 * math.pi / k, {0}, closed=True)
    before = spectrum(S)
    lam1 = 0.5 + (math.cos(math.pi / k) - math.cos(2 * math.pi / k)) / 4
    assert before[1] == pytest.approx(lam1, abs=1e-12) and lam1 > 0.5   # not C1 as it stands
    M, w = flattened(S)
    after = spectrum(M)
    assert after[0] == pytest.approx(1) and after[1] == pytest.approx(0.5, abs=1e-12)
    assert after[2] == pytest.approx(0.5, abs=1e-12) and after[3] < 0.5 - 1e-3
    P = np.array(V, dtype=float)[[0] + ring]
    want = M @ P
    for i in range(k):
        np.testing.assert_allclose(edge_point(j, 0, ring[i]), want[i + 1], atol=1e-12,
                                   err_msg=f"edge 0-{ring[i]}")
    np.testing.assert_array_equal(j["vertices"][0], V[0])
    # the crease point is the midpoint: the modification leaves it
    np.testing.assert_allclose(edge_point(j, 0, 1), (P[0] + P[1]) / 2, atol=1e-15)


def test_dart_at_a_simple_vertex_keeps_the_first_stage(daemon):
    """A fan with one fin on edge 0-1: vertex 0 has two singular edges (0-1 non-manifold, the
    fin's boundary 0-6) in one flower, a simple vertex moving along the B-spline of its singular
    edges, so the petal matrix is not closed under the dart's centre (003 assumes all petals of a
    simple vertex share both edges): the dart rule stays at its first stage (DECISIONS 28)."""
    k = 5
    V, T = dart_mesh(k)
    T = T[:-1]
    (j,), c = ours(daemon, V, T)
    assert c["classes"]["vertices"][0]["rule"] == "ying-zorin-crease"
    assert edge_rules(c)[(0, 3)] == "ying-zorin-petal"
    g = 0.5 - math.cos(2 * math.pi / k) / 4
    P = np.array(V, dtype=float)
    np.testing.assert_allclose(edge_point(j, 0, 3), (0.75 - g) * P[0] + g * P[3] + (P[2] + P[4]) / 8,
                               atol=1e-14)


# ---- open petals at a complex vertex: convex, concave, smooth --------------------------------

def fins_end():
    """Three fins on a spine 0-1-2 ending at vertex 0 (complex: three singular edges there).
    Each fin's petal at 0 has k = 2 triangles, bounded by the spine 0-1 and the fin's boundary
    edge 0-a (a = 3, 6, 9) at 90 degrees; its inner edge is 0-(a+1)."""
    V = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2],
         [-.5, .8, 0], [-.5, .8, 1], [-.5, .8, 2], [-.5, -.8, 0], [-.5, -.8, 1], [-.5, -.8, 2]]
    T = []
    for a in (3, 6, 9):
        T += [[0, 1, a + 1], [0, a + 1, a], [1, 2, a + 2], [1, a + 2, a + 1]]
    return V, T


def corner_expected(P, v, ring, theta, flat):
    S = first_stage(len(ring) - 1, theta, {0, len(ring) - 1}, closed=False)
    if not flat:
        return S @ P[[v] + ring], S
    M, _ = flattened(S)
    return M @ P[[v] + ring], M


def test_concave_corner_flatness(daemon):
    V, T = fins_end()
    petals = [{"vertex": 0, "triangle": [0, 4, 3], "kind": "concave"}]
    (j1, j2), c = ours(daemon, V, T, L=2, petals=petals)
    assert c["tags"]["petals"] == petals
    rules = edge_rules(c)
    assert rules[(0, 4)] == "ying-zorin-concave"
    assert rules[(0, 7)] == rules[(0, 10)] == "ying-zorin-petal"     # the others stay convex
    P = np.array(V, dtype=float)
    alpha = math.pi / 2
    theta = (2 * math.pi - alpha) / 2
    want, M = corner_expected(P, 0, [1, 4, 3], theta, flat=True)
    S = first_stage(2, theta, {0, 2}, closed=False)
    assert spectrum(S)[1] > 0.5 + 1e-3                                  # the Dirichlet mode
    sp = spectrum(M)
    assert sp[1] == pytest.approx(0.5) and sp[2] == pytest.approx(0.5) and sp[3] < 0.5 - 1e-3
    np.testing.assert_allclose(edge_point(j1, 0, 4), want[2], atol=1e-12)
    # a convex fin: theta = alpha/k, first stage only
    want7, _ = corner_expected(P, 0, [1, 7, 6], alpha / 2, flat=False)
    np.testing.assert_allclose(edge_point(j1, 0, 7), want7[2], atol=1e-12)
    # level 2: the tag holds for the children of the petal's triangles; alpha measured again on
    # level 1 (the crease points are midpoints: still 90 degrees)
    Q = np.array(j1["vertices"])
    oe = {tuple(sorted(e)): i for i, e in enumerate(j1["origin"]["edge_of"]) if e}
    ring = [oe[(0, 1)], oe[(0, 4)], oe[(0, 3)]]
    want2, _ = corner_expected(Q, 0, ring, theta, flat=True)
    np.testing.assert_allclose(edge_point(j2, 0, ring[1]), want2[2], atol=1e-12)
    np.testing.assert_array_equal(j2["vertices"][0], V[0])


def test_smooth_petal(daemon):
    V, T = fins_end()
    petals = [{"vertex": 0, "triangle": [0, 1, 7], "kind": "smooth"}]
    (j,), c = ours(daemon, V, T, petals=petals)
    P = np.array(V, dtype=float)
    want, _ = corner_expected(P, 0, [1, 7, 6], math.pi / 2, flat=False)   # theta = pi/k
    np.testing.assert_allclose(edge_point(j, 0, 7), want[2], atol=1e-12)
    g = 0.5                                                               # cos(pi/2) = 0
    np.testing.assert_allclose(edge_point(j, 0, 7), 0.25 * P[0] + g * P[7] + (P[1] + P[6]) / 8,
                               atol=1e-14)


def test_convex_tag_is_the_default(daemon):
    V, T = fins_end()
    (a,), _ = ours(daemon, V, T)
    (b,), c = ours(daemon, V, T, petals=[{"vertex": 0, "triangle": [0, 4, 3], "kind": "convex"}])
    np.testing.assert_array_equal(a["vertices"], b["vertices"])


def test_petal_tags_have_no_effect_under_chang_qin(daemon):
    V, T = fins_end()
    s = Session(daemon)
    assert s.put_complex({"vertices": V, "simplices": T}).status_code == 200
    plain = s.level(1, format="json").json()["vertices"]
    r = s.req("PUT", "/tags", json={"petals": [{"vertex": 0, "triangle": [0, 4, 3], "kind": "concave"}]})
    assert r.status_code == 200, r.text
    assert s.level(1, format="json").json()["vertices"] == plain
    s.delete()


def test_refine_carries_petal_tags(daemon):
    V, T = fins_end()
    s = Session(daemon)
    assert s.put_complex({"vertices": V, "simplices": T}).status_code == 200
    petals = [{"vertex": 0, "triangle": [0, 4, 3], "kind": "concave"}]
    assert s.req("PUT", "/tags", json={"singular": [], "petals": petals}).status_code == 200
    r = s.req("POST", "/refine", json={"select": {"simplices": [[0, 4, 3]]}, "positions": "midpoint"})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    (p,) = c["tags"]["petals"]
    assert p["vertex"] == 0 and p["kind"] == "concave" and 0 in p["triangle"]
    tri = sorted(p["triangle"])
    assert tri in [sorted(t) for t in c["simplices"]]
    # the new triangle lies in the tagged fin (x = 1 plane, y = 0)
    assert all(abs(c["vertices"][i][1]) < 1e-12 and c["vertices"][i][0] >= 0 for i in tri)
    s.delete()


# ---- petals sharing both singular edges: smooth together or not at all --------------------

def three_fans_and_a_triangle():
    """Three fans between edges 0-1 and 0-2 (so both are non-manifold) and a lone triangle
    touching vertex 0: two flowers, a complex vertex whose three fan petals share both singular
    edges."""
    V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.3], [1, 1, -0.3], [1.2, 0.8, 0.8],
         [-1, -1, 0], [-1, -0.5, 1]]
    T = [[0, 1, 3], [0, 3, 2], [0, 1, 4], [0, 4, 2], [0, 1, 5], [0, 5, 2], [0, 6, 7]]
    return V, T


def put_tags(daemon, V, T, body):
    s = Session(daemon)
    assert s.put_complex({"vertices": V, "simplices": T}).status_code == 200
    r = s.req("PUT", "/tags", json=body)
    s.delete()
    return r


def test_smooth_needs_all_petals_between_the_same_edges(daemon):
    V, T = three_fans_and_a_triangle()
    one = {"vertex": 0, "triangle": [0, 1, 3], "kind": "smooth"}
    r = put_tags(daemon, V, T, {"petals": [one]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/petals/0/kind", r.text
    every = [{"vertex": 0, "triangle": t, "kind": "smooth"} for t in ([0, 1, 3], [0, 1, 4], [0, 5, 2])]
    assert put_tags(daemon, V, T, {"petals": every}).status_code == 200
    # concave beside convex is allowed (003: "if one is concave, the other can be either")
    mixed = [{"vertex": 0, "triangle": [0, 1, 3], "kind": "concave"}]
    assert put_tags(daemon, V, T, {"petals": mixed}).status_code == 200


# ---- every error path of "petals" -----------------------------------------------------------

@pytest.mark.parametrize("petal, status, pointer", [
    ("x", 400, "/petals/0"),
    ({"vertex": 0, "triangle": [0, 4, 3]}, 400, "/petals/0/kind"),
    ({"triangle": [0, 4, 3], "kind": "convex"}, 400, "/petals/0/vertex"),
    ({"vertex": 0, "kind": "convex"}, 400, "/petals/0/triangle"),
    ({"vertex": 0, "triangle": [0, 4, 3], "kind": "convex", "x": 1}, 400, "/petals/0/x"),
    ({"vertex": 0, "triangle": [0, 4, 3], "kind": "flat"}, 422, "/petals/0/kind"),
    ({"vertex": 0, "triangle": [0, 4, 3], "kind": 3}, 400, "/petals/0/kind"),
    ({"vertex": 99, "triangle": [0, 4, 3], "kind": "convex"}, 422, "/petals/0/vertex"),
    ({"vertex": "0", "triangle": [0, 4, 3], "kind": "convex"}, 400, "/petals/0/vertex"),
    ({"vertex": 0, "triangle": [0, 4], "kind": "convex"}, 422, "/petals/0/triangle"),
    ({"vertex": 0, "triangle": 3, "kind": "convex"}, 400, "/petals/0/triangle"),
    ({"vertex": 0, "triangle": [0, 4, 99], "kind": "convex"}, 422, "/petals/0/triangle/2"),
    ({"vertex": 0, "triangle": [0, 4, 4], "kind": "convex"}, 422, "/petals/0/triangle/2"),
    ({"vertex": 0, "triangle": [0, 4, 5], "kind": "convex"}, 422, "/petals/0/triangle"),  # none
    ({"vertex": 0, "triangle": [1, 5, 4], "kind": "convex"}, 422, "/petals/0/triangle"),  # not at 0
    ({"vertex": 4, "triangle": [0, 4, 3], "kind": "concave"}, 422, "/petals/0/vertex"),   # manifold
    ({"vertex": 1, "triangle": [0, 1, 4], "kind": "concave"}, 422, "/petals/0/vertex"),   # simple
])
def test_petal_errors(daemon, petal, status, pointer):
    V, T = fins_end()
    r = put_tags(daemon, V, T, {"petals": [petal]})
    assert r.status_code == status, r.text
    j = r.json()
    assert j["errors"][0]["pointer"] == pointer, j
    assert r.headers["Content-Type"].startswith("application/problem+json")


def test_petal_errors_of_the_petal(daemon):
    V, T = fins_end()
    good = {"vertex": 0, "triangle": [0, 4, 3], "kind": "concave"}
    # the same petal twice (its other triangle)
    r = put_tags(daemon, V, T, {"petals": [good, {"vertex": 0, "triangle": [0, 1, 4], "kind": "smooth"}]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/petals/1/triangle", r.text
    # a vertex tagged singular has no corner rule
    r = put_tags(daemon, V, T, {"singular": [[0]], "petals": [good]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/petals/0/vertex", r.text
    # a dart and a closed petal are not open
    V, T = dart_mesh(5)
    r = put_tags(daemon, V, T, {"petals": [{"vertex": 0, "triangle": [0, 2, 3], "kind": "concave"}]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/petals/0/triangle", r.text
    assert "dart" in r.json()["detail"]
    V = [[0, 0, 0], [1, 0, .8], [-.5, .9, 1], [-.4, -.8, 1.1],
         [1, .1, -1], [.1, 1, -1.1], [-1, 0, -.9], [0, -1, -1]]
    T = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]
    T += [[0, 4 + i, 4 + (i + 1) % 4] for i in range(4)] + [[4, 7, 6], [4, 6, 5]]
    r = put_tags(daemon, V, T, {"petals": [{"vertex": 0, "triangle": [0, 1, 2], "kind": "concave"}]})
    assert r.status_code == 422 and "closed" in r.json()["detail"], r.text
    # before any complex
    s = Session(daemon)
    r = s.req("PUT", "/tags", json={"petals": [good]})
    assert r.status_code == 409 and r.json()["errors"][0]["pointer"] == "/petals", r.text
    assert s.req("PUT", "/tags", json={"petals": []}).status_code == 200
    r = s.req("PUT", "/tags", json={"petals": {}})
    assert r.status_code in (400, 409)
    s.delete()
    # a body with neither member
    s = Session(daemon)
    r = s.req("PUT", "/tags", json={})
    assert r.status_code == 400 and r.json()["errors"][0]["pointer"] == "/singular"
    s.delete()


# ---- edits move the points alpha is measured on -----------------------------------------------

@pytest.mark.parametrize("moved, kind", [(3, "convex"), (3, "concave"), (0, "convex"), (5, "concave")])
def test_edit_remeasures_alpha(daemon, moved, kind):
    """An edit that moves a far end of a corner petal's singular edge (3) or the corner (0)
    changes alpha: the cached matrix of that level is stale, so the edit rebuilds it. The result
    equals the level-1 formula with the new angle (numpy, as above) and a new session with the
    moved points, at every cached level; a point alpha does not read (5) takes the ordinary path."""
    V, T = fins_end()
    petals = [{"vertex": 0, "triangle": [0, 4, 3], "kind": kind}]
    s = Session(daemon)
    assert s.put_complex({"vertices": V, "simplices": T}).status_code == 200
    assert s.req("PUT", "/rules", json={"nonmanifold_surface": "ying-zorin",
                                        "surface_weights": "loop"}).status_code == 200
    r = s.req("PUT", "/tags", json={"petals": petals})
    assert r.status_code == 200, r.text
    for level in range(4):
        assert s.level(level, format="json").status_code == 200
    W = [list(p) for p in V]
    W[moved] = [W[moved][0] + 0.2, W[moved][1] + 0.7, W[moved][2] - 0.1]
    r = s.req("PATCH", "/control-points", json={"moves": [{"index": moved, "position": W[moved]}]},
              headers={"If-Match": r.headers["ETag"]})
    assert r.status_code == 200, r.text
    up = r.json()["updated_points"]
    fresh = Session(daemon)
    assert fresh.put_complex({"vertices": W, "simplices": T}).status_code == 200
    assert fresh.req("PUT", "/rules", json={"nonmanifold_surface": "ying-zorin",
                                            "surface_weights": "loop"}).status_code == 200
    assert fresh.req("PUT", "/tags", json={"petals": petals}).status_code == 200
    for level in range(4):
        a = s.level(level, format="json").json()
        b = fresh.level(level, format="json").json()
        np.testing.assert_allclose(a["vertices"], b["vertices"], rtol=0, atol=1e-12,
                                   err_msg=f"level {level}")
    j1 = s.level(1, format="json").json()
    P = np.array(W, dtype=float)
    u, w = P[1] - P[0], P[3] - P[0]
    alpha = math.acos(np.dot(u, w) / np.linalg.norm(u) / np.linalg.norm(w))
    theta = (2 * math.pi - alpha) / 2 if kind == "concave" else alpha / 2
    want, _ = corner_expected(P, 0, [1, 4, 3], theta, flat=kind == "concave")
    np.testing.assert_allclose(edge_point(j1, 0, 4), want[2], atol=1e-12)
    if moved != 5:                              # the rebuilt levels count all their points
        assert up["2"] == len(s.level(2, format="json").json()["vertices"])
    else:
        assert up["1"] < len(j1["vertices"])
    s.delete()
    fresh.delete()


# ---- a concave corner whose singular edges are nearly in line ---------------------------------

def straightish(alpha):
    """One fin of fins_end() with its boundary end 3 turned to the angle alpha from the spine
    0-1 (in the x-z plane), the other two fins as they are."""
    V, T = fins_end()
    V[3] = [math.sin(alpha), 0, math.cos(alpha)]
    return V, T


def concave_point(daemon, alpha):
    V, T = straightish(alpha)
    (j,), c = ours(daemon, V, T, petals=[{"vertex": 0, "triangle": [0, 4, 3], "kind": "concave"}])
    return edge_point(j, 0, 4), edge_rules(c)[(0, 4)], np.array(V, dtype=float)


def test_concave_corner_fades_near_straight(daemon):
    """The modification divides by sin(k theta) = -sin(alpha): near alpha = pi (and 0) it has no
    tangent pair to flatten to. s fades as 3/4 (sin(alpha)/0.1)^2 there (DECISIONS 28): the rule
    is continuous in alpha and is the first stage at alpha = pi. Expected values: numpy's
    eigen-decomposition with that s; continuity: the point moves by O(delta alpha)."""
    for alpha in (math.pi - 0.05, 0.07, math.pi - 0.2):
        got, rule, P = concave_point(daemon, alpha)
        assert rule == "ying-zorin-concave"
        theta = (2 * math.pi - alpha) / 2
        s = 0.75 * min(1.0, (math.sin(alpha) / 0.1) ** 2)
        M, _ = flattened(first_stage(2, theta, {0, 2}, closed=False), s=s)
        np.testing.assert_allclose(got, (M @ P[[0, 1, 4, 3]])[2], atol=1e-11, err_msg=str(alpha))
    # at pi: the first stage (theta = pi/2); approaching it, the point converges to that
    at_pi, rule, P = concave_point(daemon, math.pi)
    first = first_stage(2, math.pi / 2, {0, 2}, closed=False) @ P[[0, 1, 4, 3]]
    np.testing.assert_allclose(at_pi, first[2], atol=1e-12)
    prev = None
    for d in (1e-2, 1e-3, 1e-4, 1e-5):
        p, _, _ = concave_point(daemon, math.pi - d)
        assert np.linalg.norm(p - at_pi) < 50 * d, (d, p, at_pi)
        if prev is not None:
            assert np.linalg.norm(p - prev) < 50 * d * 10
        prev = p
    # and across the ends of the ramp (sin alpha = 0.1) nothing jumps
    a = math.pi - math.asin(0.1)
    p1, _, _ = concave_point(daemon, a - 1e-6)
    p2, _, _ = concave_point(daemon, a + 1e-6)
    assert np.linalg.norm(p1 - p2) < 1e-3


# ---- asymmetric petals, darts away from ring position 0, level 2 --------------------------------

def test_concave_corner_of_three_uneven_triangles(daemon):
    """A concave-tagged fin of three uneven triangles (k = 3): the two crease ends enter the
    projection with different weights (sin((k-i) theta) vs sin(i theta)), which a symmetric
    k = 2 petal cannot tell apart."""
    V, T = fins_end()
    T = [t for t in T if t not in ([0, 1, 4], [0, 4, 3])]
    V += [[0.9, 0.05, 0.6], [1.1, -0.1, 0.25]]                 # 12, 13: inside the fin
    T += [[0, 1, 12], [0, 12, 13], [0, 13, 3], [1, 4, 12]]
    petals = [{"vertex": 0, "triangle": [0, 13, 3], "kind": "concave"}]
    (j1, j2), c = ours(daemon, V, T, L=2, petals=petals)
    rules = edge_rules(c)
    assert rules[(0, 12)] == rules[(0, 13)] == "ying-zorin-concave"
    P = np.array(V, dtype=float)
    u, w = P[1] - P[0], P[3] - P[0]
    alpha = math.acos(np.dot(u, w) / np.linalg.norm(u) / np.linalg.norm(w))
    theta = (2 * math.pi - alpha) / 3
    want, _ = corner_expected(P, 0, [1, 12, 13, 3], theta, flat=True)
    np.testing.assert_allclose(edge_point(j1, 0, 12), want[2], atol=1e-12)
    np.testing.assert_allclose(edge_point(j1, 0, 13), want[3], atol=1e-12)
    Q = np.array(j1["vertices"])
    oe = {tuple(sorted(e)): i for i, e in enumerate(j1["origin"]["edge_of"]) if e}
    ring = [oe[(0, 1)], oe[(0, 12)], oe[(0, 13)], oe[(0, 3)]]
    want2, _ = corner_expected(Q, 0, ring, theta, flat=True)
    np.testing.assert_allclose(edge_point(j2, 0, ring[1]), want2[2], atol=1e-12)
    np.testing.assert_allclose(edge_point(j2, 0, ring[2]), want2[3], atol=1e-12)


@pytest.mark.parametrize("s_at", [2, 4])
def test_dart_with_its_crease_elsewhere_on_the_ring_level_2(daemon, s_at):
    """dart_mesh with the fins moved to edge 0-s_at: the dart's singular edge is not the ring's
    first; level 2 is checked on the level-1 points (the dart persists around the corner)."""
    k = 5
    V, T = dart_mesh(k)
    T = T[:k] + [[0, s_at, k + 1], [0, s_at, k + 2]]
    (j1, j2), c = ours(daemon, V, T, L=2)
    ring = list(range(s_at, k + 1)) + list(range(1, s_at))        # p_0: the singular edge's end
    M, _ = flattened(first_stage(k, 2 * math.pi / k, {0}, closed=True))
    P = np.array(V, dtype=float)
    want = M @ P[[0] + ring]
    for i in range(1, k):
        np.testing.assert_allclose(edge_point(j1, 0, ring[i]), want[i + 1], atol=1e-12)
    Q = np.array(j1["vertices"])
    oe = {tuple(sorted(e)): i for i, e in enumerate(j1["origin"]["edge_of"]) if e}
    ring1 = [oe[(0, r)] for r in ring]
    want2 = M @ Q[[0] + ring1]
    for i in range(1, k):
        np.testing.assert_allclose(edge_point(j2, 0, ring1[i]), want2[i + 1], atol=1e-12)


# ---- hostile or ignored petal tags ---------------------------------------------------------------

def test_petal_tags_at_vertices_the_singular_tags_rule(daemon):
    V, T = fins_end()
    good = {"vertex": 0, "triangle": [0, 4, 3], "kind": "concave"}
    # vertex 0 on a tagged crease (0-7): it follows the crease
    r = put_tags(daemon, V, T, {"singular": [[0, 7]], "petals": [good]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/petals/0/vertex", r.text
    assert "crease" in r.json()["detail"]
    # on a tagged triangle's corner
    r = put_tags(daemon, V, T, {"singular": [[0, 1, 7]], "petals": [good]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/petals/0/vertex", r.text
    # a rule of vertex 0's own (PUT /rules) or the G1 default: the tag is kept and waits (it
    # acts again when the rule goes), as under chang-qin; a rules change is never refused for it
    s = Session(daemon)
    assert s.put_complex({"vertices": V, "simplices": T}).status_code == 200
    assert s.req("PUT", "/tags", json={"petals": [good]}).status_code == 200
    for rules in ({"nonmanifold_surface": "ying-zorin", "overrides": [{"simplex": [0], "rule": "G2"}]},
                  {"nonmanifold_surface": "ying-zorin", "overrides": [{"simplex": [0], "rule": "G1"}]},
                  {"nonmanifold_default": "G1"},
                  {"overrides": [{"simplex": [0, 1], "rule": "G1"}]}):
        r = s.req("PUT", "/rules", json=rules)
        assert r.status_code == 200, (rules, r.text)
        assert s.req("GET", "/complex").json()["tags"]["petals"] == [good]
    s.delete()


def test_many_smooth_petals_validate_quickly(daemon):
    """n fans between the non-manifold edges 0-1 and 0-2 (plus a lone triangle, so vertex 0 is
    complex), all tagged smooth, in reverse order: validation is near-linear in the tags (a walk
    per petal), so thousands of petals are checked well within a request's time."""
    n = 3000
    V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, -1, 0], [-1, -0.5, 1]]
    T = [[0, 3, 4]]
    for i in range(n):
        a = 2 * math.pi * i / n
        V.append([0.6, 0.6, 0.3 * math.cos(a) + 1e-4 * i])
        T += [[0, 1, 5 + i], [0, 5 + i, 2]]
    petals = [{"vertex": 0, "triangle": [0, 1, 5 + i], "kind": "smooth"} for i in reversed(range(n))]
    s = Session(daemon)
    assert s.put_complex({"vertices": V, "simplices": T}).status_code == 200
    r = s.req("PUT", "/tags", json={"petals": petals})
    assert r.status_code == 200, r.text[:300]
    # one left untagged: refused, naming a smooth tag's kind
    r = s.req("PUT", "/tags", json={"petals": petals[:-1]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"].endswith("/kind"), r.text[:300]
    s.delete()
