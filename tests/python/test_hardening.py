"""Hostile clients must not take the daemon down or push it out of memory (issue 14).

Attackers connect from other loopback addresses (127.0.0.2 and up) than the well-behaved client
(127.0.0.1), so per-client limits apply to them only; every load here is bounded in time and
count and stays on loopback. Each test failed on the daemon before the hardening change."""
import json
import os
import re
import signal
import socket
import subprocess
import threading
import time

import pytest
import requests

import daemon as daemon_mod
from daemon import SLOW, Daemon, Session, create_from
from meshes import kuhn_grid

CUBE_V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]]
CUBE_S = [[0, 1, 2, 3], [1, 2, 3, 4]]


def raw_socket(d, src="127.0.0.2", timeout=5.0):
    """A TCP connection to the daemon from loopback address `src`."""
    host, port = d.url.split("//")[1].split(":")
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(timeout)
    s.bind((src, 0))
    s.connect((host, int(port)))
    return s


def closed_by_peer(s, within):
    """True if the daemon closes (or resets) the socket within `within` seconds."""
    s.settimeout(0.2)
    end = time.time() + within
    while time.time() < end:
        try:
            if s.recv(65536) == b"":
                return True
        except socket.timeout:
            continue
        except OSError:
            return True
    return False


def put_head(s, *headers, ctype="application/json"):
    """The head of a PUT /complex to session s with more header lines ("Name: value" each)."""
    return (f"PUT /v1/sessions/{s.id}/complex HTTP/1.1\r\nHost: x\r\n"
            f"Authorization: Bearer {s.token}\r\nContent-Type: {ctype}\r\n"
            + "".join(h + "\r\n" for h in headers) + "\r\n").encode()


def read_head(k, until_close=False):
    """What the daemon answers on k: up to the end of the head, or all until it closes."""
    out = b""
    try:
        while until_close or b"\r\n\r\n" not in out:
            c = k.recv(65536)
            if not c:
                break
            out += c
    except OSError:
        pass
    return out


def trickle_until_closed(k, piece, within):
    """Send `piece` again and again until the daemon closes k: the seconds that took, or None
    when it was still open after `within` seconds."""
    t0 = time.time()
    while time.time() - t0 < within:
        try:
            k.send(piece)
        except OSError:
            return time.time() - t0
        if closed_by_peer(k, 0.5):
            return time.time() - t0
    return None


CHUNK = b"%x\r\n" % 65536 + b" " * 65536 + b"\r\n"


def chunks_until_answered(k, most, within=20):
    """Send 64 KiB chunks on k until the daemon answers (or closes), `most` bytes or `within`
    seconds at most: (bytes sent, the answer's head)."""
    sent, answer = 0, b""
    k.settimeout(0.01)
    t0 = time.time()
    while sent < most and time.time() - t0 < within and not answer:
        try:
            k.sendall(CHUNK)
            sent += 65536
        except OSError:
            break
        try:
            answer = k.recv(4096) or b"<closed>"
        except socket.timeout:
            pass
    k.settimeout(2)
    if answer != b"<closed>":
        answer += read_head(k)
    return sent, answer


def timed_get(url, **kw):
    t = time.time()
    r = requests.get(url, timeout=10, **kw)
    return r, time.time() - t


class Slowloris:
    """`n` sockets from addresses 127.0.0.2.. that send request headers one byte at a time
    (and reconnect when the daemon closes them), until stop()."""

    def __init__(self, d, n, per_address, first=2):
        self.d, self.n, self.per, self.first = d, n, per_address, first
        self.stop_ev = threading.Event()
        self.socks = []
        for i in range(n):
            self.socks.append(self._open(i))
        self.t = threading.Thread(target=self._run, daemon=True)
        self.t.start()

    def _open(self, i):
        src = f"127.0.0.{self.first + i // self.per}"
        try:
            s = raw_socket(self.d, src, timeout=1)
            s.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
            s.setblocking(False)
            return s
        except OSError:
            return None

    def _run(self):
        while not self.stop_ev.wait(0.5):
            for i, s in enumerate(self.socks):
                try:
                    if s is None:
                        raise OSError
                    s.send(b"X")
                except (OSError, BlockingIOError):
                    if s is not None:
                        s.close()
                    self.socks[i] = self._open(i)

    def stop(self):
        self.stop_ev.set()
        self.t.join(5)
        for s in self.socks:
            if s is not None:
                s.close()


# ---- availability: connection slots ----------------------------------------------------------

def test_slowloris_and_idle_sockets_do_not_lock_out_health_or_sessions():
    """64 slots: 48 slowloris sockets and 16 idle keep-alive sockets from other addresses. Health
    checks and an authenticated client keep getting answers."""
    d = Daemon("--max-connections", "64", "--max-connections-per-client", "16",
               "--header-timeout", "4")
    try:
        s = Session(d)
        assert s.put_complex({"vertices": CUBE_V, "simplices": CUBE_S}).status_code == 200
        idle = []
        for i in range(16):
            k = raw_socket(d, "127.0.0.6")
            k.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
            assert b"200" in k.recv(4096).split(b"\r\n")[0]
            idle.append(k)
        loris = Slowloris(d, 48, 16)
        try:
            worst = 0.0
            for _ in range(8):
                r, dt = timed_get(d.url + "/healthz")
                assert r.status_code == 200
                r2 = s.req("GET", "")
                assert r2.status_code == 200
                worst = max(worst, dt)
                time.sleep(0.5)
            assert worst < 3.0, worst
        finally:
            loris.stop()
            for k in idle:
                k.close()
    finally:
        assert d.stop() == 0


