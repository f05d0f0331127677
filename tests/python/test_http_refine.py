"""POST /refine (000 Sec. 4.2, red-green): the refined control complex is conforming (the volume
and the boundary area are unchanged, no face has a hanging vertex), untouched tetrahedra stay,
the selected region reaches the requested depth, new points sit where the subdivision rules put
them (the level-1 edge points) or at midpoints, and the result subdivides."""
import itertools

import numpy as np
import pytest

from conftest import REPO
from daemon import Daemon, Session, complex_from_text

CUBE = REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt"
MIXED = REPO / "examples" / "mixed.txt"


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


def tets_of(c):
    return [t for t in c["simplices"] if len(t) == 4]


def volume_and_boundary(c):
    p = np.array(c["vertices"])
    vol, faces = 0.0, {}
    for t in tets_of(c):
        a, b, cc, d = p[t]
        vol += abs(np.dot(np.cross(b - a, cc - a), d - a)) / 6
        for f in itertools.combinations(sorted(t), 3):
            faces[f] = faces.get(f, 0) + 1
    area = sum(np.linalg.norm(np.cross(p[f[1]] - p[f[0]], p[f[2]] - p[f[0]])) / 2
               for f, n in faces.items() if n == 1)
    assert max(faces.values()) <= 2, "a face shared by more than two tetrahedra"
    return vol, area


def no_hanging_vertex(c):
    """No vertex lies at the midpoint of an edge of a simplex (the split edges are all gone)."""
    p = np.array(c["vertices"])
    edges = {tuple(sorted(e)) for s in c["simplices"] for e in itertools.combinations(s, 2)}
    mids = {tuple(np.round((p[a] + p[b]) / 2, 12)): (a, b) for a, b in edges}
    for i, q in enumerate(p):
        hit = mids.get(tuple(np.round(q, 12)))
        assert hit is None or i in hit, f"vertex {i} hangs on edge {hit}"


def test_refine_one_tetrahedron(daemon):
    body = complex_from_text(CUBE)
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    vol0, area0 = volume_and_boundary(body)
    t0 = tets_of(body)[5]
    r = s.req("POST", "/refine", json={"select": {"simplices": [t0]}, "positions": "midpoint"})
    assert r.status_code == 200, r.text
    j = r.json()
    assert j["version"] == 2 and j["refined"]["red"] == 1 and j["refined"]["green"] >= 1
    assert j["refined"]["steps"] == 1 and j["refined"]["capped"] is False, j
    c = s.req("GET", "/complex").json()
    assert len(c["vertices"]) == len(body["vertices"]) + 6
    vol, area = volume_and_boundary(c)
    assert abs(vol - vol0) < 1e-12 * vol0 and abs(area - area0) < 1e-12 * area0
    no_hanging_vertex(c)
    before = {tuple(t) for t in tets_of(body)}
    after = {tuple(t) for t in tets_of(c)}
    assert len(before & after) == len(before) - j["refined"]["red"] - j["refined"]["green"]
    assert s.level(2, format="json").status_code == 200       # it subdivides
    assert all(cl["rule"] for cl in c["classes"]["vertices"])


def test_subdivision_positions_are_level1_edge_points(daemon):
    body = complex_from_text(CUBE)
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    l1 = s.level(1, format="json").json()
    edge_point = {tuple(sorted(e)): l1["vertices"][i]
                  for i, e in enumerate(l1["origin"]["edge_of"]) if e}
    r = s.req("POST", "/refine", json={"select": {"sphere": {"center": [0, 0, 0], "radius": 0.3}}})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    p = np.array(c["vertices"])
    n0 = len(body["vertices"])
    assert len(p) > n0
    # each new point is a level-1 edge point of the complex before the refinement
    new_pts = p[n0:]
    targets = np.array(list(edge_point.values()))
    for q in new_pts:
        assert np.min(np.linalg.norm(targets - q, axis=1)) < 1e-12


