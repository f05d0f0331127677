"""Control points at arbitrary levels (004 Sec. 5.2; docs/API.md "Live edits"; DECISIONS 29-30,
35, 39), checked independently of the edited session's own output.

The expected level l is p^l = S_{l-1} p^{l-1} + d^l, summed here (scipy's CSR product sums each
row in stored order from zero, as the daemon's row_sum does, so the comparison is bit for bit):
S comes from a *fresh* session holding the same control points, tags and rules and no offsets,
and d^l = position - (S_{l-1} p^{l-1})_i is taken here, after the coarser moves, as the docs say.
Cases: offsets at levels 1, 2 and 3 on one point's lineage, several moves of one PATCH at mixed
levels in no sorted order, on a solid, a surface, a curve and a non-manifold complex, a coarser
edit afterwards, PUT /rules and /tags (offsets kept), POST /refine and PUT /complex (dropped and
counted), GET /complex posted back, export/import, an embedded model following the offsets, a
PATCH with one bad move changing nothing, and restarts on SQLite and on a real redis-server."""
import json
import re
import struct

import numpy as np
import pytest
from scipy.sparse import csr_matrix

from conftest import REPO
from daemon import Daemon, Session, complex_from_text


CUBE = REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt"
MIXED = REPO / "examples" / "mixed.txt"
TOP = 3


def surface():
    V = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.3], [0, 0, -1]]
    T = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    return {"vertices": [[float(x) for x in v] for v in V], "simplices": T}


def curve():
    V = [[i, 0.3 * np.sin(i), 0.1 * i * i] for i in range(6)] + [[2, 1, 0], [2, 2, 0.5], [2, 3, 0]]
    S = [[i, i + 1] for i in range(5)] + [[2, 6], [6, 7], [7, 8]]
    return {"vertices": [[float(x) for x in v] for v in V], "simplices": S}


MESHES = {"solid": lambda: complex_from_text(CUBE), "surface": surface, "curve": curve,
          "mixed": lambda: complex_from_text(MIXED)}


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


# ---- helpers ----------------------------------------------------------------------------------

def new_session(daemon, body, rules=None, tags=None):
    s = Session(daemon)
    r = s.put_complex(body)
    assert r.status_code == 200, r.text
    if rules is not None:
        assert s.req("PUT", "/rules", json=rules).status_code == 200
    if tags is not None:
        assert s.req("PUT", "/tags", json=tags).status_code == 200
    return s


def version_of(s):
    return s.req("GET").json()["version"]


def patch(s, moves, version=None):
    v = version_of(s) if version is None else version
    r = s.req("PATCH", "/control-points", json={"moves": moves}, headers={"If-Match": f'"{v}"'})
    assert r.status_code == 200, r.text
    return r.json()


def xyz(s, level):
    r = s.level(level, format="json")
    assert r.status_code == 200, r.text
    return np.array(r.json()["vertices"], dtype=float)


def matrix(s, to):
    r = s.req("GET", f"/matrices/{to}", params={"from": to - 1, "format": "json"})
    assert r.status_code == 200, r.text
    j = r.json()
    return csr_matrix((np.array(j["val"], float), np.array(j["col"], np.int64),
                       np.array(j["rowptr"], np.int64)), shape=(j["rows"], j["cols"]))


def details_of(s):
    return {(e["level"], e["index"]): np.array(e["offset"], float)
            for e in s.req("GET", "/complex").json()["details"]}


