"""The output writers (api/out*.c) through build/outwrite, checked against independent sources.

Expected values never come from the file under test: counts, cells, coordinates, origins and
rules come from `sdlevel` (a different program printing the core's level as text), the solid
boundary and the cross-section are recomputed here from those cells, attribute values from the
affine function `outwrite --xattr` defines (subdivision reproduces affine functions), and files
are read back by the Khronos glTF-Validator, VTK's own readers and meshio.

Meshes: a mixed complex (examples/mixed.txt), a TetGen cube (pure tets), a block of cubes, a
closed triangle surface, and curves + points only; levels 0..2; every format.
"""
import base64
import collections
import functools
import itertools
import json
import os
import pathlib
import struct
import subprocess

import numpy as np
import pytest

from conftest import REPO, SDLEVEL, make_mesh_file
from sdtext import parse_level_text

# beside sdlevel by default, so that `make sanitize` (SDLEVEL=build-asan/sdlevel) runs ASan's
OUTWRITE = pathlib.Path(os.environ.get("OUTWRITE", str(SDLEVEL.parent / "outwrite"))).resolve()
VALIDATOR = REPO / "tests" / "tools" / "gltf_validate.js"
RULES = ["corner", "curve", "loop", "loop-boundary", "solid", "solid-boundary", "N1", "N2", "G1", "G2"]
FORMATS = ["glb", "gltf", "vtu", "vtk", "json"]
LEVELS = [0, 1, 2]
CURVES_TEXT = """# curves and isolated points only
v 0 0 0
v 1 0 0
v 2 1 0
v 3 1 1
v 1 2 0.5
v 5 5 5
v 6 5 5
s 0 1
s 1 2
s 2 3
s 1 4
s 5
s 6
"""
# planes n.x = d through each mesh's solids (none for meshes without solids); no control
# vertex lies on them
SLICES = {"mixed": (1, 1, 1, 0.7531), "cube": (1, 2, -0.5, 1.0123), "blocks": (0.3, -1, 2, 1.7123),
          "surface": (0, 0, 1, 0.1), "curves": (1, 0, 0, 1.5)}
# matplotlib's viridis at 0, 0.5 and 1 (its published 256-entry table: entries 0, 128, 255)
VIRIDIS_0 = (0.267004, 0.004874, 0.329415)
VIRIDIS_HALF = (0.127568, 0.566949, 0.550556)
VIRIDIS_1 = (0.993248, 0.906157, 0.143936)
# ... as hex colours (its documented end points)
VIRIDIS_HEX_0, VIRIDIS_HEX_1 = "#440154", "#fde725"


def srgb_to_linear(c):
    """IEC 61966-2-1's sRGB transfer function inverted: glTF's COLOR_0 is linear (2.0, 3.7.2.1)."""
    c = np.asarray(c, dtype=float)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c):
    c = np.asarray(c, dtype=float)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)


LIN_0, LIN_HALF, LIN_1 = (srgb_to_linear(v) for v in (VIRIDIS_0, VIRIDIS_HALF, VIRIDIS_1))
ATTRS = ["--xattr", "temp", "--xattr", "vec:3", "--xattr", "wide:6"]


@pytest.fixture(scope="session")
def meshes(tmp_path_factory):
    d = tmp_path_factory.mktemp("meshes")
    curves = d / "curves.txt"
    curves.write_text(CURVES_TEXT)
    return {
        "mixed": REPO / "examples" / "mixed.txt",
        "cube": REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt",
        "blocks": make_mesh_file(d, "cubes", 2),
        "surface": make_mesh_file(d, "icosphere", 1),
        "curves": curves,
    }


# ---- tools ----------------------------------------------------------------------------------


def outwrite(mesh, level, fmt, out, *opts, check=True):
    r = subprocess.run([str(OUTWRITE), str(mesh), "-l", str(level), "-f", fmt, "-o", str(out),
                        *map(str, opts)], capture_output=True, text=True)
    if check:
        assert r.returncode == 0, r.stderr
    return r


def validate(*files):
    """The Khronos validator on every file: 0 errors and 0 warnings (infos/hints allowed)."""
    r = subprocess.run(["node", str(VALIDATOR), *map(str, files)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout


@functools.lru_cache(maxsize=None)
def sdlevel(mesh, level):
    """The level as printed by sdlevel, with each vertex's rule (--classes)."""
    r = subprocess.run([str(SDLEVEL), "-l", str(level), "--classes", str(mesh)], check=True,
                       capture_output=True, text=True)
    lv = parse_level_text(r.stdout)
    lv["rules"] = [lv["vclass"][i]["rule"] for i in range(len(lv["verts"]))]
    return lv


def affine(p, k):
    """Component k of the --xattr attribute at positions p (outwrite's definition)."""
    return p[:, 0] + k * p[:, 1] + k * k * p[:, 2] + k


def oct_tets(o):
    """The 4 tetrahedra around the major diagonal p-q of octahedra (p,q,a,a2,b,b2): around the
    equator cycle a, b, a2, b2 (docs/API.md; docs/OUTPUTS.md)."""
    eq = [2, 4, 3, 5]
    return [o[:, [0, 1, eq[k], eq[(k + 1) % 4]]] for k in range(4)]


def det(a, b, c, d):
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)


def cells_volume(lv):
    """Volume of the solids: |det|/6 per tetrahedron; per octahedron the absolute value of the
    signed sum over its 4 tetrahedra around p-q (one of them may be inverted where the
    octahedron is not convex along that diagonal: a few at level 2)."""
    p = lv["verts"]
    t = lv["tetrahedra"]
    vol = np.abs(det(*(p[t[:, k]] for k in range(4)))).sum() / 6
    if len(lv["octahedra"]):
        signed = sum(det(*(p[q[:, k]] for k in range(4))) for q in oct_tets(lv["octahedra"]))
        vol += np.abs(signed).sum() / 6
    return vol


def independent_boundary(lv):
    """Faces of exactly one tetrahedron or octahedron, each oriented away from its cell's
    centroid: {sorted triple: oriented triple}."""
    p = lv["verts"]
    faces = {}
    for t in lv["tetrahedra"]:
        for k in range(4):
            f = tuple(int(v) for j, v in enumerate(t) if j != k)
            faces.setdefault(tuple(sorted(f)), []).append((f, p[t].mean(0)))
    eq = [2, 4, 3, 5]
    for o in lv["octahedra"]:
        for pole in (0, 1):
            for k in range(4):
                f = (int(o[pole]), int(o[eq[k]]), int(o[eq[(k + 1) % 4]]))
                faces.setdefault(tuple(sorted(f)), []).append((f, p[o].mean(0)))
    out = {}
    for key, owners in faces.items():
        if len(owners) != 1:
            continue
        (a, b, c), centre = owners[0]
        n = np.cross(p[b] - p[a], p[c] - p[a])
        out[key] = (a, b, c) if n @ (p[[a, b, c]].mean(0) - centre) > 0 else (a, c, b)
    return out


def slice_count(lv, plane):
    """Cross-section triangles: 1 per tetrahedron cut 1|3, 2 per cut 2|2, octahedra as their 4
    tetrahedra around the major diagonal."""
    n, d = np.array(plane[:3], float), plane[3]
    n, d = n / np.linalg.norm(n), d / np.linalg.norm(n)
    f = lv["verts"] @ n - d
    total = 0
    for t in [lv["tetrahedra"], *oct_tets(lv["octahedra"])]:
        pos = (f[t] > 0).sum(1)
        total += int(((pos == 1) | (pos == 3)).sum() + 2 * (pos == 2).sum())
    return total


# ---- glTF reading (from the specification, not from our code) -------------------------------


def split_glb(data):
    magic, version, length = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67 and version == 2 and length == len(data)
    jlen, jtype = struct.unpack_from("<II", data, 12)
    assert jtype == 0x4E4F534A and jlen % 4 == 0
    doc = json.loads(data[20:20 + jlen])
    blen, btype = struct.unpack_from("<II", data, 20 + jlen)
    assert btype == 0x004E4942 and blen % 4 == 0 and 28 + jlen + blen == len(data)
    return doc, data[28 + jlen:]


def accessor_reader(doc, bin_):
    def accessor(i):
        a = doc["accessors"][i]
        v = doc["bufferViews"][a["bufferView"]]
        dt = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}[a["componentType"]]
        n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
        arr = np.frombuffer(bin_, dtype=np.dtype(dt).newbyteorder("<"), count=a["count"] * n,
                            offset=v.get("byteOffset", 0) + a.get("byteOffset", 0))
        return arr.reshape(a["count"], n) if n > 1 else arr
    return accessor


