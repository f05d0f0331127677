"""Sessions that survive (docs/API.md "Persistence and sessions", docs/SERVICE.md "Persistence"):
exact export/import, the stored orientation of tetrahedra, the SQLite store across kill -9, and
what the daemon does when the store fails.

Expected level bytes never come from the persistence path itself: they are fetched from the live
session before the save, or computed by a second daemon with the in-memory store to which the
same acknowledged requests were sent."""
import hashlib
import http.client
import random
import sqlite3
import subprocess
import threading
import time

import pytest
import requests

from daemon import SLOW, SUBDIVD, Daemon, Session, create_from
from redisd import REDIS_SERVER, RedisServer
from test_fill import surface

TETS = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [1.2, -0.3, 0.4],
                     [2, 2, 0]],
        "simplices": [[0, 1, 2, 3], [1, 2, 3, 4], [0, 1, 3, 5], [4, 6]],
        "attributes": {"t": [1, 2, 3, 4, 5, 6, 7], "uv": [[0, 0], [1, 0], [0, 1], [0, 0], [1, 1],
                                                          [2, 0], [0, 2]]}}


def adopt(daemon, http, created):
    """A Session object for an answer of POST /v1/sessions made by hand."""
    s = Session.__new__(Session)
    s.d, s.http = daemon, http
    s.id, s.token = created["id"], created["token"]
    s.base = f"{daemon.url}/v1/sessions/{s.id}"
    s.auth = {"Authorization": f"Bearer {s.token}"}
    return s


def on(daemon, s):
    """The same session (id, token) addressed on another daemon."""
    t = Session.__new__(Session)
    t.d, t.http, t.id, t.token, t.auth = daemon, requests.Session(), s.id, s.token, s.auth
    t.base = f"{daemon.url}/v1/sessions/{s.id}"
    return t


def edit(s, moves, version):
    r = s.req("PATCH", "/control-points", json={"moves": moves}, headers={"If-Match": f'"{version}"'})
    assert r.status_code == 200, r.text
    return r.json()["version"]


def levels(s, top=3, fmt="glb"):
    out = {}
    for level in range(1, top + 1):
        r = s.level(level, format=fmt)
        assert r.status_code == 200, r.text
        out[level] = r.content
    return out


def signed_volume(v, t):
    a, b, c, d = (v[i] for i in t)
    u = [b[k] - a[k] for k in range(3)]
    w = [c[k] - a[k] for k in range(3)]
    z = [d[k] - a[k] for k in range(3)]
    return (u[0] * (w[1] * z[2] - w[2] * z[1]) - u[1] * (w[0] * z[2] - w[2] * z[0]) +
            u[2] * (w[0] * z[1] - w[1] * z[0]))


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    d.stop()


def shaped_session(daemon):
    """A session with everything the document carries: attributes, rules with an override,
    tags, an edit that turns tetrahedron 1 inside out, and a detail offset at level 1."""
    s = Session(daemon)
    assert s.put_complex(TETS).status_code == 200
    r = s.req("PUT", "/rules", json={"surface_weights": "loop",
                                     "overrides": [{"simplex": [4], "rule": "G1"}]})
    assert r.status_code == 200, r.text
    r = s.req("PUT", "/tags", json={"singular": [[0, 1]]})
    assert r.status_code == 200, r.text
    v = edit(s, [{"index": 4, "position": [-0.2, -0.2, -0.2]}], r.json()["version"])
    assert signed_volume([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-0.2, -0.2, -0.2]],
                         [1, 2, 3, 4]) < 0   # the edit did invert it
    v = edit(s, [{"level": 1, "index": 3, "position": [0.1, 0.2, 0.3]}], v)
    return s, v


def test_export_import_is_bit_identical(daemon):
    s, v = shaped_session(daemon)
    want = {f: levels(s, 3, f) for f in ("glb", "json", "vtu")}
    ex = s.req("GET", "/export")
    assert ex.status_code == 200 and ex.headers["ETag"] == f'"{v}"'
    doc = ex.json()
    assert doc["format"] == "subdivd-session" and doc["version"] == v
    assert doc["complex"]["details"] and doc["rules"]["overrides"] and doc["tags"]["singular"]
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 201, r.text
    t = adopt(daemon, s.http, r.json())
    assert t.id != s.id and t.token != s.token and r.json()["version"] == v
    assert t.req("GET", "").json()["version"] == v
    for f in want:
        assert levels(t, 3, f) == want[f], f
    again = t.req("GET", "/export")
    assert again.content == ex.content       # a fixed point: export(import(doc)) == doc
    # the version continues from the exported one
    assert edit(t, [{"index": 0, "position": [0.01, 0, 0]}], v) == v + 1