class Model:
    """The expected session: control points, the offsets (level, index) -> d, and the matrices of
    a fresh session with the same control data (no offsets)."""

    def __init__(self, daemon, body, rules=None, tags=None, top=TOP):
        self.daemon, self.body, self.rules, self.tags, self.top = daemon, body, rules, tags, top
        self.p0 = np.array(body["vertices"], dtype=float)
        self.d = {}
        # the tetrahedra stored reversed at the first PUT: a level-0 move may turn one inside
        # out, and a fresh session of the moved points must keep the session's numbering
        first = new_session(daemon, body)
        self.reoriented = first.req("GET", "/complex").json()["reoriented"]
        first.delete()
        self.refresh()

    def control(self, **more):
        return dict(self.body, vertices=self.p0.tolist(), reoriented=self.reoriented, **more)

    def refresh(self):
        """The matrices again, from a fresh session of the current control points."""
        fresh = new_session(self.daemon, self.control(), self.rules, self.tags)
        self.S = {l: matrix(fresh, l) for l in range(1, self.top + 1)}
        fresh.delete()

    def levels(self):
        p = [self.p0.copy()]
        for l in range(1, self.top + 1):
            q = self.S[l] @ p[-1]
            for (lv, i), d in self.d.items():
                if lv == l:
                    q[i] = q[i] + d
            p.append(q)
        return p

    def apply(self, moves):
        """A PATCH's moves as the docs define them: level 0 first, then each finer level's
        offsets taken against S p^(l-1) after the coarser ones."""
        for m in moves:
            if m.get("level", 0) == 0:
                self.p0[m["index"]] = m["position"]
        if any(m.get("level", 0) == 0 for m in moves):
            self.refresh()
        for l in range(1, self.top + 1):
            p = self.levels()
            s = self.S[l] @ p[l - 1]
            for m in moves:
                if m.get("level", 0) == l:
                    self.d[(l, m["index"])] = np.array(m["position"], float) - s[m["index"]]


def check(s, model):
    """The session's offsets and levels 0-3 against the sums made here (to a few ulps: the
    daemon sums a row in its own order, a vertex point's own entry first, where the CSR lists
    columns ascending), and bit for bit against a fresh session built with the same control
    points, rules, tags and the offsets computed here (DECISIONS 29: an edited level is the level
    of a fresh build)."""
    want = model.levels()
    got = details_of(s)
    assert sorted(got) == sorted(model.d)
    tol = 1e-13 * max(1.0, float(np.abs(model.p0).max()))
    for k, d in model.d.items():
        np.testing.assert_allclose(got[k], d, rtol=0, atol=tol, err_msg=f"offset {k}")
    for l in range(TOP + 1):
        np.testing.assert_allclose(xyz(s, l), want[l], rtol=0, atol=tol, err_msg=f"level {l}")
    fresh = new_session(model.daemon, model.control(details=[
        {"level": l, "index": i, "offset": got[(l, i)].tolist()} for (l, i) in sorted(got)]),
                        model.rules, model.tags)
    assert level_bytes(fresh) == level_bytes(s)
    fresh.delete()
    return want


def unversioned(data, fmt):
    """A level's bytes without the version it names (JSON "version", the GLB's JSON chunk): a
    fresh session has another version."""
    if fmt == "json":
        return re.sub(rb'"version":\d+', b"", data)
    n = struct.unpack_from("<I", data, 12)[0]
    chunk = data[20:20 + n].rstrip(b" ")           # (padded to 4 bytes)
    return re.sub(rb'"version":\s*"?\d+"?', b"", chunk), data[20 + n:]


def level_bytes(s, top=TOP, versioned=False):
    out = {}
    for l in range(1, top + 1):
        for f in ("glb", "json"):
            r = s.level(l, format=f)
            assert r.status_code == 200, r.text
            out[(l, f)] = r.content if versioned else unversioned(r.content, f)
    return out


def shifted(p, k, h=0.02):
    return [float(p[0] + h * (1 + k % 3)), float(p[1] - h * (k % 2)), float(p[2] + 0.5 * h)]


def lineage_moves(s, body):
    """One PATCH, levels in no sorted order: a vertex's point at levels 3, 1 and 2 (its lineage:
    a vertex point keeps its index), a level-1 edge point at level 3 and 1, a level-0 move of a
    neighbour, and another level-2 point."""
    n0 = len(body["vertices"])
    p = {l: xyz(s, l) for l in range(1, TOP + 1)}
    i = 2                            # a vertex point: the same index at every level
    j = n0 + 1                       # an edge point of level 1, kept at levels 2 and 3
    k2 = len(p[2]) - 3               # a point new at level 2
    return [{"index": i, "level": 3, "position": shifted(p[3][i], 0, 0.01)},
            {"index": j, "level": 1, "position": shifted(p[1][j], 1)},
            {"index": 1, "position": shifted(body["vertices"][1], 2, 0.03)},
            {"index": i, "level": 1, "position": shifted(p[1][i], 3)},
            {"index": k2, "level": 2, "position": shifted(p[2][k2], 4)},
            {"index": j, "level": 3, "position": shifted(p[3][j], 5, 0.01)},
            {"index": i, "level": 2, "position": shifted(p[2][i], 6)}]


# ---- the tests --------------------------------------------------------------------------------

