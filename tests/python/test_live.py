"""The live modeling loop (docs/API.md "Live edits"): deltas of a level after edits, the event
stream of a session, and moves at finer levels kept as detail offsets.

A delta applied to the level fetched before an edit must give the level fetched after it: the
JSON delta exactly (doubles, as format=json), the binary one as float32 (the GLB's POSITION and
NORMAL accessors, whose rows are the delta's indices). Detail offsets are checked against
p^l = S p^(l-1) + d computed here from the matrices and levels of fresh sessions."""
import json
import socket
import statistics
import struct
import sys
import threading
import time

import numpy as np
import pytest
import requests

from conftest import REPO
from daemon import SLOW, Daemon, Session, complex_from_text
from redisd import REDIS_SERVER, RedisServer

sys.path.insert(0, str(REPO / "clients" / "python"))
import subdiv  # noqa: E402

CUBE = REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt"
MIXED = REPO / "examples" / "mixed.txt"
LEVEL = 2


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


# ---- meshes -----------------------------------------------------------------------------------

def surface():
    """An octahedron's surface with one vertex pulled out (a closed Loop surface)."""
    V = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.3], [0, 0, -1]]
    T = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    return {"vertices": V, "simplices": T}


def curve():
    """A polyline with a branch (a junction of three) and an isolated point."""
    V = [[i, 0.3 * np.sin(i), 0.1 * i * i] for i in range(6)] + [[2, 1, 0], [2, 2, 0.5], [2, 3, 0]]
    S = [[i, i + 1] for i in range(5)] + [[2, 6], [6, 7], [7, 8]]
    V.append([5, 5, 5])
    S.append([9])
    return {"vertices": [[float(x) for x in v] for v in V], "simplices": S}


def with_attrs(body):
    n = len(body["vertices"])
    b = dict(body)
    b["attributes"] = {"t": [0.1 * i for i in range(n)], "v": [[i, -0.5 * i] for i in range(n)]}
    return b


MESHES = {"solid": lambda: complex_from_text(CUBE), "surface": surface, "curve": curve,
          "mixed": lambda: complex_from_text(MIXED)}


def new_session(daemon, body):
    s = Session(daemon)
    r = s.put_complex(body)
    assert r.status_code == 200, r.text
    return s


def version_of(s):
    return s.req("GET").json()["version"]


def patch(s, body, version=None):
    v = version_of(s) if version is None else version
    r = s.req("PATCH", "/control-points", json=body, headers={"If-Match": f'"{v}"'})
    assert r.status_code == 200, r.text
    return r.json()["version"]


# ---- GLB and SDD1 readers ---------------------------------------------------------------------

def glb_arrays(data):
    """POSITION, NORMAL (None without triangle primitives) and the `_<name>` attributes of a GLB,
    after checking that every indexed primitive shares one POSITION accessor."""
    magic, _, length = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67 and length == len(data)
    jlen, _ = struct.unpack_from("<II", data, 12)
    doc = json.loads(data[20:20 + jlen])
    bin_ = data[28 + jlen:]

    def acc(i):
        a = doc["accessors"][i]
        v = doc["bufferViews"][a["bufferView"]]
        n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
        assert a["componentType"] == 5126
        x = np.frombuffer(bin_, dtype="<f4", count=a["count"] * n,
                          offset=v.get("byteOffset", 0) + a.get("byteOffset", 0))
        return x.reshape(a["count"], n).copy()

    prims = [p for m in doc["meshes"] for p in m["primitives"] if "indices" in p]
    assert len({p["attributes"]["POSITION"] for p in prims}) == 1
    attrs = prims[0]["attributes"]
    normal = next((p["attributes"]["NORMAL"] for p in prims if "NORMAL" in p["attributes"]), None)
    out = {"POSITION": acc(attrs["POSITION"]), "NORMAL": None if normal is None else acc(normal)}
    for k, i in attrs.items():
        if k.startswith("_") and k != "_RULE":
            out[k] = acc(i)
    return out


def parse_sdd1(data, comps):
    """The binary delta (docs/API.md): header, indices, positions, normals, attributes."""
    assert data[:4] == b"SDD1"
    level, since, version, n, flags = struct.unpack_from("<5I", data, 4)
    off = 24
    idx = np.frombuffer(data, "<u4", n, off)
    off += 4 * n
    pos = np.frombuffer(data, "<f4", 3 * n, off).reshape(n, 3)
    off += 12 * n
    nrm = None
    if flags & 1:
        nrm = np.frombuffer(data, "<f4", 3 * n, off).reshape(n, 3)
        off += 12 * n
    attrs = {}
    for name, nc in comps:
        if flags & 2:
            attrs[name] = np.frombuffer(data, "<f4", nc * n, off).reshape(n, nc)
            off += 4 * nc * n
    assert off == len(data), (off, len(data))
    return {"level": level, "since": since, "version": version, "indices": idx, "positions": pos,
            "normals": nrm, "flags": flags, "attributes": attrs}


def snapshot(s, level):
    glb = s.level(level, attributes="t,v")
    assert glb.status_code == 200, glb.text
    js = s.level(level, format="json")
    assert js.status_code == 200
    return glb_arrays(glb.content), js.json()


def deltas(s, level, since, attrs="t,v"):
    p = {"since": since, "attributes": attrs} if attrs else {"since": since}
    b = s.req("GET", f"/levels/{level}/delta", params=p)
    j = s.req("GET", f"/levels/{level}/delta", params=dict(p, format="json"))
    assert b.status_code == 200 and j.status_code == 200, (b.text, j.text)
    assert b.headers["Content-Type"] == "application/octet-stream"
    assert b.headers["ETag"] == j.headers["ETag"]
    comps = [(c.split("=")[0], int(c.split("=")[1]))
             for c in b.headers.get("X-Attribute-Components", "").split(",") if c]
    return parse_sdd1(b.content, comps), j.json(), len(b.content)


