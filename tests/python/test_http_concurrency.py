"""Sessions are isolated under load (docs/SERVICE.md "Threads and isolation").

- 16 sessions driven by 16 threads at once (each with its own connection pool) get, for every
  request of a mixed script (create, rules, complex, levels 0..2 as json/glb/vtu, stats, refused
  requests, a second complex under If-Match, delete), exactly the status, headers that matter
  and bytes that the same scripts get when run one session at a time on the same daemon.
- Concurrent writers and readers of ONE session: every answer is consistent with the version it
  names (ETag = body version, bytes = the mesh published as that version), and concurrent
  If-Match writers cannot both win.
- A long computation in one session does not hold up another session's small requests nor the
  service endpoints, and the busy session reports its progress meanwhile.
- Deleting a session while one of its levels streams neither crashes nor cuts other sessions.
- A session with a request in flight (a slow download, a long computation) does not expire.
- The memory-limit check of a level request, made beside a computation of the same session,
  names the need of the state the session is in.
- Downloads given up half-way (closed or reset) log no warnings and change nothing.
"""
import json
import threading
import time

import requests

from conftest import REPO, make_mesh_file
from daemon import Daemon, Session, complex_from_text

TET = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 2, 3]]}
TWO_TETS = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]],
            "simplices": [[0, 1, 2, 3], [1, 2, 3, 4]],
            "attributes": {"temp": [0, 10, 20, 30, 40]}}
FAN = {"vertices": [[0, 0, 0.2], [1, 0, 0], [0.3, 1, 0], [-0.8, 0.6, 0], [-0.8, -0.6, 0], [0.3, -1, 0]],
       "simplices": [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [0, 5, 1]],
       "attributes": {"vel": [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1]]}}
CURVES_POINTS = {"vertices": [[0, 0, 0], [1, 0, 0], [2, 1, 0], [3, 1, 1], [5, 5, 5], [6, 5, 5], [-1, 2, 0]],
                 "simplices": [[0, 1], [1, 2], [2, 3], [1, 6], [4], [5]]}
