"""clients/python installs with pip the documented way, without a network (clients/README.md):
    python3 -m venv --system-site-packages V
    V/bin/pip install --no-deps --no-build-isolation --no-index ./clients/python
Then `V/bin/subdiv` is the console script, `import subdiv` in V's python finds the installed copy
(not the source tree), and the script talks to a daemon. The client's version is the daemon's."""
import json
import os
import shutil
import subprocess
import sys

import pytest

from conftest import REPO
from daemon import SUBDIVD, Daemon

SRC = REPO / "clients" / "python"


@pytest.fixture(scope="module")
def venv(tmp_path_factory):
    """A venv with the client installed. pip builds in the source directory (build/, egg-info),
    so the install reads a copy of clients/python: the tree under test stays untouched."""
    top = tmp_path_factory.mktemp("pkg")
    src = top / "python"
    shutil.copytree(SRC, src, ignore=shutil.ignore_patterns("__pycache__", "build", "*.egg-info"))
    v = top / "V"
    py = "/usr/bin/python3" if os.path.exists("/usr/bin/python3") else sys.executable
    r = subprocess.run([py, "-m", "venv", "--system-site-packages", str(v)],
                       capture_output=True, encoding="utf-8")
    assert r.returncode == 0, f"python3 -m venv failed (Debian: python3-venv): {r.stderr}"
    r = subprocess.run([str(v / "bin" / "pip"), "install", "--no-deps", "--no-build-isolation",
                        "--no-index", str(src)], capture_output=True, encoding="utf-8",
                       env={**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"})
    assert r.returncode == 0, f"pip install failed: {r.stdout}\n{r.stderr}"
    return v


def clean_env(**extra):
    """The environment without PYTHONPATH (so nothing reaches the source tree) or SUBDIV_*."""
    e = {k: v for k, v in os.environ.items()
         if k != "PYTHONPATH" and not k.startswith("SUBDIV")}
    e.update(extra)
    return e


def test_console_script_and_import(venv, tmp_path):
    r = subprocess.run([str(venv / "bin" / "subdiv"), "--help"], capture_output=True, encoding="utf-8",
                       env=clean_env(), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "refine" in r.stdout and "batch" in r.stdout and "convert" in r.stdout
    r = subprocess.run([str(venv / "bin" / "python"), "-c",
                        "import subdiv, json; print(json.dumps([subdiv.__file__, subdiv.__version__,"
                        " subdiv.Client.__name__]))"],
                       capture_output=True, encoding="utf-8", env=clean_env(), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    path, version, name = json.loads(r.stdout)
    assert path.startswith(str(venv)), path   # the installed copy, not clients/python
    assert (venv / path).parent.joinpath("py.typed").exists()
    assert name == "Client"
    r = subprocess.run([str(venv / "bin" / "subdiv"), "--version"], capture_output=True,
                       encoding="utf-8", env=clean_env(), cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.split() == ["subdiv", version]
    spec = json.loads((REPO / "api" / "openapi.json").read_text(encoding="utf-8"))
    assert version == spec["info"]["version"]
    r = subprocess.run([str(SUBDIVD), "--version"], capture_output=True, encoding="utf-8")
    assert r.returncode == 0 and r.stdout == f"subdivd {version}\n", r.stdout


def test_console_script_against_a_daemon(venv, tmp_path):
    body = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 2, 3]]}
    (tmp_path / "tet.json").write_text(json.dumps(body))
    d = Daemon()
    try:
        r = subprocess.run([str(venv / "bin" / "subdiv"), "refine", "tet.json", "--level", "1",
                            "-o", "tet.vtu", "-o", "tet.json.out.json", "--url", d.url,
                            "--progress", "none"],
                           capture_output=True, encoding="utf-8", env=clean_env(), cwd=tmp_path,
                           timeout=120)
        assert r.returncode == 0, r.stdout + r.stderr
        assert (tmp_path / "tet.vtu").read_bytes().startswith(b"<?xml")
        level = json.loads((tmp_path / "tet.json.out.json").read_text(encoding="utf-8"))
        assert level["level"] == 1 and len(level["vertices"]) > 4
    finally:
        d.stop()
    # --spawn finds the daemon through $SUBDIVD (nothing is beside the venv's script)
    r = subprocess.run([str(venv / "bin" / "subdiv"), "refine", "tet.json", "--level", "1",
                        "-o", "spawned.vtu", "--spawn", "-q"],
                       capture_output=True, encoding="utf-8", env=clean_env(SUBDIVD=str(SUBDIVD)),
                       cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "spawned.vtu").stat().st_size > 0