def check_delta(s, level, before, after, since, version):
    """The deltas since `since` bring `before` (GLB arrays, JSON level) to `after`."""
    (g0, j0), (g1, j1) = before, after
    db, dj, _ = deltas(s, level, since)
    assert db["level"] == dj["level"] == level and db["since"] == dj["since"] == since
    assert db["version"] == dj["version"] == version == j1["version"]
    idx = db["indices"]
    assert list(idx) == dj["indices"] and list(idx) == sorted(set(idx))
    # binary: float32 into the GLB's accessors
    pos = g0["POSITION"].copy()
    pos[idx] = db["positions"]
    np.testing.assert_array_equal(pos, g1["POSITION"])
    if g1["NORMAL"] is not None and db["flags"] & 1:
        nrm = g0["NORMAL"].copy()
        nrm[idx] = db["normals"]
        np.testing.assert_array_equal(nrm, g1["NORMAL"])
        np.testing.assert_array_equal(np.asarray(dj["normals"], dtype=np.float32), db["normals"])
    elif g1["NORMAL"] is not None:       # no drawn triangle: the normals are all (0, 0, 1)
        np.testing.assert_array_equal(g0["NORMAL"], g1["NORMAL"])
    # JSON: exactly the doubles of format=json
    verts = [list(v) for v in j0["vertices"]]
    for i, p in zip(dj["indices"], dj["positions"]):
        verts[i] = p
    assert verts == j1["vertices"]
    for name in ("t", "v"):
        a = list(j0["attributes"][name])
        for i, x in zip(dj["indices"], dj["attributes"][name]):
            a[i] = x
        assert a == j1["attributes"][name], name
        got = db["attributes"][name]
        want = np.asarray(j1["attributes"][name], dtype=np.float64).reshape(len(verts), -1)[idx]
        np.testing.assert_array_equal(got, want.astype(np.float32))
        ga = g0["_" + name.upper()].copy()
        ga[idx] = got[:, :ga.shape[1]]
        np.testing.assert_array_equal(ga, g1["_" + name.upper()])
    # nothing else changed: a point outside the delta is the same before and after
    out = np.setdiff1d(np.arange(len(verts)), idx)
    np.testing.assert_array_equal(g0["POSITION"][out], g1["POSITION"][out])
    return db


def moved(v, k, d=0.03):
    return [v[0] + d * (1 + k % 3), v[1] - d * (k % 2), v[2] + 0.5 * d]


@pytest.mark.parametrize("edit", ["single", "multi", "fine", "attributes"])
@pytest.mark.parametrize("mesh", list(MESHES))
def test_delta_applied_equals_refetch(daemon, mesh, edit):
    body = with_attrs(MESHES[mesh]())
    s = new_session(daemon, body)
    for level in range(LEVEL + 1):
        assert s.level(level, format="json").status_code == 200
    V = body["vertices"]
    n = len(V)
    history = [snapshot(s, LEVEL)]
    versions = [history[0][1]["version"]]
    for step in range(2):                 # two edits: deltas since either version
        if edit == "single":
            k = (3 * step + 1) % n
            b = {"moves": [{"index": k, "position": moved(V[k], step)}]}
        elif edit == "multi":
            pts = sorted({(5 * step + j * 7) % n for j in range(4)})
            b = {"moves": [{"index": k, "position": moved(V[k], k)} for k in pts],
                 "attributes": {"t": [{"index": pts[0], "value": 9.5 + step}]}}
        elif edit == "fine":              # level-1 and level-2 points, and a control point
            l1 = history[-1][1]          # the level-2 JSON
            n2 = len(l1["vertices"])
            j1 = s.level(1, format="json").json()
            i1 = (11 * step + 3) % len(j1["vertices"])
            i2 = (37 * step + 5) % n2
            b = {"moves": [{"index": i2, "level": 2, "position": moved(l1["vertices"][i2], step)},
                           {"index": i1, "level": 1, "position": moved(j1["vertices"][i1], step)},
                           {"index": step % n, "position": moved(V[step % n], 1)}]}
        else:
            k = (2 * step + 1) % n
            b = {"attributes": {"t": [{"index": k, "value": -3.25 * (step + 1)}],
                                "v": [{"index": (k + 1) % n, "value": [7, 8 + step]}]}}
        versions.append(patch(s, b))
        history.append(snapshot(s, LEVEL))
        for back in range(len(versions) - 1):
            db = check_delta(s, LEVEL, history[back], history[-1], versions[back], versions[-1])
            if edit == "attributes":
                assert db["flags"] & 2
    # since the current version: empty
    db, dj, size = deltas(s, LEVEL, versions[-1])
    assert len(db["indices"]) == 0 and dj["indices"] == [] and size == 24
    s.delete()


def test_delta_bytes_per_changed_point(daemon):
    """The binary delta of a one-point edit: 24 bytes of header and 28 per point (index,
    position, normal) for a level with drawn triangles — reported for docs/BENCHMARKS.md."""
    s = new_session(daemon, complex_from_text(CUBE))
    g, j = snapshot_plain(s, 3)
    v = j["version"]
    V = complex_from_text(CUBE)["vertices"]
    v1 = patch(s, {"moves": [{"index": 5, "position": moved(V[5], 0)}]})
    db, _, size = deltas(s, 3, v, attrs=None)
    n = len(db["indices"])
    assert db["flags"] == 1 and size == 24 + 28 * n
    print(f"\nlevel 3 of the cube ({len(g['POSITION'])} vertices): a one-point edit's delta has "
          f"{n} points, {size} bytes; the GLB {s.level(3).headers['Content-Length']} bytes")
    assert n < len(g["POSITION"]) / 4
    assert v1 == v + 1
    s.delete()


# ---- 410 --------------------------------------------------------------------------------------

def gone(s, level, since):
    r = s.req("GET", f"/levels/{level}/delta", params={"since": since})
    assert r.status_code == 410, r.text
    assert r.headers["Content-Type"] == "application/problem+json"
    assert r.json()["type"].endswith("/delta-unavailable")
    return r.json()


def test_delta_410_paths(daemon):
    body = with_attrs(complex_from_text(MIXED))
    s = new_session(daemon, body)
    assert s.level(2, format="json").status_code == 200
    v = version_of(s)
    gone(s, 3, v)                                           # level not cached
    gone(s, 2, v + 1)                                       # ahead of the session
    v1 = patch(s, {"moves": [{"index": 1, "position": [1.1, 0, 0]}]})
    assert s.req("GET", "/levels/2/delta", params={"since": v}).status_code == 200
    # a level computed after V: its content at V is not known
    assert s.level(3, format="json").status_code == 200
    gone(s, 3, v)
    assert s.req("GET", "/levels/3/delta", params={"since": v1}).status_code == 200
    # changes that are not edits: complex, tags, rules, refine
    for path, method, b in (("/tags", "PUT", {"singular": [[3]]}), ("/rules", "PUT", {}),
                            ("/refine", "POST", {"select": {"simplices": [[0, 1, 2, 3]]}}),
                            ("/complex", "PUT", body)):
        w = version_of(s)
        assert s.level(2, format="json").status_code == 200
        r = s.req(method, path, json=b)
        assert r.status_code == 200, r.text
        assert s.level(2, format="json").status_code == 200
        gone(s, 2, w)
        assert s.req("GET", "/levels/2/delta", params={"since": w + 1}).status_code == 200
    # bad queries are 400 / 422, not 410
    assert s.req("GET", "/levels/2/delta").status_code == 400
    assert s.req("GET", "/levels/2/delta", params={"since": "x"}).status_code == 400
    assert s.req("GET", "/levels/2/delta", params={"since": 1, "format": "xml"}).status_code == 422
    assert s.req("GET", "/levels/2/delta", params={"since": 1, "attributes": "nope"}).status_code == 422
    for path in ("/levels/2/delta", "/levels/2"):   # a repeated name (docs/OUTPUTS.md)
        r = s.req("GET", path, params={"since": 1, "attributes": "t,v,t"} if "delta" in path
                  else {"attributes": "t,v,t"})
        assert r.status_code == 422 and r.json()["type"].endswith("/repeated-attribute"), r.text
        assert r.json()["errors"][0]["pointer"] == "attributes"
    for path in ("/levels/2/delta", "/levels/2"):   # a trailing comma is an empty name
        for q in ({"attributes": "t,"}, {"parts": "points,"}):
            r = s.req("GET", path, params={"since": 1, **q} if "delta" in path else q)
            assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == next(iter(q)), r.text
    assert s.req("GET", "/levels/2/delta", params={"since": 1, "what": 1}).status_code == 400
    s.delete()