@pytest.mark.parametrize("depth", [1, 2])
def test_depth(daemon, depth):
    body = complex_from_text(CUBE)
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    t0 = tets_of(body)[0]
    p0 = np.array(body["vertices"])
    v0 = abs(np.dot(np.cross(p0[t0[1]] - p0[t0[0]], p0[t0[2]] - p0[t0[0]]), p0[t0[3]] - p0[t0[0]])) / 6
    r = s.req("POST", "/refine", json={"select": {"simplices": [t0]}, "depth": depth,
                                      "positions": "midpoint"})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    p = np.array(c["vertices"])
    # red splits give 8 children of 1/8 the volume each: after `depth` steps the smallest
    # tetrahedra (inside the selected one) have 1/8^depth of its volume
    vols = [abs(np.dot(np.cross(p[t[1]] - p[t[0]], p[t[2]] - p[t[0]]), p[t[3]] - p[t[0]])) / 6
            for t in tets_of(c)]
    assert min(vols) == pytest.approx(v0 / 8 ** depth, rel=1e-9)
    vol0, area0 = volume_and_boundary(body)
    vol, area = volume_and_boundary(c)
    assert abs(vol - vol0) < 1e-12 * vol0 and abs(area - area0) < 1e-12 * area0
    no_hanging_vertex(c)


def test_box_on_mixed_complex(daemon):
    s = Session(daemon)
    body = complex_from_text(MIXED)
    body["attributes"] = {"h": [v[2] for v in body["vertices"]]}
    assert s.put_complex(body).status_code == 200
    r = s.req("POST", "/refine", json={"select": {"box": {"min": [-1, -1, -1], "max": [2, 2, 2]}},
                                      "positions": "midpoint"})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    # attributes carried to the new points (midpoints of a linear function stay on it)
    h = np.array(c["attributes"]["h"])
    np.testing.assert_allclose(h, np.array(c["vertices"])[:, 2], atol=1e-12)
    no_hanging_vertex(c)
    assert s.level(1, format="json").status_code == 200


@pytest.mark.parametrize("body,status,pointer", [
    ({}, 400, "/select"), ({"select": {}}, 400, "/select"),
    ({"select": {"simplices": [[0, 1, 2, 99999]]}}, 422, "/select/simplices/0/3"),
    ({"select": {"simplices": [[0, 1]]}}, 422, "/select/simplices/0"),
    ({"select": {"box": {"min": [1, 1, 1], "max": [0, 0, 0]}}}, 422, "/select/box"),
    ({"select": {"sphere": {"center": [0, 0, 0], "radius": 0}}}, 422, "/select/sphere/radius"),
    ({"select": {"sphere": {"center": [0, 0], "radius": 1}}}, 400, "/select/sphere/center"),
    ({"select": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}, "depth": 5}, 422, "/depth"),
    ({"select": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}, "positions": "cubic"}, 422, "/positions"),
    ({"select": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}, "colour": 1}, 400, "/colour"),
    # nothing selected: no new version of the same complex (its offsets and deltas stay)
    ({"select": {"simplices": []}}, 422, "/select"),
    ({"select": {"sphere": {"center": [50, 50, 50], "radius": 1}}}, 422, "/select"),
    ({"select": {"box": {"min": [50, 50, 50], "max": [51, 51, 51]}}, "depth": 2}, 422, "/select"),
])
def test_refine_errors(daemon, body, status, pointer):
    s = Session(daemon)
    assert s.put_complex(complex_from_text(CUBE)).status_code == 200
    r = s.req("POST", "/refine", json=body)
    assert r.status_code == status, r.text
    assert r.json()["errors"][0]["pointer"] == pointer
    assert s.req("GET").json()["version"] == 1


def test_a_face_of_a_listed_simplex_is_named_as_such(daemon):
    """An edge or a triangle of a tetrahedron is a simplex of the complex (000 Sec. 2), but the
    selection names listed simplices: the refusal says so rather than that it is not a simplex."""
    s = Session(daemon)
    body = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [3, 3, 3]],
            "simplices": [[0, 1, 2, 3], [3, 4]]}
    assert s.put_complex(body).status_code == 200
    for face in ([1, 0], [2, 1, 3]):
        r = s.req("POST", "/refine", json={"select": {"simplices": [[3, 4], face]}})
        assert r.status_code == 422, r.text
        assert r.json()["type"] == "/errors/no-such-simplex"
        err = r.json()["errors"][0]
        assert err["pointer"] == "/select/simplices/1"
        assert "face" in err["message"] and "not a simplex" not in err["message"], err
    assert s.req("GET").json()["version"] == 1