def test_saved_complex_reposted_keeps_levels_after_inversion(daemon):
    """GET /complex with "diagonals" and "reoriented", posted again, gives the same level bytes:
    a TetGen ball whose edit turns tetrahedra inside out (before, level 2 came out renumbered)."""
    v, f = surface("icosphere", 2)
    s = Session(daemon)
    r = s.put_complex({"vertices": v, "fill": [{"surface": f, "max_volume": 0.05}]})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    # push a surface vertex through the ball: the tetrahedra at it turn inside out
    k = 0
    target = [-0.9 * x for x in c["vertices"][k]]
    ver = edit(s, [{"index": k, "position": target}], r.json()["version"])
    c = s.req("GET", "/complex").json()
    inverted = [i for i, t in enumerate(c["simplices"]) if len(t) == 4 and k in t and
                (signed_volume(c["vertices"], t) < 0) != (i in c["reoriented"])]
    assert inverted, "the edit should have turned some tetrahedron inside out"
    want = levels(s, 2, "json")
    t = Session(daemon)
    body = {key: c[key] for key in ("vertices", "simplices", "diagonals", "reoriented")}
    assert t.put_complex(body).status_code == 200
    assert levels(t, 2, "json") == {L: b.replace(b'"version":%d' % ver, b'"version":1')
                                    for L, b in want.items()}
    # without the stored orientation the points are renumbered (what the member is for)
    u = Session(daemon)
    del body["reoriented"]
    assert u.put_complex(body).status_code == 200
    assert levels(u, 2, "json")[2] != levels(t, 2, "json")[2]


def test_reoriented_is_checked(daemon):
    s = Session(daemon)
    base = {"vertices": TETS["vertices"], "simplices": TETS["simplices"]}
    for bad, status, ptr in [([9], 422, "/reoriented/0"), ([3], 422, "/reoriented/0"),
                             ([0, 0], 422, "/reoriented/1"), (["x"], 400, "/reoriented/0"),
                             ({}, 400, "/reoriented")]:
        r = s.put_complex(dict(base, reoriented=bad))
        assert r.status_code == status, (bad, r.text)
        assert r.json()["errors"][0]["pointer"] == ptr, (bad, r.text)


def test_import_errors_point_into_the_document(daemon):
    s = Session(daemon)
    s.put_complex(TETS)
    doc = s.req("GET", "/export").json()
    post = lambda d: requests.post(daemon.url + "/v1/sessions", json={"import": d})
    for change, status, ptr in [
            (lambda d: d.update(format="other"), 422, "/import/format"),
            (lambda d: d.update(format_version=9), 422, "/import/format_version"),
            (lambda d: d.pop("version"), 400, "/import/version"),
            (lambda d: d["complex"]["simplices"][0].__setitem__(0, 99), 422,
             "/import/complex/simplices/0/0"),
            (lambda d: d["rules"].update(solid_scheme="cubic"), 422, "/import/rules/solid_scheme"),
            (lambda d: d.update(extra=1), 400, "/import/extra"),
            (lambda d: d.update(version=2 ** 52 + 1), 422, "/import/version"),
            (lambda d: d.update(embedded={"m": {}}), 400, "/import/embedded/m/vertices")]:
        d = __import__("copy").deepcopy(doc)
        change(d)
        r = post(d)
        assert r.status_code == status, r.text
        assert r.json()["errors"][0]["pointer"] == ptr, r.text
    # an empty session (rules only) round-trips too
    e = Session(daemon)
    assert e.req("PUT", "/rules", json={"solid_scheme": "averaged"}).status_code == 200
    ed = e.req("GET", "/export").json()
    assert ed["complex"] is None
    r = post(ed)
    assert r.status_code == 201, r.text
    t = adopt(daemon, requests.Session(), r.json())
    assert t.req("GET", "/export").json() == ed


# ---- the durable stores --------------------------------------------------------------------------

def kill9(d):
    d.proc.kill()
    d.proc.wait()


def store_daemon(path, *flags, env=None):
    """A daemon on a store: a path is an SQLite file, a RedisServer its redis."""
    spec = path.url if isinstance(path, RedisServer) else f"sqlite:{path}"
    return Daemon("--store", spec, *flags, env=env)


@pytest.fixture(params=["sqlite", "redis"])
def store(request, tmp_path):
    """Each durable store in turn: an SQLite file, or a redis-server of its own."""
    if request.param == "sqlite":
        yield tmp_path / "s.db"
        return
    if not REDIS_SERVER:
        pytest.skip("redis-server is not installed (tools/packages.txt lists it)")
    r = RedisServer(tmp_path).start()
    yield r
    r.stop()


def test_restart_brings_sessions_back(store):
    db = store
    d = store_daemon(db)
    try:
        s, v = shaped_session(d)
        empty = Session(d)
        want = {f: levels(s, 3, f) for f in ("glb", "json")}
        gone = Session(d)
        gone.put_complex(TETS)
        assert gone.delete().status_code == 204
    finally:
        kill9(d)
    d = store_daemon(db)
    try:
        t = on(d, s)
        # before it is loaded: a wrong or missing token loads nothing and is 401
        wrong = t.req("GET", "", headers={"Authorization": "Bearer " + "x" * 43})
        assert wrong.status_code == 401
        assert requests.get(t.base).status_code == 401
        r = t.req("GET", "")
        assert r.status_code == 200, r.text
        assert r.json()["version"] == v
        for f in want:
            assert levels(t, 3, f) == want[f], f
        wrong = t.req("GET", "", headers={"Authorization": "Bearer " + "x" * 43})
        assert wrong.status_code == 401
        assert on(d, empty).req("GET", "").status_code == 200
        assert on(d, gone).req("GET", "").status_code == 404
        # the delta history did not survive: a since= before the restart is 410
        assert t.req("GET", "/levels/2/delta", params={"since": v - 1}).status_code == 410
        assert edit(t, [{"index": 0, "position": [0.02, 0, 0]}], v) == v + 1
    finally:
        d.stop()