def test_delta_410_after_an_edit_that_rebuilds_rules(daemon):
    """A move that a level's rules read (Ying-Zorin's corner angle) publishes a new model: deltas
    from before it are 410, later ones work."""
    V = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2],
         [-.5, .8, 0], [-.5, .8, 1], [-.5, .8, 2], [-.5, -.8, 0], [-.5, -.8, 1], [-.5, -.8, 2]]
    T = []
    for a in (3, 6, 9):
        T += [[0, 1, a + 1], [0, a + 1, a], [1, 2, a + 2], [1, a + 2, a + 1]]
    s = new_session(daemon, {"vertices": V, "simplices": T})
    assert s.req("PUT", "/rules", json={"nonmanifold_surface": "ying-zorin"}).status_code == 200
    assert s.req("PUT", "/tags", json={"petals": [{"vertex": 0, "triangle": [0, 4, 3],
                                                   "kind": "convex"}]}).status_code == 200
    before = snapshot_plain(s, 2)
    v = before[1]["version"]
    v1 = patch(s, {"moves": [{"index": 3, "position": [1.2, 0.7, -0.1]}]})
    gone(s, 2, v)
    assert s.level(2, format="json").status_code == 200
    v2 = patch(s, {"moves": [{"index": 5, "position": [1.1, 0.1, 2]}]})   # no rule reads 5
    r = s.req("GET", "/levels/2/delta", params={"since": v1, "format": "json"})
    assert r.status_code == 200 and r.json()["version"] == v2
    s.delete()


def test_edits_of_a_constrained_complex_are_new_models(daemon):
    """Tangent-plane constraints (PUT /tags "tangents", under ying-zorin) read positions, so every
    move of a position — far from the constrained vertex, or at a finer level — publishes a new
    model (docs/API.md "Live edits"): deltas from before it are 410 and PATCH ?delta= says so;
    an attribute edit stays an edit with a delta. The levels are those of a fresh session."""
    V = [[float(x), 0.0, 0.1 * x * x] for x in range(-2, 3)]
    T = []
    for d in ((0.0, 1.0, 0.25), (0.15, -1.0, 0.6), (0.0, 0.2, 1.0)):   # three sheets on a curve
        row = list(range(5))
        for r in (1, 2):
            nxt = []
            for i in range(5):
                nxt.append(len(V))
                V.append([V[i][0] + r * d[0], V[i][1] + r * d[1], V[i][2] + r * d[2] + 0.07 * r])
            T += [t for i in range(4) for t in ([row[i], row[i + 1], nxt[i + 1]],
                                                 [row[i], nxt[i + 1], nxt[i]])]
            row = nxt
    body = with_attrs({"vertices": V, "simplices": T})
    rules = {"nonmanifold_surface": "ying-zorin"}
    tags = {"tangents": [{"vertex": 2, "triangle": T[4], "tangent": [0, 1, 0.5]}]}
    s = new_session(daemon, body)
    assert s.req("PUT", "/rules", json=rules).status_code == 200
    assert s.req("PUT", "/tags", json=tags).status_code == 200
    far = 34                                      # the outer row of the third sheet
    for mv in ({"index": far, "position": moved(V[far], 0)},
               {"index": 40, "level": 1, "position": [0.5, 2.0, 1.0]}):
        before = snapshot(s, LEVEL)
        v = before[1]["version"]
        r = s.req("PATCH", "/control-points", json={"moves": [mv]},
                  headers={"If-Match": f'"{v}"'}, params={"delta": LEVEL})
        assert r.status_code == 200 and r.headers["Content-Type"] == "application/json", r.text
        assert r.json()["version"] == v + 1 and r.json()["delta"]["status"] == 410
        gone(s, LEVEL, v)
    before = snapshot(s, LEVEL)
    v = before[1]["version"]
    patch(s, {"attributes": {"t": [{"index": 3, "value": 5.5}]}})
    check_delta(s, LEVEL, before, snapshot(s, LEVEL), v, v + 1)
    c = s.req("GET", "/complex").json()
    fresh = new_session(daemon, dict(body, vertices=c["vertices"], details=c["details"],
                                     attributes=c["attributes"]))
    assert fresh.req("PUT", "/rules", json=rules).status_code == 200
    assert fresh.req("PUT", "/tags", json=tags).status_code == 200
    a, b = (x.level(LEVEL, format="json").json() for x in (s, fresh))
    assert a["vertices"] == b["vertices"] and a["attributes"] == b["attributes"]
    s.delete()
    fresh.delete()


@pytest.mark.parametrize("mesh", list(MESHES))
def test_patch_answers_with_its_delta(daemon, mesh):
    """PATCH ?delta=L (one round trip for a dragging client): the answer is the delta of level L
    since the version the edit was made on — the bytes GET /delta gives (bin; the JSON delta
    inside the summary with format=json) — and, applied to the level fetched before, gives the
    level fetched after."""
    body = with_attrs(MESHES[mesh]())
    s = new_session(daemon, body)
    V, n = body["vertices"], len(body["vertices"])
    before = snapshot(s, LEVEL)
    for step in range(3):
        v = version_of(s)
        pts = sorted({(3 * step + 7 * j) % n for j in range(1 + step)})
        b = {"moves": [{"index": k, "position": moved(V[k], k + step)} for k in pts],
             "attributes": {"t": [{"index": pts[0], "value": 2.5 * step}]}}
        fmt = "json" if step == 1 else "bin"
        r = s.req("PATCH", "/control-points", json=b, headers={"If-Match": f'"{v}"'},
                  params={"delta": LEVEL, "format": fmt, "attributes": "t,v"})
        assert r.status_code == 200, r.text
        assert r.headers["ETag"] == f'"{v + 1}"' and version_of(s) == v + 1
        ups = json.loads(r.headers["X-Updated-Points"])
        assert ups["0"] == len(pts)
        after = snapshot(s, LEVEL)
        db, dj, _ = deltas(s, LEVEL, v)
        if fmt == "bin":
            assert r.headers["Content-Type"] == "application/octet-stream"
            assert r.headers["X-Attribute-Components"] == "t=1,v=2"
            got = s.req("GET", f"/levels/{LEVEL}/delta", params={"since": v, "attributes": "t,v"})
            assert r.content == got.content
            d = parse_sdd1(r.content, [("t", 1), ("v", 2)])
            assert (d["since"], d["version"]) == (v, v + 1)
        else:
            j = r.json()
            assert j["version"] == v + 1 and j["updated_points"] == ups
            assert j["delta"] == dj and (dj["since"], dj["version"]) == (v, v + 1)
        check_delta(s, LEVEL, before, after, v, v + 1)
        before = after
    s.delete()