def test_header_deadline_closes_a_trickling_socket():
    d = Daemon("--header-timeout", "2")
    try:
        k = raw_socket(d)
        k.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
        t0 = time.time()
        closed = False
        while time.time() - t0 < 8:
            try:
                k.send(b"X")
            except OSError:
                closed = True
                break
            if closed_by_peer(k, 0.5):
                closed = True
                break
        assert closed and time.time() - t0 < 5, "a socket that never finishes its headers must be closed"
        k.close()
    finally:
        d.stop()


def test_body_deadline_closes_a_trickling_upload():
    d = Daemon("--header-timeout", "2", "--body-min-rate", "100000")
    try:
        s = Session(d)
        k = raw_socket(d)
        k.sendall(put_head(s, "Content-Length: 1000000"))
        # 1 MB at >= 100 kB/s: about 2 s + 10 s, then closed
        assert trickle_until_closed(k, b" ", 12) is not None
        k.close()
    finally:
        d.stop()


def test_per_client_connection_cap():
    d = Daemon("--max-connections-per-client", "4")
    try:
        socks = [raw_socket(d, "127.0.0.3") for _ in range(4)]
        extra = raw_socket(d, "127.0.0.3")
        assert closed_by_peer(extra, 2), "a fifth connection from one address must be refused"
        assert requests.get(d.url + "/healthz", timeout=5).status_code == 200  # 127.0.0.1
        for k in socks + [extra]:
            k.close()
    finally:
        d.stop()


# ---- availability: the session table ---------------------------------------------------------

def test_ttl_is_capped():
    d = Daemon("--max-ttl", "3600")
    try:
        r = requests.post(d.url + "/v1/sessions", json={"ttl_s": 604800}, timeout=5)
        assert r.status_code == 201, r.text
        assert r.json()["ttl_s"] == 3600
    finally:
        d.stop()


def test_empty_sessions_are_evicted_before_refusing():
    """Unauthenticated clients filling the table with empty long-lived sessions lock nobody out."""
    d = Daemon("--max-sessions", "8", "--session-rate", "1000")
    try:
        src = requests.Session()
        for _ in range(8):
            assert src.post(d.url + "/v1/sessions", json={"ttl_s": 86400}).status_code == 201
        s = Session(d)   # the ninth: an empty one went
        assert s.put_complex({"vertices": CUBE_V, "simplices": CUBE_S}).status_code == 200
    finally:
        d.stop()


def test_full_table_gives_a_true_retry_after():
    d = Daemon("--max-sessions", "2", "--session-rate", "1000")
    try:
        for _ in range(2):
            s = Session(d, ttl_s=3)
            assert s.put_complex({"vertices": CUBE_V, "simplices": CUBE_S}).status_code == 200
        r = requests.post(d.url + "/v1/sessions", json={}, timeout=5)
        assert r.status_code in (429, 503)
        ra = int(r.headers["Retry-After"])
        assert 1 <= ra <= 4, ra
        time.sleep(ra + 1.5)
        assert requests.post(d.url + "/v1/sessions", json={}, timeout=5).status_code == 201
    finally:
        d.stop()


def test_one_client_cannot_fill_the_session_table():
    """--max-sessions-per-client (default a quarter of --max-sessions): a client address holding
    that many sessions with a complex gets 429 client-sessions, with Retry-After the soonest
    expiry of its own sessions; other addresses still get sessions (the table is not full); the
    client's own empty idle session makes room for it; its sessions going frees its share."""
    d = Daemon("--max-sessions", "8", "--session-rate", "1000", "--max-sessions-per-client", "2")
    try:
        def filled(j):
            s = Session.__new__(Session)
            s.d, s.http, s.id, s.token = d, requests.Session(), j["id"], j["token"]
            s.base, s.auth = f"{d.url}/v1/sessions/{j['id']}", {"Authorization": f"Bearer {j['token']}"}
            assert s.put_complex({"vertices": CUBE_V, "simplices": CUBE_S}).status_code == 200
            return s

        mine = [filled(create_from(d, "127.0.0.5", ttl)[2]) for ttl in (3, 600)]
        st, ra, j = create_from(d, "127.0.0.5", 600)
        assert st == 429 and j["type"].endswith("/client-sessions"), j
        assert "max-sessions-per-client" in j["detail"] and 1 <= int(ra) <= 3, (ra, j)
        others = [create_from(d, "127.0.0.6", 600) for _ in range(2)]
        assert [o[0] for o in others] == [201, 201]          # the table itself has room
        time.sleep(int(ra) + 1.2)                            # its 3 s session expired
        st, _, e1 = create_from(d, "127.0.0.5", 600)
        assert st == 201, e1
        st, _, e2 = create_from(d, "127.0.0.5", 600)                 # e1 (empty, idle) made room
        assert st == 201, e2
        gone = requests.get(f"{d.url}/v1/sessions/{e1['id']}",
                            headers={"Authorization": f"Bearer {e1['token']}"})
        assert gone.status_code == 404
        filled(e2)
        assert create_from(d, "127.0.0.5", 600)[0] == 429            # both hold a complex
        assert mine[1].delete().status_code == 204
        assert create_from(d, "127.0.0.5", 600)[0] == 201            # a delete frees its share
    finally:
        d.stop()