def test_no_delta_reaches_back_across_a_restart(store):
    """docs/SERVICE.md "Live edits": the delta history is not stored, so after a restart a delta
    since a version before it is 410 (refetch), also for a level the replay of the journal
    computed itself (a move at a finer level computes the levels up to it first), and the same
    for an embedded model's delta. Since the restored version and later, deltas work again."""
    d = store_daemon(store)
    try:
        s = Session(d)
        assert s.put_complex(TETS).status_code == 200
        emb = {"vertices": [[0.3, 0.2, 0.2], [0.2, 0.3, 0.25], [0.25, 0.2, 0.3]], "level": 2,
               "outside": "fixed"}
        assert s.req("PUT", "/embedded/m", json=emb).status_code == 200
        v = s.req("GET").json()["version"]
        p2 = s.level(2, format="json").json()["vertices"]
        # journal entries: a control-point move and a level-2 move (which computes level 2)
        v1 = edit(s, [{"index": 4, "position": [1.1, 1, 1]}], v)
        v2 = edit(s, [{"index": 7, "level": 2, "position": [c + 0.01 for c in p2[7]]}], v1)
        for since in (v, v1):
            assert s.req("GET", "/levels/2/delta", params={"since": since}).status_code == 200
            assert s.req("GET", "/embedded/m/delta", params={"since": since}).status_code == 200
        want = s.level(2).content
    finally:
        kill9(d)
    d = store_daemon(store)
    try:
        t = on(d, s)
        assert t.req("GET").json()["version"] == v2
        for since in (v, v1):
            for path in ("/levels/2/delta", "/embedded/m/delta"):
                r = t.req("GET", path, params={"since": since})
                assert r.status_code == 410, (path, since, r.text)
                assert r.json()["type"].endswith("/delta-unavailable")
        assert t.level(2).content == want
        r = t.req("GET", "/levels/2/delta", params={"since": v2, "format": "json"})
        assert r.status_code == 200 and r.json()["indices"] == []
        v3 = edit(t, [{"index": 4, "position": [1.05, 1, 1]}], v2)
        r = t.req("GET", "/levels/2/delta", params={"since": v2, "format": "json"})
        assert r.status_code == 200 and r.json()["version"] == v3 and r.json()["indices"]
    finally:
        d.stop()


def test_an_import_at_the_largest_version_restores_after_changes(tmp_path):
    """An import takes a version up to 2^52 (docs/API.md); the changes after it take the
    version past what an import takes, and the stored session still restores after a restart
    (the store's snapshots are read whatever version the daemon wrote)."""
    db = tmp_path / "v.db"
    d = store_daemon(db)
    try:
        doc = {"format": "subdivd-session", "format_version": 1, "version": 2 ** 52,
               "complex": {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "simplices": [[0, 1, 2]]}}
        r = requests.post(d.url + "/v1/sessions", json={"import": doc})
        assert r.status_code == 201, r.text
        s = adopt(d, requests.Session(), r.json())
        for w in ("loop", "warren", "loop"):   # a snapshot per change of rules
            assert s.req("PUT", "/rules", json={"surface_weights": w}).status_code == 200
        want = s.level(2, format="json").json()["vertices"]
    finally:
        kill9(d)
    d = store_daemon(db)
    try:
        t = on(d, s)
        r = t.req("GET", "")
        assert r.status_code == 200, r.text
        assert r.json()["version"] == 2 ** 52 + 3
        assert t.level(2, format="json").json()["vertices"] == want
        # its export is past what an import takes (docs/API.md says so)
        r = requests.post(d.url + "/v1/sessions", json={"import": t.req("GET", "/export").json()})
        assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/import/version", r.text
    finally:
        d.stop()


def test_one_daemon_per_sqlite_file(tmp_path):
    """Only a shared store (redis) tells a daemon of another's changes: a second daemon on the same
    SQLite file would serve its own stale copies, so it is refused at start (exit 1, the reason on
    stderr); the file is free again once the first has gone, even by kill -9."""
    db = tmp_path / "one.db"
    d = store_daemon(db)
    try:
        s = Session(d)
        assert s.put_complex(TETS).status_code == 200
        p = subprocess.run([str(SUBDIVD), "--port", "0", "--store", f"sqlite:{db}"],
                           capture_output=True, text=True, timeout=30)
        assert p.returncode == 1, (p.returncode, p.stdout, p.stderr)
        assert "in use by another daemon" in p.stderr, p.stderr
    finally:
        kill9(d)
    d = store_daemon(db)
    try:
        assert on(d, s).req("GET", "/complex").json()["vertices"] == TETS["vertices"]
    finally:
        d.stop()


def test_a_changed_ttl_is_stored(store):
    """PATCH /v1/sessions/{id} {"ttl_s"} changes the stored record too: after a restart the
    session keeps its new TTL (it expires after 2 s of idleness, not the 600 it was created
    with), and one lengthened from 2 s outlives its old TTL."""
    d = store_daemon(store)
    try:
        short = Session(d, ttl_s=600)
        assert short.put_complex(TETS).status_code == 200
        assert short.req("PATCH", json={"ttl_s": 2}).json()["ttl_s"] == 2
        long = Session(d, ttl_s=2)
        assert long.put_complex(TETS).status_code == 200
        assert long.req("PATCH", json={"ttl_s": 600}).json()["ttl_s"] == 600
    finally:
        kill9(d)
    d = store_daemon(store)
    try:
        time.sleep(4.5)     # past 2 s and its stored slack (1 s)
        assert on(d, short).req("GET").status_code == 404
        assert on(d, long).req("GET").status_code == 200
        assert on(d, long).req("GET", "/complex").json()["vertices"] == TETS["vertices"]
    finally:
        d.stop()