def read_glb(path):
    doc, bin_ = split_glb(path.read_bytes())
    return doc, accessor_reader(doc, bin_)


def primitives_by_role(doc, lv, nslice):
    """Map the parts to their primitives through the node names (docs/OUTPUTS.md): the root node
    "level L" has one child per part shown, in the order points, curves, surfaces, solids, slice
    (empty parts left out), node and mesh named after the part, one primitive each."""
    roles = [r for r, n in (("points", len(lv["points"])), ("curves", len(lv["edges"])),
                            ("surfaces", len(lv["triangles"])),
                            ("solids", len(lv["tetrahedra"]) + len(lv["octahedra"])),
                            ("slice", nslice)) if n]
    assert doc["scenes"][doc["scene"]]["nodes"] == [0]
    root = doc["nodes"][0]
    children = [doc["nodes"][i] for i in root.get("children", [])]
    assert [c["name"] for c in children] == roles
    assert len(doc["nodes"]) == 1 + len(roles) and len(doc.get("meshes", [])) == len(roles)
    prims = {}
    for c in children:
        mesh = doc["meshes"][c["mesh"]]
        assert mesh["name"] == c["name"] and len(mesh["primitives"]) == 1
        prims[c["name"]] = mesh["primitives"][0]
    return prims


def shared_accessor_names(doc, prims):
    """The level's parts share one accessor per attribute; every accessor is named: the
    attribute's glTF name, "slice <name>" for the slice's own, "<part> indices"."""
    level = [p for r, p in prims.items() if r != "slice"]
    for key in {k for p in level for k in p["attributes"]}:
        assert len({p["attributes"][key] for p in level if key in p["attributes"]}) == 1
    for role, p in prims.items():
        for key, i in p["attributes"].items():
            assert doc["accessors"][i]["name"] == (f"slice {key}" if role == "slice" else key)
        if "indices" in p:
            assert doc["accessors"][p["indices"]]["name"] == f"{role} indices"


# ---- the level in every format, compared with sdlevel -----------------------------------------


@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("name", ["mixed", "cube", "blocks", "surface", "curves"])
def test_gltf(tmp_path, meshes, name, level):
    mesh = meshes[name]
    lv = sdlevel(mesh, level)
    p = lv["verts"]
    lo, hi = p[:, 0].min(), p[:, 0].max()
    lo, hi = lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo)
    opts = [*ATTRS, "--colormap", f"temp:{lo!r}:{hi!r}", "--version", 7]
    glb, gltf = tmp_path / "l.glb", tmp_path / "l.gltf"
    outwrite(mesh, level, "glb", glb, *opts)
    outwrite(mesh, level, "gltf", gltf, *opts)
    validate(glb, gltf)
    doc, bin_ = split_glb(glb.read_bytes())
    acc = accessor_reader(doc, bin_)

    # .gltf: the same document, its buffer as a base64 data: URI of the same bytes
    tdoc = json.loads(gltf.read_text())
    uri = tdoc["buffers"][0].pop("uri")
    prefix = "data:application/octet-stream;base64,"
    assert uri.startswith(prefix) and base64.b64decode(uri[len(prefix):]) == bin_
    assert tdoc == doc

    assert doc["asset"]["version"] == "2.0" and doc["asset"]["generator"] == "subdivd"
    assert doc["asset"]["extras"] == {"level": level, "version": 7}
    mat = doc["materials"][0]
    assert mat["pbrMetallicRoughness"]["metallicFactor"] == 0 and mat["doubleSided"] is True
    for v in doc["bufferViews"]:
        assert v.get("byteOffset", 0) % 4 == 0 and v["target"] in (34962, 34963)
        assert "byteStride" not in v or v["target"] == 34962

    prims = primitives_by_role(doc, lv, 0)
    shared_accessor_names(doc, prims)
    assert doc["nodes"][0]["name"] == f"level {level}" and "mesh" not in doc["nodes"][0]
    index_type = 5123 if len(p) <= 65535 else 5125
    expect = {"points": (0, lv["points"]), "curves": (1, lv["edges"]),
              "surfaces": (4, lv["triangles"])}
    for role, (mode, cells) in expect.items():
        if role in prims:
            pr = prims[role]
            assert pr["mode"] == mode
            assert doc["accessors"][pr["indices"]]["componentType"] == index_type
            np.testing.assert_array_equal(acc(pr["indices"]), cells.reshape(-1))
    if "solids" in prims:
        pr = prims["solids"]
        tri = acc(pr["indices"]).astype(np.int64).reshape(-1, 3)
        bnd = independent_boundary(lv)
        assert len(tri) == len(bnd)
        for t in tri:  # the same faces, each oriented outward
            key = tuple(sorted(int(v) for v in t))
            ref = bnd[key]
            assert tuple(t) in (ref, ref[1:] + ref[:1], ref[2:] + ref[:2])
    for pr in prims.values():
        a = pr["attributes"]
        pos = acc(a["POSITION"])
        np.testing.assert_array_equal(pos, p.astype(np.float32))
        assert "NORMAL" in a if pr["mode"] == 4 else "NORMAL" not in a
        if "NORMAL" in a:
            assert np.allclose(np.linalg.norm(acc(a["NORMAL"]), axis=1), 1, atol=1e-6)
        np.testing.assert_allclose(acc(a["_TEMP"]), affine(p, 0), rtol=1e-6, atol=1e-5)
        for k in range(3):
            np.testing.assert_allclose(acc(a["_VEC"])[:, k], affine(p, k), rtol=1e-6, atol=1e-5)
        wide = acc(a["_WIDE"])  # 6 components: the first 4 are written
        assert wide.shape == (len(p), 4)
        for k in range(4):
            np.testing.assert_allclose(wide[:, k], affine(p, k), rtol=1e-6, atol=1e-5)
        assert [RULES[int(r)] for r in acc(a["_RULE"])] == lv["rules"]
        col = acc(a["COLOR_0"])
        assert ((col >= 0) & (col <= 1)).all()
        x = p[:, 0]
        np.testing.assert_allclose(col[x <= lo], np.tile(LIN_0, ((x <= lo).sum(), 1)), atol=1e-6)
        np.testing.assert_allclose(col[x >= hi], np.tile(LIN_1, ((x >= hi).sum(), 1)), atol=1e-6)
    # POSITION min/max are those of the written floats (the validator checks it too)
    if prims:
        a = doc["accessors"][next(iter(prims.values()))["attributes"]["POSITION"]]
        f = p.astype(np.float32)
        # printed with 9 digits: parsed back to float32 they are the written values exactly
        np.testing.assert_array_equal(np.float32(a["min"]), f.min(0))
        np.testing.assert_array_equal(np.float32(a["max"]), f.max(0))