def test_delta_for_a_glb_of_some_parts(daemon):
    """A client holding a GLB of some parts (parts=surfaces: normals over the surface triangles
    alone) follows it with deltas of the same parts=: positions and normals applied equal a
    refetch of that GLB. The mixed complex's fins meet its solid, so their shared points' normals
    differ between the parts. PATCH ?delta= takes parts= too; a bad one is a 422 naming it."""
    body = complex_from_text(MIXED)
    s = new_session(daemon, body)
    V, n = body["vertices"], len(body["vertices"])
    full = glb_arrays(s.level(LEVEL).content)["NORMAL"]
    differ = False
    for parts in ("surfaces", "solids", "curves,solids", "surfaces,solids", "points,curves"):
        g0 = glb_arrays(s.level(LEVEL, parts=parts).content)
        if g0["NORMAL"] is not None and parts in ("surfaces", "solids"):
            differ |= not np.array_equal(g0["NORMAL"], full)
        v = version_of(s)
        k = (7 * len(parts)) % n
        mv = {"moves": [{"index": k, "position": moved(V[k], len(parts))}]}
        r = s.req("PATCH", "/control-points", json=mv, headers={"If-Match": f'"{v}"'},
                  params={"delta": LEVEL, "parts": parts})
        assert r.status_code == 200, r.text
        got = s.req("GET", f"/levels/{LEVEL}/delta", params={"since": v, "parts": parts})
        assert got.status_code == 200 and got.content == r.content, parts
        d = parse_sdd1(got.content, [])
        g1 = glb_arrays(s.level(LEVEL, parts=parts).content)
        pos = g0["POSITION"].copy()
        pos[d["indices"]] = d["positions"]
        np.testing.assert_array_equal(pos, g1["POSITION"])
        drawn = any(x in parts for x in ("surfaces", "solids"))
        assert bool(d["flags"] & 1) == drawn, parts
        if drawn:
            nrm = g0["NORMAL"].copy()
            nrm[d["indices"]] = d["normals"]
            np.testing.assert_array_equal(nrm, g1["NORMAL"], err_msg=parts)
            j = s.req("GET", f"/levels/{LEVEL}/delta",
                      params={"since": v, "parts": parts, "format": "json"}).json()
            np.testing.assert_array_equal(np.asarray(j["normals"], np.float32), d["normals"])
    assert differ   # the case is one where the parts' normals are not the whole level's
    for params, status in [({"since": 1, "parts": "fins"}, 422), ({"since": 1, "parts": ""}, 422)]:
        r = s.req("GET", f"/levels/{LEVEL}/delta", params=params)
        assert r.status_code == status and r.json()["errors"][0]["pointer"] == "parts", r.text
    v = version_of(s)
    r = s.req("PATCH", "/control-points", json={"moves": [{"index": 0, "position": V[0]}]},
              headers={"If-Match": f'"{v}"'}, params={"parts": "surfaces"})
    assert r.status_code == 400 and r.json()["errors"][0]["pointer"] == "parts"
    assert version_of(s) == v
    s.delete()


def test_patch_delta_query_checked_before_the_edit(daemon):
    """A bad ?delta query is refused with nothing applied; a delta the daemon cannot make (a level
    not computed, an edit that rebuilt rules) leaves the edit applied and says why in the
    summary."""
    s = new_session(daemon, complex_from_text(CUBE))
    assert s.level(1, format="json").status_code == 200
    v = version_of(s)
    mv = {"moves": [{"index": 0, "position": [0.01, 0.02, -0.01]}]}
    for params, status, ptr in [({"delta": "x"}, 400, "delta"), ({"delta": 99}, 422, "delta"),
                                ({"delta": 1, "format": "xml"}, 422, "format"),
                                ({"delta": 1, "attributes": "nope"}, 422, "attributes"),
                                ({"format": "json"}, 400, "format"), ({"what": 1}, 400, None)]:
        r = s.req("PATCH", "/control-points", json=mv, headers={"If-Match": f'"{v}"'},
                  params=params)
        assert r.status_code == status, (params, r.text)
        if ptr:
            assert r.json()["errors"][0]["pointer"] == ptr
        assert version_of(s) == v
    r = s.req("PATCH", "/control-points", json=mv, headers={"If-Match": f'"{v}"'},
              params={"delta": 2})
    assert r.status_code == 200 and r.headers["Content-Type"] == "application/json"
    j = r.json()
    assert j["version"] == v + 1 == version_of(s)
    assert j["delta"]["status"] == 410 and j["delta"]["type"] == "/errors/delta-unavailable"
    s.delete()


def snapshot_plain(s, level):
    return glb_arrays(s.level(level).content), s.level(level, format="json").json()


def test_delta_after_restart_and_unknown_session(daemon):
    """The store is in memory: after a restart the session is unknown (404), so a client starts
    again; a delta of a session that was deleted is 404 too."""
    d = Daemon()
    try:
        s = new_session(d, complex_from_text(MIXED))
        assert s.level(1, format="json").status_code == 200
        v = version_of(s)
        d.stop()
        d2 = Daemon()
        try:
            s.d = d2
            s.base = f"{d2.url}/v1/sessions/{s.id}"
            assert s.req("GET", "/levels/1/delta", params={"since": v}).status_code == 404
        finally:
            d2.stop()
    finally:
        d.stop()


# ---- events -----------------------------------------------------------------------------------

class Listener:
    """Reads a session's event stream in a thread into `events` (the client's events())."""

    def __init__(self, daemon, s, last_event_id=None):
        c = subdiv.Client(daemon.url, timeout=30)
        self.session = c.session(s.id, s.token)
        self.events = []
        self.it = self.session.events(last_event_id=last_event_id, timeout=30)
        self.done = threading.Event()
        self.t = threading.Thread(target=self._run, daemon=True)
        self.t.start()

    def _run(self):
        try:
            for ev in self.it:
                self.events.append(ev)
        except subdiv.TransportError:
            pass
        self.done.set()

    def wait_for(self, pred, timeout=10):
        deadline = time.time() + timeout * SLOW
        while time.time() < deadline:
            if any(pred(e) for e in self.events):
                return True
            time.sleep(0.02)
        return False


