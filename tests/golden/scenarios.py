"""The requests whose answers must not change byte for byte unless a change means them to.

Each scenario builds one session (a complex, then rules and tags) and lists the requests whose
answers are recorded: every level format with its options, the complex and its classes, stats
(timings removed), matrices, local analysis, an edit and a local refinement, and the offline mode.
`capture.py` runs them against a daemon and writes `manifest.json` (sha256 and size of every
answer); `tests/python/test_golden.py` runs them again and compares. The manifest was made by the
build before the layout refactor (issue 13); a change that alters output bytes on purpose
regenerates it (`python3 tests/golden/capture.py --write`) and says why in its commit.
"""
import math
import pathlib
import subprocess
import sys

REPO = pathlib.Path(__file__).resolve().parents[2]


def text_mesh(path):
    verts, simp = [], []
    for line in pathlib.Path(path).read_text().splitlines():
        t = line.split("#", 1)[0].split()
        if not t:
            continue
        if t[0] == "v":
            verts.append([float(x) for x in t[1:4]])
        elif t[0] == "s":
            simp.append([int(x) for x in t[1:]])
    return {"vertices": verts, "simplices": simp}


def generated(*args):
    out = subprocess.run([sys.executable, str(REPO / "bench" / "make_mesh.py"), *map(str, args)],
                         check=True, capture_output=True, text=True).stdout
    tmp = REPO / "build" / ("golden_" + "_".join(map(str, args)) + ".txt")
    tmp.parent.mkdir(exist_ok=True)
    tmp.write_text(out)
    return text_mesh(tmp)


def fins():
    """Three fins on a spine (non-manifold edges with 3 triangles), alternating diagonals."""
    V = [[0, 0, z] for z in range(4)]
    T = []
    for f, ang in enumerate((0.0, 2.2, 4.1)):
        d = (math.cos(ang), math.sin(ang))
        base = len(V)
        for c in (1, 2):
            for z in range(4):
                r = c * (1 + 0.15 * z)
                V.append([d[0] * r, d[1] * r, z + 0.2 * c * (f - 1)])
        col = lambda c, z: z if c == 0 else base + 4 * (c - 1) + z  # noqa: E731
        for c in (0, 1):
            for z in range(3):
                a, b, cc, dd = col(c, z), col(c, z + 1), col(c + 1, z), col(c + 1, z + 1)
                T += [[a, b, dd], [a, dd, cc]] if (z + c + f) % 2 else [[a, b, cc], [b, dd, cc]]
    return {"vertices": V, "simplices": T}


def fins_end():
    V = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2],
         [-.5, .8, 0], [-.5, .8, 1], [-.5, .8, 2], [-.5, -.8, 0], [-.5, -.8, 1], [-.5, -.8, 2]]
    T = []
    for a in (3, 6, 9):
        T += [[0, 1, a + 1], [0, a + 1, a], [1, 2, a + 2], [1, a + 2, a + 1]]
    return {"vertices": V, "simplices": T}


OCTA_V = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
OCTA_T = [[4, 5, 0, 2], [4, 5, 2, 1], [4, 5, 1, 3], [4, 5, 3, 0]]


def fig17():
    """An octahedron of 4 tets with two fins, a curve and an isolated point (000 Fig. 17)."""
    V = OCTA_V + [[1.5, 1.5, 0], [-1.5, -1.5, 0], [0, 0, 2], [0.5, 0.2, 3], [3, 3, 3]]
    S = OCTA_T + [[0, 2, 6], [1, 3, 7], [4, 8], [8, 9], [10]]
    return {"vertices": V, "simplices": S,
            "attributes": {"t": [float(i) for i in range(len(V))],
                           "uv": [[i * 0.1, 1 - i * 0.1] for i in range(len(V))]}}


def with_attr(body, name="h"):
    body = dict(body)
    body["attributes"] = {name: [v[2] + 0.5 * v[0] for v in body["vertices"]]}
    return body


LEVEL_FORMATS = ["glb", "gltf", "vtu", "vtk", "json"]


def level_requests(levels, extra=()):
    rq = []
    for L in levels:
        for f in LEVEL_FORMATS:
            rq.append(("GET", f"/levels/{L}", {"format": f}))
        rq.append(("STATS", f"/levels/{L}/stats", {}))
    rq.extend(extra)
    return rq