def test_refine_needs_complex(daemon):
    r = Session(daemon).req("POST", "/refine", json={"select": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}})
    assert r.status_code == 409


def pair_edges(t, p):
    """The two opposite edges of diagonal pair p of tetrahedron t (as posted), as vertex sets."""
    o = {0: ((0, 1), (2, 3)), 1: ((0, 2), (1, 3)), 2: ((0, 3), (1, 2))}[p]
    return frozenset(frozenset((t[a], t[b])) for a, b in o)


def test_refine_keeps_the_choices_of_untouched_tetrahedra(daemon):
    """DECISIONS 17: the untouched tetrahedra keep their diagonal and their stored orientation
    (even one an edit turned inside out, whose volume now says otherwise); new ones are oriented
    by their volume."""
    body = complex_from_text(CUBE)
    s = Session(daemon)
    r = s.put_complex(body)
    assert r.status_code == 200
    c0 = s.req("GET", "/complex").json()
    tets0 = {frozenset(t): (i, t) for i, t in enumerate(c0["simplices"]) if len(t) == 4}
    diag0 = {i: p for i, p in c0["diagonals"]}
    pairs0 = {k: pair_edges(t, diag0[i]) for k, (i, t) in tets0.items()}
    reor0 = {k for k, (i, t) in tets0.items() if i in set(c0["reoriented"])}
    t0 = tets_of(body)[5]
    r = s.req("POST", "/refine", json={"select": {"simplices": [t0]}, "positions": "midpoint"})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    diag = {i: p for i, p in c["diagonals"]}
    reor = set(c["reoriented"])
    p = np.array(c["vertices"])
    kept = new = 0
    for i, t in enumerate(c["simplices"]):
        if len(t) != 4:
            continue
        k = frozenset(t)
        if k in tets0 and tets0[k][1] == t:        # untouched: same vertex list
            kept += 1
            assert pair_edges(t, diag[i]) == pairs0[k], (i, t)
            assert (i in reor) == (k in reor0), (i, t)
        else:
            new += 1
            a, b, cc, d = p[t]
            assert (i in reor) == (np.dot(np.cross(b - a, cc - a), d - a) < 0), (i, t)
    assert kept and new


@pytest.mark.parametrize("case", ["cube", "mixed-attributes-edited", "tagged-surface", "offsets"])
def test_refine_from_the_cached_level_equals_refine_from_a_fresh_model(daemon, case):
    """POST /refine places its first step's points from the session's level 1 when it is cached
    (and holds no detail offsets), else from a model it makes: both give the same refined
    complex, bit for bit (GET /complex), for solids, attributes after an edit, tags and
    rules, and a session with level-1 offsets (which must not move the new points)."""
    if case == "cube":
        body, sel = complex_from_text(CUBE), {"sphere": {"center": [0, 0, 0], "radius": 0.3}}
    elif case == "tagged-surface":
        V = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.3], [0, 0, -1]]
        T = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
        body, sel = {"vertices": V, "simplices": T}, {"simplices": [[0, 2, 4]]}
    else:
        body = complex_from_text(MIXED)
        body["attributes"] = {"h": [v[2] * v[0] for v in body["vertices"]],
                              "uv": [[v[0], v[1] * v[1]] for v in body["vertices"]]}
        sel = {"box": {"min": [-1, -1, -1], "max": [2, 2, 2]}}

    def prepare(s, offsets):
        assert s.put_complex(body).status_code == 200
        if case == "tagged-surface":
            assert s.req("PUT", "/tags", json={"singular": [[0, 2]], "sharpness": [
                {"simplex": [2, 4], "value": 1.5}]}).status_code == 200
            assert s.req("PUT", "/rules", json={"crease_method": "chaikin"}).status_code == 200
        if case != "cube":
            v = s.req("GET").json()["version"]
            r = s.req("PATCH", "/control-points", headers={"If-Match": f'"{v}"'},
                      json={"moves": [{"index": 1, "position": [0.31, -0.2, 0.45]}],
                            "attributes": {"h": [{"index": 2, "value": 7.5}]} if "attributes" in case else {}})
            assert r.status_code == 200, r.text
        if offsets:   # every level-1 edge point gets an offset
            l1 = s.level(1, format="json").json()
            moves = [{"index": i, "level": 1, "position": [x + 0.01, y - 0.02, z + 0.03]}
                     for i, ((x, y, z), e) in enumerate(zip(l1["vertices"], l1["origin"]["edge_of"]))
                     if e]
            v = s.req("GET").json()["version"]
            r = s.req("PATCH", "/control-points", headers={"If-Match": f'"{v}"'}, json={"moves": moves})
            assert r.status_code == 200, r.text

    # the first with level 1 (and 2) cached; the second computes no level (a PUT and level-0
    # edits), and has no offsets: the new points are S p's, whatever offsets the first holds
    cached, fresh = Session(daemon), Session(daemon)
    prepare(cached, case == "offsets")
    assert cached.level(2, format="json").status_code == 200
    prepare(fresh, False)
    got = []
    for s in (cached, fresh):
        r = s.req("POST", "/refine", json={"select": sel})
        assert r.status_code == 200, r.text
        c = s.req("GET", "/complex").json()
        got.append((c["vertices"], c.get("attributes"), c["simplices"]))
    assert got[0] == got[1]
    assert len(got[0][0]) > len(body["vertices"])