def test_gltf_normals_point_outward(tmp_path, meshes):
    """On a closed outward sphere the area-weighted normals point away from the centre; on the
    pure solid they are the boundary's, outward too."""
    for name, level in (("surface", 2), ("cube", 1)):
        lv = sdlevel(meshes[name], level)
        outwrite(meshes[name], level, "glb", tmp_path / "n.glb")
        doc, acc = read_glb(tmp_path / "n.glb")
        pr = doc["meshes"][0]["primitives"][0]
        nrm = acc(pr["attributes"]["NORMAL"]).astype(float)
        used = np.unique(acc(pr["indices"]))
        centre = lv["verts"].mean(0)
        assert (np.einsum("ij,ij->i", nrm[used], lv["verts"][used] - centre) > 0).all()


@pytest.mark.parametrize("fmt", ["vtu", "vtk"])
@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("name", ["mixed", "cube", "blocks", "surface", "curves"])
def test_vtk(tmp_path, meshes, name, level, fmt):
    import meshio
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy

    lv = sdlevel(meshes[name], level)
    p = lv["verts"]
    f = tmp_path / f"l.{fmt}"
    outwrite(meshes[name], level, fmt, f, *ATTRS)
    if fmt == "vtu":
        text = f.read_bytes()
        head = text[:text.index(b"<AppendedData")]
        assert b'version="1.0"' in head and b'header_type="UInt64"' in head
        assert b'byte_order="LittleEndian"' in head
        assert text.endswith(b"\n  </AppendedData>\n</VTKFile>\n")
    else:
        assert f.read_bytes().startswith(b"# vtk DataFile Version 3.0\n")
    ntet, noct = len(lv["tetrahedra"]), len(lv["octahedra"])
    counts = {1: len(lv["points"]), 3: len(lv["edges"]), 5: len(lv["triangles"]), 10: ntet + 4 * noct}
    counts = {k: v for k, v in counts.items() if v}

    r = vtk.vtkXMLUnstructuredGridReader() if fmt == "vtu" else vtk.vtkUnstructuredGridReader()
    r.SetFileName(str(f))
    r.Update()
    g = r.GetOutput()
    pts = vtk_to_numpy(g.GetPoints().GetData())
    np.testing.assert_array_equal(pts, p)  # Float64 both ways: exact
    types = np.array([g.GetCellType(i) for i in range(g.GetNumberOfCells())])
    assert (np.diff(types) >= 0).all()  # sorted by type
    assert {int(t): int((types == t).sum()) for t in np.unique(types)} == counts
    conn = [[g.GetCell(i).GetPointId(k) for k in range(g.GetCell(i).GetNumberOfPoints())]
            for i in range(g.GetNumberOfCells())]
    cd, pd = g.GetCellData(), g.GetPointData()
    dim = vtk_to_numpy(cd.GetArray("dimension"))
    kind = vtk_to_numpy(cd.GetArray("kind"))
    src = vtk_to_numpy(cd.GetArray("source_cell"))
    np.testing.assert_array_equal(dim, [{1: 0, 3: 1, 5: 2, 10: 3}[t] for t in types])
    start = 0
    for k, (key, n) in enumerate((("points", len(lv["points"])), ("edges", len(lv["edges"])),
                                  ("triangles", len(lv["triangles"])), ("tetrahedra", ntet))):
        np.testing.assert_array_equal(np.array(conn[start:start + n], dtype=np.int64).reshape(-1, lv[key].shape[1]), lv[key])
        np.testing.assert_array_equal(kind[start:start + n], k)
        np.testing.assert_array_equal(src[start:start + n], np.arange(n))
        start += n
    if noct:
        split = np.array(conn[start:], dtype=np.int64).reshape(noct, 4, 4)
        np.testing.assert_array_equal(kind[start:], 4)
        np.testing.assert_array_equal(src[start:], np.repeat(np.arange(noct), 4))
        for o, tets in zip(lv["octahedra"], split):
            assert set(tets.reshape(-1)) == set(o)  # 4 tets filling the octahedron ...
            assert all(o[0] in t and o[1] in t for t in tets)  # ... around its major diagonal
    tets = np.array([c for c, t in zip(conn, types) if t == 10], dtype=np.int64).reshape(-1, 4)
    if len(tets):  # positively oriented: every tetrahedron; each octahedron's 4 as a whole
        vol = det(*(p[tets[:, k]] for k in range(4)))
        assert (vol[:ntet] > 0).all()
        assert (vol[ntet:].reshape(-1, 4).sum(1) > 0).all()
        # a sub-tetrahedron is inverted only where its octahedron is not convex along p-q
        assert (vol[ntet:] <= 0).sum() <= 1e-3 * len(vol[ntet:]) if level >= 2 else (vol > 0).all()
    rule = vtk_to_numpy(pd.GetArray("rule"))
    assert [RULES[int(x)] for x in rule] == lv["rules"]
    np.testing.assert_allclose(vtk_to_numpy(pd.GetArray("temp")), affine(p, 0), rtol=1e-12, atol=1e-12)
    wide = vtk_to_numpy(pd.GetArray("wide"))
    assert wide.shape == (len(p), 6)
    for k in range(6):
        np.testing.assert_allclose(wide[:, k], affine(p, k), rtol=1e-12, atol=1e-12)

    m = meshio.read(str(f))
    np.testing.assert_array_equal(m.points, p)
    names = {"vertex": 1, "line": 3, "triangle": 5, "tetra": 10}
    assert {names[c.type]: len(c.data) for c in m.cells} == counts
    assert set(m.cell_data) >= {"dimension", "kind", "source_cell"}
    assert set(m.point_data) >= {"temp", "vec", "wide", "rule"}
    np.testing.assert_array_equal(np.concatenate([c.data.reshape(-1) for c in m.cells]),
                                  np.concatenate([np.array(c, dtype=np.int64) for c in conn]) if conn else [])