@pytest.mark.parametrize("mesh", sorted(MESHES))
def test_mixed_level_moves_against_fresh_matrices(daemon, mesh):
    body = MESHES[mesh]()
    s = new_session(daemon, body)
    model = Model(daemon, body)
    moves = lineage_moves(s, body)
    patch(s, moves)
    model.apply(moves)
    check(s, model)
    # every move ends exactly at its position (each finer one is within a factor 2 of where it was)
    for m in moves:
        np.testing.assert_array_equal(xyz(s, m.get("level", 0))[m["index"]], m["position"])
    # a coarser edit afterwards: two control points and a level-1 point; offsets at 2 and 3 kept
    p1 = xyz(s, 1)
    later = [{"index": 2, "level": 1, "position": shifted(p1[2], 7)},
             {"index": 0, "position": shifted(model.p0[0], 8, 0.04)},
             {"index": 3, "position": shifted(model.p0[3], 9, -0.03)}]
    patch(s, later)
    model.apply(later)
    check(s, model)
    # a move back to where a point was restores the bytes (edits recompute)
    before = level_bytes(s)
    undo = [{"index": 3, "position": shifted(model.p0[3], 0, 0.05)}]
    patch(s, undo)
    patch(s, [{"index": 3, "position": model.p0[3].tolist()}])
    assert level_bytes(s) == before
    # GET /complex posted back whole-as-listed, and an export imported: the same bytes
    c = s.req("GET", "/complex").json()
    again = new_session(daemon, {k: c[k] for k in ("vertices", "simplices", "attributes",
                                                   "diagonals", "reoriented", "details")})
    assert level_bytes(again) == before
    doc = s.req("GET", "/export").json()
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 201, r.text
    imp = Session.__new__(Session)
    imp.d, imp.http, imp.id, imp.token = daemon, s.http, r.json()["id"], r.json()["token"]
    imp.base, imp.auth = f"{daemon.url}/v1/sessions/{imp.id}", {"Authorization": f"Bearer {imp.token}"}
    assert level_bytes(imp) == before
    for x in (s, again, imp):
        x.delete()


RULES = {"solid": ({"surface_weights": "loop"}, {"singular": "edge"}),
         "surface": ({"surface_weights": "loop"}, {"singular": [[0, 2]]}),
         "curve": ({"nonmanifold_default": "G1"}, {"singular": [[2]]}),
         "mixed": ({"surface_weights": "loop", "nonmanifold_default": "G1"}, {"singular": [[1, 2]]})}


@pytest.mark.parametrize("mesh", sorted(MESHES))
def test_rules_and_tags_keep_offsets_refine_and_complex_drop_them(daemon, mesh):
    body = MESHES[mesh]()
    rules, tags = RULES[mesh]
    if tags["singular"] == "edge":   # an edge of the first tetrahedron
        tags = {"singular": [body["simplices"][0][:2]]}
    s = new_session(daemon, body)
    model = Model(daemon, body)
    moves = lineage_moves(s, body)
    patch(s, moves)
    model.apply(moves)
    check(s, model)
    r = s.req("PUT", "/rules", json=rules)
    assert r.status_code == 200 and "details_dropped" not in r.json(), r.text
    model.rules = rules
    model.refresh()
    check(s, model)
    r = s.req("PUT", "/tags", json=tags)
    assert r.status_code == 200 and "details_dropped" not in r.json(), r.text
    model.tags = tags
    model.refresh()
    check(s, model)
    # an edit under the new rules and tags, at levels 2 and 0
    p2 = xyz(s, 2)
    later = [{"index": 5, "level": 2, "position": shifted(p2[5], 1)},
             {"index": 4, "position": shifted(model.p0[4], 2, 0.02)}]
    patch(s, later)
    model.apply(later)
    check(s, model)
    n = len(model.d)
    c = s.req("GET", "/complex").json()
    r = s.req("POST", "/refine", json={"select": {"simplices": [c["simplices"][0]]}})
    assert r.status_code == 200, r.text
    assert r.json()["details_dropped"] == n
    assert s.req("GET", "/complex").json()["details"] == []
    t = new_session(daemon, body)
    patch(t, lineage_moves(t, body))
    n = len(details_of(t))
    r = t.put_complex(body)
    assert r.status_code == 200 and r.json()["details_dropped"] == n, r.text
    assert details_of(t) == {}
    # a PUT /complex that carries them back drops none
    patch(t, lineage_moves(t, body))
    c = t.req("GET", "/complex").json()
    r = t.put_complex({"vertices": c["vertices"], "simplices": c["simplices"], "details": c["details"]})
    assert r.status_code == 200 and "details_dropped" not in r.json(), r.text
    s.delete()
    t.delete()


