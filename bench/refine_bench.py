#!/usr/bin/python3
"""Refine then level L against a fresh build (docs/BENCHMARKS.md, issue 15): on 10^3 cubes (6000
tetrahedra), one tetrahedron refined red (POST /refine, its green closure around) and level L
asked for (GET /levels/{L}/stats), against the same refined complex posted to a new session
(PUT /complex) and level L asked for — the time a client waits in each case, over HTTP.

usage: refine_bench.py [--cubes N] [--level L] [--rounds R]

Prints the medians, the ratio and the goal (<= 1/4). Also checks that both sessions' level L is
the same (GET /levels/{L}?format=json, vertices compared exactly).
"""
import argparse
import http.client
import json
import pathlib
import statistics
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from http_bench import call, mesh_body, start_daemon  # noqa: E402


def timed(conn, method, path, body=None, headers=None):
    t = time.perf_counter()
    status, data = call(conn, method, path, body, headers)
    if status not in (200, 201):
        raise SystemExit(f"{method} {path}: {status} {data[:300]!r}")
    return time.perf_counter() - t, data


def session(conn):
    _, data = timed(conn, "POST", "/v1/sessions", {})
    j = json.loads(data)
    return f"/v1/sessions/{j['id']}", {"Authorization": f"Bearer {j['token']}"}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cubes", type=int, default=10)
    ap.add_argument("--level", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    body = mesh_body("cubes", a.cubes)
    target = body["simplices"][len(body["simplices"]) // 3]
    proc, port = start_daemon()
    try:
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
        rows = []
        for _ in range(a.rounds):
            base, auth = session(conn)
            timed(conn, "PUT", base + "/complex", body, auth)
            timed(conn, "GET", f"{base}/levels/{a.level}/stats", None, auth)
            t_refine, _ = timed(conn, "POST", base + "/refine",
                                {"select": {"simplices": [target]}}, auth)
            t_level, _ = timed(conn, "GET", f"{base}/levels/{a.level}/stats", None, auth)
            _, cx = timed(conn, "GET", base + "/complex", None, auth)
            refined = json.loads(cx)
            fresh_base, fresh_auth = session(conn)
            # the same control data: the refinement keeps its untouched tetrahedra's diagonals
            # and orientation (DECISIONS 17), so they go with the vertices and simplices
            fresh_body = {k: refined[k] for k in ("vertices", "simplices", "diagonals",
                                                  "reoriented") if k in refined}
            t_put, _ = timed(conn, "PUT", fresh_base + "/complex", fresh_body, fresh_auth)
            t_fresh, stats = timed(conn, "GET", f"{fresh_base}/levels/{a.level}/stats", None,
                                   fresh_auth)
            _, l1 = timed(conn, "GET", f"{base}/levels/{a.level}?format=json", None, auth)
            _, l2 = timed(conn, "GET", f"{fresh_base}/levels/{a.level}?format=json", None,
                          fresh_auth)
            same = json.loads(l1)["vertices"] == json.loads(l2)["vertices"]
            rows.append((t_refine, t_level, t_put, t_fresh, same, json.loads(stats)))
            for b, h in ((base, auth), (fresh_base, fresh_auth)):
                call(conn, "DELETE", b, None, h)
        med = lambda k: statistics.median(r[k] for r in rows)
        reuse, fresh = med(0) + med(1), med(2) + med(3)
        st = rows[-1][5]
        cells = st["counts"]["tetrahedra"] + st["counts"]["octahedra"]
        print(f"== refine one tetrahedron of {a.cubes}^3 cubes, then level {a.level} "
              f"({cells} cells, {st['counts']['vertices']} vertices), {a.rounds} rounds, medians")
        print(f"refine + level: {med(0) * 1e3:.0f} + {med(1) * 1e3:.0f} = {reuse * 1e3:.0f} ms")
        print(f"fresh build of the refined complex: PUT {med(2) * 1e3:.0f} + level "
              f"{med(3) * 1e3:.0f} = {fresh * 1e3:.0f} ms")
        equal = all(r[4] for r in rows)
        print(f"levels equal (json vertices): {equal}")
        ratio = reuse / fresh
        print(f"goal refine + level <= 1/4 of a fresh build: {ratio:.2f} — "
              f"{'met' if ratio <= 0.25 else 'NOT met'}")
        if not equal:  # a figure of two different results measures nothing
            raise SystemExit("refine_bench: the refined session's level differs from the fresh "
                             "build of the same control data")
    finally:
        proc.terminate()
        proc.wait()


if __name__ == "__main__":
    main()