@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("name", ["mixed", "cube", "surface", "curves"])
def test_json(tmp_path, meshes, name, level):
    lv = sdlevel(meshes[name], level)
    f = tmp_path / "l.json"
    outwrite(meshes[name], level, "json", f, "--xattr", "temp", "--xattr", "vec:3", "--version", 42)
    j = json.loads(f.read_text())
    assert list(j) == ["level", "version", "vertices", "cells", "attributes", "rules", "origin"]
    assert j["level"] == level and j["version"] == 42
    np.testing.assert_array_equal(np.array(j["vertices"]).reshape(-1, 3), lv["verts"])  # %.17g
    for key in ("points", "edges", "triangles", "tetrahedra", "octahedra"):
        ours = np.array(j["cells"][key], dtype=np.int64).reshape(-1, lv[key].shape[1])
        np.testing.assert_array_equal(ours, lv[key])
    assert list(j["attributes"]) == ["temp", "vec"]
    np.testing.assert_allclose(j["attributes"]["temp"], affine(lv["verts"], 0), rtol=1e-12, atol=1e-12)
    vec = np.array(j["attributes"]["vec"])
    for k in range(3):
        np.testing.assert_allclose(vec[:, k], affine(lv["verts"], k), rtol=1e-12, atol=1e-12)
    assert j["rules"] == lv["rules"]
    o = j["origin"]
    assert len(o["vertex_of"]) == len(o["edge_of"]) == len(o["cell_of"]) == len(lv["verts"])
    for i, tag in enumerate(lv["origins"]):
        want = {"I": lambda: (i, None, -1),  # level 0: every vertex is its own origin
                "V": lambda: (tag[1], None, -1),
                "E": lambda: (-1, [tag[1], tag[2]], -1),
                "C": lambda: (-1, None, tag[1])}[tag[0]]()
        assert (o["vertex_of"][i], o["edge_of"][i], o["cell_of"][i]) == want, i


def test_formats_agree(tmp_path, meshes):
    """The same level in every format: positions equal (float32 in glTF), cells equal."""
    mesh, level = meshes["mixed"], 2
    for fmt in FORMATS:
        outwrite(mesh, level, fmt, tmp_path / f"a.{fmt}")
    j = json.loads((tmp_path / "a.json").read_text())
    x = np.array(j["vertices"])
    doc, acc = read_glb(tmp_path / "a.glb")
    np.testing.assert_allclose(acc(doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]), x,
                               rtol=1e-7, atol=1e-7)
    import meshio
    for fmt in ("vtu", "vtk"):
        np.testing.assert_array_equal(meshio.read(str(tmp_path / f"a.{fmt}")).points, x)


# ---- streaming -----------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("name,level", [("mixed", 2), ("cube", 1)])
def test_chunks_identical(tmp_path, meshes, name, level, fmt):
    """Any read size gives the same bytes (and the size announced by out_size: outwrite checks
    it); so does the precomputed per-level geometry the daemon caches."""
    opts = [*ATTRS, "--colormap", "temp:0:1", "--slice", ",".join(map(str, SLICES[name]))]
    ref = tmp_path / f"ref.{fmt}"
    outwrite(meshes[name], level, fmt, ref, *opts, "--chunk", 65536)
    data = ref.read_bytes()
    for extra in (["--chunk", 1], ["--chunk", 7], ["--chunk", 4096], ["--chunk", (1 << 20) + 3],
                  ["--geometry"], ["--geometry", "--chunk", 3]):
        f = tmp_path / f"c.{fmt}"
        outwrite(meshes[name], level, fmt, f, *opts, *extra)
        assert f.read_bytes() == data, extra


def test_large_level_u32_indices(tmp_path):
    """More than 65535 vertices: 32-bit indices, still validator-clean; chunked output the same."""
    mesh = make_mesh_file(tmp_path, "torus", 150, 150)
    glb = tmp_path / "t.glb"
    r = outwrite(mesh, 1, "glb", glb, "--stats", "--chunk", 5)
    nv = int(r.stdout.split()[3])
    assert nv > 65535
    validate(glb)
    doc, acc = read_glb(glb)
    pr = doc["meshes"][0]["primitives"][0]
    assert doc["accessors"][pr["indices"]]["componentType"] == 5125
    assert int(acc(pr["indices"]).max()) == nv - 1


# ---- parts ----------------------------------------------------------------------------------


@pytest.mark.parametrize("parts", ["points", "curves", "surfaces", "solids", "points,solids",
                                   "curves,surfaces", "points,curves,surfaces,solids"])
