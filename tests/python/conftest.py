"""Shared pieces of the Python suites: repository paths, the tools under test, generated meshes.

SDLEVEL may point at another build of the tool (make sanitize uses the ASan one)."""
import os
import pathlib
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
SDLEVEL = pathlib.Path(os.environ.get("SDLEVEL", str(REPO / "build" / "sdlevel"))).resolve()
OSD = REPO / "build" / "osd_loop"
OSD_SRC = REPO / "tests" / "peers" / "osd_loop.cpp"
MAKE_MESH = REPO / "bench" / "make_mesh.py"


def make_mesh_file(directory, *args):
    """Write `bench/make_mesh.py ARGS` into a file under `directory` and return its path."""
    text = subprocess.run([sys.executable, str(MAKE_MESH), *map(str, args)], check=True,
                          capture_output=True, text=True).stdout
    p = pathlib.Path(directory) / ("_".join(map(str, args)) + ".txt")
    p.write_text(text)
    return p


@pytest.fixture(scope="session")
def osd_loop():
    """The OpenSubdiv peer, built first if missing or older than its source."""
    if not OSD.exists() or OSD.stat().st_mtime < OSD_SRC.stat().st_mtime:
        r = subprocess.run(["make", "-f", "tests/peers/Makefile.inc", "build/osd_loop"], cwd=REPO,
                           capture_output=True, text=True)
        assert r.returncode == 0, f"building the peer failed:\n{r.stdout}\n{r.stderr}"
    assert OSD.exists()
    return OSD
