#!/usr/bin/python3
"""make soak: the daemon under a mixed load for SOAK_SECONDS (default 600), on loopback only.

Well-behaved: SOAK_SESSIONS (16) sessions from 127.0.0.1, each in its own thread, edit control
points (PATCH), read small answers (the session, a level's stats) and stream a level (GLB),
one request after the other with SOAK_THINK (0.05) seconds between them, as an interactive
client does. Hostile, from 127.0.0.2 and up (so per-client limits apply to them
only), bounded in count: slowloris sockets sending request headers a byte at a time, idle
keep-alive sockets, clients sending bodies over the limit, clients sending garbage.

Reported: requests made, the latency of the well-behaved small requests (p50, p99) and the time
to first byte of their streams, their answers by status, what the hostile clients got, the
daemon's resident size at start, its peak after the warm-up (the first 10% of the run, at least
10 s) and at the end, after every session was deleted. Goals: no 5xx for the well-behaved, p99
of small requests <= 100 ms, the final resident size within 10% + 50 MB of the one at start.
Exit status 1 when a goal is missed.

    SOAK_SECONDS=60 /usr/bin/python3 bench/soak.py [extra daemon flags...]
"""
import collections
import json
import os
import random
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "python"))

import requests  # noqa: E402

from daemon import Daemon, Session  # noqa: E402
from test_hardening import raw_socket  # noqa: E402  (a socket from a given loopback address)

SECONDS = float(os.environ.get("SOAK_SECONDS", "600"))
SESSIONS = int(os.environ.get("SOAK_SESSIONS", "16"))
SLOWLORIS = int(os.environ.get("SOAK_SLOWLORIS", "48"))
IDLE = int(os.environ.get("SOAK_IDLE", "16"))
OVERSIZE = int(os.environ.get("SOAK_OVERSIZE", "2"))
GARBAGE = int(os.environ.get("SOAK_GARBAGE", "2"))
THINK = float(os.environ.get("SOAK_THINK", "0.05"))   # seconds a well-behaved client pauses
PER_ADDRESS = 8          # hostile sockets per source address (127.0.0.2, .3, ...)
MAX_BODY = 1 << 20


def block(n):
    """n^3 unit cubes as 6 tetrahedra each (bench/make_mesh.py's block), as a PUT /complex body."""
    idx = lambda i, j, k: (i * (n + 1) + j) * (n + 1) + k  # noqa: E731
    V = [[i, j, k] for i in range(n + 1) for j in range(n + 1) for k in range(n + 1)]
    S = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                c = [idx(i + a, j + b, k + d) for a in (0, 1) for b in (0, 1) for d in (0, 1)]
                for t in ((0, 1, 3, 7), (0, 3, 2, 7), (0, 2, 6, 7), (0, 6, 4, 7), (0, 4, 5, 7),
                          (0, 5, 1, 7)):
                    S.append([c[x] for x in t])
    return {"vertices": V, "simplices": S, "attributes": {"t": [float(v[0]) for v in V]}}


class Stats:
    def __init__(self):
        self.mu = threading.Lock()
        self.small = []          # seconds
        self.ttfb = []
        self.status = collections.Counter()
        self.hostile = collections.Counter()
        self.requests = 0

    def add(self, kind, dt, status):
        with self.mu:
            self.requests += 1
            self.status[status] += 1
            (self.small if kind == "small" else self.ttfb).append(dt)

    def bad(self, what):
        with self.mu:
            self.hostile[what] += 1


def pct(xs, p):
    if not xs:
        return float("nan")
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p / 100 * len(xs)))]


def well_behaved(d, body, stop, st, sessions):
    http = requests.Session()
    try:
        s = Session(d, http=http)
    except Exception:
        st.add("small", 0, "session-refused")
        return
    sessions.append(s)
    r = s.put_complex(body)
    st.add("small", r.elapsed.total_seconds(), r.status_code)
    rnd = random.Random(s.id)
    n = len(body["vertices"])
    while not stop.wait(THINK):
        try:
            t = time.time()
            r = s.req("GET", "")
            st.add("small", time.time() - t, r.status_code)
            v = r.json().get("version", 1) if r.status_code == 200 else 1
            i = rnd.randrange(n)
            p = [c + rnd.uniform(-0.05, 0.05) for c in body["vertices"][i]]
            t = time.time()
            r = s.req("PATCH", "/control-points", json={"moves": [{"index": i, "position": p}]},
                      headers={"If-Match": f'"{v}"'})
            st.add("small", time.time() - t, r.status_code)
            t = time.time()
            r = s.req("GET", "/levels/2/stats")
            st.add("small", time.time() - t, r.status_code)
            t = time.time()
            r = s.req("GET", "/levels/2", stream=True)
            first = None
            for chunk in r.iter_content(65536):
                if first is None:
                    first = time.time() - t
            st.add("stream", first if first is not None else time.time() - t, r.status_code)
        except requests.RequestException as e:
            st.add("small", 0, type(e).__name__)
            time.sleep(0.1)


def address(i):
    return f"127.0.0.{2 + i // PER_ADDRESS}"


def slowloris(d, stop, st, base):
    """SLOWLORIS sockets trickling headers, reopened when the daemon closes them."""
    socks = [None] * SLOWLORIS
    while not stop.wait(0.5):
        for i in range(SLOWLORIS):
            try:
                if socks[i] is None:
                    socks[i] = raw_socket(d, address(base + i))
                    socks[i].sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
                    socks[i].setblocking(False)
                    st.bad("slowloris opened")
                socks[i].send(b"X")
            except OSError:
                if socks[i] is not None:
                    socks[i].close()
                    st.bad("slowloris closed by the daemon")
                socks[i] = None
    with st.mu:   # what the daemon let trickle to the end (a header deadline would close them)
        st.hostile["slowloris open at the end"] += sum(k is not None for k in socks)
    for k in socks:
        if k is not None:
            k.close()