def test_events_every_version_in_order(daemon):
    body = complex_from_text(MIXED)
    s = new_session(daemon, body)
    assert s.level(2, format="json").status_code == 200
    v0 = version_of(s)
    ls = [Listener(daemon, s) for _ in range(3)]
    time.sleep(0.3)
    want = []
    for k in range(20):
        up = s.req("PATCH", "/control-points",
                   json={"moves": [{"index": k % 8, "position": moved(body["vertices"][k % 8], k)}]},
                   headers={"If-Match": f'"{v0 + k}"'})
        assert up.status_code == 200, up.text
        want.append((v0 + k + 1, "edit", up.json()["updated_points"]))
    assert s.req("PUT", "/tags", json={"singular": [[3]]}).status_code == 200
    want.append((v0 + 21, "tags", None))
    for li in ls:
        assert li.wait_for(lambda e: e.get("id") == v0 + 21), li.events
        got = [(e["id"], e["data"]["kind"], e["data"].get("updated_points"))
               for e in li.events if e["event"] == "version"]
        assert got == want
        assert all(e["data"]["version"] == e["id"] for e in li.events if e["event"] == "version")
    # a reconnect with Last-Event-ID gets what it missed, in order
    r = Listener(daemon, s, last_event_id=v0 + 15)
    assert r.wait_for(lambda e: e.get("id") == v0 + 21)
    assert [e["id"] for e in r.events if e["event"] == "version"] == list(range(v0 + 16, v0 + 22))
    # one that is not a version, or is ahead, is told to resync
    for bad in ("x", v0 + 99):
        q = Listener(daemon, s, last_event_id=bad)
        assert q.wait_for(lambda e: e["event"] == "resync")
        assert next(e for e in q.events if e["event"] == "resync")["data"]["version"] == v0 + 21
    # the session ends: every listener is told and its stream ends
    assert s.delete().status_code == 204
    for li in ls + [r]:
        assert li.wait_for(lambda e: e["event"] == "deleted")
        assert li.done.wait(5)
        assert [e for e in li.events if e["event"] == "deleted"][0]["data"]["reason"] == "deleted"


def test_events_access_token_and_heartbeat():
    d = Daemon("--sse-heartbeat", "1")
    try:
        s = new_session(d, complex_from_text(MIXED))
        url = f"{s.base}/events?access_token={s.token}"
        r = requests.get(url, stream=True, timeout=10)
        assert r.status_code == 200 and r.headers["Content-Type"] == "text/event-stream"
        t0 = time.time()
        lines = []
        for line in r.iter_lines(chunk_size=1):
            lines.append(line)
            if line == b": heartbeat":
                break
        assert time.time() - t0 < 5 * SLOW
        r.close()
        assert requests.get(f"{s.base}/events?access_token=wrong", timeout=5).status_code == 401
        # only the event stream takes the token in the query
        assert requests.get(f"{s.base}/complex?access_token={s.token}", timeout=5).status_code == 401
        time.sleep(0.3)
        assert not any(s.token in line for line in d.log_lines)
        assert any("/events" in line for line in d.log_lines)
    finally:
        assert d.stop() == 0


def test_a_closed_listener_frees_its_place():
    """A client that closes its event stream frees its place among --max-listeners within a
    second or so (the stream's thread sees the socket hung up while it waits), not only after
    events or heartbeats are written to it (docs/API.md "Live edits")."""
    d = Daemon("--max-listeners", "2", "--sse-heartbeat", "60")
    try:
        s = new_session(d, complex_from_text(MIXED))
        socks = [stuck_listener(s, rcvbuf=65536) for _ in range(2)]
        for k in socks:   # both streams are open: their first bytes came
            k.settimeout(5)
            assert b"200" in k.recv(4096)
        r = s.req("GET", "/events", stream=True)
        assert r.status_code == 429
        r.close()
        for k in socks:
            k.close()
        t0, status = time.time(), None
        while time.time() - t0 < 5 * SLOW:
            r = s.req("GET", "/events", stream=True)
            status = r.status_code
            r.close()
            if status == 200:
                break
            time.sleep(0.1)
        assert status == 200, "the closed streams still hold their places"
        assert time.time() - t0 < 3 * SLOW
    finally:
        assert d.stop() == 0


def stuck_listener(s, rcvbuf=1024):
    """An event stream whose socket is never read."""
    host, port = s.d.url.rsplit("/", 1)[1].split(":")
    k = socket.socket()
    k.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    k.connect((host, int(port)))
    k.sendall(f"GET /v1/sessions/{s.id}/events HTTP/1.1\r\nHost: x\r\n"
              f"Authorization: Bearer {s.token}\r\n\r\n".encode())
    return k


def edit_latencies(s, V, n, v):
    times = []
    for k in range(n):
        t = time.perf_counter()
        r = s.req("PATCH", "/control-points",
                  json={"moves": [{"index": k % 6, "position": moved(V[k % 6], k, 0.001 * (k % 5))}]},
                  headers={"If-Match": f'"{v}"'})
        times.append(time.perf_counter() - t)
        assert r.status_code == 200, r.text
        v = r.json()["version"]
    return times, v


def test_a_stuck_listener_does_not_slow_edits(daemon):
    body = complex_from_text(CUBE)
    s = new_session(daemon, body)
    assert s.level(2, format="json").status_code == 200
    v = version_of(s)
    free, v = edit_latencies(s, body["vertices"], 150, v)
    stuck = [stuck_listener(s) for _ in range(2)]
    live = Listener(daemon, s)
    time.sleep(0.3)
    t0 = time.time()
    busy, v = edit_latencies(s, body["vertices"], 1500, v)    # > 100 KiB of events each
    print(f"\n1500 edits in {time.time() - t0:.1f} s")
    m0, m1 = statistics.median(free), statistics.median(busy)
    p99 = sorted(busy)[int(0.99 * len(busy))]
    print(f"\nedit latency: median {m0 * 1e3:.2f} ms without listeners, {m1 * 1e3:.2f} ms with "
          f"two stuck listeners and a live one (p99 {p99 * 1e3:.2f} ms, max {max(busy) * 1e3:.2f} ms)")
    assert m1 < 2 * m0 + 0.002 * SLOW and max(busy) < 1.0 * SLOW
    assert live.wait_for(lambda e: e.get("id") == v)          # the live one got everything
    ids = [e["id"] for e in live.events if e["event"] == "version"]
    assert ids == sorted(ids) and ids[-1] == v and len(ids) == 1500
    metrics = requests.get(daemon.url + "/metrics", timeout=5).text
    dropped = [l for l in metrics.splitlines() if l.startswith("subdivd_event_listeners_dropped")]
    assert dropped and float(dropped[0].split()[-1]) >= 2, dropped
    # dropped, they no longer count (their sockets still open): only the live listener does, so
    # a stuck client holds no --max-listeners place
    gauge = [l for l in metrics.splitlines() if l.startswith("subdivd_event_listeners ")]
    assert gauge and float(gauge[0].split()[-1]) == 1, gauge
    for k in stuck:
        k.close()
    s.delete()


