"""The commands of docs/SERVICE.md run as written: the session walkthrough ("A session, step by
step", against a daemon given by SUBDIV_URL) and the offline example ("Offline mode"), from a
directory that has the repository's examples/ and build/."""
import os
import re
import shutil
import subprocess

import pytest

from conftest import REPO
from daemon import Daemon

DOC = REPO / "docs" / "SERVICE.md"


def sh_blocks():
    return re.findall(r"^```sh\n(.*?)^```", DOC.read_text(encoding="utf-8"), flags=re.S | re.M)


def test_session_and_offline_blocks_run(tmp_path):
    if not shutil.which("curl"):
        pytest.skip("curl is not installed (tools/packages.txt lists it)")
    blocks = sh_blocks()
    session = [b for b in blocks if "$U/v1/sessions" in b and "embedded" not in b]
    offline = [b for b in blocks if "subdivd refine examples/" in b]
    assert len(session) == 1 and len(offline) == 1
    assert not [b for b in session + offline if "..." in b.split("#")[0]], "placeholders left"
    (tmp_path / "examples").symlink_to(REPO / "examples")
    (tmp_path / "build").symlink_to(REPO / "build")
    script = tmp_path / "service.sh"
    script.write_text("set -eu\n" + session[0] + offline[0], encoding="utf-8")
    d = Daemon()
    try:
        env = dict(os.environ, SUBDIV_URL=d.url)
        r = subprocess.run(["sh", str(script)], cwd=tmp_path, env=env, capture_output=True,
                           encoding="utf-8", timeout=300)
    finally:
        d.stop()
    assert r.returncode == 0, r.stdout + r.stderr
    assert '"version":1' in r.stdout and '"version":2' in r.stdout
    assert (tmp_path / "l3.glb").read_bytes()[:4] == b"glTF"
    online = (tmp_path / "l3.vtu").read_bytes()
    offline_bytes = (tmp_path / "l3-offline.vtu").read_bytes()
    assert online.startswith(b"<?xml") and len(online) == len(offline_bytes)
    # the same bytes but for the version the file carries (2 in the session, 1 offline)
    diff = [i for i, (a, b) in enumerate(zip(online, offline_bytes)) if a != b]
    assert len(diff) <= 2, diff


def test_embedded_block_runs(tmp_path):
    """The HTTP example of "Embedded models" runs as written after the walkthrough's `U=`: no
    placeholders (a `$S` that is not the session id, `$T`, a fixed localhost:8080)."""
    if not shutil.which("curl"):
        pytest.skip("curl is not installed (tools/packages.txt lists it)")
    blocks = sh_blocks()
    emb = [b for b in blocks if "$U/v1/sessions" in b and "/embedded/" in b]
    assert len(emb) == 1
    assert "localhost:8080" not in emb[0] and "$T" not in emb[0]
    (tmp_path / "examples").symlink_to(REPO / "examples")
    script = tmp_path / "embedded.sh"
    script.write_text("set -eu\nU=${SUBDIV_URL:-http://127.0.0.1:8080}\n" + emb[0], encoding="utf-8")
    d = Daemon()
    try:
        r = subprocess.run(["sh", str(script)], cwd=tmp_path, env=dict(os.environ, SUBDIV_URL=d.url),
                           capture_output=True, encoding="utf-8", timeout=120)
    finally:
        d.stop()
    assert r.returncode == 0, r.stdout + r.stderr
    faces = [ln for ln in r.stdout.splitlines() if ln.startswith(("v ", "f "))]
    assert len(faces) == 4, r.stdout   # the model's 3 vertices and 1 triangle, as OBJ