def test_session_creation_is_rate_limited_per_client():
    d = Daemon("--session-rate", "5")
    try:
        host, port = d.url.split("//")[1].split(":")
        codes, ra = [], None
        for _ in range(8):
            k = raw_socket(d, "127.0.0.4")
            k.sendall(b"POST /v1/sessions HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n"
                      b"Connection: close\r\n\r\n")
            head = b""
            while b"\r\n\r\n" not in head:
                chunk = k.recv(4096)
                if not chunk:
                    break
                head += chunk
            codes.append(int(head.split(b" ")[1]))
            m = re.search(rb"Retry-After: (\d+)", head, re.I)
            if m:
                ra = int(m.group(1))
            k.close()
        assert codes[:5] == [201] * 5 and set(codes[5:]) == {429}, codes
        assert ra is not None and 1 <= ra <= 60
        # another client is not affected
        assert requests.post(d.url + "/v1/sessions", json={}, timeout=5).status_code == 201
    finally:
        d.stop()


# ---- memory outside the limits ---------------------------------------------------------------

def peak_reset(d):
    with open(f"/proc/{d.proc.pid}/clear_refs", "w") as f:
        f.write("5")


def peak_rss(d):
    for line in open(f"/proc/{d.proc.pid}/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return 0


def big_complex_text(nv, bad_last=False):
    """A PUT /complex body of nv vertices on a grid and nv-3 triangles (a strip); with bad_last,
    the last index is out of range, so the body is parsed in full and then refused."""
    pts = ",".join(f"[{i % 1000}.125,{i // 1000}.375,{(i * i) % 97}.5]" for i in range(nv))
    tris = [f"[{i},{i + 1},{i + 2}]" for i in range(nv - 2)]
    if bad_last:
        tris[-1] = f"[{nv - 3},{nv - 2},{nv + 5}]"
    return '{"vertices":[' + pts + '],"simplices":[' + ",".join(tris) + "]}"


@pytest.mark.skipif(daemon_mod.SANITIZED, reason="resident size under ASan is its allocator's, not the daemon's")
def test_parsing_a_large_body_costs_a_small_multiple_of_its_size():
    d = Daemon("--max-body-bytes", str(200 << 20))
    try:
        s = Session(d)
        body = big_complex_text(1_200_000, bad_last=True).encode()
        assert len(body) > 40e6
        base = d.rss_bytes()
        peak_reset(d)
        r = s.req("PUT", "/complex", data=body, headers={"Content-Type": "application/json"})
        assert r.status_code == 422 and "/simplices/" in r.text
        grew = peak_rss(d) - base
        assert grew < 4 * len(body), f"parse peak {grew / len(body):.1f}x the body"
    finally:
        d.stop()


@pytest.mark.skipif(daemon_mod.SANITIZED, reason="resident size under ASan is its allocator's, not the daemon's")
def test_memory_budget_refuses_instead_of_growing_and_rss_returns():
    d = Daemon("--max-body-bytes", str(200 << 20), "--max-memory", str(600 << 20))
    try:
        body = big_complex_text(1_000_000, bad_last=True).encode()
        base = d.rss_bytes()
        sessions = [Session(d) for _ in range(4)]
        codes = []

        def put(s):
            codes.append(s.req("PUT", "/complex", data=body,
                               headers={"Content-Type": "application/json"}).status_code)
        peak_reset(d)
        ts = [threading.Thread(target=put, args=(s,)) for s in sessions]
        for t in ts:
            t.start()
        for t in ts:
            t.join()
        assert set(codes) <= {422, 503}, codes
        assert peak_rss(d) < base + (600 << 20) + len(body) * 4 + (100 << 20)
        time.sleep(1.5)
        assert d.rss_bytes() < base * 1.1 + (50 << 20), (d.rss_bytes(), base)
    finally:
        d.stop()


def test_chunked_body_over_the_limit_is_refused_early():
    d = Daemon("--max-body-bytes", str(1 << 20))
    try:
        s = Session(d)
        k = raw_socket(d, "127.0.0.1", timeout=10)
        k.sendall(put_head(s, "Transfer-Encoding: chunked"))
        sent, answer = chunks_until_answered(k, 300 << 20)
        assert sent < (16 << 20), f"{sent} bytes were read before the refusal"
        assert answer.startswith(b"HTTP/1.1 413"), answer[:80]
        k.close()
    finally:
        d.stop()


@pytest.mark.skipif(daemon_mod.SANITIZED, reason="resident size under ASan is its allocator's, not the daemon's")
def test_get_complex_of_a_large_complex_streams_in_bounded_memory():
    d = Daemon("--max-body-bytes", str(200 << 20))
    try:
        s = Session(d)
        n = 1_000_000
        body = big_complex_text(n).encode()
        assert s.req("PUT", "/complex", data=body,
                     headers={"Content-Type": "application/json"}).status_code == 200
        base = d.rss_bytes()
        peak_reset(d)
        t0 = time.time()
        r = s.req("GET", "/complex", stream=True)
        assert r.status_code == 200
        size = 0
        for c in r.iter_content(1 << 20):
            size += len(c)
        dt = time.time() - t0
        assert size > 40e6
        assert peak_rss(d) - base < 200 << 20, (peak_rss(d) - base) / 1e6
        assert dt < 15, dt
    finally:
        d.stop()


# ---- one session must not stall the others ---------------------------------------------------

def block_mesh(n):
    out = subprocess.run(["/usr/bin/python3", os.path.join(os.path.dirname(__file__), "..", "..",
                                                            "bench", "make_mesh.py"), "cubes", str(n)],
                         check=True, capture_output=True, text=True).stdout
    V, S = [], []
    for line in out.splitlines():
        t = line.split()
        if t and t[0] == "v":
            V.append([float(x) for x in t[1:4]])
        elif t and t[0] == "s":
            S.append([int(x) for x in t[1:]])
    return {"vertices": V, "simplices": S}


def test_unread_stream_does_not_block_edits():
    d = Daemon()
    try:
        s = Session(d)
        assert s.put_complex(block_mesh(6)).status_code == 200
        assert s.level(3, format="vtu").status_code == 200      # computed
        k = raw_socket(d, "127.0.0.1")
        k.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        k.sendall((f"GET /v1/sessions/{s.id}/levels/3?format=vtu HTTP/1.1\r\nHost: x\r\n"
                   f"Authorization: Bearer {s.token}\r\n\r\n").encode())
        k.recv(100)          # the stream has begun; nothing more is read
        time.sleep(0.5)
        v = s.req("GET", "").json()["version"]
        t0 = time.time()
        r = s.req("PATCH", "/control-points", json={"moves": [{"index": 0, "position": [0.1, 0, 0]}]},
                  headers={"If-Match": f'"{v}"'})
        assert r.status_code == 200
        assert time.time() - t0 < 2.0, "an edit waited for a stream that is not being read"
        # other reads of the same session are not blocked either
        r, dt = timed_get(s.base + "/levels/1/stats", headers=s.auth)
        assert r.status_code == 200 and dt < 2.0
        k.close()
    finally:
        d.stop()


def test_compute_slots_are_fair_across_sessions():
    """Session A asks for its heavy uncomputed level four times at once: the requests waiting for
    A's computation hold no compute slot, so session B's small request is served while A's first
    one is still computing (before: A's waiters held both slots and B waited about 1 s for A)."""
    # one thread per computation, and a block big enough that A's level takes well over a
    # second on one core (what the check below the waits needs to mean anything)
    d = Daemon("--threads", "2", "--level-threads", "1")
    try:
        a = Session(d)
        assert a.put_complex(block_mesh(14)).status_code == 200
        b = Session(d)
        assert b.put_complex({"vertices": CUBE_V, "simplices": CUBE_S}).status_code == 200
        t0 = time.time()
        done = []

        def heavy():
            assert a.level(3, format="vtu", parts="points").status_code == 200
            done.append(time.time() - t0)
        ts = [threading.Thread(target=heavy) for _ in range(4)]
        for t in ts:
            t.start()
        time.sleep(0.15)
        tb0 = time.time()
        r = b.level(2, format="json")
        tb = time.time() - tb0
        for t in ts:
            t.join()
        assert r.status_code == 200
        assert min(done) > 1.0, "A's level should take a while to compute"
        assert tb < 0.5 * SLOW, (tb, sorted(done))
    finally:
        d.stop()


def test_a_killed_daemon_leaves_no_tetgen_helper():
    from test_fill import surface  # noqa: E402  (a closed surface)
    d = Daemon("--fill-timeout", "30")
    try:
        s = Session(d)
        V, T = surface("icosphere", 3)
        def fill():  # the daemon is killed under it: the request ends without an answer
            try:
                s.put_complex({"vertices": V, "simplices": [],
                               "fill": [{"surface": T, "max_volume": 1e-5}]})
            except requests.exceptions.ConnectionError:
                pass
        threading.Thread(target=fill, daemon=True).start()
        helper = None
        for _ in range(50):
            out = subprocess.run(["pgrep", "-P", str(d.proc.pid)], capture_output=True, text=True)
            if out.stdout.strip():
                helper = int(out.stdout.split()[0])
                break
            time.sleep(0.1)
        assert helper, "the fill did not start a helper"
        os.kill(d.proc.pid, signal.SIGKILL)
        d.proc.wait()
        for _ in range(30):
            if not os.path.exists(f"/proc/{helper}") or \
                    "State:\tZ" in open(f"/proc/{helper}/status").read():
                break
            time.sleep(0.1)
        else:
            os.kill(helper, signal.SIGKILL)
            pytest.fail("the TetGen helper outlived the daemon")
    finally:
        d.stop()


def test_fill_total_time_is_bounded():
    from test_fill import surface  # noqa: E402
    d = Daemon("--fill-timeout", "4")
    try:
        s = Session(d)
        V, T = surface("icosphere", 3)
        nv = len(V)
        verts, fill = [], []
        # 10 disjoint spheres, each about 1-2.5 s to fill on this VM (its speed drifts 2x): together
        # far beyond the 4 s deadline however fast the machine is that day
        for k in range(10):
            verts += [[x + 3 * k, y, z] for x, y, z in V]
            fill.append({"surface": [[a + k * nv, b + k * nv, c + k * nv] for a, b, c in T],
                         "max_volume": 3e-5})
        t0 = time.time()
        r = s.put_complex({"vertices": verts, "simplices": [], "fill": fill})
        assert time.time() - t0 < 7, time.time() - t0
        # a fill over its time is the limit refusal docs/SERVICE.md names (and test_fill checks)
        assert r.status_code == 413 and r.json()["limit_name"] == "fill_seconds", r.text
    finally:
        d.stop()


# ---- consistency and input -------------------------------------------------------------------

def test_level_version_is_the_version_of_its_content():
    """PATCHes move point 0 to x = version while GETs stream level 0: every answer's ETag and
    body version match the position it carries."""
    d = Daemon()
    try:
        s = Session(d)
        assert s.put_complex(block_mesh(4)).status_code == 200
        assert s.level(0, format="json").status_code == 200
        stop = threading.Event()
        bad = []

        def editor():
            while not stop.is_set():
                v = int(s.req("GET", "").json()["version"])
                s.req("PATCH", "/control-points", json={"moves": [{"index": 0, "position": [v + 1, 0, 0]}]},
                      headers={"If-Match": f'"{v}"'})

        def reader():
            http = requests.Session()
            while not stop.is_set():
                r = http.get(s.base + "/levels/0", params={"format": "json"}, headers=s.auth, timeout=10)
                j = r.json()
                etag = int(r.headers["ETag"].strip('"'))
                x = j["vertices"][0][0]
                if etag != j["version"] or (etag > 1 and x != etag):
                    bad.append((etag, j["version"], x))
        ts = [threading.Thread(target=editor)] + [threading.Thread(target=reader) for _ in range(2)]
        for t in ts:
            t.start()
        time.sleep(4)
        stop.set()
        for t in ts:
            t.join()
        assert not bad, bad[:5]
    finally:
        d.stop()


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


def new_session(daemon, body=None):
    s = Session(daemon)
    assert s.put_complex(body or {"vertices": CUBE_V, "simplices": CUBE_S}).status_code == 200
    return s


def patch(s, moves):
    v = s.req("GET", "").json()["version"]
    return s.req("PATCH", "/control-points", json={"moves": moves}, headers={"If-Match": f'"{v}"'})


def test_patch_refuses_a_degenerate_simplex_and_allows_inversion(daemon):
    s = new_session(daemon)
    r = patch(s, [{"index": 4, "position": [0.5, 0.5, 0.5]}, {"index": 3, "position": [0, 0, 0.001]},
                  {"index": 1, "position": [0, 1, 0]}])      # vertex 1 onto vertex 2
    assert r.status_code == 422, r.text
    assert any(e["pointer"].startswith("/moves/2") for e in r.json()["errors"]), r.text
    # tetrahedron [0,1,2,3] inverted: fine (z = -1 would put 3 on the plane of 1, 2, 4 and make
    # tetrahedron [1,2,3,4] flat, which is refused)
    assert patch(s, [{"index": 3, "position": [0, 0, -0.5]}]).status_code == 200
    assert patch(s, [{"index": 3, "position": [0, 0, -1]}]).status_code == 422
    for path, body in (("/tags", {"singular": []}), ("/rules", {})):   # rebuilt from the edit
        assert s.req("PUT", path, json=body).status_code == 200


def test_if_match_and_if_none_match_parse_entity_tags(daemon):
    s = new_session(daemon)
    mv = {"moves": [{"index": 0, "position": [0.01, 0, 0]}]}
    assert s.req("PATCH", "/control-points", json=mv, headers={"If-Match": "**"}).status_code == 412
    assert s.req("PATCH", "/control-points", json=mv, headers={"If-Match": "*"}).status_code == 200
    v = s.req("GET", "").json()["version"]
    assert v < 10
    r = s.level(0, format="json")
    etag = r.headers["ETag"]
    wrong = f'"{v}1"'            # contains the version as a substring
    assert s.req("GET", "/levels/0", params={"format": "json"},
                 headers={"If-None-Match": wrong}).status_code == 200
    assert s.req("GET", "/levels/0", params={"format": "json"},
                 headers={"If-None-Match": f'"x", {etag}'}).status_code == 304


def test_nul_bytes_in_path_or_query_are_refused(daemon):
    s = new_session(daemon)
    assert requests.get(daemon.url + "/v1/openapi.json%00.html", timeout=5).status_code == 400
    assert s.req("GET", "/levels/0?format=json%00x").status_code == 400


def test_control_characters_are_escaped_in_logs(daemon):
    requests.get(daemon.url + "/v1/x%0a2026-01-01T00:00:00.000Z error forged", timeout=5)
    time.sleep(0.3)
    assert not any(l.startswith("2026-01-01T00:00:00.000Z error forged") for l in daemon.log_lines)
    assert any("\\x0a" in l or "\\n" in l or "%0a" in l.lower() for l in daemon.log_lines if "forged" in l)


def test_many_query_parameters_get_400(daemon):
    s = new_session(daemon)
    q = "&".join(["format=json"] * 1000)
    r = s.req("GET", "/levels/0?" + q)
    assert r.status_code == 400, r.status_code


def test_long_path_gets_414(daemon):
    r = requests.get(daemon.url + "/v1/" + "a" * 300, timeout=5)
    assert r.status_code == 414
    p = r.json()   # a problem like every other: the status phrase as its title (RFC 9110)
    assert p["title"] == "URI Too Long" and p["type"].endswith("/uri-too-long"), p


def test_subnormal_slice_numbers_are_finite(daemon):
    s = new_session(daemon)
    r = s.level(1, format="json", slice="1e-320,0,1,0.2")
    assert r.status_code == 200, r.text


def test_attributes_beyond_1e15_are_refused(daemon):
    s = Session(daemon)
    r = s.put_complex({"vertices": CUBE_V, "simplices": CUBE_S,
                       "attributes": {"t": [0, 1, 2, 3e15, 4]}})
    assert r.status_code == 422
    assert r.json()["errors"][0]["pointer"] == "/attributes/t/3"


def test_unknown_query_parameters_get_400(daemon):
    s = new_session(daemon)
    assert s.req("GET", "/complex?bogus=1").status_code == 400
    v = s.req("GET", "").json()["version"]
    r = s.req("PATCH", "/control-points?bogus=1", json={"moves": [{"index": 0, "position": [0, 0, 0]}]},
              headers={"If-Match": f'"{v}"'})
    assert r.status_code == 400


def test_level_memory_estimate_is_close_to_the_real_cost():
    """The estimate refuses only what would not fit: a level that costs X fits a session limit
    of 1.5 X, and the estimate is within a factor 2 of what the level takes."""
    d = Daemon()
    body = block_mesh(6)
    try:
        s = Session(d)
        assert s.put_complex(body).status_code == 200
        before = s.req("GET", "").json()["memory_bytes"]
        assert s.level(3, format="json", parts="points").status_code == 200
        cost = s.req("GET", "").json()["memory_bytes"]
        st = s.req("GET", "/levels/3/stats").json()
        est = st.get("estimated_bytes")
        assert est is not None and 0.5 * (cost - before) <= est <= 2 * (cost - before), (est, cost - before)
    finally:
        d.stop()
    d = Daemon("--max-session-bytes", str(int(cost * 1.5)))
    try:
        s = Session(d)
        assert s.put_complex(body).status_code == 200
        assert s.level(3, format="json", parts="points").status_code == 200
    finally:
        d.stop()


def test_chunked_body_with_content_length_zero_is_still_timed():
    # Content-Length: 0 beside Transfer-Encoding: chunked: libmicrohttpd reads the chunked body
    # (RFC 9112 6.3), so the guard must time it as a body, not as a request being handled
    d = Daemon("--header-timeout", "2", "--body-min-rate", "100000")
    try:
        s = Session(d)
        k = raw_socket(d)
        k.sendall(put_head(s, "Content-Length: 0", "Transfer-Encoding: chunked"))
        assert trickle_until_closed(k, b"1\r\n \r\n", 12) is not None, \
            "a trickling chunked body must be closed"
        k.close()
    finally:
        d.stop()


def test_chunked_body_with_content_length_zero_needs_json(daemon):
    s = Session(daemon)
    body = json.dumps({"vertices": CUBE_V, "simplices": CUBE_S}).encode()
    k = raw_socket(daemon)
    k.sendall(put_head(s, "Connection: close", "Content-Length: 0", "Transfer-Encoding: chunked",
                       ctype="text/plain") + f"{len(body):x}\r\n".encode() + body + b"\r\n0\r\n\r\n")
    out = read_head(k, until_close=True)
    k.close()
    assert out.startswith(b"HTTP/1.1 415"), out[:200]


def test_content_lengths_that_differ_are_refused(daemon):
    """Two Content-Length headers that differ (RFC 9112 6.3, a request-smuggling shape behind a
    proxy): 400 bad-framing and the connection closed, the session unchanged; the same length
    twice is one length."""
    s = Session(daemon)
    body = json.dumps({"vertices": CUBE_V, "simplices": CUBE_S}).encode()

    def put(lengths):
        k = raw_socket(daemon, timeout=10)
        k.sendall(put_head(s, *(f"Content-Length: {n}" for n in lengths)) + body)
        out = b""
        try:
            while True:
                c = k.recv(65536)
                if not c:
                    return out, True        # closed by the daemon
                out += c
                if out.startswith(b"HTTP/1.1 200") and out.endswith(b"}"):
                    return out, False
        finally:
            k.close()
    out, closed = put([len(body), 5])
    assert out.startswith(b"HTTP/1.1 400") and b"/errors/bad-framing" in out and closed, out[:300]
    assert s.req("GET").json()["version"] == 0
    out, closed = put([len(body), len(body)])
    assert out.startswith(b"HTTP/1.1 200"), out[:300]
    assert s.req("GET").json()["version"] == 1


def test_chunked_beside_content_length_closes_the_connection(daemon):
    """Transfer-Encoding: chunked beside a Content-Length (RFC 9112 6.3, the classic smuggling
    shape behind a proxy that frames by the length): the body is framed by the chunks, and the
    connection is closed after the answer, so bytes after the chunked body are never read as a
    request of their own (they were: a GET /healthz tucked behind it was answered 200)."""
    s = Session(daemon)
    body = json.dumps({"vertices": CUBE_V, "simplices": CUBE_S}).encode()
    tail = b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n"
    for good in (True, False):
        payload = body if good else b"{}"
        k = raw_socket(daemon, timeout=5)
        k.sendall(put_head(s, f"Content-Length: {len(payload) + 200}", "Transfer-Encoding: chunked")
                  + f"{len(payload):x}\r\n".encode() + payload + b"\r\n0\r\n\r\n" + tail)
        out = read_head(k, until_close=True)
        k.close()
        assert out.startswith(b"HTTP/1.1 200" if good else b"HTTP/1.1 400"), out[:300]
        assert b"connection: close" in out.lower(), out[:600]
        assert out.count(b"HTTP/1.1 ") == 1, out
    assert s.req("GET").json()["version"] == 1
    # a Content-Length alone keeps the connection: two requests on it are both answered
    k = raw_socket(daemon, timeout=5)
    k.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n" + tail + b"GET /healthz HTTP/1.1\r\n"
              b"Host: x\r\nConnection: close\r\n\r\n")
    out = read_head(k, until_close=True)
    k.close()
    assert out.count(b"HTTP/1.1 200") == 3, out