MESHES = [TET, TWO_TETS, FAN, CURVES_POINTS,
          json.loads((REPO / "examples" / "mixed.json").read_text()),
          complex_from_text(REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt")]
RULES = [{}, {"solid_scheme": "averaged"}, {"surface_weights": "loop"},
         {"solid_scheme": "averaged", "surface_weights": "loop"}]


def script(d, k, http):
    """Worker k's mixed sequence on a fresh session; returns [(label, status, headers, body)] of
    everything deterministic (the session's id and token are blanked out of bodies)."""
    out = []
    r = http.post(d.url + "/v1/sessions", json={"ttl_s": 600 + k}, timeout=60)
    assert r.status_code == 201, r.text
    sid, tok = r.json()["id"], r.json()["token"]
    out.append(("create", r.status_code, r.headers["Location"] == f"/v1/sessions/{sid}",
                sorted(r.json()), r.json()["ttl_s"]))
    base = f"{d.url}/v1/sessions/{sid}"
    auth = {"Authorization": f"Bearer {tok}"}

    def rec(label, method, path="", keep=(), **kw):
        headers = dict(auth)
        headers.update(kw.pop("headers", {}))
        r = http.request(method, base + path, headers=headers, timeout=120, **kw)
        body = r.content.replace(sid.encode(), b"<id>").replace(tok.encode(), b"<token>")
        if keep:   # JSON with fields that vary by design (expires_at, seconds): keep the rest
            j = r.json()
            body = json.dumps({f: j.get(f) for f in keep}, sort_keys=True).encode()
        out.append((label, r.status_code, r.headers.get("Content-Type"), r.headers.get("ETag"), body))
        return r

    mesh, other = MESHES[k % len(MESHES)], MESHES[(k + 3) % len(MESHES)]
    session_fields = ("version", "levels_cached", "memory_bytes", "summary", "progress")
    rec("complex-before", "GET", "/complex")
    rec("rules", "PUT", "/rules", json=RULES[k % len(RULES)])
    rec("complex", "PUT", "/complex", json=mesh)
    rec("get-complex", "GET", "/complex")
    rec("session", "GET", "", keep=session_fields)
    for level in (0, 1, 2):
        rec(f"json-{level}", "GET", f"/levels/{level}", params={"format": "json"})
        rec(f"glb-{level}", "GET", f"/levels/{level}", params={"format": "glb"})
        if k % 2:
            rec(f"vtu-{level}", "GET", f"/levels/{level}", params={"format": "vtu", "slice": "0,0,1,0.2"})
    rec("stats", "GET", "/levels/2/stats", keep=("level", "counts", "bytes", "version"))
    rec("not-modified", "GET", "/levels/2", headers={"If-None-Match": '"2"'})
    # refused requests: nothing changes
    rec("bad-index", "PUT", "/complex", json={"vertices": [[0, 0, 0]], "simplices": [[0, 3]]})
    rec("bad-scheme", "PUT", "/rules", json={"solid_scheme": "cubic"})
    rec("bad-level", "GET", "/levels/13")
    rec("bad-param", "GET", "/levels/1", params={"colour": "red"})
    rec("bad-token", "GET", "/complex", headers={"Authorization": "Bearer nope"})
    rec("bad-method", "POST", "/complex", json=mesh)
    rec("stale", "PUT", "/complex", json=other, headers={"If-Match": '"1"'})
    rec("session-after-refusals", "GET", "", keep=session_fields)
    # a second complex under the right version, then its levels
    rec("complex-2", "PUT", "/complex", json=other, headers={"If-Match": '"2"'})
    rec("json-1-after", "GET", "/levels/1", params={"format": "json"})
    rec("glb-2-after", "GET", "/levels/2")
    rec("get-complex-2", "GET", "/complex")
    rec("session-2", "GET", "", keep=session_fields)
    rec("delete", "DELETE")
    rec("gone", "GET", "/complex")
    return out


def test_parallel_equals_sequential():
    d = Daemon("--max-sessions", "64")
    try:
        sequential = [script(d, k, requests.Session()) for k in range(16)]
        parallel, errors = [None] * 16, []
        start = threading.Barrier(16)

        def worker(k):
            try:
                http = requests.Session()
                start.wait()
                parallel[k] = script(d, k, http)
            except Exception as e:  # reported below
                errors.append((k, repr(e)))

        threads = [threading.Thread(target=worker, args=(k,)) for k in range(16)]
        t0 = time.time()
        for t in threads:
            t.start()
        for t in threads:
            t.join(120)
        assert not errors, errors
        assert time.time() - t0 < 60
        for k in range(16):
            assert len(parallel[k]) == len(sequential[k])
            for a, b in zip(parallel[k], sequential[k]):
                assert a == b, f"worker {k}, {a[0]}: parallel answer differs from sequential"
        statuses = {e[0]: e[1] for e in sequential[1]}
        assert statuses["complex-before"] == 409 and statuses["glb-2"] == 200
        assert statuses["not-modified"] == 304 and statuses["stale"] == 412
        assert statuses["bad-token"] == 401 and statuses["gone"] == 404
        assert d.alive()
    finally:
        assert d.stop() == 0


def level_without_version(r):
    j = r.json()
    return j.pop("version"), json.dumps(j, sort_keys=True)


def test_one_session_concurrent_writers_and_readers():
    """Two writers alternate two meshes while four readers fetch level 2 and the complex: every
    answer belongs to exactly the version it names."""
    d = Daemon()
    try:
        meshes = [MESHES[5], TWO_TETS]   # 500 tetrahedra (level 2 takes a while) and 2
        ref = Session(d)
        expect_level, expect_vertices = [], []
        for m in meshes:
            assert ref.put_complex(m).status_code == 200
            expect_level.append(level_without_version(ref.level(2, format="json"))[1])
            expect_vertices.append(ref.req("GET", "/complex").json()["vertices"])
        s = Session(d)
        assert s.put_complex(meshes[0]).json()["version"] == 1
        mesh_of = {1: 0}
        reads, errors = [], []
        stop = threading.Event()

        def writer(w):
            http = requests.Session()
            for i in range(15):
                r = http.put(s.base + "/complex", json=meshes[(w + i) % 2], headers=s.auth, timeout=60)
                if r.status_code != 200:
                    errors.append(("put", r.status_code, r.text))
                mesh_of[r.json()["version"]] = (w + i) % 2

        def reader(kind):
            http = requests.Session()
            while not stop.is_set():
                if kind == "level":
                    r = http.get(s.base + "/levels/2", params={"format": "json"}, headers=s.auth, timeout=60)
                else:
                    r = http.get(s.base + "/complex", headers=s.auth, timeout=60)
                if r.status_code != 200:
                    errors.append(("get", r.status_code, r.text))
                    continue
                reads.append((kind, r.headers["ETag"], r.json()))

        writers = [threading.Thread(target=writer, args=(w,)) for w in range(2)]
        readers = [threading.Thread(target=reader, args=(k,)) for k in ("level", "level", "complex", "complex")]
        for t in writers + readers:
            t.start()
        for t in writers:
            t.join(60)
        stop.set()
        for t in readers:
            t.join(60)
        assert not errors, errors[:3]
        assert sorted(mesh_of) == list(range(1, 32))
        assert len(reads) > 8
        for kind, etag, j in reads:
            version = j.pop("version")
            assert etag == f'"{version}"'
            if kind == "level":
                assert json.dumps(j, sort_keys=True) == expect_level[mesh_of[version]], version
            else:
                assert j["vertices"] == expect_vertices[mesh_of[version]], version
        assert s.req("GET").json()["version"] == 31
    finally:
        assert d.stop() == 0


def test_if_match_writers_cannot_both_win():
    d = Daemon()
    try:
        s = Session(d)
        assert s.put_complex(TET).status_code == 200
        for rnd in range(10):
            version = s.req("GET").json()["version"]
            barrier, got = threading.Barrier(2), []

            def put(mesh):
                http = requests.Session()
                barrier.wait()
                r = http.put(s.base + "/complex", json=mesh, timeout=60,
                             headers=dict(s.auth, **{"If-Match": f'"{version}"'}))
                got.append(r.status_code)

            ts = [threading.Thread(target=put, args=(m,)) for m in (TET, TWO_TETS)]
            for t in ts:
                t.start()
            for t in ts:
                t.join(60)
            assert sorted(got) == [200, 412], (rnd, got)
            assert s.req("GET").json()["version"] == version + 1
    finally:
        assert d.stop() == 0


def test_long_computation_does_not_block_others(tmp_path):
    d = Daemon()
    try:
        big_mesh = complex_from_text(make_mesh_file(tmp_path, "cubes", 8))   # 3072 tetrahedra
        big, small = Session(d), Session(d)
        assert big.put_complex(big_mesh).status_code == 200
        assert small.put_complex(MESHES[4]).status_code == 200
        assert small.level(2).status_code == 200
        small_complex = small.req("GET", "/complex").content
        done = []

        def long_request():
            t = time.time()
            r = big.req("GET", "/levels/4/stats")    # ~12.6 M cells
            done.append((r.status_code, time.time() - t))

        th = threading.Thread(target=long_request)
        th.start()
        time.sleep(0.1)
        probes = [
            ("small complex", lambda: small.req("GET", "/complex"), lambda r: r.content == small_complex),
            ("small level", lambda: small.level(2), lambda r: len(r.content) > 0),
            ("small stats", lambda: small.req("GET", "/levels/1/stats"), lambda r: True),
            ("healthz", lambda: requests.get(d.url + "/healthz", timeout=10), lambda r: True),
            ("readyz", lambda: requests.get(d.url + "/readyz", timeout=10), lambda r: True),
            ("metrics", lambda: requests.get(d.url + "/metrics", timeout=10), lambda r: True),
            ("busy session", lambda: big.req("GET"),
             lambda r: states.append((r.json()["progress"] or {}).get("state")) or True),
        ]
        states = []
        worst, n, during = {}, 0, 0
        while th.is_alive():
            for name, fn, ok in probes:
                a = time.time()
                r = fn()
                dt = time.time() - a
                running = th.is_alive()
                assert r.status_code == 200, (name, r.status_code, r.text[:200])
                if running:   # answered while the long request was still computing
                    assert ok(r), name
                    worst[name] = max(worst.get(name, 0), dt)
                    during += 1
                n += 1
        th.join()
        assert done and done[0][0] == 200, done
        assert done[0][1] > 0.5 and during >= 2 * len(probes), \
            f"the long computation ({done[0][1]:.2f} s, {during} probes) was too short to tell"
        slow = {k: round(v, 3) for k, v in worst.items() if v >= 0.5}
        assert not slow, f"requests waited behind another session's computation: {slow}"
        assert "computing" in states, states     # the busy session reports its progress
        assert big.req("GET").json()["progress"] is None
    finally:
        assert d.stop() == 0


def test_delete_while_streaming():
    """A session deleted while one of its levels streams: the stream finishes (it holds the
    model) or is cut, never crashes; the session is gone; another session is untouched."""
    d = Daemon()
    try:
        s, other = Session(d), Session(d)
        ball = complex_from_text(REPO / "tests" / "cases" / "tetgen_ball" / "mesh.txt")
        assert s.put_complex(ball).status_code == 200
        assert other.put_complex(TWO_TETS).status_code == 200
        before = other.level(2, format="json").content
        r = s.req("GET", "/levels/3", params={"format": "vtk"}, stream=True)
        assert r.status_code == 200
        it = r.iter_content(65536)
        got = len(next(it))
        assert s.delete().status_code == 204
        try:
            for chunk in it:
                got += len(chunk)
        except requests.exceptions.RequestException:
            pass
        assert got > 0
        assert d.alive()
        assert s.req("GET").status_code == 404
        assert other.level(2, format="json").content == before
        assert requests.get(d.url + "/healthz").status_code == 200
    finally:
        assert d.stop() == 0


def test_a_session_in_use_does_not_expire():
    """docs/SERVICE.md: idle sessions expire after their TTL. A session whose download is still
    being sent, or whose request is still computing, is not idle: it stays while the request is
    in flight and its TTL counts from the end of it; an event stream alone does not keep it."""
    d = Daemon()
    try:
        ball = complex_from_text(REPO / "tests" / "cases" / "tetgen_ball" / "mesh.txt")
        s = Session(d, ttl_s=1)
        assert s.put_complex(ball).status_code == 200
        assert s.level(3).status_code == 200
        # a download read slowly for 2.5 s (its TTL 1 s, the sweep every 0.2 s); the level's VTK
        # is some 30 MB, far more than the sockets buffer
        r = s.req("GET", "/levels/3", params={"format": "vtk"}, stream=True)
        assert r.status_code == 200
        it = r.iter_content(65536)
        got = len(next(it))
        time.sleep(2.5)
        got += sum(len(c) for c in it)
        assert got == int(r.headers["Content-Length"])
        assert s.req("GET").status_code == 200, "the session expired while its level was sent"
        # a computation longer than the TTL: the session is there when its answer comes
        t = time.time()
        assert s.req("GET", "/levels/4/stats").status_code == 200
        took = time.time() - t
        assert s.req("GET").status_code == 200, \
            f"the session expired as its {took:.2f} s computation ended"
        # an event stream does not keep it: idle, it expires
        events = requests.get(s.base + "/events", headers=s.auth, stream=True, timeout=30)
        lines = []
        for line in events.iter_lines(decode_unicode=True):
            lines.append(line)
            if line.startswith("data:"):
                break
        assert lines[-2:] == ["event: deleted", 'data: {"reason":"expired"}'], lines
        assert s.req("GET").status_code == 404
        assert d.alive()
    finally:
        assert d.stop() == 0


def test_limit_check_beside_a_computation_of_the_same_session(tmp_path):
    """A level request checks the session's memory limit (docs/SERVICE.md "Streaming and memory":
    what the session holds plus the estimate of the levels it lacks) without waiting for a
    computation of the same session. While another request computes levels 1..3, the session
    holds what it held before and lacks what it lacked, so a refused request for level 4 names
    the same need as before that computation started — not one that leaves out the levels the
    computation has made but not yet handed over (the check read the core's count of levels,
    which the computing thread writes as it goes, beside the session's bytes, published at the
    end)."""
    d = Daemon("--max-session-bytes", str(64 << 20))
    try:
        s = Session(d)
        assert s.put_complex(complex_from_text(make_mesh_file(tmp_path, "cubes", 6))).status_code == 200
        r = s.req("GET", "/levels/4/stats")   # 10 M cells: far over 64 MiB
        assert r.status_code == 413 and r.json()["limit_name"] == "max_session_bytes", r.text
        before = r.json()["detail"]
        assert s.req("GET").json()["levels_cached"] == 1
        done = []
        th = threading.Thread(target=lambda: done.append(s.req("GET", "/levels/3/stats").status_code))
        th.start()
        seen = []
        while th.is_alive():
            j = s.req("GET").json()
            if (j["progress"] or {}).get("state") != "computing":
                continue
            r = s.req("GET", "/levels/4/stats")
            if s.req("GET").json()["levels_cached"] != 1:
                break                               # the computation has handed its levels over
            seen.append((r.status_code, r.json().get("detail")))
        th.join(60)
        assert done == [200]
        assert seen, "no request fell within the computation"
        assert all(x == (413, before) for x in seen), \
            [x for x in seen if x != (413, before)][:3]
    finally:
        assert d.stop() == 0


def test_downloads_given_up_are_not_warnings():
    """docs/SERVICE.md "Hostile clients": libmicrohttpd's messages about clients that went away
    are debug lines, not warnings. Clients that close or reset their connection in the middle of
    a level download (a page closed, a batch client killed) leave the daemon and the session as
    they were, and log no warning each (a flood of them would flood the log)."""
    import socket
    d = Daemon()
    try:
        s = Session(d)
        ball = complex_from_text(REPO / "tests" / "cases" / "tetgen_ball" / "mesh.txt")
        assert s.put_complex(ball).status_code == 200
        whole = s.level(3).content
        host, port = d.url.split("//")[1].split(":")

        def give_up(k):
            c = socket.create_connection((host, int(port)), timeout=30)
            fmt = ("glb", "vtk", "json")[k % 3]
            c.sendall(f"GET /v1/sessions/{s.id}/levels/3?format={fmt} HTTP/1.1\r\nHost: x\r\n"
                      f"Authorization: Bearer {s.token}\r\n\r\n".encode())
            got = 0
            while got < 100000:
                b = c.recv(65536)
                assert b
                got += len(b)
            if k % 2:   # a reset rather than a close
                c.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\0\0\0\0\0\0\0")
            c.close()

        threads = [threading.Thread(target=give_up, args=(k,)) for k in range(12)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        deadline = time.time() + 10
        while time.time() < deadline and sum("/levels/3 " in l for l in d.log_lines) < 13:
            time.sleep(0.1)
        assert s.level(3).content == whole
        assert d.alive()
        warnings = [l for l in d.log_lines if " warn " in l or " error " in l]
        assert not warnings, warnings[:3]
    finally:
        assert d.stop() == 0