def test_an_expired_session_is_not_brought_back(store):
    """docs/API.md: an expired session is a 404. The store keeps a session a little past its TTL
    (the slack of its touches, docs/SERVICE.md "Persistence"); a request in that window does not
    load it back, on the daemon that held it nor after a restart. A session used within its TTL
    comes back (after a restart, and after its resident copy left memory to make room)."""
    d = store_daemon(store)
    try:
        gone = Session(d, ttl_s=2)
        assert gone.put_complex(TETS).status_code == 200
        kept = Session(d, ttl_s=60)
        assert kept.put_complex(TETS).status_code == 200
        time.sleep(3.2)                     # past gone's TTL, within its stored slack (1 s)
        assert gone.req("GET").status_code == 404
        assert kept.req("GET").status_code == 200
        late = Session(d, ttl_s=2)
        assert late.put_complex(TETS).status_code == 200
    finally:
        kill9(d)
    time.sleep(3.2)
    d = store_daemon(store)
    try:
        assert on(d, late).req("GET").status_code == 404
        assert on(d, kept).req("GET").status_code == 200
    finally:
        d.stop()
    d = store_daemon(store, "--max-sessions", "1")
    try:   # kept leaves memory for another session after a read; it comes back on use
        t = on(d, kept)
        assert t.req("GET").status_code == 200
        other = Session(d)
        assert t.req("GET").status_code == 200

        def get_other():   # t's session is in use until its request's end, which the daemon
            for _ in range(30):   # reaches just after the answer: "retry in a few seconds"
                r = other.req("GET")
                if r.status_code != 429:
                    return r.status_code
                time.sleep(0.1)
            return r.status_code
        assert get_other() == 200
    finally:
        d.stop()


def reference_level(daemon, complex_body, moves_list, level=2):
    """Level bytes of a fresh in-memory session given the same complex and edits."""
    s = Session(daemon)
    r = s.put_complex(complex_body)
    assert r.status_code == 200
    v = r.json()["version"]
    for moves in moves_list:
        v = edit(s, moves, v)
    out = s.level(level).content
    s.delete()
    return out, v


def test_kill_during_a_stream_of_edits_loses_nothing_acknowledged(store, daemon):
    """Three clients edit their own sessions without pause; the daemon is killed (-9) in the
    middle. After the restart, each session is at its last acknowledged version (or one later:
    an edit stored whose answer was lost with the daemon), with exactly the levels the
    acknowledged edits give on a daemon that never stopped."""
    db = store
    d = store_daemon(db)
    v0, f0 = surface("icosphere", 1)
    body = {"vertices": v0, "fill": [{"surface": f0}]}
    sessions = []
    for _ in range(3):
        s = Session(d)
        r = s.put_complex(body)
        assert r.status_code == 200, r.text
        sessions.append((s, r.json()["version"]))
    cx = sessions[0][0].req("GET", "/complex").json()
    saved = {k: cx[k] for k in ("vertices", "simplices", "diagonals", "reoriented")}
    nv = len(cx["vertices"])
    acked = [[] for _ in sessions]    # the moves of every acknowledged edit, in order
    sent = [None] * len(sessions)     # the edit in flight
    stop = threading.Event()

    def client(i):
        s, v = sessions[i]
        rnd = random.Random(i)
        http = requests.Session()
        while not stop.is_set():
            moves = [{"index": rnd.randrange(nv),
                      "position": [rnd.uniform(-1, 1), rnd.uniform(-1, 1), rnd.uniform(-1, 1)]}]
            sent[i] = moves
            try:
                r = http.patch(s.base + "/control-points", json={"moves": moves}, timeout=10,
                               headers=dict(s.auth, **{"If-Match": f'"{v}"'}))
            except requests.RequestException:
                return
            if r.status_code != 200:
                return
            v = r.json()["version"]
            acked[i].append(moves)

    threads = [threading.Thread(target=client, args=(i,)) for i in range(len(sessions))]
    for t in threads:
        t.start()
    time.sleep(1.5 * SLOW)
    kill9(d)
    stop.set()
    for t in threads:
        t.join(10)
    assert all(len(a) > 10 for a in acked), [len(a) for a in acked]
    d = store_daemon(db)
    try:
        for i, (s, v) in enumerate(sessions):
            t = on(d, s)
            got = t.req("GET", "")
            assert got.status_code == 200, got.text
            stored = got.json()["version"]
            n = len(acked[i])
            assert stored in (v + n, v + n + 1), (stored, v, n)
            moves = acked[i] + ([sent[i]] if stored == v + n + 1 else [])
            want, _ = reference_level(daemon, saved, moves)
            assert t.level(2).content == want
    finally:
        d.stop()