@pytest.mark.parametrize("order", [[0, 1, 2, 3], [0, 1, 3, 2]])   # positive, and reoriented
@pytest.mark.parametrize("pair", [0, 1, 2])
def test_red_split_cuts_the_octahedron_along_the_diagonal(daemon, order, pair):
    """docs/SPEC: a red tetrahedron becomes 4 corners and its octahedron split into 4 tetrahedra
    along its diagonal — pair k of the posted tetrahedron's edges (01,23), (02,13), (03,12). The
    4 inner tetrahedra share one edge: the segment between the midpoints of the pair's edges."""
    V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    t = order
    s = Session(daemon)
    r = s.put_complex({"vertices": V, "simplices": [t], "diagonals": [[0, pair]]})
    assert r.status_code == 200, r.text
    r = s.req("POST", "/refine", json={"select": {"simplices": [t]}, "positions": "midpoint"})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    p = np.array(c["vertices"])
    count = {}
    for tet in tets_of(c):
        for e in itertools.combinations(sorted(tet), 2):
            count[e] = count.get(e, 0) + 1
    axis = [e for e, n in count.items() if n == 4]
    assert len(axis) == 1, count
    got = {tuple(np.round(p[v], 12)) for v in axis[0]}
    ends = {0: ((0, 1), (2, 3)), 1: ((0, 2), (1, 3)), 2: ((0, 3), (1, 2))}[pair]
    want = {tuple(np.round((p[t[a]] + p[t[b]]) / 2, 12)) for a, b in ends}
    assert got == want


def kuhn_block(n):
    """n^3 unit cubes, each cut into the 6 tetrahedra around its main diagonal."""
    vid = lambda x, y, z: (x * (n + 1) + y) * (n + 1) + z
    V = [[x, y, z] for x in range(n + 1) for y in range(n + 1) for z in range(n + 1)]
    T = []
    for x, y, z in itertools.product(range(n), repeat=3):
        for a, b, c in itertools.permutations(range(3)):
            e = [[0, 0, 0], [0, 0, 0], [0, 0, 0]]
            e[0][a] = 1
            e[1][a] = e[1][b] = 1
            path = [[0, 0, 0], e[0], e[1], [1, 1, 1]]
            T.append([vid(x + u, y + v, z + w) for u, v, w in path])
    return {"vertices": V, "simplices": T}


def level1_positive(s):
    """Every tetrahedron of the session's level 1 is positively oriented (none inverted)."""
    j = s.level(1, format="json").json()
    p = np.array(j["vertices"])
    for t in j["cells"]["tetrahedra"]:
        a, b, cc, d = p[t]
        assert np.dot(np.cross(b - a, cc - a), d - a) > 0, t


