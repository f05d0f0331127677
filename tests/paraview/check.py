"""make test-paraview: ParaView itself (pvpython, Debian's paraview 5.11) opens what subdivd writes.

    pvpython tests/paraview/check.py INPUT.json L DIR

DIR holds level.vtu, level_z.vtu (compress=zlib, names=true) and level.vtk of level L of INPUT,
and series/levels.pvd (subdiv refine --pvd: levels 0..L). Each must open with OpenDataFile and
have the expected arrays, and the cell counts of the split table (docs/OUTPUTS.md) computed here
from INPUT: a tetrahedron gives 4 tetrahedra and an octahedron, an octahedron 8 tetrahedra and 6
octahedra, a triangle 4, a segment 2; octahedra are written as 4 tetrahedra each. INPUT must
have no simplex absorbed into another (examples/mixed.json has none). Exits non-zero on a
mismatch, printing what differs."""
import json
import os
import sys

from paraview import servermanager as sm
from paraview.simple import OpenDataFile

POINT_ARRAYS = {"rule"}
CELL_ARRAYS = {"dimension", "kind", "source_cell", "control_cell"}


def cells_at(body, level):
    n = [0] * 5
    for s in body["simplices"]:
        n[len(s) - 1] += 1
    npt, ncu, ntr, nt = n[0], n[1], n[2], n[3]
    no = 0
    for _ in range(level):
        ncu, ntr, nt, no = 2 * ncu, 4 * ntr, 4 * nt + 8 * no, nt + 6 * no
    return npt + ncu + ntr + nt + 4 * no


def names(fields):
    return {fields.GetArrayName(i) for i in range(fields.GetNumberOfArrays())}


def check(path, level, body, time=None, field_names=False):
    r = OpenDataFile(path)
    assert r is not None, f"{path}: ParaView has no reader for it"
    r.UpdatePipeline() if time is None else r.UpdatePipeline(time)
    d = sm.Fetch(r)
    want = cells_at(body, level)
    assert d.GetNumberOfCells() == want, f"{path}: {d.GetNumberOfCells()} cells, want {want}"
    assert d.GetNumberOfPoints() >= len(body["vertices"]), f"{path}: {d.GetNumberOfPoints()} points"
    pa, ca = names(d.GetPointData()), names(d.GetCellData())
    want_pa = POINT_ARRAYS | set(body.get("attributes", {}))
    assert want_pa <= pa, f"{path}: point arrays {sorted(pa)}, want {sorted(want_pa)}"
    assert CELL_ARRAYS <= ca, f"{path}: cell arrays {sorted(ca)}, want {sorted(CELL_ARRAYS)}"
    fd = d.GetFieldData()
    lv = fd.GetArray("level")
    assert lv is not None and int(lv.GetTuple1(0)) == level, f"{path}: FieldData level"
    if field_names:
        rn = fd.GetAbstractArray("rule_names")
        assert rn is not None and rn.GetValue(0) == "corner", f"{path}: FieldData rule_names"
    print(f"paraview: {os.path.basename(path)}: {d.GetNumberOfCells()} cells, "
          f"{d.GetNumberOfPoints()} points, arrays ok")
    return r


def main():
    inp, level, directory = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    with open(inp) as f:
        body = json.load(f)
    check(os.path.join(directory, "level.vtu"), level, body)
    check(os.path.join(directory, "level_z.vtu"), level, body, field_names=True)
    check(os.path.join(directory, "level.vtk"), level, body)
    pvd = os.path.join(directory, "series", "levels.pvd")
    r = OpenDataFile(pvd)
    assert r is not None, f"{pvd}: ParaView has no reader for it"
    steps = list(r.TimestepValues)
    assert steps == list(range(level + 1)), f"{pvd}: timesteps {steps}"
    for k in steps:
        check(pvd, int(k), body, time=k)
    print("paraview: all checks passed")


if __name__ == "__main__":
    main()