def test_a_request_larger_than_the_whole_budget_is_a_413():
    """A body that only the tree parse can read (a vertex that is a string) of 2 M vertices needs
    more than a 400 MB budget on its own: 413 naming max_memory with what it needed (no
    Retry-After: waiting cannot help), where it was a 503 memory-budget asking to retry; a
    request that fits is served after it."""
    d = Daemon("--max-memory", str(400_000_000))
    try:
        s = Session(d)
        n = 2_000_000
        body = '{"vertices":[' + ",".join(["[0.123456,0.234567,0.345678]"] * n) + ',"x"],' \
               '"simplices":[[0,1]]}'
        r = s.req("PUT", "/complex", data=body.encode(), headers={"Content-Type": "application/json"})
        assert r.status_code == 413, r.text[:300]
        j = r.json()
        assert j["limit_name"] == "max_memory" and j["limit"] == 400_000_000, j
        assert j["requested"] > j["limit"] and "Retry-After" not in r.headers
        assert s.put_complex({"vertices": CUBE_V, "simplices": CUBE_S}).status_code == 200
    finally:
        d.stop()


def test_a_level_larger_than_the_whole_budget_is_refused_before_it_is_built():
    """Level 3 of 24 576 tetrahedra (6.4 M cells, under --max-cells) needs some 440 MB by the
    core's estimate, more than a 300 MB budget holds even with nothing else in it: 413 naming
    max_memory before any of it is built (the daemon's RSS stays small), where it was built until
    the budget ran out and answered 503 memory-budget, \"retry later\", which no retry changes.
    Level 2 (about 55 MB) is served."""
    d = Daemon("--max-memory", str(300_000_000))
    try:
        s = Session(d)
        v, t = kuhn_grid(16)
        assert s.put_complex({"vertices": v, "simplices": t}).status_code == 200
        before = d.rss_bytes()
        for path in ("/levels/3/stats", "/levels/3?format=glb"):
            t0 = time.time()
            r = s.req("GET", path)
            assert r.status_code == 413, r.text[:300]
            j = r.json()
            assert j["limit_name"] == "max_memory" and j["limit"] == 300_000_000, j
            assert j["requested"] > j["limit"] and "Retry-After" not in r.headers, j
            assert time.time() - t0 < 0.5
        if not daemon_mod.SANITIZED:   # under ASan the resident size is its allocator's
            assert d.rss_bytes() - before < (50 << 20)
        assert s.req("GET", "/levels/2/stats").status_code == 200
    finally:
        d.stop()