def test_parts(tmp_path, meshes, parts):
    mesh, level = meshes["mixed"], 1
    lv = sdlevel(mesh, level)
    want = set(parts.split(","))
    keys = {"points": ["points"], "curves": ["edges"], "surfaces": ["triangles"],
            "solids": ["tetrahedra", "octahedra"]}
    outwrite(mesh, level, "json", tmp_path / "p.json", "--parts", parts)
    j = json.loads((tmp_path / "p.json").read_text())
    assert len(j["vertices"]) == len(lv["verts"])  # every vertex stays (shared numbering)
    for part, ks in keys.items():
        for k in ks:
            n = len(j["cells"][k])
            assert n == (len(lv[k]) if part in want else 0)
    outwrite(mesh, level, "glb", tmp_path / "p.glb", "--parts", parts, "--slice", "1,1,1,0.7531")
    validate(tmp_path / "p.glb")
    doc, _ = read_glb(tmp_path / "p.glb")
    modes = [pr["mode"] for m in doc["meshes"] for pr in m["primitives"]]
    expect = [m for part, m in (("points", [0]), ("curves", [1]), ("surfaces", [4]),
                                ("solids", [4, 4])) if part in want for m in m]  # solids: + slice
    assert modes == expect
    outwrite(mesh, level, "vtu", tmp_path / "p.vtu", "--parts", parts)
    import meshio
    m = meshio.read(str(tmp_path / "p.vtu"))
    got = {c.type: len(c.data) for c in m.cells}
    vt = {"points": ("vertex", len(lv["points"])), "curves": ("line", len(lv["edges"])),
          "surfaces": ("triangle", len(lv["triangles"])),
          "solids": ("tetra", len(lv["tetrahedra"]) + 4 * len(lv["octahedra"]))}
    assert got == dict(vt[p] for p in want)


def test_nothing_to_draw(tmp_path, meshes):
    """A selection with no cells: a valid glTF without mesh, a VTU with no cells, empty JSON."""
    mesh = meshes["surface"]
    for fmt in ("glb", "gltf"):
        outwrite(mesh, 1, fmt, tmp_path / f"e.{fmt}", "--parts", "points,curves,solids",
                 "--slice", "0,0,1,0", "--xattr", "t", "--colormap", "t:0:1")
        validate(tmp_path / f"e.{fmt}")
    doc, _ = read_glb(tmp_path / "e.glb")
    assert "meshes" not in doc and doc["nodes"] == [{"name": "level 1 (empty)"}]
    import vtk
    outwrite(mesh, 1, "vtu", tmp_path / "e.vtu", "--parts", "points")
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(tmp_path / "e.vtu"))
    r.Update()
    assert r.GetOutput().GetNumberOfCells() == 0
    assert r.GetOutput().GetNumberOfPoints() == len(sdlevel(mesh, 1)["verts"])
    # (meshio 7 cannot read a grid without cells: IndexError in _vtk_common, not checked here)
    outwrite(mesh, 1, "json", tmp_path / "e.json", "--parts", "solids")
    j = json.loads((tmp_path / "e.json").read_text())
    assert all(v == [] for v in j["cells"].values())


# ---- the solid boundary --------------------------------------------------------------------


@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("name", ["mixed", "cube", "blocks"])
def test_solid_boundary_encloses_the_solid(tmp_path, meshes, name, level):
    """Divergence theorem over the glTF solids primitive (its indices on the float64 positions):
    the enclosed volume is positive and equals the volume of the cells; closed (each directed
    edge meets its reverse once)."""
    lv = sdlevel(meshes[name], level)
    outwrite(meshes[name], level, "glb", tmp_path / "b.glb", "--parts", "solids")
    doc, acc = read_glb(tmp_path / "b.glb")
    (pr,) = doc["meshes"][0]["primitives"]
    tri = acc(pr["indices"]).astype(np.int64).reshape(-1, 3)
    p = lv["verts"]
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    enclosed = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    vol = cells_volume(lv)
    assert enclosed > 0
    assert abs(enclosed - vol) <= 1e-9 * vol
    directed = {}
    for t in tri:
        for k in range(3):
            e = (int(t[k]), int(t[(k + 1) % 3]))
            directed[e] = directed.get(e, 0) + 1
    assert all(n == 1 and directed.get((e[1], e[0])) == 1 for e, n in directed.items())


def test_polyhedra_vtu(tmp_path, meshes):
    import meshio
    import vtk
    lv = sdlevel(meshes["cube"], 1)
    f = tmp_path / "p.vtu"
    outwrite(meshes["cube"], 1, "vtu", f, "--polyhedra")
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(f))
    r.Update()
    g = r.GetOutput()
    types = [g.GetCellType(i) for i in range(g.GetNumberOfCells())]
    assert types.count(10) == len(lv["tetrahedra"]) and types.count(42) == len(lv["octahedra"])
    assert types == sorted(types)
    p = lv["verts"]
    oct_vol = 0
    for k, o in enumerate(lv["octahedra"]):
        cell = g.GetCell(types.index(42) + k)
        assert cell.GetNumberOfFaces() == 8 and cell.GetNumberOfPoints() == 6
        assert {cell.GetPointId(i) for i in range(6)} == set(o)
        centre = p[o].mean(0)
        for fi in range(8):  # every face outward: the cell's centre behind it
            face = cell.GetFace(fi)
            ids = [face.GetPointId(i) for i in range(3)]
            x = p[ids]
            nrm = np.cross(x[1] - x[0], x[2] - x[0])
            assert nrm @ (x.mean(0) - centre) > 0
            oct_vol += nrm @ x[0] / 6
    expect = cells_volume({"verts": p, "tetrahedra": np.zeros((0, 4), int), "octahedra": lv["octahedra"]})
    assert abs(oct_vol - expect) <= 1e-9 * expect
    # legacy VTK has no polyhedra: the request falls back to tetrahedra
    outwrite(meshes["cube"], 1, "vtk", tmp_path / "p.vtk", "--polyhedra")
    m = meshio.read(str(tmp_path / "p.vtk"))
    assert {c.type: len(c.data) for c in m.cells} == {"tetra": len(lv["tetrahedra"]) + 4 * len(lv["octahedra"])}


# ---- the cross-section ---------------------------------------------------------------------


def boundary_section_area(lv, n, d):
    """Area enclosed by the plane's intersection with the outward boundary (Green's theorem,
    each segment oriented along n x N)."""
    p = lv["verts"]
    area = 0.0
    for a, b, c in independent_boundary(lv).values():
        x = p[[a, b, c]]
        f = x @ n - d
        cuts = []
        for i, j in ((0, 1), (1, 2), (2, 0)):
            if (f[i] > 0) != (f[j] > 0):
                cuts.append(x[i] + f[i] / (f[i] - f[j]) * (x[j] - x[i]))
        if len(cuts) != 2:
            continue
        u, v = cuts
        N = np.cross(x[1] - x[0], x[2] - x[0])
        if (v - u) @ np.cross(n, N) < 0:
            u, v = v, u
        area += n @ np.cross(u, v) / 2
    return area