# ---- detail offsets ---------------------------------------------------------------------------

def csr(s, to, frm):
    r = s.req("GET", f"/matrices/{to}", params={"from": frm, "format": "json"})
    assert r.status_code == 200, r.text
    j = r.json()
    from scipy.sparse import csr_matrix  # noqa: PLC0415 (Debian python3-scipy)
    return csr_matrix((j["val"], j["col"], j["rowptr"]), shape=(j["rows"], j["cols"]))


def level_xyz(s, level):
    r = s.level(level, format="json")
    assert r.status_code == 200
    return np.array(r.json()["vertices"], dtype=float)


def test_fine_offsets_survive_a_coarser_edit(daemon):
    body = complex_from_text(CUBE)
    V = body["vertices"]
    s = new_session(daemon, body)
    fresh = new_session(daemon, body)                 # the unedited complex: S and p^1
    S1 = csr(fresh, 2, 1)
    p1 = level_xyz(fresh, 1)
    p2 = level_xyz(fresh, 2)
    i2 = [17, 400, 1234 % len(p2)]
    want = {i: p2[i] + np.array([0.02, -0.01, 0.015]) * (k + 1) for k, i in enumerate(i2)}
    patch(s, {"moves": [{"index": i, "level": 2, "position": list(p)} for i, p in want.items()]})
    got = level_xyz(s, 2)
    for i, p in want.items():
        np.testing.assert_array_equal(got[i], p)        # the point ends exactly at its position
    d = {i: p - (S1 @ p1)[i] for i, p in want.items()}
    c = s.req("GET", "/complex").json()
    assert sorted((e["level"], e["index"]) for e in c["details"]) == [(2, i) for i in sorted(i2)]
    for e in c["details"]:
        np.testing.assert_allclose(e["offset"], d[e["index"]], rtol=0, atol=1e-15)
    # a level-0 edit afterwards: p^2 = S p^1(new) + d, with p^1 from a fresh session of the moved
    # complex (no offsets at level 1)
    W = [list(v) for v in V]
    for k in (0, 5, 9):
        W[k] = moved(V[k], k, 0.05)
    patch(s, {"moves": [{"index": k, "position": W[k]} for k in (0, 5, 9)]})
    moved_fresh = new_session(daemon, dict(body, vertices=W))
    q1 = level_xyz(moved_fresh, 1)
    expect = S1 @ q1
    for i in i2:
        expect[i] += d[i]
    got = level_xyz(s, 2)
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(level_xyz(s, 1), q1)
    # PUT /complex with the listed offsets gives the same levels; PUT /tags and /rules keep them
    c = s.req("GET", "/complex").json()
    again = new_session(daemon, {"vertices": c["vertices"], "simplices": c["simplices"],
                                 "details": c["details"]})
    np.testing.assert_array_equal(level_xyz(again, 2), got)
    for path, b in (("/tags", {"singular": [[0]]}), ("/rules", {"solid_scheme": "box"})):
        r = again.req("PUT", path, json=b)
        assert r.status_code == 200 and "details_dropped" not in r.json()
        assert len(again.req("GET", "/complex").json()["details"]) == 3
    # refine and a PUT /complex without them drop them, and say how many
    r = again.req("POST", "/refine", json={"select": {"simplices": [c["simplices"][0]]}})
    assert r.status_code == 200 and r.json()["details_dropped"] == 3
    assert again.req("GET", "/complex").json()["details"] == []
    r = s.put_complex(body)
    assert r.status_code == 200 and r.json()["details_dropped"] == 3
    assert s.req("GET", "/complex").json()["details"] == []
    for x in (s, fresh, moved_fresh, again):
        x.delete()


def test_fine_moves_validated_all_or_nothing(daemon):
    body = complex_from_text(MIXED)
    s = new_session(daemon, body)
    before = s.req("GET", "/complex").json()
    n1 = s.req("GET", "/levels/1/stats").json()["counts"]["vertices"]
    v = version_of(s)
    for moves, ptr in (([{"index": n1, "level": 1, "position": [0, 0, 0]}], "/moves/0/index"),
                       ([{"index": 0, "level": 13, "position": [0, 0, 0]}], "/moves/0/level"),
                       ([{"index": 2, "level": 1, "position": [0, 0, 0]},
                         {"index": 2, "level": 1, "position": [1, 0, 0]}], "/moves/1/index"),
                       ([{"index": 2, "level": 1, "position": [0, 0, 0]},
                         {"index": 0, "position": [0, 0, 1e16]}], "/moves/1/position/2")):
        r = s.req("PATCH", "/control-points", json={"moves": moves}, headers={"If-Match": f'"{v}"'})
        assert r.status_code in (400, 422), r.text
        assert r.json()["errors"][0]["pointer"] == ptr, r.text
    assert s.req("GET", "/complex").json() == before and version_of(s) == v
    s.delete()


def test_a_download_in_flight_keeps_its_normals(daemon):
    """Edits update the cached normals copy-on-write: a glTF stream opened before an edit, read
    slowly across it, is the glTF of its moment byte for byte; one opened after is the edited one.
    Level 4 as embedded glTF, so that its positions alone (before the normals) outgrow what the
    kernel and libmicrohttpd buffer for a client that has read 4 KiB (~4.5 MB)."""
    body = complex_from_text(CUBE)
    s = new_session(daemon, body)
    before = s.level(4, format="gltf").content
    v = version_of(s)
    host, port = s.d.url.rsplit("/", 1)[1].split(":")
    k = socket.socket()
    k.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    k.connect((host, int(port)))
    k.sendall(f"GET /v1/sessions/{s.id}/levels/4?format=gltf HTTP/1.1\r\nHost: x\r\n"
              f"Connection: close\r\nAuthorization: Bearer {s.token}\r\n\r\n".encode())
    got = k.recv(4096)
    time.sleep(0.3)
    for j in range(3):                         # edits while the stream waits for the client
        patch(s, {"moves": [{"index": 5 + 9 * j, "position": moved(body["vertices"][5 + 9 * j], j, 0.004)}]})
    k.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)   # now read at full speed
    while True:
        b = k.recv(1 << 20)
        if not b:
            break
        got += b
    k.close()
    head, _, text = got.partition(b"\r\n\r\n")
    assert b" 200 " in head.split(b"\r\n")[0] and f'ETag: "{v}"'.encode() in head
    assert text == before
    after = s.level(4, format="gltf")
    assert after.headers["ETag"] == f'"{v + 3}"' and after.content != before
    s.delete()