def test_a_refinement_larger_than_the_whole_budget_is_a_413():
    """Refining all 24 576 tetrahedra of a grid (196 608 new ones, their level-1 placement) needs
    more than a 150 MB budget holds with nothing else in it: 413 naming max_memory, no Retry-After
    (waiting cannot help), where it was a 503 memory-budget "retry later": blocks the request
    had given back to the kept set and that were then dropped to make room were taken off its
    meter a second time, so it looked as if others held the memory. The session is unchanged and
    a refinement of one tetrahedron is served."""
    d = Daemon("--max-memory", str(150_000_000))
    try:
        s = Session(d)
        v, t = kuhn_grid(16)
        r = s.put_complex({"vertices": v, "simplices": t})
        assert r.status_code == 200
        version = r.json()["version"]
        r = s.req("POST", "/refine", json={"select": {"box": {"min": [-1, -1, -1],
                                                               "max": [17, 17, 17]}}})
        assert r.status_code == 413, r.text[:300]
        j = r.json()
        assert j["limit_name"] == "max_memory" and j["limit"] == 150_000_000, j
        assert j["requested"] > j["limit"] and "Retry-After" not in r.headers, j
        assert s.req("GET", "").json()["version"] == version
        r = s.req("POST", "/refine", json={"select": {"simplices": [t[100]]}})
        assert r.status_code == 200, r.text[:300]
    finally:
        d.stop()


