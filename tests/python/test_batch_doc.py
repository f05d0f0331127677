"""docs/BATCH.md runs as written: its sh blocks, in order, from the repository root, against its
own daemon (on a free port by default: a `make run` on 8080 is not used) with the results in a
temporary directory (OUT); when its daemon cannot start, the first block fails and says why."""
import os
import re
import signal
import socket
import subprocess

from conftest import REPO

DOC = REPO / "docs" / "BATCH.md"
VALIDATOR = REPO / "tests" / "tools" / "gltf_validate.js"


def blocks():
    return re.findall(r"^```sh\n(.*?)^```", DOC.read_text(encoding="utf-8"), flags=re.S | re.M)


def test_walkthrough_runs_as_written(tmp_path):
    assert len(blocks()) >= 8
    script = tmp_path / "walkthrough.sh"
    script.write_text("set -eu\n" + "\n".join(blocks()), encoding="utf-8")
    env = dict(os.environ, OUT=str(tmp_path / "out"))   # PORT unset: the page's default
    env.pop("SUBDIV_URL", None)
    env.pop("PORT", None)
    p = subprocess.Popen(["sh", str(script)], cwd=REPO, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, encoding="utf-8", start_new_session=True)
    try:
        out, err = p.communicate(timeout=300)
    finally:
        try:
            os.killpg(p.pid, signal.SIGKILL)   # the walkthrough's daemon, if a step failed
        except ProcessLookupError:
            pass
    assert p.returncode == 0, f"stdout:\n{out}\nstderr:\n{err}"
    o = tmp_path / "out"
    for f in ("ball.vtu", "ball.glb", "block.vtu", "mixed.glb", "ball-offline.vtu",
              "out/ball.vtu", "out/ball-L2.glb", "out/block.vtu", "out/block-L3.glb",
              "out/mixed.vtu", "out/mixed-L2.glb", "block-mpi.pvtu", "block-mpi_0.vtu",
              "block-mpi_1.vtu", "mixed-merged.vtu"):
        assert (o / f).stat().st_size > 0, f
    assert "{'tetra':" in out                                   # step 2 read the VTU back
    assert "tags: [[4, 5], [5, 7], [6, 7], [4, 6]] | rules: averaged" in out
    assert "exit code 1" in out and "/fill/0/surface/" in err
    assert "3 job(s): 3 done, 0 failed" in err
    assert (o / "ball.vtu").read_bytes() == (o / "ball-offline.vtu").read_bytes()
    r = subprocess.run(["node", str(VALIDATOR), *map(str, sorted(o.glob("**/*.glb")))],
                       capture_output=True, encoding="utf-8")
    assert r.returncode == 0, r.stdout + r.stderr


def test_first_block_fails_loudly_when_its_daemon_cannot_start(tmp_path):
    """PORT taken by another listener (a `make run`, say): the block stops with the daemon's
    reason instead of talking to whatever answers there."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        script = tmp_path / "first.sh"
        script.write_text("set -eu\n" + blocks()[0] + '\necho "reached the end"\n', encoding="utf-8")
        env = dict(os.environ, PORT=str(port), OUT=str(tmp_path / "out"))
        env.pop("SUBDIV_URL", None)
        r = subprocess.run(["sh", str(script)], cwd=REPO, env=env, capture_output=True,
                           encoding="utf-8", timeout=60)
    assert r.returncode != 0 and "reached the end" not in r.stdout
    assert "subdivd did not start" in r.stderr and "cannot listen" in r.stderr, r.stderr
