#!/usr/bin/python3
"""The daemon's cold path (docs/BENCHMARKS.md "The daemon's cold path", DECISIONS 49): how long
a level takes the daemon to build, for a new daemon's first session and for the next session
(a model built after another was freed), with the kept blocks and level threads and without.

usage: cold_bench.py [--cubes N] [--level L] [--rounds R] [--old PATH]

Per round and configuration a fresh daemon on a free loopback port: session 1 PUTs 10^3 cubes
(6000 tetrahedra) and asks for GET /levels/3/stats ("first"), is deleted, then session 2 does
the same ("next"); the time of the level request and the daemon's minor page faults during it
(/proc/PID/stat). Configurations, alternating within each round: `--old PATH` (another build
of subdivd, e.g. main before a change), this build with `--keep-memory 0 --level-threads 1`
(nothing kept, one thread), `--level-threads 1` (kept blocks, one thread), and the defaults
(kept blocks, the level on every core). Prints the medians; both sessions' levels are checked
to have the same counts.
"""
import argparse
import http.client
import json
import os
import pathlib
import statistics
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from http_bench import SUBDIVD, call, mesh_body, start_daemon  # noqa: E402


def minflt(pid):
    return int(open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[7])


def one_level(conn, pid, body, level):
    _, d = call(conn, "POST", "/v1/sessions", {})
    j = json.loads(d)
    base, auth = f"/v1/sessions/{j['id']}", {"Authorization": f"Bearer {j['token']}"}
    status, _ = call(conn, "PUT", base + "/complex", body, auth)
    assert status == 200, status
    f0, t0 = minflt(pid), time.perf_counter()
    status, stats = call(conn, "GET", f"{base}/levels/{level}/stats", None, auth)
    t1, f1 = time.perf_counter(), minflt(pid)
    assert status == 200, stats[:300]
    call(conn, "DELETE", base, None, auth)
    return t1 - t0, f1 - f0, json.loads(stats)["counts"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cubes", type=int, default=10)
    ap.add_argument("--level", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--old", help="another subdivd binary, measured in the same rounds")
    a = ap.parse_args()
    body = mesh_body("cubes", a.cubes)
    configs = ([("old binary", a.old, [])] if a.old else []) + [
        ("nothing kept, 1 thread", SUBDIVD, ["--keep-memory", "0", "--level-threads", "1"]),
        ("kept blocks, 1 thread", SUBDIVD, ["--level-threads", "1"]),
        ("defaults (kept, all cores)", SUBDIVD, []),
    ]
    res = {c[0]: [] for c in configs}
    for _ in range(a.rounds):
        for name, binary, args in configs:
            p, port = start_daemon(binary, args)
            try:
                conn = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
                t1, f1, c1 = one_level(conn, p.pid, body, a.level)
                time.sleep(0.1)   # the first session's model freed, within the second kept
                t2, f2, c2 = one_level(conn, p.pid, body, a.level)
                assert c1 == c2
                res[name].append((t1, f1, t2, f2))
            finally:
                p.terminate()
                p.wait()
    cells = c1.get("tetrahedra", 0) + c1.get("octahedra", 0)
    print(f"== the daemon's cold path: {a.cubes}^3 cubes, level {a.level} ({cells} cells), "
          f"{a.rounds} rounds, medians (cpus: {os.cpu_count()})")
    print(f"{'configuration':32} {'first level':>12} {'faults':>8} {'next level':>12} {'faults':>8}")
    for name, rows in res.items():
        med = [statistics.median(r[i] for r in rows) for i in range(4)]
        print(f"{name:32} {med[0] * 1e3:9.0f} ms {med[1]:8.0f} {med[2] * 1e3:9.0f} ms "
              f"{med[3]:8.0f}")


if __name__ == "__main__":
    main()