def test_an_embedded_model_follows_offsets(daemon):
    """A model bound to level 2 of a solid, its vertices placed at level-2 points and at the
    centroids of level-2 tetrahedra: after moves at levels 0-3 each stays that combination of the
    level's points as computed here (a level-3 offset moves none of them)."""
    body = complex_from_text(CUBE)
    s = new_session(daemon, body)
    j2 = s.level(2, format="json").json()
    p2 = np.array(j2["vertices"], float)
    tets = j2["cells"]["tetrahedra"][::37][:40]
    pts = list(range(0, len(p2), 97))
    V = [p2[i].tolist() for i in pts] + [p2[t].mean(axis=0).tolist() for t in tets]
    r = s.req("PUT", "/embedded/m", json={"vertices": V, "level": 2, "outside": "nearest"})
    assert r.status_code == 200, r.text
    model = Model(daemon, body)

    def expected(p):
        return np.array([p[i] for i in pts] + [p[t].mean(axis=0) for t in tets])

    def got():
        r = s.req("GET", "/embedded/m", params={"format": "json"})
        assert r.status_code == 200, r.text
        return np.array(r.json()["vertices"], float)

    np.testing.assert_allclose(got(), expected(p2), rtol=0, atol=1e-12)
    moves = lineage_moves(s, body) + [{"index": pts[3], "level": 2,
                                       "position": shifted(p2[pts[3]], 1, 0.03)}]
    patch(s, moves)
    model.apply(moves)
    want = check(s, model)
    assert np.abs(expected(want[2]) - expected(p2)).max() > 1e-3
    np.testing.assert_allclose(got(), expected(want[2]), rtol=0, atol=1e-12)
    v = version_of(s)
    p3 = xyz(s, 3)
    patch(s, [{"index": 50, "level": 3, "position": shifted(p3[50], 2)}], v)
    np.testing.assert_allclose(got(), expected(want[2]), rtol=0, atol=1e-12)
    r = s.req("GET", "/embedded/m/delta", params={"since": v, "format": "json"})
    assert r.status_code == 200 and r.json()["indices"] == [], r.text
    s.delete()


def bad_body(moves):
    return json.dumps({"moves": moves})


@pytest.mark.parametrize("mesh", ["solid", "mixed"])
def test_one_bad_move_changes_nothing(daemon, mesh):
    body = MESHES[mesh]()
    s = new_session(daemon, body)
    patch(s, lineage_moves(s, body))
    v = version_of(s)
    before = (level_bytes(s, versioned=True), s.req("GET", "/complex").content, s.req("GET", "/export").content)
    p = {l: xyz(s, l) for l in range(1, TOP + 1)}
    good = [{"index": 4, "level": 3, "position": shifted(p[3][4], 1)},
            {"index": 3, "level": 1, "position": shifted(p[1][3], 2)},
            {"index": 0, "position": shifted(body["vertices"][0], 3, 0.01)},
            {"index": 5, "level": 2, "position": shifted(p[2][5], 4)}]
    n3 = len(p[3])
    a, b = [x for x in body["simplices"][0] if x != 0][:2]
    far = int(np.argmax(p[2][:, 0]))
    assert p[2][far, 0] > 0.1
    bad = {
        "index out of range at 3": ({"index": n3, "level": 3, "position": [0, 0, 0]}, None),
        "index out of range at 5": ({"index": 10 ** 7, "level": 5, "position": [0, 0, 0]}, None),
        "negative index": ({"index": -1, "level": 2, "position": [0, 0, 0]}, None),
        "level 13": ({"index": 0, "level": 13, "position": [0, 0, 0]}, None),
        "level -1": ({"index": 0, "level": -1, "position": [0, 0, 0]}, None),
        "level 1.5": ({"index": 0, "level": 1.5, "position": [0, 0, 0]}, None),
        "level string": ({"index": 0, "level": "2", "position": [0, 0, 0]}, None),
        "twice at a level": ({"index": 3, "level": 1, "position": [0, 0, 0]}, None),
        "position beyond 1e15": ({"index": 7, "level": 2, "position": [0, 2e15, 0]}, None),
        # a position within 1e15 whose offset is beyond it
        "offset beyond 1e15": ({"index": far, "level": 2, "position": [-1e15, 0, 0]}, None),
        "overflowing number": (None, '{"index": 7, "level": 2, "position": [1e999, 0, 0]}'),
        "NaN": (None, '{"index": 7, "level": 2, "position": [NaN, 0, 0]}'),
        "Infinity": (None, '{"index": 7, "level": 1, "position": [0, -Infinity, 0]}'),
        # a vertex of the first simplex onto another of its vertices
        "degenerate": ({"index": a, "position": body["vertices"][b]}, None),
        "two components": ({"index": 7, "level": 2, "position": [0, 0]}, None),
    }
    for name, (move, raw) in bad.items():
        for at in (0, 2, 4):
            text = bad_body(good[:at] + [move] + good[at:]) if move is not None else \
                bad_body(good[:at] + ["@"] + good[at:]).replace('"@"', raw)
            r = s.req("PATCH", "/control-points", data=text,
                      headers={"If-Match": f'"{v}"', "Content-Type": "application/json"})
            assert r.status_code in (400, 422), (name, at, r.status_code, r.text)
            if move is not None and name != "twice at a level":   # (that names the second)
                assert r.json()["errors"][0]["pointer"].startswith(f"/moves/{at}/"), (name, at, r.text)
            assert version_of(s) == v, name
    after = (level_bytes(s, versioned=True), s.req("GET", "/complex").content, s.req("GET", "/export").content)
    assert after[1] == before[1] and after[2] == before[2]
    assert after[0] == before[0]
    # the good moves alone still apply
    patch(s, good, v)
    s.delete()


