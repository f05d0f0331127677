"""Level outputs over HTTP: validity of every format, and streaming without a copy in memory.

Expected cell counts come from the split table (tet -> 4 tets + 1 octahedron, octahedron ->
8 tets + 6 octahedra, triangle -> 4, segment -> 2), not from the daemon."""
import json
import pathlib
import subprocess
import threading
import time

import pytest

from conftest import REPO, make_mesh_file
from daemon import Daemon, Session, complex_from_text

MIXED = REPO / "examples" / "mixed.txt"
VALIDATOR = REPO / "tests" / "tools" / "gltf_validate.js"


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


def expected_cells(body, level):
    """Top cells per kind at `level` from the split table."""
    npt = sum(1 for s in body["simplices"] if len(s) == 1)
    ncu = sum(1 for s in body["simplices"] if len(s) == 2)
    ntr = sum(1 for s in body["simplices"] if len(s) == 3)
    nt = sum(1 for s in body["simplices"] if len(s) == 4)
    no = 0
    for _ in range(level):
        ncu, ntr, nt, no = 2 * ncu, 4 * ntr, 4 * nt + 8 * no, nt + 6 * no
    return npt, ncu, ntr, nt, no


def validate_gltf(paths):
    r = subprocess.run(["node", str(VALIDATOR), *map(str, paths)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.mark.parametrize("level", [0, 2])
def test_all_formats_valid(daemon, tmp_path, level):
    body = complex_from_text(MIXED)
    body["attributes"] = {"height": [v[2] for v in body["vertices"]]}
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    npt, ncu, ntr, nt, no = expected_cells(body, level)
    files = []
    for opts in ({}, {"slice": "0,0,1,0.25", "colormap": "height:0:3"}, {"parts": "solids"}):
        for fmt in ("glb", "gltf"):
            r = s.level(level, format=fmt, **opts)
            assert r.status_code == 200
            f = tmp_path / f"l{level}_{len(files)}.{fmt}"
            f.write_bytes(r.content)
            files.append(f)
    validate_gltf(files)
    import meshio
    import vtk
    nverts = len(s.level(level, format="json").json()["vertices"])
    for fmt in ("vtu", "vtk"):
        f = tmp_path / f"l{level}.{fmt}"
        f.write_bytes(s.level(level, format=fmt).content)
        rd = vtk.vtkXMLUnstructuredGridReader() if fmt == "vtu" else vtk.vtkUnstructuredGridReader()
        rd.SetFileName(str(f))
        rd.Update()
        g = rd.GetOutput()
        assert g.GetNumberOfPoints() == nverts
        types = [g.GetCellType(i) for i in range(g.GetNumberOfCells())]
        assert types.count(1) == npt and types.count(3) == ncu and types.count(5) == ntr
        assert types.count(10) == nt + 4 * no  # an octahedron is written as 4 tets
        m = meshio.read(str(f))
        got = {b.type: len(b.data) for b in m.cells}
        want = {k: v for k, v in (("vertex", npt), ("line", ncu), ("triangle", ntr),
                                   ("tetra", nt + 4 * no)) if v}
        assert got == want
        assert len(m.points) == nverts


def test_streaming_memory_below_response_size(tmp_path):
    """A level of >= 2 M cells is streamed with the daemon's RSS growing less than the response."""
    d = Daemon("--max-cells", "50000000")
    try:
        mesh = make_mesh_file(tmp_path, "cubes", 12)        # 10368 tets
        body = complex_from_text(mesh)
        s = Session(d)
        assert s.put_complex(body).status_code == 200
        npt, ncu, ntr, nt, no = expected_cells(body, 3)
        assert nt + no >= 2_000_000
        st = s.req("GET", "/levels/3/stats")                 # compute and cache first
        assert st.status_code == 200
        assert (st.json()["counts"]["tetrahedra"], st.json()["counts"]["octahedra"]) == (nt, no)
        for fmt in ("vtu", "glb"):
            before = d.rss_bytes()
            peak = [before]
            done = threading.Event()

            def sample():
                while not done.is_set():
                    peak[0] = max(peak[0], d.rss_bytes())
                    time.sleep(0.005)

            t = threading.Thread(target=sample)
            t.start()
            total = 0
            with s.req("GET", "/levels/3", params={"format": fmt}, stream=True) as r:
                assert r.status_code == 200
                for chunk in r.iter_content(1 << 20):
                    total += len(chunk)
            done.set()
            t.join()
            growth = peak[0] - before
            assert total > 0
            assert growth < total, f"{fmt}: RSS grew {growth} B while streaming {total} B"
    finally:
        assert d.stop() == 0
