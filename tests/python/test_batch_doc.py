"""docs/BATCH.md runs as written: its sh blocks, in order, from the repository root, against a
daemon on a free port (PORT) with the results in a temporary directory (OUT)."""
import os
import re
import signal
import socket
import subprocess

from conftest import REPO

DOC = REPO / "docs" / "BATCH.md"
VALIDATOR = REPO / "tests" / "tools" / "gltf_validate.js"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_walkthrough_runs_as_written(tmp_path):
    blocks = re.findall(r"^```sh\n(.*?)^```", DOC.read_text(), flags=re.S | re.M)
    assert len(blocks) >= 8
    script = tmp_path / "walkthrough.sh"
    script.write_text("set -eu\n" + "\n".join(blocks))
    env = dict(os.environ, PORT=str(free_port()), OUT=str(tmp_path / "out"))
    env.pop("SUBDIV_URL", None)
    p = subprocess.Popen(["sh", str(script)], cwd=REPO, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True)
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
              "out/mixed.vtu", "out/mixed-L2.glb"):
        assert (o / f).stat().st_size > 0, f
    assert "{'tetra':" in out                                   # step 2 read the VTU back
    assert "tags: [[4, 5], [5, 7], [6, 7], [4, 6]] | rules: averaged" in out
    assert "exit code 1" in out and "/fill/0/surface/" in err
    assert "3 job(s): 3 done, 0 failed" in err
    assert (o / "ball.vtu").read_bytes() == (o / "ball-offline.vtu").read_bytes()
    r = subprocess.run(["node", str(VALIDATOR), *map(str, sorted(o.glob("**/*.glb")))],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
