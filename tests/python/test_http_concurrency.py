"""16 sessions driven in parallel give the same bytes as the same requests run one at a time, and a
long computation in one session does not hold up another session's requests."""
import threading
import time

import requests

from conftest import REPO, make_mesh_file
from daemon import Daemon, Session, complex_from_text

MESHES = [
    {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 2, 3]]},
    {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], "simplices": [[0, 1, 2, 3], [1, 2, 3, 4]]},
    {"vertices": [[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [-0.5, 1, 0], [-1, 0, 0], [0, -1, 0.3]],
     "simplices": [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [0, 5, 1]]},
    {"vertices": [[0, 0, 0], [1, 0, 0], [2, 1, 0], [3, 1, 1], [5, 5, 5]], "simplices": [[0, 1], [1, 2], [2, 3], [4]]},
    complex_from_text(REPO / "examples" / "mixed.txt"),
]
RULES = [{}, {"solid_scheme": "averaged"}, {"surface_weights": "loop"},
         {"solid_scheme": "averaged", "surface_weights": "loop"}]


def script(s, k):
    """The requests of worker k; returns [(status, body bytes)] of everything deterministic."""
    out = []

    def rec(r):
        out.append((r.status_code, r.content))

    mesh = MESHES[k % len(MESHES)]
    rec(s.req("PUT", "/rules", json=RULES[k % len(RULES)]))
    rec(s.put_complex(mesh))
    rec(s.req("GET", "/complex"))
    for level in (0, 1, 2):
        rec(s.level(level, format="json"))
        rec(s.level(level, format="glb"))
        if k % 2:
            rec(s.level(level, format="vtu", slice="0,0,1,0.2"))
    st = s.req("GET", "/levels/2/stats").json()
    out.append((200, repr(st["counts"]).encode()))
    rec(s.put_complex({"vertices": [[0, 0, 0]], "simplices": [[3]]}))      # refused
    rec(s.req("PUT", "/rules", json={"solid_scheme": "nope"}))              # refused
    rec(s.level(1, format="gltf"))
    rec(s.put_complex(MESHES[(k + 1) % len(MESHES)]))
    rec(s.level(2, format="json"))
    return out


def test_parallel_equals_sequential():
    d = Daemon("--max-sessions", "100")
    try:
        sequential = []
        for k in range(16):
            sequential.append(script(Session(d), k))
        parallel = [None] * 16
        errors = []

        def worker(k):
            try:
                parallel[k] = script(Session(d, http=requests.Session()), k)
            except Exception as e:  # reported below
                errors.append(e)

        threads = [threading.Thread(target=worker, args=(k,)) for k in range(16)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert not errors, errors
        for k in range(16):
            assert len(parallel[k]) == len(sequential[k])
            for a, b in zip(parallel[k], sequential[k]):
                assert a == b
    finally:
        assert d.stop() == 0


def test_long_computation_does_not_block_others(tmp_path):
    d = Daemon()
    try:
        mesh = make_mesh_file(tmp_path, "cubes", 10)
        big, small = Session(d), Session(d)
        assert big.put_complex(complex_from_text(mesh)).status_code == 200
        assert small.put_complex(MESHES[0]).status_code == 200
        assert small.level(2).status_code == 200
        done = []
        t = threading.Thread(target=lambda: done.append(big.req("GET", "/levels/3/stats").status_code))
        t0 = time.time()
        t.start()
        worst = 0.0
        n = 0
        while t.is_alive():
            for fn in (lambda: small.req("GET", "/complex"), lambda: small.level(2),
                       lambda: requests.get(d.url + "/healthz")):
                a = time.time()
                assert fn().status_code == 200
                worst = max(worst, time.time() - a)
                n += 1
        t.join()
        assert done == [200]
        assert n > 3 and time.time() - t0 > 0.2, "the long computation was too short to tell"
        assert worst < 0.5, f"a small request waited {worst:.2f} s behind another session's work"
    finally:
        assert d.stop() == 0