def test_a_rebuilding_edit_keeps_offsets_and_finer_moves(daemon):
    """An edit that moves a point a Ying-Zorin corner's angle is measured on becomes a new model:
    it carries the session's offsets and applies the edit's finer moves; its levels equal a fresh
    session's with the same control points and offsets."""
    V = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2],
         [-.5, .8, 0], [-.5, .8, 1], [-.5, .8, 2], [-.5, -.8, 0], [-.5, -.8, 1], [-.5, -.8, 2]]
    T = []
    for a in (3, 6, 9):
        T += [[0, 1, a + 1], [0, a + 1, a], [1, 2, a + 2], [1, a + 2, a + 1]]
    rules = {"nonmanifold_surface": "ying-zorin"}
    tags = {"petals": [{"vertex": 0, "triangle": [0, 4, 3], "kind": "convex"}]}
    s = new_session(daemon, {"vertices": V, "simplices": T})
    assert s.req("PUT", "/rules", json=rules).status_code == 200
    assert s.req("PUT", "/tags", json=tags).status_code == 200
    p2 = level_xyz(s, 2)
    patch(s, {"moves": [{"index": 7, "level": 2, "position": list(p2[7] + 0.01)}]})
    p1 = level_xyz(s, 1)
    target = list(p1[4] + [0.02, 0, -0.01])
    W = [list(v) for v in V]
    W[3] = [1.2, 0.7, -0.1]
    patch(s, {"moves": [{"index": 3, "position": W[3]}, {"index": 4, "level": 1, "position": target}]})
    got1, got2 = level_xyz(s, 1), level_xyz(s, 2)
    np.testing.assert_array_equal(got1[4], target)
    c = s.req("GET", "/complex").json()
    assert sorted((e["level"], e["index"]) for e in c["details"]) == [(1, 4), (2, 7)]
    assert c["vertices"][3] == W[3]
    fresh = new_session(daemon, {"vertices": W, "simplices": T, "details": c["details"]})
    assert fresh.req("PUT", "/rules", json=rules).status_code == 200
    assert fresh.req("PUT", "/tags", json=tags).status_code == 200
    np.testing.assert_array_equal(level_xyz(fresh, 1), got1)
    np.testing.assert_array_equal(level_xyz(fresh, 2), got2)
    s.delete()
    fresh.delete()


def test_events_deleted_on_expiry(daemon):
    s = Session(daemon, ttl_s=1)
    li = Listener(daemon, s)
    assert li.wait_for(lambda e: e["event"] == "deleted", timeout=15), li.events
    assert [e for e in li.events if e["event"] == "deleted"][0]["data"]["reason"] == "expired"
    assert li.done.wait(5)
    assert s.req("GET").status_code == 404


def test_client_delta_reads_both_layouts(daemon):
    body = with_attrs(complex_from_text(MIXED))
    s = new_session(daemon, body)
    c = subdiv.Client(daemon.url, timeout=30).session(s.id, s.token)
    before = snapshot(s, 2)
    v = before[1]["version"]
    c.edit(moves=[{"index": 1, "position": [1.05, 0.02, 0]}, {"index": 30, "level": 2,
                                                            "position": [0.3, 0.3, 0.3]}],
           attributes={"v": [{"index": 2, "value": [5, 6]}]})
    after = snapshot(s, 2)
    b = c.delta(2, since=v, attributes=["t", "v"])
    j = c.delta(2, since=v, format="json", attributes="t,v")
    assert b["version"] == j["version"] == c.version == after[1]["version"]
    np.testing.assert_array_equal(b["indices"], j["indices"])
    np.testing.assert_array_equal(b["positions"], j["positions"].astype(np.float32))
    np.testing.assert_array_equal(b["normals"], j["normals"])
    for name in ("t", "v"):
        np.testing.assert_array_equal(b["attributes"][name], j["attributes"][name].astype(np.float32))
    pos = before[0]["POSITION"].copy()
    pos[b["indices"]] = b["positions"]
    np.testing.assert_array_equal(pos, after[0]["POSITION"])
    assert [e["level"] for e in c.get_complex()["details"]] == [2]
    c.put_tags([[3]])
    with pytest.raises(subdiv.Gone):
        c.delta(2, since=v)
    s.delete()


def test_client_empty_json_delta_with_attributes(daemon):
    """An empty delta (since = the current version, or an edit that moved nothing) read as JSON
    with attributes: arrays of shape (0, ncomp), as the binary layout gives, from the
    X-Attribute-Components header (GET /delta and PATCH ?delta= both send it)."""
    body = with_attrs(complex_from_text(MIXED))
    s = new_session(daemon, body)
    c = subdiv.Client(daemon.url, timeout=30).session(s.id, s.token)
    v = snapshot(s, 2)[1]["version"]
    for fmt in ("json", "bin"):
        d = c.delta(2, since=v, format=fmt, attributes="t,v")
        assert len(d["indices"]) == 0 and d["positions"].shape == (0, 3), fmt
        assert {k: a.shape for k, a in d["attributes"].items()} == {"t": (0, 1), "v": (0, 2)}, fmt
    r = s.req("PATCH", "/control-points", params={"delta": 2, "format": "json", "attributes": "t,v"},
              json={"moves": []}, headers={"If-Match": f'"{v}"'})
    assert r.status_code == 200 and r.headers["X-Attribute-Components"] == "t=1,v=2"
    r = c.edit(moves=[], delta=2, delta_format="json", delta_attributes=["t", "v"], if_match=v + 1)
    assert {k: a.shape for k, a in r["delta"]["attributes"].items()} == {"t": (0, 1), "v": (0, 2)}
    s.delete()


def test_client_edit_with_its_delta(daemon):
    """Session.edit(delta=L): the edit's delta in the PATCH answer, as delta() reads it, both
    layouts; None with the problem when the level is not computed (the edit stands)."""
    body = with_attrs(complex_from_text(MIXED))
    s = new_session(daemon, body)
    c = subdiv.Client(daemon.url, timeout=30).session(s.id, s.token)
    before = snapshot(s, 2)
    v = before[1]["version"]
    r = c.edit(moves=[{"index": 1, "position": [1.05, 0.02, 0]}], delta=2, delta_attributes="t,v")
    assert r["version"] == v + 1 == c.version and r["updated_points"]["0"] == 1
    after = snapshot(s, 2)
    d = r["delta"]
    assert (d["since"], d["version"], d["level"]) == (v, v + 1, 2)
    pos = before[0]["POSITION"].copy()
    pos[d["indices"]] = d["positions"]
    np.testing.assert_array_equal(pos, after[0]["POSITION"])
    assert set(d["attributes"]) == {"t", "v"}
    r = c.edit(moves=[{"index": 1, "position": [1.0, 0.0, 0]}], delta=2, delta_format="json")
    j = c.delta(2, since=v + 1, format="json")
    np.testing.assert_array_equal(r["delta"]["indices"], j["indices"])
    np.testing.assert_array_equal(r["delta"]["positions"], j["positions"])
    r = c.edit(moves=[{"index": 1, "position": [1.0, 0.01, 0]}], delta=4)
    assert r["delta"] is None and r["gone"]["status"] == 410 and r["version"] == v + 3 == c.version
    # parts=: the normals of a GLB of those parts (test_delta_for_a_glb_of_some_parts)
    g0 = glb_arrays(s.level(2, parts="surfaces").content)
    r = c.edit(moves=[{"index": 1, "position": [1.02, 0.0, 0]}], delta=2, delta_parts=["surfaces"])
    d = c.delta(2, since=v + 3, parts="surfaces")
    np.testing.assert_array_equal(r["delta"]["normals"], d["normals"])
    nrm = g0["NORMAL"].copy()
    nrm[d["indices"]] = d["normals"]
    np.testing.assert_array_equal(nrm, glb_arrays(s.level(2, parts="surfaces").content)["NORMAL"])
    s.delete()