# ---- restarts on the durable stores -------------------------------------------------------------

# each durable store in turn, and a daemon on it: test_persist.py's
from test_persist import store, store_daemon  # noqa: E402,F401  (store is a fixture)


def on(daemon, s):
    t = Session.__new__(Session)
    t.d, t.http, t.id, t.token, t.auth = daemon, s.http, s.id, s.token, s.auth
    t.base = f"{daemon.url}/v1/sessions/{s.id}"
    return t


def test_offsets_survive_restarts(store):
    """Offsets made by PATCHes (the journal), kept through PUT /rules (a snapshot), more PATCHes
    past the 256 edits folded into a snapshot, then kill -9 and a new daemon: levels and offsets
    bit-identical to before, and to the levels computed here."""
    body = complex_from_text(MIXED)
    d = store_daemon(store)
    try:
        s = new_session(d, body)
        model = Model(d, body)
        moves = lineage_moves(s, body)
        patch(s, moves)
        model.apply(moves)
        r = s.req("PUT", "/rules", json={"surface_weights": "loop"})
        assert r.status_code == 200
        model.rules = {"surface_weights": "loop"}
        model.refresh()
        p2 = xyz(s, 2)
        v = version_of(s)
        for k in range(260):              # past a fold of the journal into a snapshot
            lv = k % 4
            i = (k * 7) % (len(body["vertices"]) if lv == 0 else 18)
            base = model.p0[i] if lv == 0 else p2[i]
            m = [{"index": i, "level": lv, "position": shifted(base, k, 0.001 * (1 + k % 5))}]
            v = patch(s, m, v)["version"]
            model.apply(m)
        want = check(s, model)
        before = level_bytes(s, versioned=True)
        details = s.req("GET", "/complex").json()["details"]
        assert len(details) > 10
    finally:
        d.proc.kill()
        d.proc.wait()
    for _ in range(2):
        d = store_daemon(store)
        try:
            t = on(d, s)
            assert version_of(t) == v
            assert level_bytes(t, versioned=True) == before
            assert t.req("GET", "/complex").json()["details"] == details
            tol = 1e-13 * max(1.0, float(np.abs(model.p0).max()))
            for l in range(TOP + 1):
                np.testing.assert_allclose(xyz(t, l), want[l], rtol=0, atol=tol)
        finally:
            d.proc.kill()
            d.proc.wait()
    # one more edit after a restart, then a restart again
    d = store_daemon(store)
    try:
        t = on(d, s)
        model.daemon = d
        p3 = xyz(t, 3)
        m = [{"index": 9, "level": 3, "position": shifted(p3[9], 1)},
             {"index": 6, "position": shifted(model.p0[6], 2, 0.05)}]
        v = patch(t, m, v)["version"]
        model.apply(m)
        check(t, model)
        before = level_bytes(t, versioned=True)
    finally:
        d.proc.kill()
        d.proc.wait()
    d = store_daemon(store)
    try:
        t = on(d, s)
        assert version_of(t) == v and level_bytes(t, versioned=True) == before
    finally:
        assert d.stop() == 0


