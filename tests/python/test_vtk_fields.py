"""VTU / legacy VTK extras read back with VTK and meshio: FieldData (level, version, the names of
the rule and kind values), the control_cell cell data, compress=zlib and the query's errors.

Expected values: the version is the ETag the daemon answers with; the rule names are the table
of docs/OUTPUTS.md; control_cell is derived here from the JSON output alone — each cell's parent
is the cell of the previous level whose vertices its vertices come from (`origin`), composed
down to level 0, whose cells are matched to the posted simplices by their vertex sets."""
import numpy as np
import pytest

from daemon import Daemon, Session

vtk = pytest.importorskip("vtk")
meshio = pytest.importorskip("meshio")
from vtk.util.numpy_support import vtk_to_numpy  # noqa: E402

# docs/OUTPUTS.md: the rule ids in the order of the rule table
RULES = ["corner", "curve", "loop", "loop-boundary", "solid", "solid-boundary", "N1", "N2", "G1",
         "G2", "ying-zorin-crease", "ying-zorin-corner", "ying-zorin-petal",
         "ying-zorin-fixed-disk", "ying-zorin-dart", "ying-zorin-concave"]
KINDS = ["point", "curve", "triangle", "tetrahedron", "octahedron", "slice"]

# Two tetrahedra sharing a face, a triangle that is a face of one (absorbed into the solid), a fin
# triangle, a curve that is a fin edge (absorbed), a free curve, a point that is a vertex
# (absorbed) and an isolated point — in an order that mixes the kinds.
BODY = {
    "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [1, 1, -1], [2, 2, 2],
                 [3, 0, 0], [5, 5, 5]],
    "simplices": [[7, 1], [0, 1, 2], [1, 2, 5], [0, 1, 2, 3], [8], [1, 5], [3], [1, 2, 3, 4],
                  [5, 6]],
}
KIND_KEYS = ["points", "edges", "triangles", "tetrahedra", "octahedra"]


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


@pytest.fixture(scope="module")
def session(daemon):
    s = Session(daemon)
    r = s.put_complex(BODY)
    assert r.status_code == 200, r.text
    return s


def read_vtk(path, legacy=False):
    r = vtk.vtkUnstructuredGridReader() if legacy else vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(path))
    if legacy:
        r.ReadAllFieldsOn()
    r.Update()
    return r.GetOutput()


def strings(a):
    return [a.GetValue(i) for i in range(a.GetNumberOfValues())]


@pytest.mark.parametrize("fmt", ["vtu", "vtk"])
@pytest.mark.parametrize("names", [None, "true"])
def test_field_data(session, tmp_path, fmt, names):
    level = 1
    params = {"format": fmt}
    if names:
        params["names"] = names
    r = session.level(level, **params)
    assert r.status_code == 200, r.text
    version = int(r.headers["ETag"].strip('"'))
    f = tmp_path / f"l.{fmt}"
    f.write_bytes(r.content)
    g = read_vtk(f, legacy=fmt == "vtk")
    fd = g.GetFieldData()
    assert vtk_to_numpy(fd.GetArray("level")).tolist() == [level]
    assert vtk_to_numpy(fd.GetArray("version")).tolist() == [version]
    if not names:
        assert fd.GetAbstractArray("rule_names") is None
        m = meshio.read(str(f))  # meshio 7 reads numeric FieldData (VTU), not strings
        if fmt == "vtu":  # (its legacy reader skips the dataset's FIELD)
            assert m.field_data["level"].tolist() == [level]
            assert m.field_data["version"].tolist() == [version]
        return
    assert strings(fd.GetAbstractArray("rule_names")) == RULES
    assert strings(fd.GetAbstractArray("kind_names")) == KINDS
    # the names mean what the JSON output's rule names say, vertex by vertex
    j = session.level(level, format="json").json()
    rule = vtk_to_numpy(g.GetPointData().GetArray("rule"))
    assert [RULES[k] for k in rule[: len(j["rules"])]] == j["rules"]


