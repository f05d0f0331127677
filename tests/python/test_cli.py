"""The `subdiv` command (clients/python/subdiv/cli.py, installed as build/subdiv): every supported
input format round-trips to VTU and GLB through the real daemon (checked with meshio, VTK and the
Khronos validator), tags come from job files and Gmsh physical groups, job files run several
meshes, and the exit codes are the documented ones."""
import json
import os
import pathlib
import subprocess

import pytest

from conftest import REPO
from daemon import SUBDIVD, Daemon
from test_fill import surface

SUBDIV = REPO / "build" / "subdiv"
VALIDATOR = REPO / "tests" / "tools" / "gltf_validate.js"
ENV = dict(os.environ, SUBDIVD=str(SUBDIVD))


@pytest.fixture(scope="module")
def daemon():
    d = Daemon("--max-sessions", "100")
    yield d
    assert d.stop() == 0


def run(*args, cwd=None, env=None):
    return subprocess.run([str(SUBDIV), *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          env=env or ENV, timeout=300)


def write_msh41(path, points, blocks, names):
    """Gmsh 4.1 ASCII (meshio cannot write physical groups in 4.1). blocks: [(dim, cells,
    physical tag or 0)], names: {name: (dim, tag)}."""
    et = {0: 15, 1: 1, 2: 2, 3: 4}
    L = ["$MeshFormat", "4.1 0 8", "$EndMeshFormat", "$PhysicalNames", str(len(names))]
    L += [f'{d} {t} "{n}"' for n, (d, t) in names.items()]
    L += ["$EndPhysicalNames", "$Entities"]
    ents = {0: [], 1: [], 2: [], 3: []}
    for d, _, phys in blocks:
        ents[d].append((len(ents[d]) + 1, phys))
    L.append(" ".join(str(len(ents[d])) for d in range(4)))
    lo = [min(p[k] for p in points) for k in range(3)]
    hi = [max(p[k] for p in points) for k in range(3)]
    for d in range(4):
        for tag, phys in ents[d]:
            ph = f"1 {phys}" if phys else "0"
            L.append(f"{tag} {' '.join(map(str, lo))} {ph}" if d == 0 else
                     f"{tag} {' '.join(map(str, lo + hi))} {ph} 0")
    L.append("$EndEntities")
    n = len(points)
    L += ["$Nodes", f"1 {n} 1 {n}", f"{blocks[0][0]} 1 0 {n}"] + [str(i + 1) for i in range(n)]
    L += [" ".join(repr(float(x)) for x in p) for p in points] + ["$EndNodes", "$Elements"]
    total = sum(len(c) for _, c, _ in blocks)
    L.append(f"{len(blocks)} {total} 1 {total}")
    seen, k = {0: 0, 1: 0, 2: 0, 3: 0}, 1
    for d, cells, _ in blocks:
        seen[d] += 1
        L.append(f"{d} {seen[d]} {et[d]} {len(cells)}")
        for c in cells:
            L.append(f"{k} " + " ".join(str(i + 1) for i in c))
            k += 1
    L.append("$EndElements")
    pathlib.Path(path).write_text("\n".join(L) + "\n")


# A mixed complex: a block of 6 tets (unit cube), a fin triangle on its edge 0-1, a curve from
# vertex 7 and an isolated point. Counts per kind: 6 tets, 1 triangle, 2 segments, 1 point.
CUBE = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1]]
TETS = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]]
MIXED_PTS = CUBE + [[0.5, -1, 0], [1.5, 1.5, 1.5], [2, 2, 2.5], [3, 0, 0]]
MIXED = {"tetra": TETS, "triangle": [[0, 1, 8]], "line": [[7, 9], [9, 10]], "vertex": [[11]]}


def expected(counts, level):
    P, C, F, T, O = counts.get("vertex", 0), counts.get("line", 0), counts.get("triangle", 0), counts.get("tetra", 0), 0
    for _ in range(level):
        C, F, T, O = 2 * C, 4 * F, 4 * T + 8 * O, T + 6 * O
    return {k: v for k, v in (("vertex", P), ("line", C), ("triangle", F), ("tetra", T + 4 * O)) if v}


