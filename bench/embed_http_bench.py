#!/usr/bin/python3
"""Embedded models over HTTP (docs/BENCHMARKS.md "Embedded models", issue 17).

usage: embed_http_bench.py [--cubes N] [--level L] [--points N] [--edits N]

A block of N³ cubes, level L computed (10 and 3: 1.56 M cells), a model of POINTS random points
inside it bound by PUT /embedded/m (the binary body), then one-point control-point edits, each
followed by GET /embedded/m/delta?since=<the version before>&format=bin — the time a client
waits for the model's update after its edit (the edit's own time is printed apart). Goal: <= 5 ms
at the median for 1 M model vertices. Also the binding's time as the PUT answers it.
"""
import argparse
import http.client
import json
import pathlib
import random
import statistics
import struct
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from http_bench import call, mesh_body, start_daemon  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cubes", type=int, default=10)
    ap.add_argument("--level", type=int, default=3)
    ap.add_argument("--points", type=int, default=1000000)
    ap.add_argument("--edits", type=int, default=50)
    a = ap.parse_args()
    p, port = start_daemon()
    try:
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
        st, body = call(conn, "POST", "/v1/sessions", {})
        j = json.loads(body)
        base, auth = f"/v1/sessions/{j['id']}", {"Authorization": f"Bearer {j['token']}"}
        cx = mesh_body("cubes", a.cubes)
        st, body = call(conn, "PUT", base + "/complex", cx, auth)
        assert st == 200, body[:200]
        version = json.loads(body)["version"]
        st, body = call(conn, "GET", f"{base}/levels/{a.level}/stats", None, auth)
        stats = json.loads(body)["counts"]
        cells = stats["tetrahedra"] + stats["octahedra"]
        rnd = random.Random(7)
        lo, hi = 0.5, a.cubes - 0.5   # inside the subdivided block (its rounded edges shrink it)
        xyz = [rnd.uniform(lo, hi) for _ in range(3 * a.points)]
        blob = struct.pack(f"<II{3 * a.points}d", a.points, 0, *xyz)
        h = dict(auth, **{"Content-Type": "application/octet-stream", "If-Match": f'"{version}"'})
        t0 = time.perf_counter()
        conn.request("PUT", f"{base}/embedded/m?level={a.level}&outside=nearest", body=blob, headers=h)
        r = conn.getresponse()
        body = r.read()
        put_s = time.perf_counter() - t0
        assert r.status == 200, body[:300]
        j = json.loads(body)
        version = j["version"]
        print(f"embedded over HTTP: {a.points} model vertices, cubes {a.cubes} level {a.level} "
              f"({cells} cells)")
        print(f"  PUT /embedded/m (binary, {len(blob) / 1e6:.0f} MB): {put_s:.2f} s, the binding "
              f"{j['embedded']['seconds']:.2f} s of it")
        inner = [i for i, v in enumerate(cx["vertices"]) if all(1 <= c <= a.cubes - 1 for c in v)]
        waits, edits, moved = [], [], []
        for k in range(a.edits + 3):
            i = inner[k % len(inner)]
            x = cx["vertices"][i]
            pos = [x[0] + 0.05 * ((k % 3) - 1), x[1] + 0.04, x[2] - 0.03]
            t0 = time.perf_counter()
            st, body = call(conn, "PATCH", base + "/control-points",
                            {"moves": [{"index": i, "position": pos}]},
                            dict(auth, **{"If-Match": f'"{version}"'}))
            t1 = time.perf_counter()
            assert st == 200, body[:200]
            since, version = version, json.loads(body)["version"]
            st, body = call(conn, "GET", f"{base}/embedded/m/delta?since={since}&format=bin", None, auth)
            t2 = time.perf_counter()
            assert st == 200 and body[:4] == b"SDD1", body[:200]
            if k >= 3:   # the first edits build the edit maps
                edits.append(t1 - t0)
                waits.append(t2 - t1)
                moved.append(struct.unpack_from("<I", body, 16)[0])
        med = statistics.median(waits)
        print(f"  one-point edit: PATCH median {1e3 * statistics.median(edits):.2f} ms; then the "
              f"model's delta: median {1e3 * med:.2f} ms, p90 {1e3 * sorted(waits)[int(0.9 * len(waits))]:.2f} ms, "
              f"{int(statistics.median(moved))} model vertices moved (goal <= 5 ms: "
              f"{'met' if med <= 5e-3 else 'MISSED'})")
    finally:
        p.terminate()
        p.wait()


if __name__ == "__main__":
    main()