def scenarios():
    cube = text_mesh(REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt")
    block = with_attr(generated("cubes", 2))
    torus = with_attr(generated("torus", 8, 6))
    mixed = __import__("json").loads((REPO / "examples" / "mixed.json").read_text())
    cube_edges = [torus["simplices"][0][:2], torus["simplices"][0][1:3]]
    return [
        {"name": "mixed", "complex": mixed,
         "requests": [("GET", "/complex", {})] + level_requests(range(4), [
             ("GET", "/levels/2", {"format": "glb", "attributes": "height",
                                   "colormap": "height:0:3"}),
             ("GET", "/levels/2", {"format": "vtu", "slice": "0,0,1,0.3", "attributes": "height"}),
             ("GET", "/levels/2", {"format": "json", "parts": "solids,curves"}),
             ("GET", "/levels/3", {"format": "gltf", "parts": "surfaces,points"}),
             ("GET", "/levels/2", {"format": "vtu", "octahedra": "tets"}),
             ("GET", "/matrices/2", {"from": "0", "format": "mtx"}),
             ("GET", "/matrices/2", {"from": "1", "format": "json"}),
             ("GET", "/analysis", {"vertex": "1"}),
             ("GET", "/analysis", {"edge": "1,2"}),
             ("PATCH", "/control-points", {"moves": [{"index": 1, "position": [1.2, 0.1, -0.1]}],
                                           "attributes": {"height": [{"index": 1, "value": 4}]}}),
             ("GET", "/levels/3", {"format": "json"}),
             ("GET", "/levels/2", {"format": "glb", "attributes": "height"}),
             ("REFINE", "/refine", {"select": {"simplices": [[0, 1, 2, 3]]}, "depth": 1}),
             ("GET", "/complex", {}),
             ("GET", "/levels/2", {"format": "json"}),
         ])},
        {"name": "tetgen-cube-averaged", "complex": cube,
         "rules": {"solid_scheme": "averaged"},
         "requests": level_requests(range(3), [
             ("GET", "/levels/2", {"format": "vtu", "slice": "1,0.2,0.1,0.4"}),
             ("GET", "/analysis", {"vertex": "0"}),
             ("GET", "/matrices/1", {"from": "0", "format": "mtx"}),
         ])},
        {"name": "block-tags", "complex": block,
         "tags": {"singular": [[block["simplices"][0][0]], block["simplices"][0][:2],
                               block["simplices"][0][1:3], block["simplices"][20][:3]]},
         "requests": [("GET", "/complex", {})] + level_requests(range(4), [
             ("GET", "/levels/3", {"format": "glb", "attributes": "h", "colormap": "h:0:2",
                                   "slice": "0,0,1,1"}),
             ("PATCH", "/control-points", {"moves": [{"index": 13, "position": [1.1, 1.0, 0.9]},
                                                     {"index": 0, "position": [-0.1, 0, 0]}]}),
             ("GET", "/levels/3", {"format": "vtu"}),
             ("REFINE", "/refine", {"select": {"sphere": {"center": [0, 0, 0], "radius": 1.0}},
                                    "depth": 1, "positions": "midpoint"}),
             ("GET", "/levels/1", {"format": "json"}),
         ])},
        {"name": "torus-loop", "complex": torus, "rules": {"surface_weights": "loop"},
         "tags": {"singular": cube_edges},
         "requests": level_requests(range(4), [
             ("GET", "/analysis", {"vertex": "7"}),
             ("GET", "/matrices/3", {"from": "0", "format": "json"}),
             ("REFINE", "/refine", {"select": {"box": {"min": [0.5, -1, -1], "max": [2, 1, 1]}}}),
             ("GET", "/levels/2", {"format": "glb"}),
         ])},
        {"name": "fins-ying-zorin", "complex": fins(),
         "rules": {"nonmanifold_surface": "ying-zorin"},
         "requests": [("GET", "/complex", {})] + level_requests(range(4), [
             ("GET", "/analysis", {"vertex": "1"}),
         ])},
        {"name": "fins-end-petals", "complex": fins_end(),
         "rules": {"nonmanifold_surface": "ying-zorin"},
         "tags": {"petals": [{"vertex": 0, "triangle": [0, 4, 3], "kind": "concave"},
                             {"vertex": 0, "triangle": [0, 7, 6], "kind": "smooth"}]},
         "requests": [("GET", "/complex", {})] + level_requests(range(3))},
        {"name": "fins-g1", "complex": fins(), "rules": {"nonmanifold_default": "G1"},
         "requests": level_requests(range(3))},
        {"name": "fig17-overrides", "complex": fig17(),
         "rules": {"overrides": [{"simplex": [0], "rule": "G1"},
                                 {"simplex": [1, 3], "rule": "N1", "dimension": 3}]},
         "requests": [("GET", "/complex", {})] + level_requests(range(3), [
             ("GET", "/levels/2", {"format": "glb", "attributes": "t,uv"}),
             ("GET", "/levels/2", {"format": "vtk", "attributes": "uv"}),
             ("GET", "/analysis", {"edge": "0,2"}),
         ])},
    ]


OFFLINE = [
    # (name, input, args)
    ("mixed-l3-vtu", "examples/mixed.json", ["--level", "3"], "vtu"),
    ("mixed-l2-glb", "examples/mixed.json", ["--level", "2", "--attributes", "height"], "glb"),
    ("mixed-l2-json", "examples/mixed.json", ["--level", "2"], "json"),
]

# sdlevel, the core's text tool: (name, input, args)
SDLEVEL = [
    ("mixed-l2", "examples/mixed.txt", ["-l", "2", "--classes", "--matrix"]),
    ("cube-averaged-l2", "tests/cases/tetgen_cube/mesh.txt", ["-l", "2", "-s", "averaged", "--classes"]),
    ("ball-l1", "tests/cases/tetgen_ball/mesh.txt", ["-l", "1", "--matrix"]),
]