def min_quality(c):
    """The smallest 6 V / (longest edge)^3 over the tetrahedra."""
    p = np.array(c["vertices"])
    q = []
    for t in tets_of(c):
        a, b, cc, d = p[t]
        L = max(np.linalg.norm(p[x] - p[y]) for x, y in itertools.combinations(t, 2))
        q.append(abs(np.dot(np.cross(b - a, cc - a), d - a)) / L ** 3)
    return min(q)


@pytest.mark.parametrize("place", ["midpoint", "subdivision"])
def test_deep_refinement_keeps_the_cells_shape(daemon, place):
    """Red-green refinement (000 Sec. 4.2 follows the usual red-green rules): a green cell is a
    closure, never split again; when a later step would split it, its parent is split red in
    its step instead. So the cells' shape does not degrade with depth: on a 2x2x2 block of cubes
    of 6 tetrahedra, one tetrahedron refined to depth 4 keeps a worst shape within a small factor
    of depth 1's (without taking green cells back it fell about fourfold per step, 64x by depth
    4), the result stays conforming and its level 1 has no inverted tetrahedron."""
    body = kuhn_block(2)
    t0 = body["simplices"][0]
    worst = {}
    for depth in (1, 4):
        s = Session(daemon)
        assert s.put_complex(body).status_code == 200
        r = s.req("POST", "/refine", json={"select": {"simplices": [t0]}, "depth": depth,
                                          "positions": place})
        assert r.status_code == 200, r.text
        # depth steps, and more when a step is made again to take its green cells back
        assert r.json()["refined"]["steps"] >= depth and not r.json()["refined"]["capped"], r.json()
        c = s.req("GET", "/complex").json()
        worst[depth] = min_quality(c)
        if place == "midpoint":
            vol0, area0 = volume_and_boundary(body)
            vol, area = volume_and_boundary(c)
            assert abs(vol - vol0) < 1e-12 * vol0 and abs(area - area0) < 1e-12 * area0
            no_hanging_vertex(c)
        level1_positive(s)
        s.delete()
    assert worst[4] > 0.2 * worst[1], worst


@pytest.mark.parametrize("select", [{"box": {"min": [0.3, -1, -1], "max": [0.7, 1, 1]}},
                                    {"sphere": {"center": [0.4, 0, 0], "radius": 0.5}},
                                    {"simplices": [[0, 1]]}])
def test_depth_follows_the_children_of_a_region(daemon, select):
    """docs/SERVICE.md: `depth` repeats the refinement on the children of the selection — a box
    or a sphere selects by centroid once, and its simplices' children are refined on, wherever
    their own centroids fall. A segment selected, depth 4: 16 equal segments."""
    s = Session(daemon)
    assert s.put_complex({"vertices": [[0, 0, 0], [1, 0, 0]], "simplices": [[0, 1]]}).status_code == 200
    r = s.req("POST", "/refine", json={"select": select, "depth": 4, "positions": "midpoint"})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    p = np.array(c["vertices"])
    lengths = sorted(np.linalg.norm(p[a] - p[b]) for a, b in c["simplices"])
    assert lengths == pytest.approx([1 / 16] * 16, abs=1e-15)


def five_tet_grid(n, jitter, seed):
    """n^3 jittered cubes, each cut into 5 tetrahedra (alternating by parity)."""
    rng = np.random.default_rng(seed)
    vid = lambda i, j, k: (i * (n + 1) + j) * (n + 1) + k
    V = np.array([[i, j, k] for i in range(n + 1) for j in range(n + 1) for k in range(n + 1)], float)
    V += rng.uniform(-jitter, jitter, V.shape)
    A = [[1, 2, 4, 7], [0, 1, 2, 4], [3, 1, 2, 7], [5, 1, 4, 7], [6, 2, 4, 7]]
    B = [[0, 3, 5, 6], [1, 0, 3, 5], [2, 0, 3, 6], [4, 0, 5, 6], [7, 3, 5, 6]]
    T = []
    for i, j, k in itertools.product(range(n), repeat=3):
        c = [vid(i + (b & 1), j + (b >> 1 & 1), k + (b >> 2 & 1)) for b in range(8)]
        T += [[c[x] for x in t] for t in (A if (i + j + k) % 2 == 0 else B)]
    return {"vertices": V.tolist(), "simplices": T}


