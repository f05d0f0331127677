"""Semi-sharp creases over HTTP (docs/API.md "Creases"): PUT /tags {"sharpness"} and PUT /rules
{"crease_method"}. Levels of a surface with sharpness equal OpenSubdiv's (the peer, matched by
position, one to one); s >= 10 is the same as a singular tag; sharpness is reported by GET
/complex, survives export and import, rules changes and a refinement (halves of a refined edge
keep its value); bad entries are 4xx naming the field."""
import subprocess

import numpy as np
import pytest
from scipy.spatial import cKDTree

from daemon import Daemon, Session
from test_persist import adopt
from test_sharp_vs_osd import edges_of, parse, torus, write
import random

U, V = 8, 6


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


@pytest.fixture(scope="module")
def mesh():
    xyz, tris = torus(U, V, random.Random(5))
    return [list(p) for p in xyz], [list(t) for t in tris]


SHARP = [([0, 1], 0.3), ([1, 2], 1.5), ([2, 3], 2.7), ([3, 4], 3.7), ([4, 5], 1.0),
         ([6, 7], 0.5), ([7, 8], 2.25), ([7, 13], 1.25), ([20], 1.6)]


def body(sharp):
    return {"sharpness": [{"simplex": s, "value": v} for s, v in sharp]}


def session(daemon, mesh, weights="loop"):
    s = Session(daemon)
    assert s.put_complex({"vertices": mesh[0], "simplices": mesh[1]}).status_code == 200
    assert s.req("PUT", "/rules", json={"surface_weights": weights}).status_code == 200
    return s


def osd_level(osd, tmp_path, mesh, sharp, level, chaikin=False):
    path = tmp_path / "m.txt"
    write(path, mesh[0], mesh[1], [tuple(s) + (v,) for s, v in sharp])
    cmd = [str(osd), "-l", str(level)] + (["--chaikin"] if chaikin else []) + [str(path)]
    return parse(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)[0]


def assert_same_points(ours, theirs, tol=1e-12):
    ours = np.asarray(ours)
    assert ours.shape == theirs.shape
    d, j = cKDTree(theirs).query(ours)
    assert d.max() < tol, d.max()
    assert len(set(j.tolist())) == len(ours)


@pytest.mark.parametrize("chaikin", [False, True])
def test_levels_equal_opensubdiv(daemon, mesh, osd_loop, tmp_path, chaikin):
    s = session(daemon, mesh)
    if chaikin:
        assert s.req("PUT", "/rules", json={"surface_weights": "loop",
                                            "crease_method": "chaikin"}).status_code == 200
    r = s.req("PUT", "/tags", json=body(SHARP))
    assert r.status_code == 200, r.text
    for level in (1, 2, 3):
        ours = s.level(level, format="json").json()["vertices"]
        assert_same_points(ours, osd_level(osd_loop, tmp_path, mesh, SHARP, level, chaikin))
    c = s.req("GET", "/complex").json()
    assert c["tags"]["sharpness"] == body(SHARP)["sharpness"]
    assert c["rules"]["crease_method"] == ("chaikin" if chaikin else "uniform")


def test_methods_differ_and_sharpness_matters(daemon, mesh):
    a = session(daemon, mesh)
    assert a.req("PUT", "/tags", json=body(SHARP)).status_code == 200
    b = session(daemon, mesh)
    assert b.req("PUT", "/tags", json=body(SHARP)).status_code == 200
    assert b.req("PUT", "/rules", json={"surface_weights": "loop",
                                        "crease_method": "chaikin"}).status_code == 200
    c = session(daemon, mesh)
    pa, pb, pc = (np.array(x.level(3, format="json").json()["vertices"]) for x in (a, b, c))
    assert np.abs(pa - pb).max() > 1e-4   # 7-8 and 7-13 meet at 7: Chaikin averages them
    assert np.abs(pa - pc).max() > 1e-2   # and the sharpness changes the surface


def test_infinite_sharpness_is_a_singular_tag(daemon, mesh):
    ring = [[2 * V + j, 2 * V + (j + 1) % V] for j in range(V)]  # a closed ring: no ends
    a = session(daemon, mesh)
    # 9.9999999 is 10 as the 32-bit float the values are used as (docs/API.md): infinitely sharp
    vals = [10 if j % 2 else 9.9999999 for j in range(V)]
    r = a.req("PUT", "/tags", json=body(list(zip(ring, vals)) + [([30], 12.5)]))
    assert r.status_code == 200, r.text
    b = session(daemon, mesh)
    assert b.req("PUT", "/tags", json={"singular": ring + [[30]]}).status_code == 200
    for level in (1, 2):
        assert a.level(level, format="json").json()["vertices"] == \
            b.level(level, format="json").json()["vertices"]
    assert a.req("GET", "/complex").json()["tags"]["sharpness"][-1] == {"simplex": [30],
                                                                        "value": 12.5}