@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("name", ["mixed", "cube", "blocks"])
def test_slice(tmp_path, meshes, name, level):
    lv = sdlevel(meshes[name], level)
    plane = SLICES[name]
    n0 = np.array(plane[:3], float)
    n, d = n0 / np.linalg.norm(n0), plane[3] / np.linalg.norm(n0)
    assert (np.abs(lv["verts"] @ n - d) > 1e-9).all()  # no vertex on the plane: a clean test
    arg = ",".join(map(str, plane))
    opts = ["--slice", arg, "--xattr", "temp", "--xattr", "vec:3", "--colormap", "temp:0:2"]
    outwrite(meshes[name], level, "json", tmp_path / "s.json", *opts)
    j = json.loads((tmp_path / "s.json").read_text())
    sv = np.array(j["slice"]["vertices"]).reshape(-1, 3)
    st = np.array(j["slice"]["triangles"], dtype=np.int64).reshape(-1, 3)
    ns = slice_count(lv, plane)
    assert ns > 0 and len(st) == ns and len(sv) == 3 * ns
    assert np.abs(sv @ n0 - plane[3]).max() < 1e-9 * np.linalg.norm(n0)  # on the plane
    solid = np.unique(np.concatenate([lv["tetrahedra"].reshape(-1), lv["octahedra"].reshape(-1)]))
    lo, hi = lv["verts"][solid].min(0), lv["verts"][solid].max(0)
    assert (sv >= lo - 1e-12).all() and (sv <= hi + 1e-12).all()  # inside the solid's box
    cr = np.cross(sv[st[:, 1]] - sv[st[:, 0]], sv[st[:, 2]] - sv[st[:, 0]])
    assert (cr @ n > -1e-15).all()  # facing +n
    area = np.linalg.norm(cr, axis=1).sum() / 2
    ref = boundary_section_area(lv, n, d)
    assert abs(area - ref) <= 1e-9 * ref, (area, ref)

    # VTU: the same points after the level's, triangles marked as slice cells, attributes
    # interpolated (an affine function stays exact)
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy
    outwrite(meshes[name], level, "vtu", tmp_path / "s.vtu", *opts)
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(tmp_path / "s.vtu"))
    r.Update()
    g = r.GetOutput()
    nv = len(lv["verts"])
    pts = vtk_to_numpy(g.GetPoints().GetData())
    np.testing.assert_array_equal(pts[nv:], sv)
    kind = vtk_to_numpy(g.GetCellData().GetArray("kind"))
    dim = vtk_to_numpy(g.GetCellData().GetArray("dimension"))
    src = vtk_to_numpy(g.GetCellData().GetArray("source_cell"))
    sl = np.flatnonzero(kind == 5)
    assert len(sl) == ns and (dim[sl] == 2).all() and all(g.GetCellType(int(i)) == 5 for i in sl)
    assert src[sl].max() < max(len(lv["tetrahedra"]), len(lv["octahedra"]))
    conn = np.array([[g.GetCell(int(i)).GetPointId(k) for k in range(3)] for i in sl])
    np.testing.assert_array_equal(conn, nv + st)
    pd = g.GetPointData()
    np.testing.assert_allclose(vtk_to_numpy(pd.GetArray("temp"))[nv:], affine(sv, 0), rtol=1e-9, atol=1e-12)
    assert (vtk_to_numpy(pd.GetArray("rule"))[nv:] == 255).all()

    # glTF: the last primitive, non-indexed, own POSITION, plane normal, attributes, colours
    outwrite(meshes[name], level, "glb", tmp_path / "s.glb", *opts)
    validate(tmp_path / "s.glb")
    doc, acc = read_glb(tmp_path / "s.glb")
    prims = primitives_by_role(doc, lv, ns)
    shared_accessor_names(doc, prims)
    sp = prims["slice"]
    assert sp["mode"] == 4 and "indices" not in sp
    a = sp["attributes"]
    np.testing.assert_array_equal(acc(a["POSITION"]), sv.astype(np.float32))
    np.testing.assert_allclose(acc(a["NORMAL"]), np.tile(n, (len(sv), 1)), atol=1e-6)
    np.testing.assert_allclose(acc(a["_TEMP"]), affine(sv, 0), rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(acc(a["_VEC"])[:, 2], affine(sv, 2), rtol=1e-6, atol=1e-5)
    col = acc(a["COLOR_0"])
    assert ((col >= 0) & (col <= 1)).all()
    t = affine(sv, 0)
    np.testing.assert_allclose(col[t <= 0], np.tile(LIN_0, ((t <= 0).sum(), 1)), atol=1e-6)


def test_slice_area_of_the_unit_cube(tmp_path, meshes):
    """Level 0 of the TetGen cube is [0,1]^3: the plane x = 0.37 cuts a unit square."""
    outwrite(meshes["cube"], 0, "json", tmp_path / "q.json", "--slice", "2,0,0,0.74")
    j = json.loads((tmp_path / "q.json").read_text())
    sv = np.array(j["slice"]["vertices"]).reshape(-1, 3)
    st = np.array(j["slice"]["triangles"]).reshape(-1, 3)
    area = np.linalg.norm(np.cross(sv[st[:, 1]] - sv[st[:, 0]], sv[st[:, 2]] - sv[st[:, 0]]), axis=1).sum() / 2
    assert abs(area - 1) < 1e-12 and np.allclose(sv[:, 0], 0.37, atol=1e-15)


def test_slice_normal_of_any_magnitude(tmp_path, meshes):
    """n need not be unit (docs/OUTPUTS.md), however large or small: the plane scaled by 2^600
    or 2^-600 (exact, so the same doubles once made unit) gives the same file in every format,
    and one scaled by 1e200 or 1e-200 (not a power of 2) the same number of triangles, that
    of the plane itself recomputed here from the level's cells."""
    mesh, plane = meshes["cube"], SLICES["cube"]
    lv = sdlevel(mesh, 1)
    ns = slice_count(lv, plane)
    assert ns > 0
    for fmt in FORMATS:
        outwrite(mesh, 1, fmt, tmp_path / f"u.{fmt}", "--slice", ",".join(map(repr, plane)))
        for e in (600, -600):
            arg = ",".join(repr(x * 2.0 ** e) for x in plane)
            outwrite(mesh, 1, fmt, tmp_path / f"s.{fmt}", "--slice", arg)
            assert (tmp_path / f"s.{fmt}").read_bytes() == (tmp_path / f"u.{fmt}").read_bytes(), (fmt, arg)
    for scale in (1e200, 1e-200):
        arg = ",".join(repr(x * scale) for x in plane)
        outwrite(mesh, 1, "json", tmp_path / "s.json", "--slice", arg)
        j = json.loads((tmp_path / "s.json").read_text())
        assert len(j["slice"]["triangles"]) == ns, arg


def read_slice(tmp_path, mesh, level, plane):
    outwrite(mesh, level, "json", tmp_path / "v.json", "--slice", ",".join(map(repr, plane)))
    j = json.loads((tmp_path / "v.json").read_text())
    sv = np.array(j["slice"]["vertices"], dtype=float).reshape(-1, 3)
    st = np.array(j["slice"]["triangles"], dtype=np.int64).reshape(-1, 3)
    return sv[st]


@pytest.mark.parametrize("plane,want", [
    # through corner 0 only, 1 and 2 above, 3 below: the triangle 0, cut 1-3 at 1/3, cut 2-3
    ((1, 1, -2, 0), [[(0, 0, 0), (2 / 3, 0, 1 / 3), (0, 2 / 3, 1 / 3)]]),
    ((1, 1, 1, 0), []),        # through corner 0, the others above: only a point
    ((1, 1, 0, 0), []),        # through the edge 0-3, the others above: only a segment
    ((1, -1, 0, 0), [[(0, 0, 0), (0, 0, 1), (0.5, 0.5, 0)]]),  # through 0-3 between 1 and 2
    ((0, 0, 1, 0), [[(0, 0, 0), (1, 0, 0), (0, 1, 0)]]),        # the face 0 1 2, 3 above
])
def test_slice_through_a_vertex(tmp_path, plane, want):
    """A plane through a corner of the tetrahedron (0,0,0),(1,0,0),(0,1,0),(0,0,1): the section
    worked out by hand, as triangles facing +n and without two corners at one point."""
    mesh = tmp_path / "tet.txt"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\ns 0 1 2 3\n")
    tri = read_slice(tmp_path, mesh, 0, plane)
    assert len(tri) == len(want)
    n = np.array(plane[:3], float)
    for got, w in zip(tri, want):
        w = np.array(w, float)
        assert np.cross(got[1] - got[0], got[2] - got[0]) @ n > 0  # facing +n, not degenerate
        # the same corners (in some rotation of the order that faces +n)
        assert any(np.allclose(np.roll(got, k, axis=0), w, atol=1e-15) or
                   np.allclose(np.roll(got, k, axis=0), w[[0, 2, 1]], atol=1e-15) for k in range(3))


@pytest.mark.parametrize("level", [0, 1, 2])
def test_slice_through_vertices_is_a_closed_section(tmp_path, meshes, level):
    """The block [0,2]^3 of 8 cubes cut at x = 1, through vertices of every level (and near
    none): no triangle with two corners at one point, every one facing +x, the area of the
    section that the solid's outward boundary encloses (at level 0 the 2 x 2 square), and at
    level 0 every side shared with another triangle the other way round or on the square's
    border."""
    lv = sdlevel(meshes["blocks"], level)
    x = lv["verts"][:, 0]
    assert (x == 1).any() and not ((np.abs(x - 1) < 1e-9) & (x != 1)).any()
    tri = read_slice(tmp_path, meshes["blocks"], level, (1, 0, 0, 1))
    assert len(tri) and (tri[:, :, 0] == 1).all()
    for i, j in ((0, 1), (1, 2), (2, 0)):
        assert (np.linalg.norm(tri[:, i] - tri[:, j], axis=1) > 1e-9).all()
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (cr[:, 0] > 1e-12).all()
    area = cr[:, 0].sum() / 2
    ref = boundary_section_area(lv, np.array([1.0, 0, 0]), 1.0)
    assert abs(area - ref) <= 1e-9 * ref, (area, ref)
    if level == 0:
        assert abs(area - 4) < 1e-12
        key = [[tuple(p) for p in t] for t in tri]
        sides = collections.Counter((a, b) for t in key for a, b in zip(t, t[1:] + t[:1]))
        for (a, b), k in sides.items():
            on_border = any(a[c] == b[c] in (0, 2) for c in (1, 2))
            assert on_border or sides[(b, a)] == k, (a, b)


def test_slice_without_solids(tmp_path, meshes):
    """No solid cut: an empty slice (JSON), no slice primitive/cells."""
    for name in ("surface", "curves"):
        outwrite(meshes[name], 1, "json", tmp_path / "s.json", "--slice", "0,0,1,0")
        assert json.loads((tmp_path / "s.json").read_text())["slice"] == {"vertices": [], "triangles": []}
    outwrite(meshes["mixed"], 1, "json", tmp_path / "m.json", "--slice", "1,1,1,0.7531", "--parts", "surfaces")
    assert json.loads((tmp_path / "m.json").read_text())["slice"] == {"vertices": [], "triangles": []}


# ---- colour map and names -------------------------------------------------------------------


def colours(tmp_path, mesh, rng):
    """Level 1 of mesh as GLB coloured by the attribute t (its x) over rng ("min:max"): the
    level points' x and their COLOR_0."""
    f = tmp_path / "c.glb"
    outwrite(mesh, 1, "glb", f, "--xattr", "t", "--colormap", "t:" + rng)
    doc, acc = read_glb(f)
    return sdlevel(mesh, 1)["verts"][:, 0], acc(doc["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"])


def test_colormap_viridis(tmp_path, meshes):
    """COLOR_0 = viridis((t - min) / (max - min)) clamped: the published end and middle colours,
    converted from sRGB to linear as glTF requires."""
    x, col = colours(tmp_path, meshes["surface"], "-0.5:0.5")
    assert ((col >= 0) & (col <= 1)).all()
    np.testing.assert_allclose(col[x <= -0.5], np.tile(LIN_0, ((x <= -0.5).sum(), 1)), atol=1e-6)
    np.testing.assert_allclose(col[x >= 0.5], np.tile(LIN_1, ((x >= 0.5).sum(), 1)), atol=1e-6)
    mid = np.abs(x) < 1e-12
    assert mid.any()
    np.testing.assert_allclose(col[mid], np.tile(LIN_HALF, (mid.sum(), 1)), atol=1e-6)
    # and the hex end points #440154, #fde725: back in sRGB within their rounding to 1/255
    for sel, hexc in ((x <= -0.5, VIRIDIS_HEX_0), (x >= 0.5, VIRIDIS_HEX_1)):
        want = np.array([int(hexc[k:k + 2], 16) / 255 for k in (1, 3, 5)])
        assert sel.any() and (np.abs(linear_to_srgb(col[sel]) - want) <= 0.5 / 255 + 1e-6).all()
        # the same end colour as linear values: not the sRGB numbers themselves
        assert (np.abs(col[sel] - want) > 0.05).any()
    # the luminance of viridis grows with t: colours ordered like the attribute
    lum = col @ np.array([0.2126, 0.7152, 0.0722])
    order = np.argsort(x)
    assert (np.diff(lum[order]) >= -1e-6).all()


def test_colormap_viridis_every_stop(tmp_path, meshes):
    """Between the end and middle colours too: COLOR_0 is piecewise linear in sRGB through
    matplotlib's viridis at t = k/8, i.e. entries 0, 32, 64, ..., 224 and 255 of its 256-entry
    table (lib/matplotlib/_cm_listed.py; t = 1/8 is entry 32 = #472d7b), then made linear."""
    stops = np.array([
        (0.267004, 0.004874, 0.329415),  # 0
        (0.278826, 0.175490, 0.483397),  # 32
        (0.229739, 0.322361, 0.545706),  # 64
        (0.172719, 0.448791, 0.557885),  # 96
        (0.127568, 0.566949, 0.550556),  # 128
        (0.157851, 0.683765, 0.501686),  # 160
        (0.369214, 0.788888, 0.382914),  # 192
        (0.678489, 0.863742, 0.189503),  # 224
        (0.993248, 0.906157, 0.143936),  # 255
    ])
    x, col = colours(tmp_path, meshes["surface"], "-1:1")
    t = np.clip((x + 1) / 2, 0, 1)
    assert ((t > 0.02) & (t < 0.23)).sum() >= 3  # the first interval, where entry 32 matters
    want = srgb_to_linear(np.column_stack([np.interp(t, np.arange(9) / 8, stops[:, k]) for k in range(3)]))
    np.testing.assert_allclose(col, want, atol=2e-6)


def test_colormap_range_wider_than_a_double(tmp_path, meshes):
    """t = (v - min)/(max - min) (docs/OUTPUTS.md) for a range whose width exceeds the largest
    double: values near 0 in -1e308:1e308 are at t = 0.5, in -1.7e308:1e-300 at t = 1 and in
    -1e-300:1.7e308 at t = 0 (to far below float precision), whatever the size of max - min."""
    for rng, want in (("-1e308:1e308", LIN_HALF), ("-1.7e308:1e-300", LIN_1), ("-1e-300:1.7e308", LIN_0)):
        _, col = colours(tmp_path, meshes["surface"], rng)
        np.testing.assert_allclose(col, np.tile(want, (len(col), 1)), atol=1e-6, err_msg=rng)


def test_attribute_names(tmp_path, meshes):
    """glTF names are `_` + upper case, unique (`_RULE` stays the rule's); VTK keeps the posted
    names and renames its own rule array on a clash; JSON keeps the posted names."""
    mesh = meshes["mixed"]
    opts = ["--xattr", "rule", "--xattr", "a-b", "--xattr", "A_B:2", "--xattr", "Rule"]
    outwrite(mesh, 1, "gltf", tmp_path / "n.gltf", *opts)
    validate(tmp_path / "n.gltf")
    doc = json.loads((tmp_path / "n.gltf").read_text())
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    assert set(attrs) == {"POSITION", "_RULE", "_RULE_2", "_A_B", "_A_B_2", "_RULE_3"}
    assert doc["accessors"][attrs["_A_B_2"]]["type"] == "VEC2"
    outwrite(mesh, 1, "vtu", tmp_path / "n.vtu", *opts)
    import meshio
    m = meshio.read(str(tmp_path / "n.vtu"))
    assert set(m.point_data) == {"rule", "a-b", "A_B", "Rule", "rule_2"}
    lv = sdlevel(mesh, 1)
    assert [RULES[int(r)] for r in m.point_data["rule_2"]] == lv["rules"]
    np.testing.assert_allclose(m.point_data["rule"].reshape(-1), affine(lv["verts"], 0), rtol=1e-12, atol=1e-12)


# ---- refused requests ----------------------------------------------------------------------


def test_bad_requests_refused(meshes, tmp_path):
    r = subprocess.run([str(OUTWRITE), str(meshes["mixed"]), "--check-errors"], capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = dict(line.split(" ", 1) for line in r.stdout.splitlines())
    assert lines.pop("ok") == "OK"
    assert len(lines) >= 20
    for case, rest in lines.items():
        assert rest.startswith("argument "), (case, rest)
        option = case.split("-")[0]
        if option != "no":
            assert rest[len("argument "):].startswith(option + ":"), (case, rest)
    # a level that is not computed, from the command line
    r = outwrite(meshes["mixed"], 2, "glb", tmp_path / "x.glb", "--compute", 1, check=False)
    assert r.returncode == 1 and "level: 2 has not been computed" in r.stderr


@pytest.mark.parametrize("name", ["mixed", "blocks", "surface"])
def test_meshio_reads_every_layout(tmp_path, meshes, name):
    """meshio's raw VTU reader rewrites block offsets as it walks them (see out_vtk.c): many
    layouts (levels, parts, attribute counts and sizes, slice), every one must read back."""
    import meshio
    for level in LEVELS:
        lv = sdlevel(meshes[name], level)
        for parts in ("points", "curves,solids", "points,solids", "surfaces,solids",
                      "points,curves,surfaces,solids"):
            for attrs, cut in itertools.product(([], ["a"], ["a", "b:2"], ["a:3", "b", "c:5", "d:16"]),
                                                (False, True)):
                opts = ["--parts", parts]
                if cut:
                    opts += ["--slice", ",".join(map(str, SLICES[name]))]
                for a in attrs:
                    opts += ["--xattr", a]
                f = tmp_path / "m.vtu"
                outwrite(meshes[name], level, "vtu", f, *opts)
                import vtk
                r = vtk.vtkXMLUnstructuredGridReader()
                r.SetFileName(str(f))
                r.Update()
                if r.GetOutput().GetNumberOfCells() == 0:
                    continue  # meshio 7 cannot read a grid without cells
                m = meshio.read(str(f))
                np.testing.assert_array_equal(m.points[:len(lv["verts"])], lv["verts"])
                for a in attrs:
                    nm, _, nc = a.partition(":")
                    assert m.point_data[nm].reshape(len(m.points), -1).shape[1] == int(nc or 1)
