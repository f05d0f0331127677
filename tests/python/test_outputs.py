"""Geometry carried by the outputs, checked independently of the writers' own bookkeeping:
the solid boundary in glTF is closed and outward (its enclosed volume equals the volume of the
level's tetrahedra and octahedra, computed from the JSON cells), slice points lie on the plane,
the colour map hits viridis' published end colours, and normals are unit vectors."""
import json
import struct
import subprocess

import numpy as np
import pytest

from conftest import REPO, make_mesh_file
from daemon import SUBDIVD, complex_from_text

CUBE = REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt"
MIXED = REPO / "examples" / "mixed.txt"


def refine(tmp_path, body, level, name, *opts):
    inp = tmp_path / "in.json"
    inp.write_text(json.dumps(body))
    out = tmp_path / name
    subprocess.run([str(SUBDIVD), "refine", str(inp), "--level", str(level), *opts, "-o", str(out)],
                   check=True, capture_output=True)
    if out.suffix in (".glb", ".gltf"):  # every glTF the tests make must validate cleanly
        r = subprocess.run(["node", str(REPO / "tests" / "tools" / "gltf_validate.js"), str(out)],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stdout + r.stderr
    return out


def read_glb(path):
    """(gltf json, accessor reader) for a GLB file, parsed from the spec, not from our code."""
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67 and version == 2 and length == len(data)
    jlen, jtype = struct.unpack_from("<II", data, 12)
    assert jtype == 0x4E4F534A
    doc = json.loads(data[20:20 + jlen])
    blen, btype = struct.unpack_from("<II", data, 20 + jlen)
    assert btype == 0x004E4942
    bin_ = data[28 + jlen:28 + jlen + blen]

    def accessor(i):
        a = doc["accessors"][i]
        v = doc["bufferViews"][a["bufferView"]]
        dt = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}[a["componentType"]]
        n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
        arr = np.frombuffer(bin_, dtype=dt, count=a["count"] * n,
                            offset=v.get("byteOffset", 0) + a.get("byteOffset", 0))
        return arr.reshape(a["count"], n) if n > 1 else arr
    return doc, accessor


def tet_volume(p, t):
    a, b, c, d = (p[t[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6


def oct_volume(p, o):
    """An octahedron (p,q,a,a2,b,b2) is 4 tetrahedra around p-q; absolute volumes."""
    total = 0
    for a, b in ((2, 4), (4, 3), (3, 5), (5, 2)):
        total += np.abs(tet_volume(p, o[:, [0, 1, a, b]]))
    return total


@pytest.mark.parametrize("level", [0, 1, 2])
def test_solid_boundary_closed_outward(tmp_path, level):
    body = complex_from_text(CUBE)
    j = json.loads(refine(tmp_path, body, level, "l.json").read_text())
    p = np.array(j["vertices"])
    tets = np.array(j["cells"]["tetrahedra"], dtype=np.int64).reshape(-1, 4)
    octs = np.array(j["cells"]["octahedra"], dtype=np.int64).reshape(-1, 6)
    vol = np.abs(tet_volume(p, tets)).sum() + (oct_volume(p, octs).sum() if len(octs) else 0)
    doc, acc = read_glb(refine(tmp_path, body, level, "l.glb"))
    prims = doc["meshes"][0]["primitives"]
    assert len(prims) == 1 and prims[0]["mode"] == 4  # a pure solid: only its boundary
    pos = acc(prims[0]["attributes"]["POSITION"]).astype(np.float64)
    tri = acc(prims[0]["indices"]).astype(np.int64).reshape(-1, 3)
    a, b, c = pos[tri[:, 0]], pos[tri[:, 1]], pos[tri[:, 2]]
    enclosed = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6  # divergence theorem
    assert enclosed > 0
    assert abs(enclosed - vol) <= 1e-5 * vol
    # closed: every boundary edge is used twice, once in each direction
    edges = {}
    for t in tri:
        for k in range(3):
            e = (t[k], t[(k + 1) % 3])
            edges[e] = edges.get(e, 0) + 1
    assert all(edges.get((b_, a_), 0) == 1 for (a_, b_) in edges)
    nrm = acc(prims[0]["attributes"]["NORMAL"])
    assert np.allclose(np.linalg.norm(nrm, axis=1), 1, atol=1e-6)


def test_slice_on_plane(tmp_path):
    body = complex_from_text(CUBE)
    n, d = np.array([1.0, 2.0, -0.5]), 0.1
    j = json.loads(refine(tmp_path, body, 1, "s.json", "--slice", "1,2,-0.5,0.1").read_text())
    sv = np.array(j["slice"]["vertices"])
    assert len(sv) > 0 and len(j["slice"]["triangles"]) * 3 == len(sv)
    assert np.abs(sv @ n - d).max() < 1e-9 * np.linalg.norm(n)
    lo, hi = np.array(j["vertices"]).min(0), np.array(j["vertices"]).max(0)
    assert (sv >= lo - 1e-12).all() and (sv <= hi + 1e-12).all()
    # the slice primitive of the GLB has the same points (float32) and the plane's normal
    doc, acc = read_glb(refine(tmp_path, body, 1, "s.glb", "--slice", "1,2,-0.5,0.1"))
    sp = doc["meshes"][0]["primitives"][-1]
    assert "indices" not in sp
    np.testing.assert_allclose(acc(sp["attributes"]["POSITION"]), sv, atol=1e-6)
    np.testing.assert_allclose(acc(sp["attributes"]["NORMAL"]), np.tile(n / np.linalg.norm(n), (len(sv), 1)), atol=1e-6)


def test_colormap_endpoints(tmp_path):
    body = complex_from_text(MIXED)
    body["attributes"] = {"t": [float(i) for i in range(len(body["vertices"]))]}
    doc, acc = read_glb(refine(tmp_path, body, 0, "c.glb", "--colormap", "t:1:6"))
    prim = doc["meshes"][0]["primitives"][0]
    col = acc(prim["attributes"]["COLOR_0"])
    t = acc(prim["attributes"]["_T"])
    assert ((col >= 0) & (col <= 1)).all()
    # matplotlib's viridis(0) = (0.267004, 0.004874, 0.329415), viridis(1) = (0.993248, 0.906157, 0.143936)
    np.testing.assert_allclose(col[t <= 1], [[0.267004, 0.004874, 0.329415]] * int((t <= 1).sum()), atol=1e-6)
    np.testing.assert_allclose(col[t >= 6], [[0.993248, 0.906157, 0.143936]] * int((t >= 6).sum()), atol=1e-6)
    # rules as a float attribute: the values are sd_rule ids, consistent with the JSON names
    j = json.loads(refine(tmp_path, body, 0, "c.json").read_text())
    names = ["corner", "curve", "loop", "loop-boundary", "solid", "solid-boundary", "N1", "N2", "G1", "G2"]
    assert [names[int(r)] for r in acc(prim["attributes"]["_RULE"])] == j["rules"]


def test_polyhedra_vtu(tmp_path):
    import vtk
    body = complex_from_text(CUBE)
    f = refine(tmp_path, body, 1, "p.vtu", "--octahedra", "polyhedra")
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(f))
    r.Update()
    g = r.GetOutput()
    ntet = sum(1 for s in body["simplices"] if len(s) == 4)
    types = [g.GetCellType(i) for i in range(g.GetNumberOfCells())]
    assert types.count(10) == 4 * ntet and types.count(42) == ntet
    oct_cell = g.GetCell(types.index(42))
    assert oct_cell.GetNumberOfFaces() == 8 and oct_cell.GetNumberOfPoints() == 6