def idle(d, stop, st, base):
    """IDLE keep-alive sockets: one request, then silence; reopened when closed."""
    socks = [None] * IDLE
    while not stop.wait(1.0):
        for i in range(IDLE):
            try:
                if socks[i] is None:
                    k = raw_socket(d, address(base + i))
                    k.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
                    k.recv(4096)
                    k.setblocking(False)
                    socks[i] = k
                    st.bad("idle opened")
                elif socks[i].recv(1) == b"":
                    raise OSError
            except BlockingIOError:
                pass
            except OSError:
                if socks[i] is not None:
                    socks[i].close()
                    st.bad("idle closed by the daemon")
                socks[i] = None
    for k in socks:
        if k is not None:
            k.close()


def oversize(d, stop, st, base, token_session):
    """A body announced over --max-body-bytes, then sent anyway: expect 413 before it is read."""
    head = (f"PUT /v1/sessions/{token_session.id}/complex HTTP/1.1\r\nHost: x\r\n"
            f"Authorization: Bearer {token_session.token}\r\nContent-Type: application/json\r\n"
            f"Content-Length: {8 * MAX_BODY}\r\nConnection: close\r\n\r\n").encode()
    while not stop.wait(0.2):
        try:
            k = raw_socket(d, address(base), timeout=5)
            k.sendall(head)
            try:
                k.sendall(b" " * 65536)
            except OSError:
                pass
            answer = k.recv(64)
            k.close()
            st.bad("oversize " + (answer.split(b" ")[1].decode() if answer.count(b" ") else "cut"))
        except OSError:
            st.bad("oversize refused connection")


def garbage(d, stop, st, base):
    rnd = random.Random(base)
    while not stop.wait(0.2):
        try:
            k = raw_socket(d, address(base), timeout=5)
            k.sendall(bytes(rnd.randrange(256) for _ in range(rnd.randrange(1, 4096))) + b"\r\n\r\n")
            answer = k.recv(64)
            k.close()
            st.bad("garbage " + (answer.split(b" ")[1].decode(errors="replace")
                                 if answer.count(b" ") else "closed"))
        except OSError:
            st.bad("garbage cut")


def main():
    flags = ["--max-body-bytes", str(MAX_BODY), "--max-sessions", str(SESSIONS + 8),
             "--max-sessions-per-client", str(SESSIONS + 8),
             "--log-level", "warn"] + sys.argv[1:]
    d = Daemon(*flags)
    st = Stats()
    stop = threading.Event()
    sessions = []
    body = block(4)
    try:
        rss_start = d.rss_bytes()
        victim = Session(d)
        base = 0
        hostile = [threading.Thread(target=slowloris, args=(d, stop, st, base))]
        base += SLOWLORIS
        hostile.append(threading.Thread(target=idle, args=(d, stop, st, base)))
        base += IDLE
        for i in range(OVERSIZE):
            hostile.append(threading.Thread(target=oversize, args=(d, stop, st, base, victim)))
            base += PER_ADDRESS
        for i in range(GARBAGE):
            hostile.append(threading.Thread(target=garbage, args=(d, stop, st, base)))
            base += PER_ADDRESS
        good = [threading.Thread(target=well_behaved, args=(d, body, stop, st, sessions))
                for _ in range(SESSIONS)]
        t0 = time.time()
        for t in hostile + good:
            t.daemon = True
            t.start()
        warm = min(max(10.0, SECONDS / 10), SECONDS / 2)
        peak, warmed = 0, False
        while time.time() - t0 < SECONDS:
            time.sleep(0.5)
            if not warmed and time.time() - t0 >= warm:
                with st.mu:   # the warm-up's latencies are not the steady state's
                    st.small.clear()
                    st.ttfb.clear()
                warmed = True
            if warmed:
                peak = max(peak, d.rss_bytes())
            if not d.alive():
                break
        stop.set()
        for t in good + hostile:
            t.join(30)
        alive = d.alive()
        for s in sessions + [victim]:
            try:
                s.delete()
            except requests.RequestException:
                pass
        time.sleep(2)
        rss_end = d.rss_bytes() if alive else 0
    finally:
        code = d.stop()
    fivexx = sum(n for s, n in st.status.items() if isinstance(s, int) and s >= 500)
    others = {str(k): v for k, v in sorted(st.status.items(), key=lambda x: str(x[0]))}
    p50, p99 = pct(st.small, 50) * 1e3, pct(st.small, 99) * 1e3
    report = {
        "seconds": SECONDS, "sessions": SESSIONS, "requests": st.requests,
        "small_ms": {"p50": round(p50, 2), "p99": round(p99, 2), "n": len(st.small)},
        "stream_ttfb_ms": {"p50": round(pct(st.ttfb, 50) * 1e3, 2),
                           "p99": round(pct(st.ttfb, 99) * 1e3, 2), "n": len(st.ttfb)},
        "status": others, "hostile": dict(sorted(st.hostile.items())),
        "rss_mb": {"start": round(rss_start / 1e6, 1), "peak_after_warmup": round(peak / 1e6, 1),
                   "end_after_delete": round(rss_end / 1e6, 1)},
        "daemon_exit": code,
    }
    goals = {
        "no 5xx": alive and fivexx == 0,
        "p99 <= 100 ms": p99 <= 100,
        "RSS back within 10% + 50 MB": alive and rss_end <= rss_start * 1.1 + 50e6,
    }
    print(json.dumps(report, indent=1))
    for g, ok in goals.items():
        print(f"{'ok  ' if ok else 'FAIL'} {g}")
    return 0 if all(goals.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