def test_a_damaged_journal_entry_is_refused_not_replayed(tmp_path):
    db = tmp_path / "c.db"
    d = store_daemon(db)
    try:
        s = Session(d)
        v = s.put_complex(TETS).json()["version"]
        for i in range(3):
            v = edit(s, [{"index": 4, "position": [1, 1, 1 + 0.1 * i]}], v)
        other = Session(d)
        other.put_complex(TETS)
    finally:
        d.stop()
    con = sqlite3.connect(db)
    con.execute("UPDATE journal SET entry = substr(entry, 1, 10) WHERE id = ? AND version = ?",
                (s.id, v - 1))   # truncated, its checksum no longer matches
    con.commit()
    con.close()
    d = store_daemon(db)
    try:
        r = on(d, s).req("GET", "")
        assert r.status_code == 503 and r.json()["type"] == "/errors/store-corrupt", r.text
        assert "sqlite" not in r.json()["detail"]      # where the file is: for the log only
        assert on(d, other).req("GET", "").status_code == 200   # the others are served
        assert any("store-corrupt" in l and "version %d" % (v - 1) in l for l in d.log_lines)
        assert "DELETE it" in r.json()["detail"]
        # its holder may still delete it (the record and token are whole); nobody else may
        stranger = requests.delete(on(d, s).base, headers={"Authorization": "Bearer " + "x" * 43})
        assert stranger.status_code == 401, stranger.text
        assert on(d, s).req("DELETE").status_code == 204
        assert on(d, s).req("GET", "").status_code == 404
        assert on(d, other).req("GET", "").status_code == 200
    finally:
        d.stop()
    con = sqlite3.connect(db)
    assert con.execute("SELECT count(*) FROM sessions WHERE id = ?", (s.id,)).fetchone() == (0,)
    assert con.execute("SELECT count(*) FROM journal WHERE id = ?", (s.id,)).fetchone() == (0,)
    con.close()


def test_a_damaged_session_can_be_deleted_on_redis(tmp_path):
    """The same on redis: a journal entry that is not one (LSET over it) makes the session
    503 store-corrupt; its holder's DELETE removes every key of it, a stranger's is a 401."""
    if not REDIS_SERVER:
        pytest.skip("redis-server is not installed (tools/packages.txt lists it)")
    red = RedisServer(tmp_path).start()
    try:
        d = store_daemon(red)
        try:
            s = Session(d)
            v = s.put_complex(TETS).json()["version"]
            edit(s, [{"index": 4, "position": [1, 1, 1.5]}], v)
        finally:
            kill9(d)
        assert red.command("LSET", f"subdivd:j:{{{s.id}}}", 0, "garbage").startswith(b"+OK")
        d = store_daemon(red)
        try:
            r = on(d, s).req("GET", "")
            assert r.status_code == 503 and r.json()["type"] == "/errors/store-corrupt", r.text
            stranger = requests.delete(on(d, s).base, headers={"Authorization": "Bearer " + "x" * 43})
            assert stranger.status_code == 401, stranger.text
            assert on(d, s).req("DELETE").status_code == 204
            assert on(d, s).req("GET", "").status_code == 404
        finally:
            d.stop()
        for key in (f"subdivd:s:{{{s.id}}}", f"subdivd:snap:{{{s.id}}}", f"subdivd:j:{{{s.id}}}"):
            assert red.command("EXISTS", key) == b":0\r\n", key
    finally:
        red.stop()


def test_a_full_disk_refuses_writes_and_loses_nothing(tmp_path):
    """The file may grow by only a few pages (SQLITE_FULL, as on a full disk): changes that do
    not fit are 503 and not made; what was acknowledged is there after a restart."""
    db = tmp_path / "f.db"
    d = store_daemon(db, env={"SUBDIVD_SQLITE_MAX_PAGES": "12"})
    try:
        s = Session(d)
        r = s.put_complex(TETS)
        assert r.status_code == 200, r.text
        v = r.json()["version"]
        big_v, big_f = surface("icosphere", 3)
        r = s.put_complex({"vertices": big_v, "simplices": big_f})
        assert r.status_code == 503, r.text
        assert r.json()["type"] == "/errors/store-unavailable"
        assert "full" in r.json()["detail"]
        assert r.headers.get("Retry-After")
        # answers say what happened, not where: the file is named in the log only
        assert str(db) not in r.text and str(tmp_path) not in r.text, r.text
        assert any(str(db) in l and "full" in l for l in d.log_lines)
        # nothing of it is visible: the session is as it was
        c = on(d, s).req("GET", "/complex")
        assert c.status_code == 200 and c.json()["version"] == v
        assert len(c.json()["vertices"]) == len(TETS["vertices"])
        ready = requests.get(d.url + "/readyz")
        assert ready.status_code == 503 and "store" in ready.json()["detail"]
        assert str(tmp_path) not in ready.text, ready.text
        assert on(d, s).level(2).status_code == 200        # reads go on
    finally:
        kill9(d)
    d = store_daemon(db)
    try:
        c = on(d, s).req("GET", "/complex").json()
        assert c["version"] == v and c["vertices"] == [[float(x) for x in p] for p in TETS["vertices"]]
    finally:
        d.stop()


