"""Big core blocks kept between builds (api/mem.c, --keep-memory; DECISIONS 49).

The allocator's own rules are checked by tests/api/keep.c (build/keep_test). Here the daemon:
a level built in pages another session's level left behind — handed out filled with 0xff bytes
(SUBDIVD_KEEP_POISON=1), so any read of memory the core did not write would show — is the same
bytes as the level built by a daemon that keeps nothing; the blocks are reused (the counters of
/metrics say so), stay counted against the budget, and go back to the system after a second."""
import json
import os
import random
import subprocess
import time

import pytest
import requests

from conftest import REPO
from daemon import SANITIZED, Daemon, Session

KEEP = os.environ.get("KEEP_TEST", str(REPO / "build" / "keep_test"))


def test_the_allocator_keeps_and_gives_back():
    r = subprocess.run([KEEP], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert ", 0 failed" in r.stdout


def cubes(nx, ny, nz, jitter, seed):
    """A block of nx * ny * nz jittered cubes of 6 tetrahedra each, a curve hanging off a corner
    and a triangle fin on one face (so kept blocks meet every dimension's arrays)."""
    rnd = random.Random(seed)
    V, idx = [], {}
    for k in range(nz + 1):
        for j in range(ny + 1):
            for i in range(nx + 1):
                idx[i, j, k] = len(V)
                V.append([i + jitter * rnd.uniform(-1, 1), j + jitter * rnd.uniform(-1, 1),
                          k + jitter * rnd.uniform(-1, 1)])
    S = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                c = [idx[i + a, j + b, k + cc] for cc in (0, 1) for b in (0, 1) for a in (0, 1)]
                for t in ((0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7),
                          (0, 4, 6, 7)):
                    S.append([c[x] for x in t])
    o = len(V)
    V += [[-1.0, -1.0, -1.0], [-2.0, -1.5, -1.0], [nx / 2, -1.5, 0.5]]
    S += [[idx[0, 0, 0], o], [o, o + 1], [idx[0, 0, 0], idx[1, 0, 0], o + 2]]
    return {"vertices": V, "simplices": S}


def metrics(d):
    out = {}
    for line in requests.get(d.url + "/metrics", timeout=10).text.splitlines():
        if line.startswith("subdivd_kept") or line.startswith("subdivd_memory_used"):
            k, v = line.split()
            out[k] = float(v)
    return out


def build(d, body, level, fmt="json"):
    s = Session(d)
    assert s.put_complex(body).status_code == 200
    r = s.level(level, format=fmt)
    assert r.status_code == 200, r.text
    return s, r.content


@pytest.mark.skipif(SANITIZED, reason="under AddressSanitizer no block is kept (api/mem.c)")
def test_levels_built_in_kept_pages_are_the_same_bytes():
    first = cubes(7, 6, 6, 0.12, 1)
    second = cubes(6, 7, 6, 0.15, 2)     # other data, about the same size classes
    keep = Daemon(env={"SUBDIVD_KEEP_POISON": "1"})
    plain = Daemon("--keep-memory", "0")
    try:
        m0 = metrics(keep)
        s, _ = build(keep, first, 3, "glb")
        first_mapped = metrics(keep)["subdivd_kept_mapped_total"] - m0["subdivd_kept_mapped_total"]
        s.delete()
        t = time.time()   # the last reference may go with the download's end, just after
        while (before := metrics(keep))["subdivd_kept_bytes"] == 0 and time.time() < t + 0.8:
            time.sleep(0.02)
        assert before["subdivd_kept_bytes"] > 0
        assert before["subdivd_memory_used_bytes"] >= before["subdivd_kept_bytes"]
        s, got_json = build(keep, second, 3)
        got_glb = s.level(3, format="glb").content
        after = metrics(keep)
        # the second session's build took the blocks the first one left: it mapped far fewer
        # fresh ones than the first build did (which could reuse only its own transients)
        second_mapped = after["subdivd_kept_mapped_total"] - before["subdivd_kept_mapped_total"]
        assert after["subdivd_kept_reused_total"] > before["subdivd_kept_reused_total"]
        assert second_mapped < first_mapped / 2, (first_mapped, second_mapped)
        p, want_json = build(plain, second, 3)
        want_glb = p.level(3, format="glb").content
        assert got_json == want_json
        assert got_glb == want_glb
        assert metrics(plain)["subdivd_kept_reused_total"] == 0
        s.delete()
        t = time.time()    # idle for over a second: given back by the main loop
        while (m := metrics(keep))["subdivd_kept_bytes"] > 0 and time.time() < t + 5:
            time.sleep(0.1)
        assert m["subdivd_kept_bytes"] == 0, m
        assert time.time() - t > 0.9      # not before its second
    finally:
        keep.stop()
        plain.stop()


@pytest.mark.skipif(SANITIZED, reason="under AddressSanitizer no block is kept (api/mem.c)")
def test_edits_after_a_build_in_kept_pages():
    """An edit walks the by-column index made with the levels, in reused pages too: the edited
    level equals a fresh build of the moved control points in a daemon that keeps nothing."""
    body = cubes(5, 5, 5, 0.1, 3)
    keep = Daemon(env={"SUBDIVD_KEEP_POISON": "1"})
    plain = Daemon("--keep-memory", "0")
    try:
        s, _ = build(keep, cubes(5, 6, 5, 0.1, 4), 3)
        s.delete()
        s, _ = build(keep, body, 3)
        moves = [{"index": v, "position": [body["vertices"][v][0] + 0.3,
                                           body["vertices"][v][1] - 0.2,
                                           body["vertices"][v][2] + 0.1]} for v in (40, 41, 97)]
        r = s.req("PATCH", "/control-points", json={"moves": moves}, headers={"If-Match": "*"})
        assert r.status_code == 200, r.text
        moved = {"vertices": [list(p) for p in body["vertices"]], "simplices": body["simplices"]}
        for m in moves:
            moved["vertices"][m["index"]] = m["position"]
        _, want = build(plain, moved, 3)
        got = json.loads(s.level(3, format="json").content)
        want = json.loads(want)
        assert got.pop("version") != want.pop("version")    # the edit made a version
        assert got == want
    finally:
        keep.stop()
        plain.stop()
