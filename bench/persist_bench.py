#!/usr/bin/python3
"""The durable session stores (docs/BENCHMARKS.md "Persistence", docs/SERVICE.md "Persistence").

usage: persist_bench.py [--edits N] [--sessions N] [--cubes N]

1. PATCH latency: one-point edits (each answered only once it is in the store) of a session of
   N³ cubes whose level 2 is computed, one after another over one kept-alive connection, with
   --store memory, sqlite:FILE and redis://127.0.0.1:PORT (a redis-server of its own, no AOF) —
   medians and what each store adds to memory's (goal: <= 1 ms at the median).
2. Restart: N sessions stored (a small complex and 5 edits each), the daemon killed (-9) and
   started again: seconds until /readyz answers 200, and until every one of the N sessions has
   answered a GET once (each is loaded from the store on that first GET) — goal: ready to serve
   in <= 2 s.
"""
import argparse
import http.client
import json
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests" / "python"))
from http_bench import SUBDIVD, call, mesh_body  # noqa: E402
from redisd import REDIS_SERVER, RedisServer  # noqa: E402


def start(store):
    p = subprocess.Popen([SUBDIVD, "--port", "0", "--log-level", "warn", "--store", store,
                          "--session-rate", "1000000", "--max-sessions", "64",
                          "--max-stored-sessions-per-client", "0"],
                         stdout=subprocess.PIPE, text=True)
    line = p.stdout.readline()
    return p, int(line.split(":")[2].split("/")[0])


def wait_ready(port, deadline=30):
    t = time.time() + deadline
    while time.time() < t:
        try:
            c = http.client.HTTPConnection("127.0.0.1", port, timeout=2)
            if call(c, "GET", "/readyz")[0] == 200:
                return
        except OSError:
            time.sleep(0.002)
    raise SystemExit("the daemon did not become ready")


def session(conn, body):
    st, data = call(conn, "POST", "/v1/sessions", {})
    j = json.loads(data)
    auth = {"Authorization": "Bearer " + j["token"]}
    base = "/v1/sessions/" + j["id"]
    st, data = call(conn, "PUT", base + "/complex", body, auth)
    if st != 200:
        raise SystemExit(f"PUT /complex: {st} {data[:200]!r}")
    return base, auth, json.loads(data)["version"]


def edit_latencies(store, body, n):
    p, port = start(store)
    try:
        conn = http.client.HTTPConnection("127.0.0.1", port)
        base, auth, v = session(conn, body)
        st, _ = call(conn, "GET", base + "/levels/2/stats", None, auth)
        assert st == 200
        out = []
        x0 = body["vertices"][7]
        for i in range(n + 20):
            h = dict(auth, **{"If-Match": f'"{v}"'})
            t = time.perf_counter()
            st, data = call(conn, "PATCH", base + "/control-points",
                            {"moves": [{"index": 7, "position": [x0[0] + 0.001 * (i % 20), x0[1], x0[2]]}]}, h)
            dt = time.perf_counter() - t
            if st != 200:
                raise SystemExit(f"PATCH: {st} {data[:200]!r}")
            v = json.loads(data)["version"]
            if i >= 20:   # the first edits build the edit maps
                out.append(dt)
        return out
    finally:
        p.kill()
        p.wait()


def restart(store, n):
    small = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]],
             "simplices": [[0, 1, 2, 3], [1, 2, 3, 4]]}
    p, port = start(store)
    made = []
    try:
        conn = http.client.HTTPConnection("127.0.0.1", port)
        for i in range(n):
            base, auth, v = session(conn, small)
            for k in range(5):
                st, data = call(conn, "PATCH", base + "/control-points",
                                {"moves": [{"index": 4, "position": [1, 1, 1 + 0.01 * k]}]},
                                dict(auth, **{"If-Match": f'"{v}"'}))
                v = json.loads(data)["version"]
            made.append((base, auth, v))
    finally:
        p.kill()
        p.wait()
    t0 = time.perf_counter()
    p, port = start(store)
    try:
        wait_ready(port)
        ready = time.perf_counter() - t0
        conn = http.client.HTTPConnection("127.0.0.1", port)
        for base, auth, v in made:
            st, data = call(conn, "GET", base, None, auth)
            if st != 200 or json.loads(data)["version"] != v:
                raise SystemExit(f"GET {base}: {st} {data[:200]!r}")
        served = time.perf_counter() - t0
        return ready, served
    finally:
        p.kill()
        p.wait()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--edits", type=int, default=300)
    ap.add_argument("--sessions", type=int, default=1000)
    ap.add_argument("--cubes", type=int, default=6)
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="persist-bench-")
    redis = RedisServer(tmp).start() if REDIS_SERVER else None
    try:
        stores = [("memory", "memory"), ("sqlite", f"sqlite:{tmp}/bench.db")]
        if redis:
            stores.append(("redis", redis.url))
        body = mesh_body("cubes", a.cubes)
        print(f"persistence: PATCH latency, {a.edits} one-point edits, {a.cubes}^3 cubes "
              f"({len(body['simplices'])} tetrahedra) with level 2 computed")
        med = {}
        for name, spec in stores:
            lat = edit_latencies(spec, body, a.edits)
            med[name] = statistics.median(lat)
            p90 = sorted(lat)[int(0.9 * len(lat))]
            added = "" if name == "memory" else \
                f"  added {1e3 * (med[name] - med['memory']):+.3f} ms (goal <= 1 ms: " \
                f"{'met' if med[name] - med['memory'] <= 1e-3 else 'MISSED'})"
            print(f"  {name:7s} median {1e3 * med[name]:.3f} ms  p90 {1e3 * p90:.3f} ms{added}")
        for name, spec in stores[1:]:
            if name == "redis":
                redis.stop()
                redis.start()
            ready, served = restart(spec, a.sessions)
            print(f"  restart ({name}, {a.sessions} sessions stored): ready in {ready:.3f} s, all "
                  f"{a.sessions} served once in {served:.3f} s (goal: ready <= 2 s: "
                  f"{'met' if ready <= 2 else 'MISSED'}; all served <= 2 s: "
                  f"{'met' if served <= 2 else 'MISSED'})")
    finally:
        if redis:
            redis.stop()
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