def test_one_client_cannot_hold_the_budget_with_slow_bodies():
    """--max-client-body-bytes: bodies one address is sending hold at most that much. Two slow
    bodies of 400 kB from 127.0.0.2 fit a cap of 1 MB, a third is 429 client-bodies at once
    (Retry-After), while 127.0.0.3 still sends its own; once the first is complete, 127.0.0.2
    may send another. The held bytes follow the bodies (nothing is left held after them)."""
    d = Daemon("--max-client-body-bytes", "1000000", "--body-min-rate", "0")
    try:
        s = Session(d)
        body = json.dumps({"vertices": CUBE_V, "simplices": CUBE_S}).encode()
        body = body[:-1] + b" " * (400_000 - len(body)) + b"}"

        def start(src):
            k = raw_socket(d, src, timeout=10)
            k.sendall(put_head(s, f"Content-Length: {len(body)}") + body[:1000])
            return k
        a, b = start("127.0.0.2"), start("127.0.0.2")
        time.sleep(0.3)                      # both bodies' buffers are held
        c = start("127.0.0.2")
        got = read_head(c, until_close=True)  # answered at once, and closed
        assert got.startswith(b"HTTP/1.1 429") and b"Retry-After: 5" in got, got[:300]
        assert b"/errors/client-bodies" in got, got
        c.close()
        other = start("127.0.0.3")           # another address is not held back
        other.sendall(body[1000:])
        assert read_head(other).startswith(b"HTTP/1.1 200")
        other.close()
        a.sendall(body[1000:])               # the first body completes: its bytes come back
        assert read_head(a).startswith(b"HTTP/1.1 200")
        a.close()
        time.sleep(0.3)
        e = start("127.0.0.2")
        e.sendall(body[1000:])
        assert read_head(e).startswith(b"HTTP/1.1 200")
        e.close()
        b.close()
    finally:
        d.stop()