def derived_control(session, level):
    """control[kind][i] for the cells of `level`, from the JSON output of levels 0..level."""
    posted = {frozenset(s): n for n, s in enumerate(BODY["simplices"])}
    lv = [session.level(l, format="json").json() for l in range(level + 1)]

    def cells(j, k):
        c = j["cells"][KIND_KEYS[k]]
        return [[x] if k == 0 else x for x in c]

    ctrl = [[posted[frozenset(c)] for c in cells(lv[0], k)] for k in range(5)]
    for l in range(1, level + 1):
        prev, cur = lv[l - 1], lv[l]
        o = cur["origin"]
        index = {}
        for k in range(5):
            for i, c in enumerate(cells(prev, k)):
                index[(k, frozenset(c))] = i
        nxt = []
        for k in range(5):
            out = []
            for c in cells(cur, k):
                octa = [o["cell_of"][v] for v in c if o["cell_of"][v] >= 0]
                if octa:  # a child of an octahedron has its cell point
                    assert len(set(octa)) == 1
                    out.append(ctrl[4][octa[0]])
                    continue
                u = set()
                for v in c:
                    u |= {o["vertex_of"][v]} if o["vertex_of"][v] >= 0 else set(o["edge_of"][v])
                pk = 3 if k == 4 else k  # an octahedron without a cell point is a tet's middle
                out.append(ctrl[pk][index[(pk, frozenset(u))]])
            nxt.append(out)
        ctrl = nxt
    return ctrl