def test_client_events_open_when_called(daemon):
    """Session.events() opens the stream when it is called, not at the first next(): a change
    made after the call and before the iteration starts comes as an event (the stream began at
    the version before it), a refusal raises at the call, and close() ends a stream never read
    (its place among --max-listeners is freed)."""
    body = complex_from_text(MIXED)
    s = new_session(daemon, body)
    c = subdiv.Client(daemon.url, timeout=30).session(s.id, s.token)
    v = version_of(s)
    it = c.events(timeout=30)
    v1 = patch(s, {"moves": [{"index": 1, "position": moved(body["vertices"][1], 1)}]}, v)
    got = []
    t = threading.Thread(target=lambda: got.append(next(it)), daemon=True)
    t.start()
    t.join(5 * SLOW)   # heartbeats come every 15 s: a stream opened after the edit has nothing
    assert got and got[0]["id"] == v1 and got[0]["data"]["kind"] == "edit", got
    it.close()
    with pytest.raises(subdiv.Unauthorized):
        subdiv.Client(daemon.url, timeout=30).session(s.id, "not-the-token").events()
    s.delete()
    # --max-listeners (16): each call holds a place, the 17th is refused at once
    s = new_session(daemon, body)
    c = subdiv.Client(daemon.url, timeout=30).session(s.id, s.token)
    streams = [c.events(timeout=30) for _ in range(16)]
    with pytest.raises(subdiv.TooManyRequests):
        c.events(timeout=30)
    for st in streams:
        st.close()
    t0 = time.time()
    while True:   # closed without being read: the places come free within about a second
        try:
            c.events(timeout=30).close()
            break
        except subdiv.TooManyRequests:
            assert time.time() - t0 < 5 * SLOW, "closed streams still hold their places"
            time.sleep(0.1)
    s.delete()


def test_events_end_without_deleted_when_a_daemon_reloads(tmp_path):
    """Two daemons on one redis store (docs/DEPLOY.md): an edit through one makes the other drop
    its resident copy of the session at its next request and load the stored one. The session
    is not gone, so that daemon's listeners are not told `event: deleted`: their streams end,
    and a reconnect with Last-Event-ID is told to resync (it missed the other daemon's edit). A
    session deleted through the other daemon is `deleted` for them."""
    if not REDIS_SERVER:
        pytest.skip("redis-server is not installed (tools/packages.txt lists it)")
    redis = RedisServer(tmp_path).start()
    a, b = Daemon("--store", redis.url), Daemon("--store", redis.url)
    try:
        body = complex_from_text(MIXED)
        s = new_session(a, body)
        v = version_of(s)
        on_b = Session.__new__(Session)
        on_b.http, on_b.id, on_b.token, on_b.auth = requests.Session(), s.id, s.token, s.auth
        on_b.base = f"{b.url}/v1/sessions/{s.id}"
        li = Listener(a, s)
        assert li.wait_for(lambda e: False, timeout=0.3) is False   # its stream is open
        patch(on_b, {"moves": [{"index": 1, "position": moved(body["vertices"][1], 1)}]}, v)
        assert version_of(s) == v + 1          # a: the stored session, loaded again
        assert li.done.wait(5 * SLOW), "the stream of the dropped copy did not end"
        assert [e for e in li.events if e["event"] == "deleted"] == [], li.events
        again = Listener(a, s, last_event_id=v)
        assert again.wait_for(lambda e: e["event"] == "resync"), again.events
        assert on_b.req("DELETE").status_code == 204
        assert s.req("GET").status_code == 404   # a: gone from the store
        assert again.wait_for(lambda e: e["event"] == "deleted"), again.events
        assert [e["data"]["reason"] for e in again.events if e["event"] == "deleted"] == ["deleted"]
    finally:
        assert a.stop() == 0 and b.stop() == 0
        redis.stop()


def test_unknown_attribute_messages_name_the_whole_name(daemon):
    """An unknown attribute near the 48-character limit is named whole in the problem (it was cut
    to 40 characters, so two such names that differ late read the same); an item too long to be
    a name says so instead of showing a cut one (docs/OUTPUTS.md: refused, never cut)."""
    known = "k" * 48
    asked = "k" * 47 + "x"                      # 48 characters, not posted
    b = surface()
    b["attributes"] = {known: [float(i) for i in range(len(b["vertices"]))]}
    s = Session(daemon)
    r = s.put_complex(b)
    assert r.status_code == 200, r.text
    version = r.json()["version"]
    for path, params in (("/levels/1", {"attributes": asked}),
                         ("/levels/1", {"colormap": f"{asked}:0:1"}),
                         ("/levels/1/delta", {"since": version, "attributes": asked})):
        r = s.req("GET", path, params=params)
        assert r.status_code == 422 and r.json()["type"].endswith("/unknown-attribute"), r.text
        assert f'"{asked}"' in r.json()["detail"], (path, r.json()["detail"])
    for path, params in (("/levels/1", {"attributes": f"{known},{known}"}),
                         ("/levels/1/delta", {"since": version, "attributes": f"{known},{known}"})):
        r = s.req("GET", path, params=params)
        assert r.status_code == 422 and r.json()["type"].endswith("/repeated-attribute"), r.text
        assert f'"{known}"' in r.json()["detail"], (path, r.json()["detail"])
    r = s.req("PATCH", "/control-points", headers={"If-Match": f'"{version}"'},
              json={"attributes": {asked: [{"index": 0, "value": 1}]}})
    assert r.status_code == 422 and r.json()["type"].endswith("/unknown-attribute"), r.text
    assert f'"{asked}"' in r.json()["detail"], r.json()["detail"]
    for path, params in (("/levels/1", {"attributes": "k" * 64}),
                         ("/levels/1/delta", {"since": version, "attributes": "k" * 64})):
        r = s.req("GET", path, params=params)
        assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "attributes", r.text
        assert "k" * 40 not in r.json()["detail"] and "at most 48" in r.json()["detail"], r.text
    r = s.req("PATCH", "/control-points", headers={"If-Match": f'"{version}"'},
              json={"attributes": {"k" * 64: [{"index": 0, "value": 1}]}})
    assert r.status_code == 422 and "at most 48" in r.json()["detail"], r.text