def test_a_rebuilding_edit_refuses_a_bad_finer_move_like_any_edit(daemon):
    """An edit that moves a point a Ying-Zorin corner's angle is measured on becomes a new model,
    whose offsets are taken there: a finer move of it whose offset is beyond 1e15 is the same 422
    `out-of-range` at /moves/k/position/c as in an edit in place (it was an `invalid-complex`
    pointing nowhere), and nothing changes."""
    V = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2],
         [-.5, .8, 0], [-.5, .8, 1], [-.5, .8, 2], [-.5, -.8, 0], [-.5, -.8, 1], [-.5, -.8, 2]]
    T = []
    for a in (3, 6, 9):
        T += [[0, 1, a + 1], [0, a + 1, a], [1, 2, a + 2], [1, a + 2, a + 1]]
    s = new_session(daemon, {"vertices": V, "simplices": T}, {"nonmanifold_surface": "ying-zorin"},
                    {"petals": [{"vertex": 0, "triangle": [0, 4, 3], "kind": "convex"}]})
    p = {l: xyz(s, l) for l in (1, 2, 3)}
    patch(s, [{"index": 7, "level": 2, "position": (p[2][7] + 0.01).tolist()},
              {"index": 4, "level": 3, "position": (p[3][4] + 0.01).tolist()}])
    v = version_of(s)
    before = (level_bytes(s, versioned=True), s.req("GET", "/complex").content)
    far = int(np.argmax(p[2][:, 0]))
    assert p[2][far, 0] > 0.1
    corner = {"index": 3, "position": [1.2, 0.7, -0.1]}     # the corner's angle changes
    fine = {"index": 5, "level": 1, "position": (p[1][5] + 0.01).tolist()}
    bad = {"index": far, "level": 2, "position": [-1e15, 0, 0]}
    for moves, k in (([bad, corner], 0), ([corner, fine, bad], 2), ([fine, bad, corner], 1)):
        r = s.req("PATCH", "/control-points", json={"moves": moves}, headers={"If-Match": f'"{v}"'})
        assert r.status_code == 422 and r.json()["type"] == "/errors/out-of-range", r.text
        assert r.json()["errors"][0]["pointer"] == f"/moves/{k}/position/0", r.text
        assert version_of(s) == v
        assert (level_bytes(s, versioned=True), s.req("GET", "/complex").content) == before
    # without the bad move it is a new model with the offsets of both
    patch(s, [corner, fine], v)
    assert sorted(details_of(s)) == [(1, 5), (2, 7), (3, 4)]
    np.testing.assert_array_equal(xyz(s, 1)[5], fine["position"])
    s.delete()


def test_a_refused_edit_leaves_no_offset_behind(tmp_path):
    """The store fills up under edits that add offsets at levels 1-3 and change existing ones:
    the edit it refuses (503) is undone in place — no new offset left (not even a zero one), the
    changed ones back to their bytes, the levels as before — and a restart gives the last
    acknowledged edit's offsets and levels."""
    db = tmp_path / "e.db"
    d = Daemon("--store", f"sqlite:{db}", env={"SUBDIVD_SQLITE_MAX_PAGES": "8"})
    body = complex_from_text(MIXED)
    try:
        s = new_session(d, body)
        v = version_of(s)
        p = {l: xyz(s, l) for l in range(1, TOP + 1)}
        acked = None
        for k in range(len(p[3]) - 3):
            l = 1 + k % 2
            i = 3 + (5 * k) % (len(p[l]) - 3)
            moves = [{"index": i, "level": l, "position": shifted(p[l][i], k, 1e-3)},
                     {"index": 2, "level": 3, "position": shifted(p[3][2], k, 1e-4)},
                     {"index": 3 + k, "level": 3, "position": shifted(p[3][3 + k], k, 1e-4)},
                     {"index": (k * 3) % len(body["vertices"]),
                      "position": shifted(body["vertices"][(k * 3) % len(body["vertices"])], k, 1e-3)}]
            before = (level_bytes(s, versioned=True), s.req("GET", "/complex").content)
            r = s.req("PATCH", "/control-points", json={"moves": moves}, headers={"If-Match": f'"{v}"'})
            if r.status_code != 200:
                break
            v, acked = r.json()["version"], before
        assert r.status_code == 503 and r.json()["type"] == "/errors/store-unavailable", r.text
        assert acked, "no edit fitted"
        assert (3, 3 + k) not in details_of(s)        # the refused edit's new offset
        assert version_of(s) == v
        after = (level_bytes(s, versioned=True), s.req("GET", "/complex").content)
        assert after[1] == before[1]
        assert after[0] == before[0]
    finally:
        d.proc.kill()
        d.proc.wait()
    d = Daemon("--store", f"sqlite:{db}")
    try:
        t = on(d, s)
        assert version_of(t) == v
        assert (level_bytes(t, versioned=True), t.req("GET", "/complex").content) == before
    finally:
        assert d.stop() == 0