def test_a_placement_that_folds_the_complex_is_refused(daemon):
    """New points placed by the subdivision rules (the level-1 edge points of each step's complex)
    move off the midpoints; on an irregular complex refined deep, that can turn tetrahedra inside
    out against the midpoints' placement, which keeps every child's orientation. Such a
    placement is a 422 at /positions naming the step (nothing changed); midpoints refine the same
    selection, and every tetrahedron of a taken refinement keeps its orientation."""
    body = five_tet_grid(2, 0.2, 2)
    t = [9, 3, 1, 13]
    assert t in body["simplices"]
    for depth, place, status in [(1, "subdivision", 200), (3, "subdivision", 422),
                                 (3, "midpoint", 200)]:
        s = Session(daemon)
        assert s.put_complex(body).status_code == 200
        r = s.req("POST", "/refine", json={"select": {"simplices": [t]}, "depth": depth,
                                          "positions": place})
        assert r.status_code == status, r.text
        if status == 422:
            assert r.json()["errors"][0]["pointer"] == "/positions"
            assert s.req("GET").json()["version"] == 1
        else:
            level1_positive(s)
        s.delete()


def edges_of(simplices):
    return {tuple(sorted((t[a], t[b]))) for t in simplices for a in range(len(t))
            for b in range(a + 1, len(t))}


@pytest.mark.parametrize("limit,depth,requested,name", [
    ({"--max-simplices": 20000}, 3, 48 * 8 ** 3, "max_simplices"),   # step 3: 8 x step 2's
    ({"--max-simplices": 20000}, 2, 48 * 8 ** 2, None),               # within it
    ({"--max-vertices": None}, 2, None, "max_vertices"),
])
def test_refine_limits_are_counted_before_the_result(daemon, limit, depth, requested, name):
    """POST /refine of every tetrahedron of a 2^3 Kuhn block (48) to a depth: the result's size
    is counted before it is made (the marked tetrahedra's red children alone at once), so a step
    past --max-simplices or --max-vertices is a 413 naming that limit with the count, and the
    session is as it was. Every simplex split red splits every edge: step 2 has the vertices
    and the edges of step 1's complex, counted here from a refinement of depth 1."""
    box = {"select": {"box": {"min": [-1, -1, -1], "max": [3, 3, 3]}}, "positions": "midpoint"}
    if name == "max_vertices":
        one = Session(daemon)
        assert one.put_complex(kuhn_block(2)).status_code == 200
        assert one.req("POST", "/refine", json=box).status_code == 200
        c = one.req("GET", "/complex").json()
        requested = len(c["vertices"]) + len(edges_of(c["simplices"]))
        limit = {"--max-vertices": requested - 1}
    d = Daemon(*[str(x) for kv in limit.items() for x in kv])
    try:
        s = Session(d)
        assert s.put_complex(kuhn_block(2)).status_code == 200
        r = s.req("POST", "/refine", json=dict(box, depth=depth))
        if name is None:
            assert r.status_code == 200, r.text
            assert len(s.req("GET", "/complex").json()["simplices"]) == requested
            return
        assert r.status_code == 413, r.text
        j = r.json()
        assert (j["limit_name"], j["limit"], j["requested"]) == \
            (name, next(iter(limit.values())), requested), j
        assert s.req("GET").json()["version"] == 1
    finally:
        d.stop()


@pytest.mark.parametrize("depth,place", [(2, "midpoint"), (4, "midpoint"), (1, "subdivision"),
                                         (3, "subdivision")])
