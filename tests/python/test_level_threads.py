"""Levels computed with several threads (--level-threads in the daemon, --threads offline;
DECISIONS 48, 49): the same bytes as one thread, for a solid with a curve and a fin and for a
Loop surface with a crease, and bad values refused."""
import json
import math
import subprocess
import threading

from daemon import SUBDIVD, Daemon, Session
from test_kept_memory import cubes


def torus(n=40, m=24, R=2.0, r=0.7):
    V = [[(R + r * math.cos(2 * math.pi * j / m)) * math.cos(2 * math.pi * i / n),
          (R + r * math.cos(2 * math.pi * j / m)) * math.sin(2 * math.pi * i / n),
          r * math.sin(2 * math.pi * j / m)] for i in range(n) for j in range(m)]
    T = []
    for i in range(n):
        for j in range(m):
            a, b = i * m + j, i * m + (j + 1) % m
            c, d = ((i + 1) % n) * m + j, ((i + 1) % n) * m + (j + 1) % m
            T += [[a, c, d], [a, d, b]]
    return {"vertices": V, "simplices": T}


def levels(d, body, level, tags=None, rules=None):
    s = Session(d)
    assert s.put_complex(body).status_code == 200
    if rules:
        assert s.req("PUT", "/rules", json=rules).status_code == 200
    if tags:
        assert s.req("PUT", "/tags", json=tags).status_code == 200
    out = [s.level(level, format=f).content for f in ("json", "glb")]
    s.delete()
    return out


def threads_while(d, fn):
    """fn() while the daemon's thread count is sampled: (before, the most seen during)."""
    status = f"/proc/{d.proc.pid}/status"

    def count():
        for line in open(status):
            if line.startswith("Threads:"):
                return int(line.split()[1])
        return 0
    before, most, done = count(), [0], threading.Event()

    def watch():
        while not done.is_set():
            most[0] = max(most[0], count())
    w = threading.Thread(target=watch)
    w.start()
    try:
        out = fn()
    finally:
        done.set()
        w.join()
    return before, most[0], out


def test_daemon_levels_are_the_same_bytes_for_any_number_of_threads():
    solid = cubes(9, 8, 8, 0.1, 5)     # level 3: 1.2 M cells, every loop cut in parts
    surf = torus()
    crease = {"singular": [[i * 24, ((i + 1) % 40) * 24] for i in range(40)]}
    loop = {"surface_weights": "loop"}
    one = Daemon("--level-threads", "1")
    three = Daemon("--level-threads", "3")
    try:
        b1, most1, want = threads_while(one, lambda: levels(one, solid, 3))
        b3, most3, got = threads_while(three, lambda: levels(three, solid, 3))
        # beyond the connections' threads, the level's loops ran on threads of their own
        assert most3 - b3 > most1 - b1, (b1, most1, b3, most3)
        assert want == got
        assert levels(one, surf, 4, crease, loop) == levels(three, surf, 4, crease, loop)
    finally:
        one.stop()
        three.stop()


def test_bad_level_threads_is_refused():
    r = subprocess.run([str(SUBDIVD), "--level-threads", "0"], capture_output=True, text=True,
                       timeout=10)
    assert r.returncode == 2 and "level-threads" in r.stderr


def test_offline_threads(tmp_path):
    src = tmp_path / "solid.json"
    src.write_text(json.dumps(cubes(6, 5, 5, 0.1, 6)))
    outs = []
    for t in ("1", "2", "5"):
        out = tmp_path / f"l3-{t}.vtu"
        r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "3", "--threads", t,
                            "-o", str(out)], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] == outs[2]
    for bad in ("0", "x", "65"):
        r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "1", "--threads", bad,
                            "-o", str(tmp_path / "bad.vtu")], capture_output=True, text=True,
                           timeout=60)
        assert r.returncode == 2 and "--threads" in r.stderr, r.stderr
        assert not (tmp_path / "bad.vtu").exists()