@pytest.mark.parametrize("level", [0, 1, 2])
def test_control_cell(session, tmp_path, level):
    ctrl = derived_control(session, level)
    for fmt in ("vtu", "vtk"):
        r = session.level(level, format=fmt, slice="0.3,0.2,1,0.4")
        assert r.status_code == 200, r.text
        f = tmp_path / f"c.{fmt}"
        f.write_bytes(r.content)
        g = read_vtk(f, legacy=fmt == "vtk")
        cd = g.GetCellData()
        kind = vtk_to_numpy(cd.GetArray("kind"))
        src = vtk_to_numpy(cd.GetArray("source_cell"))
        skind = vtk_to_numpy(cd.GetArray("source_kind"))
        got = vtk_to_numpy(cd.GetArray("control_cell"))
        # a slice triangle's source_cell counts in its source_kind (the cut tetrahedron or
        # octahedron); every other cell's source_kind is its kind
        assert (skind[kind != 5] == kind[kind != 5]).all()
        assert set(skind[kind == 5].tolist()) == ({3} if level == 0 else {3, 4})
        assert [ctrl[k][s] for k, s in zip(skind, src)] == got.tolist()
        # slice triangles descend from a posted tetrahedron (3 or 7)
        assert set(got[kind == 5].tolist()) <= {3, 7}
        assert (kind == 5).any()
        # and each lies in the cell it names (a tetrahedron, or one of the 4 tetrahedra of an
        # octahedron (p, q, a, a2, b, b2) around its major diagonal p-q)
        j = session.level(level, format="json").json()
        x = np.array(j["vertices"])
        pts = vtk_to_numpy(g.GetPoints().GetData())
        for c in np.flatnonzero(kind == 5):
            cell = j["cells"][KIND_KEYS[skind[c]]][src[c]]
            if skind[c] == 3:
                parts = [cell]
            else:
                p, q, a, a2, b, b2 = cell
                parts = [[p, q, a, b], [p, q, b, a2], [p, q, a2, b2], [p, q, b2, a]]
            for v in range(3):
                y = pts[g.GetCell(int(c)).GetPointId(v)]
                inside = [np.linalg.solve(np.vstack([x[t].T, np.ones(4)]), np.append(y, 1.0)).min()
                          >= -1e-9 for t in parts]
                assert any(inside), (c, skind[c], src[c], y)
        m = meshio.read(str(f))
        mc = [x for block in m.cell_data["control_cell"] for x in block.tolist()]
        assert mc == got.tolist()
    if level == 1:  # against the split structure directly: tet t's children are 4t..4t+3, oct t
        n_tet0 = len(ctrl_tets := derived_control(session, 0)[3])
        assert ctrl[3][: 4 * n_tet0] == [ctrl_tets[t // 4] for t in range(4 * n_tet0)]
        assert ctrl[4] == ctrl_tets


def problem(r, status, param):
    assert r.status_code == status, r.text
    assert r.headers["Content-Type"] == "application/problem+json"
    p = r.json()
    assert p["errors"][0]["pointer"] == param, p
    assert param in p["detail"], p
    return p


def test_bad_parameters(session):
    problem(session.level(1, format="vtu", names="yes"), 422, "names")
    problem(session.level(1, format="glb", names="true"), 422, "names")
    problem(session.level(1, format="vtu", compress="gzip"), 422, "compress")
    p = problem(session.level(1, format="vtk", compress="zlib"), 422, "compress")
    assert "vtu" in p["detail"]
    problem(session.level(1, format="json", compress="zlib"), 422, "compress")
    for fmt in ("glb", "gltf", "json"):   # a VTK option with another format (docs/API.md)
        p = problem(session.level(1, format=fmt, octahedra="polyhedra"), 422, "octahedra")
        assert fmt in p["detail"]
    problem(session.level(1, format="glb", octahedra="tets"), 422, "octahedra")
    # an option with a format it does not apply to, whatever its value (docs/OUTPUTS.md)
    for fmt in ("glb", "gltf", "vtk", "json"):
        p = problem(session.level(1, format=fmt, compress="none"), 422, "compress")
        assert p["type"] == "/errors/not-applicable" and p["detail"].startswith("compress:"), p
    problem(session.level(1, format="glb", names="false"), 422, "names")
    assert session.level(1, format="vtu", compress="none").status_code == 200


def arrays(g):
    """Every point and cell data array, the points and the cells of a grid, as numpy arrays."""
    out = {"Points": vtk_to_numpy(g.GetPoints().GetData()),
           "types": vtk_to_numpy(g.GetCellTypesArray()),
           "connectivity": vtk_to_numpy(g.GetCells().GetConnectivityArray()),
           "offsets": vtk_to_numpy(g.GetCells().GetOffsetsArray())}
    for kind, d in (("point", g.GetPointData()), ("cell", g.GetCellData())):
        for i in range(d.GetNumberOfArrays()):
            out[kind + ":" + d.GetArrayName(i)] = vtk_to_numpy(d.GetArray(i))
    return out


@pytest.mark.parametrize("level", [0, 2, 5])
@pytest.mark.parametrize("opts", [{}, {"slice": "0.3,0.2,1,0.4", "names": "true"},
                                  {"octahedra": "polyhedra"}, {"parts": "curves"}])
def test_zlib_vtu(session, tmp_path, level, opts):
    raw = session.level(level, format="vtu", **opts)
    z = session.level(level, format="vtu", compress="zlib", **opts)
    assert raw.status_code == 200 and z.status_code == 200, z.text
    assert "Content-Length" in raw.headers
    assert "Content-Length" not in z.headers and z.headers["Transfer-Encoding"] == "chunked"
    assert z.headers["ETag"] == raw.headers["ETag"]
    fr, fz = tmp_path / "raw.vtu", tmp_path / "z.vtu"
    fr.write_bytes(raw.content)
    fz.write_bytes(z.content)
    assert b'compressor="vtkZLibDataCompressor"' in z.content[:400]
    gr, gz = read_vtk(fr), read_vtk(fz)
    assert gz.GetNumberOfPoints() == gr.GetNumberOfPoints() > 0
    assert gz.GetNumberOfCells() == gr.GetNumberOfCells()
    ar, az = arrays(gr), arrays(gz)
    assert ar.keys() == az.keys()
    for k in ar:
        assert ar[k].dtype == az[k].dtype and (ar[k] == az[k]).all(), k
    if level == 5 and not opts:  # several 32 KiB blocks per array, and smaller than raw
        assert gz.GetNumberOfPoints() * 24 > 3 * 32768 and len(z.content) < len(raw.content)
    if opts.get("octahedra") or opts.get("names"):
        return  # meshio 7 reads polyhedra only alone, and no string arrays
    mr, mz = meshio.read(str(fr)), meshio.read(str(fz))
    assert (mr.points == mz.points).all()
    assert [c.type for c in mr.cells] == [c.type for c in mz.cells]
    for a, b in zip(mr.cells, mz.cells):
        assert (a.data == b.data).all()
    for k in mr.cell_data:
        assert all((a == b).all() for a, b in zip(mr.cell_data[k], mz.cell_data[k])), k
    for k in mr.point_data:
        assert (mr.point_data[k] == mz.point_data[k]).all(), k


def test_offline_same_bytes(daemon, tmp_path):
    """`subdivd refine` writes what the daemon streams (both version 1: a fresh session)."""
    import json
    import subprocess

    from daemon import SUBDIVD
    s = Session(daemon)
    assert s.put_complex(BODY).status_code == 200
    src = tmp_path / "c.json"
    src.write_text(json.dumps(BODY))
    for flags, params in ((["--compress", "zlib", "--names", "true"], {"compress": "zlib", "names": "true"}),
                          ([], {})):
        out = tmp_path / "o.vtu"
        r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "2", "-o", str(out), *flags],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        assert out.read_bytes() == s.level(2, format="vtu", **params).content
    r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "1", "-o", str(tmp_path / "o.vtk"),
                        "--compress", "zlib"], capture_output=True, text=True)
    assert r.returncode == 1 and "compress" in r.stderr