def yz_session(daemon):
    V = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2],
         [-.5, .8, 0], [-.5, .8, 1], [-.5, .8, 2], [-.5, -.8, 0], [-.5, -.8, 1], [-.5, -.8, 2]]
    T = []
    for a in (3, 6, 9):
        T += [[0, 1, a + 1], [0, a + 1, a], [1, 2, a + 2], [1, a + 2, a + 1]]
    return new_session(daemon, {"vertices": V, "simplices": T}, {"nonmanifold_surface": "ying-zorin"},
                       {"petals": [{"vertex": 0, "triangle": [0, 4, 3], "kind": "convex"}]})


def test_a_rebuilding_edit_with_offsets_survives_a_restart(store):
    """Journal entries of edits that became new models (a Ying-Zorin corner's angle changed),
    with finer moves in them at levels 1-3 on one lineage: replayed after kill -9, the levels and
    offsets are those before, and those of a fresh session of the same control data."""
    d = store_daemon(store)
    try:
        s = yz_session(d)
        v = version_of(s)
        for k in range(3):
            p = {l: xyz(s, l) for l in (1, 2, 3)}
            moves = [{"index": 4, "level": 3, "position": shifted(p[3][4], k, 0.003)},
                     {"index": 3, "position": [1.0 + 0.1 * k, 0.2 * k, -0.05 * k]},
                     {"index": 4, "level": 1, "position": shifted(p[1][4], k)},
                     {"index": 20 + k, "level": 2, "position": shifted(p[2][20 + k], k)}]
            r = patch(s, moves, v)
            v = r["version"]
            for m in moves:   # each ends at its position (to the last bit within a factor 2)
                np.testing.assert_allclose(xyz(s, m.get("level", 0))[m["index"]], m["position"],
                                           rtol=0, atol=1e-15)
        before = (level_bytes(s, versioned=True), s.req("GET", "/complex").content)
        c = s.req("GET", "/complex").json()
        assert len(c["details"]) == 5
    finally:
        d.proc.kill()
        d.proc.wait()
    d = store_daemon(store)
    try:
        t = on(d, s)
        assert version_of(t) == v
        assert (level_bytes(t, versioned=True), t.req("GET", "/complex").content) == before
        fresh = new_session(d, {k: c[k] for k in ("vertices", "simplices", "reoriented", "details")},
                            c["rules"], c["tags"])
        assert level_bytes(fresh) == {k: unversioned(b, k[1]) for k, b in before[0].items()}
    finally:
        assert d.stop() == 0


def top_glb(s, level):
    r = s.level(level)
    assert r.status_code == 200, r.text
    return r.content