def test_client_body_cap_with_chunked_and_single_bodies():
    """--max-client-body-bytes with chunked bodies: the buffer grows to --max-body-bytes + 1 at
    most, so a chunked body within --max-body-bytes fits a cap of that size (it held its doubled
    buffer: 429); a chunked body refused by the cap still counts against --max-body-bytes (413
    once past it, not after reading it all); a body alone larger than the cap is 413
    max_client_body_bytes (waiting cannot help), not 429."""
    d = Daemon("--max-body-bytes", "3000000", "--max-client-body-bytes", "3000001",
               "--body-min-rate", "0")
    try:
        s = Session(d)
        body = json.dumps({"vertices": CUBE_V, "simplices": CUBE_S}).encode()
        body = body[:-1] + b" " * (2_500_000 - len(body)) + b"}"
        r = s.req("PUT", "/complex", data=iter([body[i:i + 65536] for i in range(0, len(body), 65536)]),
                  headers={"Content-Type": "application/json"})   # chunked
        assert r.status_code == 200, r.text[:300]
    finally:
        d.stop()
    d = Daemon("--max-body-bytes", "1000000", "--max-client-body-bytes", "600000")
    try:
        s = Session(d)
        k = raw_socket(d, "127.0.0.2", timeout=10)
        k.sendall(put_head(s, "Transfer-Encoding: chunked"))
        sent, answer = chunks_until_answered(k, 8 << 20)
        k.close()
        assert answer.startswith(b"HTTP/1.1 413") and sent < (3 << 20), (sent, answer[:200])
        r = s.req("PUT", "/complex", data=b"{" + b" " * 700_000 + b"}",
                  headers={"Content-Type": "application/json"})
        assert r.status_code == 413 and r.json()["limit_name"] == "max_client_body_bytes", r.text
        assert "Retry-After" not in r.headers
    finally:
        d.stop()
