"""The redis store (server/persist_redis.c) against a real redis-server: the checks of
tests/api/persist_redis_test.c (compare-and-set, load, compaction, damage, expiry, a server that
is down, two connections racing one snapshot 50 times), and its reconnects while this test
restarts, stops and starts the server under it."""
import os
import subprocess
import time

import pytest

from conftest import REPO
from redisd import REDIS_SERVER, RedisServer, free_port

TEST = os.environ.get("PERSIST_REDIS_TEST", str(REPO / "build" / "persist_redis_test"))

pytestmark = pytest.mark.skipif(REDIS_SERVER is None,
                                reason="redis-server is not installed (tools/packages.txt lists it)")


@pytest.fixture
def redis(tmp_path):
    r = RedisServer(tmp_path).start()
    yield r
    r.stop()


def test_redis_store(redis):
    t0 = time.time()
    r = subprocess.run([TEST, "127.0.0.1", str(redis.port), str(free_port())],
                       capture_output=True, text=True, timeout=60)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert out.rstrip().endswith("ok"), out
    assert "race: 50 rounds, one winner each" in out, out
    assert "Connection refused" in out, out
    assert time.time() - t0 < 30, out


def test_redis_store_reconnects(redis):
    """RESTART: redis restarted under an idle connection (the call is retried on a new one);
    STOP: redis down (the call is refused quickly); START: it works again."""
    p = subprocess.Popen([TEST, "127.0.0.1", str(redis.port), str(free_port()), "recover"],
                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True)
    seen = []
    try:
        for line in p.stdout:
            line = line.rstrip("\n")
            seen.append(line)
            if line == "RESTART":
                redis.stop()
                redis.start()
            elif line == "STOP":
                redis.stop()
            elif line == "START":
                redis.start()
            else:
                continue
            p.stdin.write("go\n")
            p.stdin.flush()
        assert p.wait(30) == 0, "\n".join(seen)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert seen[-1] == "ok" and seen.count("RESTART") == 2 and "START" in seen, "\n".join(seen)
    assert any(l.startswith("down: redis 127.0.0.1:") for l in seen), "\n".join(seen)