def test_a_refused_edit_is_undone_not_kept(tmp_path):
    """The file fills up under a stream of edits: the edit the store refuses is a 503 and is
    undone in place (the session stays resident, reads go on with the content before it), no
    later change stores it, and after a restart the session is at its last acknowledged edit."""
    db = tmp_path / "e.db"
    d = store_daemon(db, env={"SUBDIVD_SQLITE_MAX_PAGES": "6"})
    try:
        s = Session(d)
        r = s.put_complex(TETS)
        assert r.status_code == 200, r.text
        v = r.json()["version"]
        acked = None
        for i in range(2000):
            before = (s.req("GET", "/complex").json()["vertices"], s.level(2).content)
            pos = [1, 1, 1 + 1e-3 * (i + 1)]
            p = s.req("PATCH", "/control-points", json={"moves": [{"index": 4, "position": pos}]},
                      headers={"If-Match": f'"{v}"'})
            if p.status_code != 200:
                break
            v, acked = p.json()["version"], pos
        assert p.status_code == 503 and p.json()["type"] == "/errors/store-unavailable", p.text
        assert acked, "no edit fitted"
        after = (s.req("GET", "/complex").json(), s.level(2).content)
        assert after[0]["version"] == v
        assert after[0]["vertices"] == before[0] and after[1] == before[1]
        assert after[0]["vertices"][4] == [float(x) for x in acked]
        # a later change (a snapshot: it replaces the journal, so it may fit) must not carry it
        t = s.req("PUT", "/tags", json={"singular": [[0, 1]]})
        assert t.status_code in (200, 503), t.text
        tagged = t.status_code == 200
        if tagged:
            v = t.json()["version"]
    finally:
        kill9(d)
    d = store_daemon(db)
    try:
        c = on(d, s).req("GET", "/complex").json()
        assert c["version"] == v and c["vertices"][4] == [float(x) for x in acked]
        assert c["tags"]["singular"] == ([[0, 1]] if tagged else [])
    finally:
        d.stop()


def test_resident_and_stored_sessions_are_counted_apart(tmp_path):
    """--max-sessions bounds what is in memory; with a durable store, idle sessions leave the
    table and come back on use."""
    d = store_daemon(tmp_path / "r.db", "--max-sessions", "2")
    try:
        made = []
        for i in range(5):
            s = Session(d)
            body = dict(TETS, vertices=[[x + i, y, z] for x, y, z in TETS["vertices"]])
            assert s.put_complex(body).status_code == 200
            made.append(s)
        for i, s in enumerate(made):
            c = s.req("GET", "/complex")
            assert c.status_code == 200
            assert c.json()["vertices"][0][0] == float(i)
    finally:
        d.stop()


def test_one_client_cannot_fill_the_store(store):
    """Idle sessions leave memory for the store, so the table's per-client share does not bound
    what a client keeps: --max-stored-sessions-per-client counts its unexpired stored sessions
    (docs/SERVICE.md "A session, step by step"). Beyond, 429 client-sessions with Retry-After;
    other addresses are not affected; a delete frees a place; the count survives a restart
    (the record keeps its client)."""
    flags = ("--max-sessions", "8", "--session-rate", "1000", "--max-sessions-per-client", "2",
             "--max-stored-sessions-per-client", "4")
    d = store_daemon(store, *flags)
    try:
        ready = requests.get(d.url + "/readyz").json()   # the kind, never the file or server
        assert ready["store"] == ("redis" if isinstance(store, RedisServer) else "sqlite"), ready
        mine = []
        for i in range(4):
            st, _, j = create_from(d, "127.0.0.7", 600 - i)
            assert st == 201, j
            mine.append(adopt(d, requests.Session(), j))
            assert mine[-1].put_complex(TETS).status_code == 200
        st, ra, j = create_from(d, "127.0.0.7")
        assert st == 429 and j["type"].endswith("/client-sessions"), j
        assert "max-stored-sessions-per-client" in j["detail"], j
        assert 500 <= int(ra) <= 900, ra          # the soonest of its four (TTL 597 + slack)
        assert create_from(d, "127.0.0.8")[0] == 201
        for s in mine:                            # two were resident, all four are kept
            assert s.req("GET", "/complex").status_code == 200
        assert mine[0].delete().status_code == 204
        st, _, j = create_from(d, "127.0.0.7")
        assert st == 201, j
        mine[0] = adopt(d, requests.Session(), j)
        assert create_from(d, "127.0.0.7")[0] == 429
    finally:
        kill9(d)
    d = store_daemon(store, *flags)
    try:
        st, _, j = create_from(d, "127.0.0.7")
        assert st == 429 and "max-stored-sessions-per-client" in j["detail"], j
        assert on(d, mine[1]).delete().status_code == 204
        assert create_from(d, "127.0.0.7")[0] == 201
    finally:
        d.stop()


def creates_at_once(daemons, src, n):
    """n POST /v1/sessions from address src let go at the same moment, spread over the daemons in
    turn (each connected first, so the requests come at once): their statuses."""
    go, out = threading.Barrier(n), []

    def one(c):
        go.wait()
        c.request("POST", "/v1/sessions", "{}", {"Content-Type": "application/json"})
        r = c.getresponse()
        r.read()
        out.append(r.status)
        c.close()

    conns = []
    for k in range(n):
        host, port = daemons[k % len(daemons)].url.split("//")[1].split(":")
        conns.append(http.client.HTTPConnection(host, int(port), timeout=30,
                                                source_address=(src, 0)))
    for c in conns:
        c.connect()
    threads = [threading.Thread(target=one, args=(c,)) for c in conns]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return out


def test_concurrent_creates_do_not_pass_the_stored_count(store):
    """The count of a client's stored sessions and the creation it admits are one step: creates
    from one address at once get --max-stored-sessions-per-client sessions, no more (two counting
    at the same time would both see room)."""
    d = store_daemon(store, "--max-connections-per-client", "0",
                     "--max-stored-sessions-per-client", "3")
    n = 30
    try:
        out = creates_at_once([d], "127.0.0.11", n)
        assert sorted(out) == [201] * 3 + [429] * (n - 3), out
        assert create_from(d, "127.0.0.11")[0] == 429
    finally:
        d.stop()