def test_export_import_and_rules_keep_sharpness(daemon, mesh):
    s = session(daemon, mesh)
    assert s.req("PUT", "/tags", json={"singular": [[40]], **body(SHARP)}).status_code == 200
    want = s.level(2, format="json").json()["vertices"]
    doc = s.req("GET", "/export").json()
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 201, r.text
    t = adopt(daemon, s.http, r.json())
    assert t.level(2, format="json").json()["vertices"] == want
    # a rules change keeps the tags (and so the sharpness)
    assert s.req("PUT", "/rules", json={"surface_weights": "warren"}).status_code == 200
    assert s.req("GET", "/complex").json()["tags"]["sharpness"] == body(SHARP)["sharpness"]
    assert s.req("PUT", "/rules", json={"surface_weights": "loop"}).status_code == 200
    assert s.level(2, format="json").json()["vertices"] == want


def test_refine_splits_sharp_edges_into_halves(daemon, mesh):
    s = session(daemon, mesh)
    assert s.req("PUT", "/tags", json=body(SHARP)).status_code == 200
    r = s.req("POST", "/refine", json={"select": {"simplices": mesh[1][:2]}})
    assert r.status_code == 200, r.text
    c = s.req("GET", "/complex").json()
    got = {tuple(sorted(x["simplex"])): x["value"] for x in c["tags"]["sharpness"]}
    nv = len(mesh[0])
    # triangles 0 and 1 hold edge 0-... : every sharp edge either stays or is two halves with
    # a new vertex (index >= nv), each with the same value
    for e, v in SHARP:
        key = tuple(sorted(e))
        if key in got:
            assert got[key] == v
        else:
            halves = [k for k in got if len(k) == 2 and (e[0] in k or e[1] in k) and max(k) >= nv
                      and got[k] == v]
            mids = {max(k) for k in halves}
            assert len(halves) == 2 and len(mids) == 1, (e, halves)
    assert any(max(k) >= nv for k in got if len(k) == 2), "no sharp edge was split"


@pytest.mark.parametrize("sharp,status,pointer", [
    ([{"simplex": [0, 9], "value": 1}], 422, "/sharpness/0"),            # not an edge
    ([{"simplex": [0, 1], "value": -1}], 422, "/sharpness/0/value"),
    ([{"simplex": [0, 1], "value": "1"}], 400, "/sharpness/0/value"),
    ([{"simplex": [0, 1]}], 400, "/sharpness/0/value"),
    ([{"simplex": [0, 1, 7], "value": 1}], 422, "/sharpness/0/simplex"),  # a triangle
    ([{"simplex": [0, 0], "value": 1}], 422, "/sharpness/0/simplex/1"),
    ([{"simplex": [0, 999], "value": 1}], 422, "/sharpness/0/simplex/1"),
    ([{"simplex": [0, 1], "value": 1}, {"simplex": [1, 0], "value": 2}], 422,
     "/sharpness/1/simplex"),
    ([{"simplex": [3], "value": 1}, {"simplex": [3], "value": 12}], 422, "/sharpness/1/simplex"),
    ([{"simplex": [0, 1], "value": 1, "x": 2}], 400, "/sharpness/0/x"),
    ({"simplex": [0, 1]}, 400, "/sharpness"),
])
def test_bad_sharpness(daemon, mesh, sharp, status, pointer):
    s = session(daemon, mesh)
    r = s.req("PUT", "/tags", json={"sharpness": sharp})
    assert r.status_code == status, r.text
    assert r.headers["Content-Type"].startswith("application/problem+json")
    assert r.json()["errors"][0]["pointer"].startswith(pointer), r.json()
    assert "sharpness" not in s.req("GET", "/complex").json()["tags"]  # nothing kept