def test_pvd_time_series(daemon, tmp_path):
    """`subdiv refine --pvd DIR`: levels.pvd (parsed as XML: python3-vtk9 has no vtkPVDReader)
    lists level_K.vtu at timestep K for K = 0..L, each readable by VTK with FieldData level K and
    the cell counts of the split table."""
    import json
    import os
    import subprocess
    import xml.etree.ElementTree as ET

    from conftest import REPO
    src = tmp_path / "c.json"
    src.write_text(json.dumps(BODY))
    out = tmp_path / "series"
    r = subprocess.run([str(REPO / "build" / "subdiv"), "refine", str(src), "--level", "3",
                        "--pvd", str(out), "--compress", "zlib", "--url", daemon.url, "-q"],
                       capture_output=True, text=True, timeout=300, env=dict(os.environ))
    assert r.returncode == 0, r.stderr
    root = ET.parse(out / "levels.pvd").getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    sets = root.find("Collection").findall("DataSet")
    assert [(d.get("timestep"), d.get("file")) for d in sets] == \
        [(str(k), f"level_{k}.vtu") for k in range(4)]
    assert sorted(p.name for p in out.iterdir()) == ["level_0.vtu", "level_1.vtu", "level_2.vtu",
                                                     "level_3.vtu", "levels.pvd"]
    # top cells per kind from the split table: tets 2, octahedra 0 at level 0
    npt, ncu, ntr, nt, no = 1, 2, 1, 2, 0  # [8]; [7,1], [5,6]; [1,2,5]; two tets (see BODY)
    for k, d in enumerate(sets):
        g = read_vtk(out / d.get("file"))
        assert vtk_to_numpy(g.GetFieldData().GetArray("level")).tolist() == [k]
        kind = vtk_to_numpy(g.GetCellData().GetArray("kind"))
        assert [(kind == c).sum() for c in range(5)] == [npt, ncu, ntr, nt, 4 * no]
        ncu, ntr, nt, no = 2 * ncu, 4 * ntr, 4 * nt + 8 * no, nt + 6 * no
    r = subprocess.run([str(REPO / "build" / "subdiv"), "refine", str(src), "--level", "1",
                        "--url", daemon.url], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--pvd" in r.stderr