def test_a_refinement_into_degenerate_cells_is_refused_at_the_selection(daemon, depth, place):
    """PUT /complex refuses an edge shorter than 1e-12 of the bounding box's diagonal (DECISIONS
    7). A unit tetrahedron next to a point 4e11 away passes (the bound is 0.4); refined to depth
    2 its edges are 0.25 (depth 1 keeps 0.5; subdivision placement pulls a lone tetrahedron's new
    points inwards, so its depth 1 is under the bound too). Such a refinement is refused as the
    request's doing: a 422 invalid-complex at /select, not at a /simplices this request does
    not have, and the session is unchanged."""
    V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [4e11, 0, 0]]
    s = Session(daemon)
    assert s.put_complex({"vertices": V, "simplices": [[0, 1, 2, 3], [4]]}).status_code == 200
    before = s.req("GET", "/complex").content
    r = s.req("POST", "/refine", json={"select": {"simplices": [[0, 1, 2, 3]]}, "depth": depth,
                                      "positions": place})
    assert r.status_code == 422, r.text
    j = r.json()
    assert j["type"] == "/errors/invalid-complex", j
    assert [e["pointer"] for e in j["errors"]] == ["/select"], j
    assert "degenerate" in j["detail"] and "refined complex" in j["detail"], j
    assert s.req("GET").json()["version"] == 1
    assert s.req("GET", "/complex").content == before
    # one step with midpoints stays above the bound
    r = s.req("POST", "/refine", json={"select": {"simplices": [[0, 1, 2, 3]]},
                                      "positions": "midpoint"})
    assert r.status_code == 200, r.text
    s.delete()


def test_a_refinement_past_the_step_cap_says_so(daemon):
    """At most 64 steps are made (a step made again to take back its green cells counts again):
    one tetrahedron of a TetGen ball refined to depth 4 can need more. Past the cap the green
    cells left are split as they are; the answer says so ("capped") and the result is still
    conforming. The ball's tetrahedra are tried in turn until one needs the cap."""
    from meshes import icosphere
    v, f = icosphere(2)
    s = Session(daemon)
    assert s.put_complex({"vertices": v, "simplices": f, "fill": [{"surface": f}]}).status_code == 200
    ball = s.req("GET", "/complex").json()
    body = {"vertices": ball["vertices"], "simplices": ball["simplices"],
            "diagonals": ball["diagonals"], "reoriented": ball["reoriented"]}
    tets = [t for t in ball["simplices"] if len(t) == 4]
    capped = None
    for t in tets[::5]:
        t_s = Session(daemon)
        assert t_s.put_complex(body).status_code == 200
        r = t_s.req("POST", "/refine", json={"select": {"simplices": [t]}, "depth": 4,
                                              "positions": "midpoint"})
        assert r.status_code == 200, r.text
        done = r.json()["refined"]
        assert 4 <= done["steps"] <= 64 and (not done["capped"] or done["steps"] == 64), done
        if done["capped"]:
            capped = t_s
            break
        t_s.delete()
    assert capped is not None, "no tetrahedron of the ball needed more than 64 steps"
    assert done["steps"] == 64
    no_hanging_vertex(capped.req("GET", "/complex").json())


def test_a_refinement_past_the_limit_is_refused_before_any_step():
    """The selection's own red descendants bound the result from below: a tetrahedron split red
    to depth d ends as 8^d tetrahedra, every other simplex as at least one. One tetrahedron of
    the 48 of a 2^3 Kuhn block to depth 4 makes at least 47 + 8^4 = 4143: past --max-simplices
    4000 it is refused at once with that count (the steps themselves would have found out at the
    fourth, after the three before were made, with the green cells around counted too)."""
    d = Daemon("--max-simplices", "4000")
    try:
        s = Session(d)
        body = kuhn_block(2)
        assert s.put_complex(body).status_code == 200
        t = s.req("GET", "/complex").json()["simplices"][20]
        r = s.req("POST", "/refine", json={"select": {"simplices": [t]}, "depth": 4,
                                           "positions": "midpoint"})
        assert r.status_code == 413, r.text
        j = r.json()
        assert (j["limit_name"], j["limit"], j["requested"]) == ("max_simplices", 4000, 47 + 8 ** 4)
        assert "at least 4143" in j["detail"]
        assert s.req("GET").json()["version"] == 1
        # within the bound: made (depth 3: 47 + 512 at least, with the green cells around)
        r = s.req("POST", "/refine", json={"select": {"simplices": [t]}, "depth": 3,
                                           "positions": "midpoint"})
        assert r.status_code == 200, r.text
    finally:
        d.stop()