def test_solid_interior_edge_refused_boundary_edge_accepted(daemon):
    # two tetrahedra sharing face 0-1-2: edge 0-1 is on the boundary, and so is every edge of
    # this small solid; the edge 3-4 is not an edge at all
    s = Session(daemon)
    cube_v = [[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)] + [[0.5, 0.5, 0.5]]
    tets = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]]
    # split around the centre 8 so that edges 0-8 ... are inside
    star = []
    for t in tets:
        for k in range(4):
            f = t[:k] + t[k + 1:]
            if sum(1 for u in tets for q in range(4) if sorted(u[:q] + u[q + 1:]) == sorted(f)) == 1:
                star.append(f + [8])
    assert s.put_complex({"vertices": cube_v, "simplices": star}).status_code == 200
    r = s.req("PUT", "/tags", json={"sharpness": [{"simplex": [0, 8], "value": 2}]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/sharpness/0/simplex", r.text
    assert s.req("PUT", "/tags", json={"sharpness": [{"simplex": [0, 1], "value": 2}, {
        "simplex": [8], "value": 1.5}]}).status_code == 200


def test_no_complex_and_limits(daemon):
    s = Session(daemon)
    r = s.req("PUT", "/tags", json={"sharpness": [{"simplex": [0, 1], "value": 1}]})
    assert r.status_code == 409 and r.json()["errors"][0]["pointer"] == "/sharpness"
    assert s.req("PUT", "/tags", json={"sharpness": []}).status_code == 200
    t = Session(daemon)
    assert t.put_complex({"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                          "simplices": [[0, 1, 2]]}).status_code == 200
    many = [{"simplex": [0, 1], "value": 1}] * 100
    r = t.req("PUT", "/tags", json={"sharpness": many})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/sharpness"


def test_edits_equal_a_fresh_build(daemon, mesh):
    """An edit recomputes rows through the same (sharp) matrices: levels after a move equal a
    new session posted with the moved point."""
    s = session(daemon, mesh)
    assert s.req("PUT", "/tags", json=body(SHARP)).status_code == 200
    s.level(3, format="json")  # built, so the edit goes through the cached matrices
    v = s.req("GET", "").json()["version"]
    moved = [1.1, 0.2, 0.3]
    r = s.req("PATCH", "/control-points", json={"moves": [{"index": 7, "position": moved}]},
              headers={"If-Match": f'"{v}"'})
    assert r.status_code == 200, r.text
    verts = [list(p) for p in mesh[0]]
    verts[7] = moved
    t = session(daemon, (verts, mesh[1]))
    assert t.req("PUT", "/tags", json=body(SHARP)).status_code == 200
    for level in (1, 2, 3):
        assert s.level(level, format="json").json()["vertices"] == \
            t.level(level, format="json").json()["vertices"]


def test_sharp_triangles_inside_a_solid(daemon):
    """A sharp triangle inside a solid is an embedded surface while its sharpness lasts: with
    s = 2, levels 1 and 2 equal the same triangles tagged singular, level 3 does not; s >= 10 is
    the singular tag at every level (docs/RULES.md "Semi-sharp creases")."""
    from test_sharp_vs_osd import cube_tets
    xyz, tets = cube_tets(3, random.Random(2))
    cx = {"vertices": [list(p) for p in xyz], "simplices": [list(t) for t in tets]}
    faces = {}
    for t in tets:
        for k in range(4):
            f = tuple(sorted(t[:k] + t[k + 1:]))
            faces[f] = faces.get(f, 0) + 1
    inner = [list(f) for f, c in faces.items() if c == 2 and all(
        v // 16 == 1 and 1 <= v % 4 <= 2 and 1 <= v // 4 % 4 <= 2 for v in f)]
    assert len(inner) == 2

    def make(tags):
        s = Session(daemon)
        assert s.put_complex(cx).status_code == 200
        r = s.req("PUT", "/tags", json=tags)
        assert r.status_code == 200, r.text
        return s
    sharp = make({"sharpness": [{"simplex": f, "value": 2} for f in inner]})
    inf = make({"sharpness": [{"simplex": f, "value": 10} for f in inner]})
    tagged = make({"singular": inner})
    for level in (1, 2, 3):
        t = tagged.level(level, format="json").json()["vertices"]
        assert inf.level(level, format="json").json()["vertices"] == t
        same = sharp.level(level, format="json").json()["vertices"] == t
        assert same == (level < 3), level
    # a face on the solid's boundary is not inside it
    bnd = next(list(f) for f, c in faces.items() if c == 1)
    s = Session(daemon)
    assert s.put_complex(cx).status_code == 200
    r = s.req("PUT", "/tags", json={"sharpness": [{"simplex": bnd, "value": 1}]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/sharpness/0/simplex"