@pytest.mark.skipif(not REDIS_SERVER, reason="redis-server is not installed")
def test_concurrent_creates_through_two_daemons_do_not_pass_the_stored_count(tmp_path):
    """docs/SERVICE.md: the daemons of one redis share a client's count of stored sessions, and
    concurrent creates are counted one after the other, across the daemons too: creates from one
    address sent at once to two daemons on one redis get --max-stored-sessions-per-client
    sessions, no more (each daemon counting while the other creates would both see room)."""
    redis = RedisServer(tmp_path).start()
    ds = []
    try:
        ds = [store_daemon(redis, "--max-connections-per-client", "0",
                           "--max-stored-sessions-per-client", "3") for _ in range(2)]
        for rnd in range(8):
            src, n = f"127.0.1.{rnd + 1}", 16
            out = creates_at_once(ds, src, n)             # half to each daemon
            assert sorted(out) == [201] * 3 + [429] * (n - 3), (rnd, out)
            assert [create_from(d, src)[0] for d in ds] == [429, 429]
    finally:
        for d in ds:
            d.stop()
        redis.stop()


@pytest.mark.skipif(not REDIS_SERVER, reason="redis-server is not installed")
def test_a_daemon_started_before_redis_is_not_ready_until_it_is(tmp_path):
    """docs/DEPLOY.md: a daemon may be started before redis is up. It finds the store unreachable
    at start (it counts the stored sessions), says so in its log, and /readyz is 503
    store-unavailable, so a balancer sends it nothing it could not store; once redis is up, a
    probe write (at most every 5 s) makes it ready, and it creates sessions."""
    redis = RedisServer(tmp_path)                   # its port, nothing listening on it yet
    d = Daemon("--store", redis.url, wait_ready=False)
    try:
        deadline = time.time() + 5                  # the count follows the first line on stdout
        while time.time() < deadline and not any("session store" in l for l in d.log_lines):
            time.sleep(0.05)
        r = requests.get(d.url + "/readyz", timeout=10)
        assert r.status_code == 503 and r.json()["type"] == "/errors/store-unavailable", r.text
        start = [l for l in d.log_lines if "session store" in l]
        assert start and " warn " in start[0] and "Connection refused" in start[0], d.log_lines
        assert not any("-1 session" in l for l in d.log_lines), d.log_lines
        redis.start()
        deadline = time.time() + 8
        while time.time() < deadline and \
                requests.get(d.url + "/readyz", timeout=10).status_code != 200:
            time.sleep(0.2)
        assert requests.get(d.url + "/readyz", timeout=10).status_code == 200
        assert requests.post(d.url + "/v1/sessions", json={}, timeout=10).status_code == 201
    finally:
        d.stop()
        redis.stop()


def test_sessions_kept_alive_past_their_first_expiry_still_count(store):
    """A stored session whose expiry moved on (a PATCHed TTL, changes while in use) still counts
    for its client after the expiry it was created with: redis keeps the client's set alive as
    long as the sessions it names."""
    d = store_daemon(store, "--max-stored-sessions-per-client", "2")
    try:
        a, b = (adopt(d, requests.Session(), create_from(d, "127.0.0.12", ttl_s=2)[2])
                for _ in range(2))
        assert create_from(d, "127.0.0.12")[0] == 429
        assert a.req("PATCH", json={"ttl_s": 600}).status_code == 200
        end = time.time() + 5                       # past the 2 s TTL and its slack
        while time.time() < end:                    # b in use: each change stores a later expiry
            assert b.put_complex(TETS).status_code == 200
            time.sleep(0.3)
        st, ra, j = create_from(d, "127.0.0.12")
        assert st == 429 and "max-stored-sessions-per-client" in j["detail"], j
        assert 1 <= int(ra) <= 4, ra                # b's: TTL 2 s and its slack after its last use
    finally:
        d.stop()


def test_retry_after_of_the_stored_count_is_enough(store):
    """A client that waits the Retry-After of a 429 client-sessions (the stored count) finds its
    soonest session expired: the store counts a session through its expiry's second."""
    d = store_daemon(store, "--max-stored-sessions-per-client", "1")
    try:
        assert create_from(d, "127.0.0.13", ttl_s=1)[0] == 201
        st, ra, j = create_from(d, "127.0.0.13")
        assert st == 429 and "max-stored-sessions-per-client" in j["detail"], j
        time.sleep(int(ra))
        st, ra, j = create_from(d, "127.0.0.13")
        assert st == 201, (ra, j)
    finally:
        d.stop()


def test_a_client_set_in_redis_forgets_expired_sessions(tmp_path):
    """Redis: the per-client set of session ids drops the ones whose sessions expired when it is
    written, also with the count lifted (--max-stored-sessions-per-client 0, behind a proxy where
    every session has one client): it does not grow with every session ever created."""
    if not REDIS_SERVER:
        pytest.skip("redis-server is not installed (tools/packages.txt lists it)")
    r = RedisServer(tmp_path).start()
    key = "subdivd:o:{047f00000e000000000000000000000000}"  # 127.0.0.14 (rate_key_of)
    try:
        for cap in ("0", "5"):
            d = store_daemon(r, "--max-stored-sessions-per-client", cap)
            try:
                r.command("ZADD", key, "1", "0" * 32)   # a session that expired long ago
                assert create_from(d, "127.0.0.14")[0] == 201
                assert r.command("ZSCORE", key, "0" * 32) == b"$-1\r\n", cap
                assert r.command("ZCARD", key) == b":%d\r\n" % (1 if cap == "0" else 2)
                ttl = int(r.command("TTL", key)[1:].split(b"\r")[0])
                assert ttl >= 600, ttl                  # the sessions' TTL at least
            finally:
                d.stop()
    finally:
        r.stop()