def write_inputs(d):
    """{file: (cell counts of the complex the CLI should post, cli extra args)}"""
    import meshio
    import numpy as np
    out = {}
    mixed = meshio.Mesh(np.array(MIXED_PTS, float), [(k, np.array(v)) for k, v in MIXED.items()],
                        point_data={"height": np.array([p[2] for p in MIXED_PTS])})
    mixed_counts = {k: len(v) for k, v in MIXED.items()}
    for name, kw in (("mixed.vtu", {}), ("mixed.vtk", {}), ("mixed22.msh", {"file_format": "gmsh22", "binary": False}),
                     ("mixed22b.msh", {"file_format": "gmsh22", "binary": True})):
        meshio.write(d / name, mixed, **kw)
        out[name] = (mixed_counts, [])
    blocks = [(3, TETS, 1), (2, MIXED["triangle"], 2), (1, MIXED["line"], 3), (0, MIXED["vertex"], 4)]
    write_msh41(d / "mixed41.msh", MIXED_PTS, blocks, {"solid": (3, 1), "fin": (2, 2), "wire": (1, 3), "dot": (0, 4)})
    out["mixed41.msh"] = (mixed_counts, [])
    tets = meshio.Mesh(np.array(CUBE, float), [("tetra", np.array(TETS))])
    meshio.write(d / "cube.node", tets)     # writes cube.node and cube.ele
    out["cube.ele"] = ({"tetra": 6}, [])
    out["cube.node"] = ({"tetra": 6}, [])
    v, f = surface("icosphere", 1)
    sph = meshio.Mesh(np.array(v), [("triangle", np.array(f))])
    for name in ("sphere.obj", "sphere.off"):
        meshio.write(d / name, sph)
        out[name] = ({"triangle": len(f)}, [])
    meshio.write(d / "sphere.stl", sph)
    out["sphere.stl"] = (None, ["--fill", "--min-ratio", "1.5"])     # filled: tets from TetGen
    # an OBJ with quads (split into triangles by the client): a cube's six faces
    obj = ["v %g %g %g" % tuple(p) for p in CUBE]
    quads = [(1, 3, 4, 2), (5, 6, 8, 7), (1, 2, 6, 5), (3, 7, 8, 4), (1, 5, 7, 3), (2, 4, 8, 6)]
    (d / "box.obj").write_text("\n".join(obj + ["f %d %d %d %d" % q for q in quads]) + "\n")
    out["box.obj"] = ({"triangle": 12}, [])
    (d / "box.off").write_text("OFF\n8 6 0\n" + "".join("%g %g %g\n" % tuple(p) for p in CUBE)
                               + "".join("4 %d %d %d %d\n" % tuple(i - 1 for i in q) for q in quads))
    out["box.off"] = ({"triangle": 12}, [])
    # points, polylines and polygons: a square (2 triangles), a fin triangle on its edge 0-1, a
    # curve of 2 segments from vertex 2 and an isolated point; OBJ p/l/f records, OFF faces of
    # 1, 2, 3 and 4 vertices
    pts = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, -1, 0.5], [1.5, 1.5, 1.5], [2, 2, 2.5], [3, 0, 0]]
    vs = ["v %g %g %g" % tuple(p) for p in pts]
    (d / "wire.obj").write_text("\n".join(vs + ["f 1/1 2/2 3/3 4/4", "f 1//1 2//1 5//1", "l 3 6 7", "p -1"]) + "\n")
    out["wire.obj"] = ({"triangle": 3, "line": 2, "vertex": 1}, [])
    (d / "wire.off").write_text("OFF\n# comment\n8 5 0\n" + "".join("%g %g %g\n" % tuple(p) for p in pts)
                                + "4 0 1 2 3\n3 0 1 4 255 0 0\n2 2 5\n2 5 6\n1 7\n")
    out["wire.off"] = ({"triangle": 3, "line": 2, "vertex": 1}, [])
    body = {"vertices": MIXED_PTS, "simplices": TETS + MIXED["triangle"] + MIXED["line"] + MIXED["vertex"]}
    (d / "mixed.json").write_text(json.dumps(body))
    out["mixed.json"] = (mixed_counts, [])
    return out