def test_a_replay_over_limits_or_memory_is_not_damage(tmp_path):
    """A journal entry of a move at level 3 or 4 computes that level when it is replayed. A
    daemon restarted with a lower --max-cells cannot, and one whose memory budget other sessions
    hold cannot now: neither is damaged data. Under a lower limit the answer is a 503
    `store-corrupt` that says so (not 'damaged data; DELETE it'), the holder may still delete it,
    and a daemon with the old limits loads it bit for bit; with the budget in use it is a 503
    `memory-budget` with Retry-After, and it loads once the memory is free."""
    db = tmp_path / "s.db"
    body = complex_from_text(CUBE)
    d = Daemon("--store", f"sqlite:{db}")
    try:
        ss, want = [], []
        for k, level in enumerate((3, 4, 4)):
            s = new_session(d, body)
            p = xyz(s, 3)                    # a vertex point keeps its index at level 4
            patch(s, [{"index": 5 + k, "level": level, "position": shifted(p[5 + k], k)}])
            ss.append(s)
            want.append(top_glb(s, level))
    finally:
        d.proc.kill()
        d.proc.wait()
    a, b, c = ss
    d = Daemon("--store", f"sqlite:{db}", "--max-cells", "50000")   # level 3 has 130 000
    try:
        r = on(d, a).req("GET")
        assert r.status_code == 503 and r.json()["type"] == "/errors/store-corrupt", r.text
        assert "damaged" not in r.json()["detail"] and "limits" in r.json()["detail"], r.text
        assert any("cannot be replayed" in x and "50000" in x for x in d.log_lines)
    finally:
        assert d.stop() == 0
    # the budget holds one session at level 4 (about 55 MB resident, 73 MB to build) but not two
    d = Daemon("--store", f"sqlite:{db}", "--max-memory", "120000000", "--keep-memory", "0")
    try:
        assert on(d, b).req("GET").status_code == 200
        r = on(d, c).req("GET")
        assert r.status_code == 503 and r.json()["type"] == "/errors/memory-budget", r.text
        assert int(r.headers["Retry-After"]) > 0 and "DELETE" not in r.json()["detail"], r.text
        assert on(d, b).delete().status_code == 204
        assert top_glb(on(d, c), 4) == want[2]
        assert top_glb(on(d, a), 3) == want[0]
    finally:
        assert d.stop() == 0
    d = Daemon("--store", f"sqlite:{db}", "--max-cells", "50000")
    try:
        assert on(d, c).delete().status_code == 204      # its holder lets it go unloaded
    finally:
        assert d.stop() == 0
    d = Daemon("--store", f"sqlite:{db}")
    try:
        assert on(d, c).req("GET").status_code == 404
        assert top_glb(on(d, a), 3) == want[0]
    finally:
        assert d.stop() == 0


def test_a_detail_past_32_bit_indices_names_the_levels_true_count(daemon):
    """A level-12 offset of one tetrahedron: the level has (n+1)(n+2)(n+3)/6 points with
    n = 2^12 (the lattice points of a tetrahedron cut 2^12 times along each edge), more than
    32-bit indices name; an index past 2^32 - 1 is refused and the detail gives the true count."""
    n = 2 ** 12
    points = (n + 1) * (n + 2) * (n + 3) // 6
    assert points > 2 ** 32
    s = Session(daemon)
    body = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 2, 3]],
            "details": [{"level": 12, "index": 2 ** 32, "offset": [0, 0, 0]}]}
    r = s.put_complex(body)
    assert r.status_code == 422, r.text
    p = r.json()
    assert p["errors"][0]["pointer"] == "/details/0/index"
    assert f"level 12 has {points} points" in p["detail"], p["detail"]
    body["details"][0]["index"] = points
    r = s.put_complex(body)
    assert r.status_code == 422 and f"level 12 has {points} points" in r.json()["detail"]


def test_a_repeated_detail_names_both_entries_in_the_document(daemon):
    """A point given two offsets is a 422 repeated-index at the later entry, and the earlier one
    is an error of its own with its pointer, so that an import's problem points at both in its
    document (the message said "also /details/0", a place the import's body does not have)."""
    tet = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 2, 3]],
           "details": [{"level": 1, "index": 2, "offset": [0, 0, 0.1]},
                       {"level": 2, "index": 2, "offset": [0, 0, 0.1]},
                       {"level": 1, "index": 2, "offset": [0, 0.1, 0]}]}
    s = Session(daemon)
    r = s.put_complex(tet)
    assert r.status_code == 422 and r.json()["type"] == "/errors/repeated-index", r.text
    assert [e["pointer"] for e in r.json()["errors"]] == ["/details/2/index", "/details/0/index"]
    doc = {"format": "subdivd-session", "format_version": 1, "version": 3, "complex": tet,
           "tags": {"singular": []}, "rules": {}, "embedded": {}}
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 422 and r.json()["type"] == "/errors/repeated-index", r.text
    assert [e["pointer"] for e in r.json()["errors"]] == ["/import/complex/details/2/index",
                                                         "/import/complex/details/0/index"]
    assert "/details/" not in r.json()["detail"]