def test_a_store_written_before_owners_is_opened(tmp_path):
    """An SQLite file of the schema before records kept their client: opened, its sessions
    served (they count for nobody), and new ones counted."""
    db = tmp_path / "old.db"
    c = sqlite3.connect(db)
    c.executescript(
        "CREATE TABLE sessions(id TEXT PRIMARY KEY, token_hash BLOB NOT NULL, "
        "ttl_s INTEGER NOT NULL, created INTEGER NOT NULL, expires_at INTEGER NOT NULL, "
        "version INTEGER NOT NULL, snapshot_version INTEGER NOT NULL, snapshot BLOB, "
        "snapshot_crc INTEGER);"
        "CREATE TABLE journal(id TEXT NOT NULL, version INTEGER NOT NULL, "
        "entry BLOB NOT NULL, crc INTEGER NOT NULL, PRIMARY KEY (id, version)) WITHOUT ROWID;")
    token = "t" * 43
    c.execute("INSERT INTO sessions VALUES (?, ?, 600, ?, ?, 0, 0, NULL, NULL)",
              ("ab" * 16, hashlib.sha256(token.encode()).digest(), int(time.time()),
               int(time.time()) + 600))
    c.commit()
    c.close()
    d = store_daemon(db, "--max-stored-sessions-per-client", "1")
    try:
        old = requests.get(f"{d.url}/v1/sessions/{'ab' * 16}",
                           headers={"Authorization": f"Bearer {token}"})
        assert old.status_code == 200, old.text
        assert create_from(d, "127.0.0.9")[0] == 201
        assert create_from(d, "127.0.0.9")[0] == 429
    finally:
        d.stop()
    cols = [r[1] for r in sqlite3.connect(db).execute("PRAGMA table_info(sessions)")]
    assert "owner" in cols


def test_store_flag_is_checked():
    for bad in ("disk", "sqlite:", "redis://host:99999", "redis://a@b:1"):
        p = subprocess.run([str(SUBDIVD), "--port", "0", "--store", bad],
                           capture_output=True, text=True, timeout=10)
        assert p.returncode != 0 and "--store" in p.stderr + p.stdout, (bad, p.stderr)
    p = subprocess.run([str(SUBDIVD), "--sync", "sometimes"],
                       capture_output=True, text=True, timeout=10)
    assert p.returncode != 0


def test_redis_down_refuses_changes_and_keeps_reading(tmp_path):
    """redis stops: changes are 503 store-unavailable and not made, /readyz is 503, resident
    sessions are still read; redis back (empty: it keeps nothing, as in these tests), the daemon
    writes again without a restart."""
    if not REDIS_SERVER:
        pytest.skip("redis-server is not installed")
    r = RedisServer(tmp_path).start()
    d = store_daemon(r)
    try:
        s = Session(d)
        v = s.put_complex(TETS).json()["version"]
        before = s.level(2).content
        r.stop()
        p = s.req("PATCH", "/control-points", json={"moves": [{"index": 0, "position": [0.1, 0, 0]}]},
                  headers={"If-Match": f'"{v}"'})
        assert p.status_code == 503 and p.json()["type"] == "/errors/store-unavailable", p.text
        assert p.headers.get("Retry-After")
        assert requests.post(d.url + "/v1/sessions", json={}).status_code == 503
        ready = requests.get(d.url + "/readyz")
        assert ready.status_code == 503 and ready.json()["type"] == "/errors/store-unavailable"
        assert any("store refused" in l or "store cannot be written" in l for l in d.log_lines)
        where = f"127.0.0.1:{r.port}"          # the server is named in the log, not to clients
        assert any(where in l for l in d.log_lines)
        for answer in (p, ready, requests.post(d.url + "/v1/sessions", json={})):
            assert where not in answer.text and "refused" in answer.json()["detail"], answer.text
        during = s.level(2)                   # the resident copy is still read
        assert during.status_code == 200 and during.content == before
        r.start()   # the same port; an empty redis: the old session is gone from it
        deadline = time.time() + 10 * SLOW
        while requests.get(d.url + "/readyz").status_code != 200 and time.time() < deadline:
            time.sleep(0.5)
        assert requests.get(d.url + "/readyz").status_code == 200
        t = Session(d)   # new sessions are stored again
        assert t.put_complex(TETS).status_code == 200
        assert s.req("GET", "").status_code == 404   # redis lost it (no AOF here), and says so
    finally:
        d.stop()
        r.stop()


def test_a_session_is_free_once_its_answer_is_made(tmp_path):
    """--max-sessions 1 on a durable store: two sessions with a complex take turns in memory.
    Each request's session is let go when its answer is complete, before it is sent, so the
    other session's request right after the answer never finds the table full (429); it did
    about one time in ten when the session stayed in use until the request's end."""
    d = store_daemon(tmp_path / "s.db", "--max-sessions", "1")
    try:
        a, b = Session(d), Session(d)
        for s in (a, b):
            assert s.put_complex(TETS).status_code == 200
        codes = [s.req("GET").status_code for _ in range(60) for s in (a, b)]
        assert set(codes) == {200}, codes
    finally:
        d.stop()