def test_every_format_to_vtu_and_glb(daemon, tmp_path):
    import meshio
    import vtk
    inputs = write_inputs(tmp_path)
    glbs = []
    for name, (counts, extra) in inputs.items():
        vtu, glb = tmp_path / f"{name}.vtu", tmp_path / f"{name}.glb"
        r = run("refine", tmp_path / name, "--level", 2, "-o", vtu, "-o", glb, "--url", daemon.url,
                "--progress", "lines", *extra)
        assert r.returncode == 0, (name, r.stdout, r.stderr)
        assert "received" in r.stderr and f"level 2 -> {vtu}" in r.stderr
        m = meshio.read(vtu)
        got = {}
        for b in m.cells:
            got[b.type] = got.get(b.type, 0) + len(b.data)
        if counts is None:   # filled sphere: only tetrahedra, 64 per generated tet at level 2
            assert set(got) == {"tetra"} and got["tetra"] % 64 == 0, got
        else:
            assert got == expected(counts, 2), (name, got)
        rd = vtk.vtkXMLUnstructuredGridReader()
        rd.SetFileName(str(vtu))
        rd.Update()
        assert rd.GetOutput().GetNumberOfCells() == sum(got.values())
        if name.startswith("mixed") and name != "mixed.json" and not name.startswith("mixed2") and not name.startswith("mixed4"):
            assert "height" in m.point_data                               # point data became an attribute
        glbs.append(glb)
    r = subprocess.run(["node", str(VALIDATOR), *map(str, glbs)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_gmsh_physical_groups_are_tags(daemon, tmp_path):
    """Lines of the group "singular-crease" (the default prefix) become crease tags; a named
    group list overrides the default; an unknown group name is a usage error."""
    v, f = surface("octahedron")
    crease = [[0, 2], [2, 1]]                                         # edges of the octahedron
    blocks = [(2, f, 1), (1, crease, 2), (0, [[4]], 3)]
    names = {"skin": (2, 1), "singular-crease": (1, 2), "tip": (0, 3)}
    write_msh41(tmp_path / "oct41.msh", v, blocks, names)
    import meshio
    import numpy as np
    meshio.write(tmp_path / "oct22.msh", meshio.Mesh(np.array(v), [("triangle", np.array(f)), ("line", np.array(crease)), ("vertex", np.array([[4]]))],
                 cell_data={"gmsh:physical": [np.full(len(f), 1), np.array([2, 2]), np.array([3])],
                            "gmsh:geometrical": [np.full(len(f), 1), np.array([2, 2]), np.array([3])]},
                 field_data={k: np.array([t, d]) for k, (d, t) in names.items()}), file_format="gmsh22")
    for name in ("oct41.msh", "oct22.msh"):
        saved = tmp_path / f"{name}.complex.json"
        r = run("refine", tmp_path / name, "--level", 1, "-o", tmp_path / "o.vtu", "--url", daemon.url,
                "--save-complex", saved)
        assert r.returncode == 0, r.stderr
        c = json.loads(saved.read_text())
        assert sorted(c["tags"]["singular"]) == [[0, 2], [1, 2]], c["tags"]
        assert sum(k["singular"] for k in c["classes"]["edges"]) == 2
        r = run("refine", tmp_path / name, "--level", 1, "-o", tmp_path / "o.vtu", "--url", daemon.url,
                "--save-complex", saved, "--singular-groups", "singular-crease,tip")
        assert r.returncode == 0, r.stderr
        assert sorted(json.loads(saved.read_text())["tags"]["singular"]) == [[0, 2], [1, 2], [4]]
    r = run("refine", tmp_path / "oct41.msh", "--level", 1, "-o", tmp_path / "o.vtu", "--url", daemon.url,
            "--singular-groups", "nope")
    assert r.returncode == 2 and "no physical group named nope" in r.stderr
    # tags change the result: the crease stays a B-spline, so level 1 differs from untagged
    a = run("refine", tmp_path / "oct41.msh", "--level", 1, "-o", tmp_path / "a.json", "--url", daemon.url)
    b = run("refine", tmp_path / "oct41.msh", "--level", 1, "-o", tmp_path / "b.json", "--url", daemon.url,
            "--singular-groups", "")
    assert a.returncode == b.returncode == 0
    assert json.loads((tmp_path / "a.json").read_text())["vertices"] != json.loads((tmp_path / "b.json").read_text())["vertices"]


def test_job_file(daemon, tmp_path):
    """Several meshes in one job file: defaults, {name} outputs and save_complex, inline and file tags/rules,
    fill, and a failing job that makes the exit code 1 without stopping the others."""
    import meshio
    import numpy as np
    v, f = surface("icosphere", 1)
    (tmp_path / "in").mkdir()
    meshio.write(tmp_path / "in" / "ball.stl", meshio.Mesh(np.array(v), [("triangle", np.array(f))]))
    meshio.write(tmp_path / "in" / "shell.obj", meshio.Mesh(np.array(v), [("triangle", np.array(f))]))
    g = [t for i, t in enumerate(f) if i != 3]
    meshio.write(tmp_path / "in" / "open.off", meshio.Mesh(np.array(v), [("triangle", np.array(g))]))
    (tmp_path / "rules.json").write_text(json.dumps({"surface_weights": "loop"}))
    jobs = {"defaults": {"level": 1, "outputs": ["out/{name}.vtu", "out/{name}-L{level}.glb"], "rules": "rules.json"},
            "jobs": [{"input": "in/ball.stl", "fill": {"min_ratio": 1.5}, "save_complex": "ball.json"},
                     {"input": "in/open.off", "fill": True},
                     {"input": "in/shell.obj", "level": 2, "tags": {"singular": [f[0][:2]]},
                      "save_complex": "{name}-L{level}.json", "options": {"parts": "surfaces"}}]}
    (tmp_path / "jobs.json").write_text(json.dumps(jobs))
    r = run("batch", tmp_path / "jobs.json", "--url", daemon.url, "--progress", "lines", cwd="/")
    assert r.returncode == 1, r.stderr                                   # the open surface: 422
    assert "job 2 (in/open.off): refused (422 invalid-surface)" in r.stderr
    assert "/fill/0/surface/" in r.stderr
    assert "3 job(s): 2 done, 1 failed" in r.stderr
    out = tmp_path / "out"
    assert sorted(p.name for p in out.iterdir()) == ["ball-L1.glb", "ball.vtu", "shell-L2.glb", "shell.vtu"]
    ball = json.loads((tmp_path / "ball.json").read_text())
    assert ball["summary"]["fill"][0]["tets"] > 0 and ball["rules"]["surface_weights"] == "loop"
    shell = json.loads((tmp_path / "shell-L2.json").read_text())   # {name} and {level} expanded
    assert shell["tags"]["singular"] == [sorted(f[0][:2])]
    r = run("batch", tmp_path / "jobs.json", "--url", daemon.url, "--fail-fast", "--progress", "none")
    assert r.returncode == 1 and "3 job(s): 1 done, 1 failed, 1 not run" in r.stderr
    # job-file mistakes are usage errors, named by their place
    (tmp_path / "bad.json").write_text(json.dumps({"jobs": [{"input": "x.stl", "outputs": ["y.vtu"], "levle": 2}]}))
    r = run("batch", tmp_path / "bad.json", "--url", daemon.url)
    assert r.returncode == 2 and "/jobs/0: unknown member 'levle'" in r.stderr


def test_exit_codes(daemon, tmp_path):
    v, f = surface("icosphere", 1)
    (tmp_path / "s.json").write_text(json.dumps({"vertices": v, "simplices": f}))
    ok = ["--url", daemon.url, "--progress", "none"]
    assert run("refine", tmp_path / "s.json", "--level", 1, "-o", tmp_path / "s.glb", *ok).returncode == 0
    # 2: usage and local files
    assert run("refine", tmp_path / "s.json", "--level", 1, *ok).returncode == 2            # no -o
    r = run("refine", tmp_path / "s.json", "--level", 1, "-o", tmp_path / "s.png", *ok)
    assert r.returncode == 2 and "cannot tell the format" in r.stderr
    r = run("refine", tmp_path / "missing.stl", "--level", 1, "-o", tmp_path / "m.vtu", *ok)
    assert r.returncode == 2 and "no such file" in r.stderr
    r = run("refine", tmp_path / "s.json", "--level", -1, "-o", tmp_path / "m.vtu", *ok)
    assert r.returncode == 2 and "a level is 0 or more" in r.stderr                     # not sent
    (tmp_path / "hex.vtu").write_bytes(b"")
    import meshio
    import numpy as np
    meshio.write(tmp_path / "hex.vtu", meshio.Mesh(np.array(CUBE, float), [("hexahedron", np.array([[0, 1, 3, 2, 4, 5, 7, 6]]))]))
    r = run("refine", tmp_path / "hex.vtu", "--level", 1, "-o", tmp_path / "h.vtu", *ok)
    assert r.returncode == 2 and "not simplices" in r.stderr
    # 1: the daemon refused the input (with the pointer)
    (tmp_path / "bad.json").write_text(json.dumps({"vertices": v, "simplices": [[0, 1, 99]]}))
    r = run("refine", tmp_path / "bad.json", "--level", 1, "-o", tmp_path / "b.vtu", *ok)
    assert r.returncode == 1 and "refused (422" in r.stderr and "/simplices/0/2" in r.stderr
    assert not (tmp_path / "b.vtu").exists() and not (tmp_path / "b.vtu.part").exists()
    r = run("refine", tmp_path / "s.json", "--level", 13, "-o", tmp_path / "s.glb", *ok)
    assert r.returncode == 1 and "level-out-of-range" in r.stderr
    # rules the daemon has: ying-zorin is accepted
    (tmp_path / "yz.json").write_text(json.dumps({"nonmanifold_surface": "ying-zorin"}))
    r = run("refine", tmp_path / "s.json", "--level", 1, "-o", tmp_path / "s.glb", "--rules", tmp_path / "yz.json", *ok)
    assert r.returncode == 0, r.stderr
    # 3: no daemon there
    r = run("refine", tmp_path / "s.json", "--level", 1, "-o", tmp_path / "s.glb", "--url", "http://127.0.0.1:1")
    assert r.returncode == 3, r.stderr


def test_spawn_progress_bar_and_convert(tmp_path):
    """--spawn starts a private daemon (found beside build/subdiv); --progress bar draws one
    updating line; convert writes the body `subdivd refine` takes offline, with the same bytes."""
    v, f = surface("torus", 12, 8)
    import meshio
    import numpy as np
    meshio.write(tmp_path / "t.off", meshio.Mesh(np.array(v), [("triangle", np.array(f))]))
    env = {k: x for k, x in ENV.items() if k != "SUBDIVD"}
    r = run("refine", tmp_path / "t.off", "--fill", "--level", 1, "-o", tmp_path / "a.vtu", "--spawn",
            "--progress", "bar", env=env)
    assert r.returncode == 0, r.stderr
    assert "\x1b[K" in r.stderr and "upload 100%" in r.stderr and "download 100%" in r.stderr
    r = run("convert", tmp_path / "t.off", "--fill", "-o", tmp_path / "t.json")
    assert r.returncode == 0, r.stderr
    r = subprocess.run([str(SUBDIVD), "refine", str(tmp_path / "t.json"), "--level", "1", "-o",
                        str(tmp_path / "b.vtu")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "a.vtu").read_bytes() == (tmp_path / "b.vtu").read_bytes()


def test_spawn_uses_the_named_subdivd_or_refuses(tmp_path):
    """--subdivd PATH (or $SUBDIVD) names the daemon --spawn starts: one that is not an executable
    file is a usage error, not silently replaced by the subdivd beside the launcher."""
    (tmp_path / "t.json").write_text(json.dumps({"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
                                                 "simplices": [[0, 1, 2, 3]]}))
    args = ("refine", tmp_path / "t.json", "--level", 1, "-o", tmp_path / "t.vtu", "--spawn", "-q")
    r = run(*args, "--subdivd", tmp_path / "no-such-subdivd")
    assert r.returncode == 2 and "--subdivd" in r.stderr and "no-such-subdivd" in r.stderr, r.stderr
    assert not (tmp_path / "t.vtu").exists()
    r = run(*args, env=dict(ENV, SUBDIVD=str(tmp_path)))            # a directory
    assert r.returncode == 2 and "SUBDIVD" in r.stderr, r.stderr
    r = run(*args, "--subdivd", SUBDIVD, env=dict(ENV, SUBDIVD=str(tmp_path / "x")))
    assert r.returncode == 0 and (tmp_path / "t.vtu").exists(), r.stderr


def test_fill_warning_is_shown(tmp_path):
    """A fill whose max_volume TetGen cannot meet (one tetrahedron's surface, kept as posted):
    the job succeeds and the daemon's warning reaches stderr."""
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                                    "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    env = {k: x for k, x in ENV.items() if k != "SUBDIVD"}
    r = run("refine", tmp_path / "t.obj", "--fill", "--max-volume", "0.01", "--level", 1,
            "-o", tmp_path / "t.vtu", "--spawn", "-q", env=env)
    assert r.returncode == 0, r.stderr
    assert "fill: max_volume is not met" in r.stderr


def test_mesh_file_meshio_cannot_read(daemon, tmp_path):
    """A file meshio refuses with its ReadError (for which meshio.read prints and calls
    sys.exit(1)) is an unreadable mesh file: exit 2 from refine, and in a batch a failed job
    after which the next one runs (clients/README.md)."""
    bad = tmp_path / "bad.vtk"
    bad.write_text("this is not a VTK file\n")
    r = run("refine", bad, "--level", 1, "-o", tmp_path / "b.vtu", "--url", daemon.url, "--progress", "none")
    assert r.returncode == 2 and "bad.vtk" in r.stderr, (r.returncode, r.stdout, r.stderr)
    assert not (tmp_path / "b.vtu").exists()
    v, f = surface("icosphere", 1)
    (tmp_path / "s.json").write_text(json.dumps({"vertices": v, "simplices": f}))
    (tmp_path / "jobs.json").write_text(json.dumps(
        {"defaults": {"level": 1, "outputs": ["out/{name}.vtu"]},
         "jobs": [{"input": "bad.vtk"}, {"input": "s.json"}]}))
    r = run("batch", tmp_path / "jobs.json", "--url", daemon.url, "--progress", "none")
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "job 1 (bad.vtk)" in r.stderr and "2 job(s): 1 done, 1 failed" in r.stderr
    assert (tmp_path / "out" / "s.vtu").exists() and not (tmp_path / "out" / "bad.vtu").exists()


def test_level_options_go_to_the_outputs_they_apply_to(daemon, tmp_path):
    """octahedra and names apply to VTU and VTK, compress to VTU only (docs/OUTPUTS.md): with
    several -o and --pvd (clients/README.md) each output gets the options of its format; an
    option that applies to none of the outputs is a usage error."""
    import vtk
    (tmp_path / "cube.json").write_text(json.dumps({"vertices": CUBE, "simplices": TETS}))
    ok = ["--url", daemon.url, "--progress", "none"]

    def cell_types(path):
        rd = vtk.vtkXMLUnstructuredGridReader()
        rd.SetFileName(str(path))
        rd.Update()
        g = rd.GetOutput()
        return {g.GetCellType(i) for i in range(g.GetNumberOfCells())}

    r = run("refine", tmp_path / "cube.json", "--level", 2, "-o", tmp_path / "a.glb", "--pvd", tmp_path / "D",
            "--compress", "zlib", *ok)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "a.glb").read_bytes()[:4] == b"glTF"
    for k in range(3):
        head = (tmp_path / "D" / f"level_{k}.vtu").read_bytes()[:400]
        assert b'compressor="vtkZLibDataCompressor"' in head, (k, head)
    r = run("refine", tmp_path / "cube.json", "--level", 2, "-o", tmp_path / "b.glb", "-o", tmp_path / "b.vtu",
            "-o", tmp_path / "b.vtk", "--octahedra", "polyhedra", "--names", "true", *ok)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "b.glb").read_bytes()[:4] == b"glTF"
    assert cell_types(tmp_path / "b.vtu") == {10, 42}        # tetrahedra and polyhedra
    assert b"rule_names" in (tmp_path / "b.vtu").read_bytes()
    assert b"rule_names" in (tmp_path / "b.vtk").read_bytes()
    for opt, value in (("--compress", "zlib"), ("--octahedra", "polyhedra"), ("--names", "true")):
        r = run("refine", tmp_path / "cube.json", "--level", 1, "-o", tmp_path / "c.glb", "-o", tmp_path / "c.json",
                opt, value, *ok)
        assert r.returncode == 2 and opt[2:] + " applies to vtu" in r.stderr, (opt, r.stderr)
        assert not (tmp_path / "c.glb").exists() and not (tmp_path / "c.json").exists()


def test_pvd_result_lines_name_each_files_level(daemon, tmp_path):
    """--pvd writes level_K.vtu for K = 0..L: each result line names the level its file holds."""
    (tmp_path / "cube.json").write_text(json.dumps({"vertices": CUBE, "simplices": TETS}))
    d = tmp_path / "D"
    r = run("refine", tmp_path / "cube.json", "--level", 2, "--pvd", d, "-o", tmp_path / "a.vtu",
            "--url", daemon.url, "--progress", "none")
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert f"cube.json: level 2 -> {tmp_path / 'a.vtu'} (" in r.stderr
    for k in range(3):
        mine = [ln for ln in lines if f"-> {d / f'level_{k}.vtu'} (" in ln]
        assert len(mine) == 1 and mine[0].startswith(f"cube.json: level {k} -> "), lines
    assert any(ln.startswith(f"cube.json: levels 0..2 -> {d / 'levels.pvd'} (") for ln in lines), lines


def test_fill_takes_quads(tmp_path):
    """--fill takes every 2-D cell as the surface: a cube of six quad faces (OBJ) is filled, and
    its tetrahedra fill the unit cube (their volumes sum to 1, computed here from the complex)."""
    (tmp_path / "cube.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
        "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")
    env = {k: x for k, x in ENV.items() if k != "SUBDIVD"}
    r = run("refine", tmp_path / "cube.obj", "--fill", "--level", 0, "-o", tmp_path / "c.vtu",
            "--save-complex", tmp_path / "c.json", "--spawn", "-q", env=env)
    assert r.returncode == 0, r.stderr
    cx = json.loads((tmp_path / "c.json").read_text())
    tets = [s for s in cx["simplices"] if len(s) == 4]
    assert tets and all(len(s) == 4 for s in cx["simplices"])
    v = cx["vertices"]

    def vol(t):
        a, b, c, d = (v[i] for i in t)
        u, w, x = ([b[k] - a[k] for k in range(3)], [c[k] - a[k] for k in range(3)],
                   [d[k] - a[k] for k in range(3)])
        return abs(u[0] * (w[1] * x[2] - w[2] * x[1]) - u[1] * (w[0] * x[2] - w[2] * x[0])
                   + u[2] * (w[0] * x[1] - w[1] * x[0])) / 6
    assert abs(sum(vol(t) for t in tets) - 1.0) < 1e-12


def test_job_keys_override_defaults_in_either_spelling(daemon, tmp_path):
    """clients/README.md: every key of a job may also be in `defaults`, and `outputs` may be
    spelled `output`: a job's own `output` replaces the defaults' `outputs` (it was dropped for
    them). A `save_complex` in a directory that does not exist yet is written there, as outputs
    and `pvd` are (the job failed after its upload)."""
    mesh = REPO / "examples" / "mixed.json"
    jobs = {"defaults": {"level": 1, "outputs": ["all/{name}.vtu"]},
            "jobs": [{"input": str(mesh), "output": "one/{name}.glb",
                      "save_complex": "complexes/{name}-L{level}.json"},
                     {"input": str(mesh), "name": "second"}]}
    (tmp_path / "jobs.json").write_text(json.dumps(jobs))
    r = run("batch", tmp_path / "jobs.json", "--url", daemon.url, "--progress", "none")
    assert r.returncode == 0, r.stderr
    assert "2 job(s): 2 done, 0 failed" in r.stderr
    assert sorted(p.name for p in (tmp_path / "one").iterdir()) == ["mixed.glb"]
    assert sorted(p.name for p in (tmp_path / "all").iterdir()) == ["mixed.vtu"]   # job 2 alone
    assert (tmp_path / "one" / "mixed.glb").read_bytes()[:4] == b"glTF"
    saved = json.loads((tmp_path / "complexes" / "mixed-L1.json").read_text())
    assert len(saved["vertices"]) == 8 and saved["rules"] is not None   # GET /complex


def test_quiet_prints_errors_alone(daemon, tmp_path):
    """-q: no result lines and, unless --progress asks for them, no progress lines either (as
    `refine --mpi N -q`, docs/BATCH.md): a successful run is silent on stderr (stderr is not a
    terminal here, where progress defaulted to milestone lines even with -q); errors still show."""
    mesh = REPO / "examples" / "mixed.json"
    r = run("refine", mesh, "--level", 1, "-o", tmp_path / "m.glb", "--url", daemon.url, "-q")
    assert r.returncode == 0 and r.stderr == "" and r.stdout == "", r.stderr
    assert (tmp_path / "m.glb").exists()
    r = run("refine", mesh, "--level", 1, "-o", tmp_path / "m.glb", "--url", daemon.url, "-q",
            "--progress", "lines")           # asked for: progress, still no result line
    assert r.returncode == 0 and "received" in r.stderr and "level 1 ->" not in r.stderr, r.stderr
    r = run("refine", mesh, "--level", 13, "-o", tmp_path / "m.glb", "--url", daemon.url, "-q")
    assert r.returncode == 1 and "level-out-of-range" in r.stderr and "sent" not in r.stderr
    (tmp_path / "jobs.json").write_text(json.dumps({"jobs": [{"input": str(mesh), "level": 1,
                                                             "output": str(tmp_path / "b.vtu")}]}))
    r = run("batch", tmp_path / "jobs.json", "--url", daemon.url, "-q")
    assert r.returncode == 0 and r.stderr == "", r.stderr


def test_deform_moves_file_mistakes(daemon, tmp_path):
    """`subdiv deform --moves M.json` (a PATCH /control-points body or a list of them): a file
    that is not JSON or not such bodies is a usage error (2) naming --moves, a body the daemon
    refuses is exit 1 with its pointer; never a Python traceback."""
    ffd = REPO / "examples" / "ffd"
    args = ("deform", ffd / "block.json", "--embed", ffd / "torus.obj", "-o", tmp_path / "t.obj",
            "--url", daemon.url, "-q")
    for name, text, code, words in (("broken", "{", 2, ["--moves", "broken.json", "not JSON"]),
                                    ("ints", "[1, 2]", 2, ["--moves", "ints.json"]),
                                    ("member", '{"bogus": 1}', 1, ["unknown-field", "/bogus"]),
                                    ("noposition", '{"moves": [{"index": 0}]}', 1,
                                     ["/moves/0/position"])):
        (tmp_path / f"{name}.json").write_text(text)
        r = run(*args, "--moves", tmp_path / f"{name}.json")
        assert r.returncode == code and "Traceback" not in r.stderr, (name, r.stderr)
        assert all(w in r.stderr for w in words), (name, r.stderr)
        assert not (tmp_path / "t.obj").exists()
    r = run(*args, "--moves", ffd / "moves.json")
    assert r.returncode == 0 and (tmp_path / "t.obj").read_text().startswith(("v ", "#")), r.stderr


def test_spawned_daemon_that_does_not_start_says_why(tmp_path):
    """--spawn with a flag the daemon refuses (or a store it cannot open): exit 3 and the
    daemon's own message, not an empty "subdivd did not start:" (its stderr was read before it
    had exited)."""
    mesh = REPO / "examples" / "mixed.json"
    args = ("refine", mesh, "--level", 1, "-o", tmp_path / "m.glb", "--spawn", "--subdivd", SUBDIVD)
    r = run(*args, "--daemon-flag=--no-such-flag")
    assert r.returncode == 3, r.stderr
    assert 'unknown option "--no-such-flag"' in r.stderr and "usage:" not in r.stderr, r.stderr
    r = run(*args, f"--daemon-flag=--store=sqlite:{tmp_path / 'missing' / 's.db'}")
    assert r.returncode == 3 and "did not start" in r.stderr and "s.db" in r.stderr, r.stderr
    assert not (tmp_path / "m.glb").exists()
