"""subdivd's Loop surfaces against OpenSubdiv (Debian libosd-dev, PrimvarRefinerReal<double>).

With surface_weights = loop, positions after 2 levels of closed triangle meshes equal
OpenSubdiv's to 1e-12, matched by position (not by order): every one of our points has an
OpenSubdiv point within 1e-12 and the matching is one-to-one. The peer itself is checked
against Loop's formulas in test_osd_peer.py.
"""
import subprocess

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import OSD, SDLEVEL, make_mesh_file as mesh_file  # noqa: E402


def read_points(text):
    return np.array([[float(x) for x in line.split()[1:4]] for line in text.splitlines()
                     if line.startswith("v ")])


def osd_points(path, level):
    out = subprocess.run([str(OSD), "-l", str(level), str(path)], check=True,
                         capture_output=True, text=True).stdout
    return read_points(out), out


def our_points(path, level, weights="loop"):
    out = subprocess.run([str(SDLEVEL), "-l", str(level), "-w", weights, str(path)], check=True,
                         capture_output=True, text=True).stdout
    return read_points(out)


@pytest.mark.parametrize("shape", [("bumpy", 1), ("icosphere", 2), ("torus", 7, 5),
                                   ("octahedron",)])
def test_loop_two_levels_equal_opensubdiv(tmp_path, osd_loop, shape):
    path = mesh_file(tmp_path, *shape)
    ours = our_points(path, 2)
    theirs, _ = osd_points(path, 2)
    assert ours.shape == theirs.shape
    d, j = cKDTree(theirs).query(ours)
    assert d.max() < 1e-12, f"max distance {d.max():.3g}"
    assert len(set(j.tolist())) == len(ours), "matching is not one-to-one"


def test_warren_differs_from_loop_only_at_extraordinary(tmp_path):
    """On the icosahedron (valence 5) Warren's c = 3/40 differs from Loop's beta(5); level 1
    vertex points must differ, edge points must not."""
    path = mesh_file(tmp_path, "icosphere", 0)
    w = our_points(path, 1, "warren")
    lp = our_points(path, 1, "loop")
    assert np.abs(w[:12] - lp[:12]).max() > 1e-3
    assert np.abs(w[12:] - lp[12:]).max() < 1e-15
