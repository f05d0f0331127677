"""Embedded models (free-form deformation, 004 Sec. 5.1; docs/API.md "Embedded models").

Expected values come from outside the daemon's binding code: the containing cell and the
barycentric coordinates of a model vertex are found here from the level's own JSON (its
tetrahedra, and its octahedra split into the 4 tetrahedra around their major diagonal, 004
eq. 13) with numpy's solver, and the deformed position is that combination of the level's
points after the edit; affine maps of every control point must carry the model by the same map
(subdivision reproduces affine functions)."""
import json
import struct
import time

import numpy as np
import pytest
import requests

from daemon import Daemon, Session
from meshes import icosphere
from test_persist import adopt, edit, on, store_daemon

# a block of 2 x 2 x 1 cubes, 5 tetrahedra each (so the solid has room inside at level 2)
def cubes(nx=2, ny=2, nz=1):
    vid = {}
    verts, tets = [], []

    def v(i, j, k):
        if (i, j, k) not in vid:
            vid[(i, j, k)] = len(verts)
            verts.append([float(i), float(j), float(k)])
        return vid[(i, j, k)]
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                c = [v(i + a, j + b, k + d) for d in (0, 1) for b in (0, 1) for a in (0, 1)]
                if (i + j + k) % 2 == 0:
                    tets += [[c[0], c[1], c[2], c[4]], [c[1], c[3], c[2], c[7]],
                             [c[1], c[4], c[5], c[7]], [c[2], c[4], c[7], c[6]],
                             [c[1], c[2], c[4], c[7]]]
                else:
                    tets += [[c[0], c[1], c[3], c[5]], [c[0], c[3], c[2], c[6]],
                             [c[0], c[5], c[4], c[6]], [c[3], c[5], c[6], c[7]],
                             [c[0], c[3], c[5], c[6]]]
    return {"vertices": verts, "simplices": tets}


BLOCK = cubes()


def model_points(n, seed=1):
    rnd = np.random.default_rng(seed)
    return (rnd.uniform([0.6, 0.6, 0.35], [1.4, 1.4, 0.65], size=(n, 3))).tolist()


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    d.stop()


def session_with_model(daemon, pts, level=2, **extra):
    s = Session(daemon)
    r = s.put_complex(BLOCK)
    assert r.status_code == 200, r.text
    r = s.req("PUT", "/embedded/m", json=dict({"vertices": pts, "level": level}, **extra))
    assert r.status_code == 200, r.text
    return s, r.json()["version"]


def deformed(s, name="m"):
    r = s.req("GET", f"/embedded/{name}")
    assert r.status_code == 200, r.text
    return np.array(r.json()["vertices"])


def level_cells(s, level):
    j = s.level(level, format="json").json()
    x = np.array(j["vertices"])
    tets = [list(t) for t in j["cells"]["tetrahedra"]]
    for p, q, a, a2, b, b2 in j["cells"]["octahedra"]:     # around the major diagonal (p, q)
        tets += [[p, q, a, b], [p, q, b, a2], [p, q, a2, b2], [p, q, b2, a]]
    return x, np.array(tets)


def bent(daemon, blk, amount, seed, level):
    """blk with its vertices moved by up to `amount` at random, posted to a new session: the
    session, the complex and level `level`'s points and cells (level_cells)."""
    rnd = np.random.default_rng(seed).uniform(-amount, amount, size=(len(blk["vertices"]), 3))
    blk["vertices"] = (np.array(blk["vertices"]) + rnd).tolist()
    s = Session(daemon)
    assert s.put_complex(blk).status_code == 200
    return s, blk, *level_cells(s, level)


def locate(x, tets, p, tol=1e-12):
    """The lowest cell containing p and its barycentric coordinates, by an independent solve."""
    for c, t in enumerate(tets):
        P = x[t]
        A = np.vstack([P.T, np.ones(4)])
        lam = np.linalg.solve(A, np.append(p, 1.0))
        if lam.min() >= -tol:
            return c, lam
    return None, None


def test_no_edit_gives_the_rest_shape(daemon):
    pts = model_points(200)
    s, _ = session_with_model(daemon, pts)
    assert np.abs(deformed(s) - np.array(pts)).max() <= 1e-12


def test_positions_are_the_barycentric_combination_of_the_cell(daemon):
    """After an edit, each model vertex is sum(w_i p_i) over the level cell it was bound in (the
    cell and weights found here, at the positions of the time of the binding)."""
    pts = model_points(60, seed=3)
    s, v = session_with_model(daemon, pts)
    x0, tets = level_cells(s, 2)
    bound = [locate(x0, tets, np.array(p)) for p in pts]
    assert all(c is not None for c, _ in bound)
    v = edit(s, [{"index": 4, "position": [1.1, 0.9, 0.2]}], v)
    x1, _ = level_cells(s, 2)
    want = np.array([lam @ x1[tets[c]] for c, lam in bound])
    assert np.abs(deformed(s) - want).max() <= 1e-9
    # in octahedra too: some of the vertices sit in the 4 tetrahedra of an octahedron
    ntet = len(s.level(2, format="json").json()["cells"]["tetrahedra"])
    assert any(c >= ntet for c, _ in bound) and any(c < ntet for c, _ in bound)


def test_an_affine_map_of_the_control_points_maps_the_model(daemon):
    pts = model_points(150, seed=5)
    s, v = session_with_model(daemon, pts)
    A = np.array([[1.1, 0.2, 0.0], [-0.1, 0.9, 0.3], [0.05, 0.0, 1.2]])
    b = np.array([0.3, -0.2, 0.5])
    moves = [{"index": i, "position": (A @ np.array(p) + b).tolist()}
             for i, p in enumerate(BLOCK["vertices"])]
    edit(s, moves, v)
    want = np.array(pts) @ A.T + b
    assert np.abs(deformed(s) - want).max() <= 1e-9


def test_a_move_leaves_vertices_outside_its_support_unchanged(daemon):
    pts = model_points(400, seed=7)
    s, v = session_with_model(daemon, pts)
    before = deformed(s)
    x0, tets = level_cells(s, 2)
    bound = [locate(x0, tets, np.array(p))[0] for p in pts]
    v2 = edit(s, [{"index": 0, "position": [-0.1, -0.1, 0.05]}], v)
    x1, _ = level_cells(s, 2)
    moved_pts = set(np.nonzero(np.any(x1 != x0, axis=1))[0].tolist())
    after = deformed(s)
    touched = np.array([bool(set(tets[c].tolist()) & moved_pts) for c in bound])
    assert (after[~touched] == before[~touched]).all()       # bit for bit
    assert touched.any() and (~touched).any()
    # the delta lists exactly the vertices that moved, with their new positions
    d = s.req("GET", "/embedded/m/delta", params={"since": v, "format": "json"})
    assert d.status_code == 200 and d.headers["ETag"] == f'"{v2}"'
    j = d.json()
    changed = np.nonzero(np.any(after != before, axis=1))[0].tolist()
    assert sorted(j["indices"]) == changed
    assert np.array_equal(np.array(j["positions"]), after[j["indices"]])
    # binary: SDD1, float32 positions
    b = s.req("GET", "/embedded/m/delta", params={"since": v}).content
    assert b[:4] == b"SDD1"
    lvl, since, ver, n, flags = struct.unpack_from("<5I", b, 4)
    assert (lvl, since, ver, n, flags) == (2, v, v2, len(changed), 0)
    idx = np.frombuffer(b, "<u4", n, 24)
    xyz = np.frombuffer(b, "<f4", 3 * n, 24 + 4 * n).reshape(n, 3)
    assert idx.tolist() == sorted(changed)
    assert np.array_equal(xyz, after[idx].astype(np.float32))
    # a version before the binding is 410
    assert s.req("GET", "/embedded/m/delta", params={"since": v - 1}).status_code == 410


def test_outside_vertices(daemon):
    s = Session(daemon)
    assert s.put_complex(BLOCK).status_code == 200
    pts = model_points(20) + [[5, 5, 5], [-1, 0.5, 0.5]]
    r = s.req("PUT", "/embedded/m", json={"vertices": pts})
    assert r.status_code == 422, r.text
    assert "2 of its 22 vertices" in r.json()["detail"] and "20, 21" in r.json()["detail"]
    assert s.req("GET", "/embedded/m").status_code == 404                 # nothing was kept
    r = s.req("PUT", "/embedded/m", json={"vertices": pts, "outside": "fixed"})
    assert r.status_code == 200 and r.json()["embedded"]["outside_vertices"] == 2
    v = r.json()["version"]
    edit(s, [{"index": i, "position": [x + 0.5, y, z]} for i, (x, y, z) in enumerate(BLOCK["vertices"])], v)
    got = deformed(s)
    assert got[20:].tolist() == [[5.0, 5.0, 5.0], [-1.0, 0.5, 0.5]]          # rigid
    assert np.abs(got[:20] - (np.array(pts[:20]) + [0.5, 0, 0])).max() <= 1e-9
    # nearest: bound to the closest cell, coordinates outside [0, 1]: still exact with no edit,
    # and carried by an affine map like the others
    t = Session(daemon)
    assert t.put_complex(BLOCK).status_code == 200
    r = t.req("PUT", "/embedded/n", json={"vertices": pts, "outside": "nearest"})
    assert r.status_code == 200, r.text
    assert np.abs(deformed(t, "n") - np.array(pts)).max() <= 1e-9
    v = r.json()["version"]
    edit(t, [{"index": i, "position": [x + 0.5, y, z]} for i, (x, y, z) in enumerate(BLOCK["vertices"])], v)
    assert np.abs(deformed(t, "n") - (np.array(pts) + [0.5, 0, 0])).max() <= 1e-9


def test_nearest_is_the_nearest_cell(daemon):
    """"nearest" binds a vertex outside to the cell nearest to it, however far: straight above
    a flat top, where that cell is the one under the foot."""
    s = Session(daemon)
    assert s.put_complex(BLOCK).status_code == 200
    x, tets = level_cells(s, 1)
    # feet on the flat middle of the top face (z = 1 near (1, 1) stays planar at level 1), the
    # vertices straight above them: the nearest cell is the one under the foot, alone
    rnd = np.random.default_rng(5)
    feet = np.column_stack([rnd.uniform(0.75, 1.25, 12), rnd.uniform(0.75, 1.25, 12), np.ones(12)])
    top = x[(np.abs(x[:, :2] - 1).max(axis=1) <= 0.5) & (x[:, 2] > 0.75)]
    assert len(top) >= 5 and np.abs(top[:, 2] - 1).max() < 1e-15
    heights = [0.01, 0.3, 2, 7, 40, 300, 1e3, 5e3, 1e4, 3e4, 1e5, 1e6]
    pts = feet + np.column_stack([np.zeros(12), np.zeros(12), heights])
    r = s.req("PUT", "/embedded/n", json={"vertices": pts.tolist(), "level": 1, "outside": "nearest"})
    assert r.status_code == 200, r.text
    assert r.json()["embedded"]["outside_vertices"] == 12
    v = r.json()["version"]
    rest = x.copy()
    moves = [{"index": i, "position": [a + 0.1 * b * b, b + 0.05 * a, c * (1 + 0.1 * a)]}
             for i, (a, b, c) in enumerate(BLOCK["vertices"])]
    edit(s, moves, v)
    moved, _ = level_cells(s, 1)
    want = []
    for f, p in zip(feet, pts):
        c, _ = locate(rest, tets, f - [0, 0, 1e-9])
        P = rest[tets[c]]
        lam = np.linalg.solve(np.vstack([P.T, np.ones(4)]), np.append(p, 1.0))
        want.append(lam @ moved[tets[c]])
    got = deformed(s, "n")
    assert np.abs(got - np.array(want)).max() <= 1e-9 * np.abs(want).max(), np.abs(got - want).max()



def tri_dist(p, a, b, c):
    """Distance from p to each triangle (a[i], b[i], c[i]): to its plane where the foot falls
    inside it, else to the nearest of its edges."""
    def seg(x, y):
        e = y - x
        t = np.clip(np.einsum("ij,ij->i", p - x, e) / np.einsum("ij,ij->i", e, e), 0, 1)
        return np.linalg.norm(p - (x + t[:, None] * e), axis=1)
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    t = np.einsum("ij,ij->i", p - a, n) / nn
    q = p - t[:, None] * n
    u = np.einsum("ij,ij->i", np.cross(c - b, q - b), n) / nn
    v = np.einsum("ij,ij->i", np.cross(a - c, q - c), n) / nn
    inside = (u >= 0) & (v >= 0) & (1 - u - v >= 0)
    return np.where(inside, np.abs(t) * np.sqrt(nn),
                    np.minimum(np.minimum(seg(a, b), seg(b, c)), seg(c, a)))


def nearest_cell(x, tets, p):
    """The lowest-numbered of the cells nearest to p (outside all of them), by brute force: a
    cell's distance is its nearest face's; cells within 1e-12 of their longest edge of the least
    are equally near (docs/SERVICE.md "Embedded models": they share the nearest point, computed
    through different faces)."""
    P = x[tets]
    # only the cells whose box is no farther than the nearest corner of any cell can be nearest
    box = np.linalg.norm(np.maximum(np.maximum(P.min(axis=1) - p, p - P.max(axis=1)), 0), axis=1)
    cand = np.flatnonzero(box <= np.linalg.norm(P[:, 0] - p, axis=1).min() * (1 + 1e-9))
    P = P[cand]
    d = np.full(len(cand), np.inf)
    for skip in range(4):
        a, b, c = (P[:, k] for k in range(4) if k != skip)
        d = np.minimum(d, tri_dist(p, a, b, c))
    longest = np.max([np.linalg.norm(P[:, i] - P[:, j], axis=1)
                      for i in range(4) for j in range(i + 1, 4)], axis=0)
    return int(cand[np.flatnonzero(d <= d.min() + 1e-12 * longest)[0]])


def icosphere_shell(k, r0=1.0, r1=1.2):
    """A hollow sphere: the triangles of an icosahedron split k times, on radii r0 and r1, each
    pair a prism of 3 tetrahedra (diagonals from the lowest vertex, so neighbours agree)."""
    v, f = icosphere(k)
    v, n = np.array(v), len(v)
    tets = []
    for tri in f:
        i, j, l = sorted(tri)
        tets += [[i, j, l, l + n], [i, j, j + n, l + n], [i, i + n, j + n, l + n]]
    return {"vertices": np.vstack([v * r0, v * r1]).tolist(), "simplices": tets}


def test_nearest_far_from_a_curved_solid_and_its_bounded_search(daemon):
    """Far outside a curved solid of ~70 000 cells (level 2 of 216 bent cubes), straight above
    it or off the axes, each vertex is bound to the nearest cell, the lowest-numbered among equals,
    found here by brute force; after an edit each equals the extrapolation of that cell. The
    search is bounded: vertices that thousands of cells are about equally near (the centre of a
    hollow sphere) are a 422 naming the first one past the budget, in seconds, not a bind of
    hours; one of them alone binds, to its nearest cell."""
    t, big, x, tets = bent(daemon, cubes(6, 6, 6), 0.15, 9, 2)
    assert len(tets) > 60000
    rnd = np.random.default_rng(3)
    far = np.column_stack([rnd.uniform(0, 6, 1000), rnd.uniform(0, 6, 1000),
                           1e4 + rnd.uniform(0, 1, 1000)])
    off = np.random.default_rng(4).normal(size=(64, 3)) * 1e4 + 3
    near = np.column_stack([rnd.uniform(-0.5, 6.5, 200), rnd.uniform(-0.5, 6.5, 200),
                            rnd.choice([-0.4, 6.4], 200)])
    pts = np.vstack([far, off, near])
    r = t.req("PUT", "/embedded/far", json={"vertices": pts.tolist(), "level": 2,
                                            "outside": "nearest"})
    assert r.status_code == 200, r.text
    assert r.json()["embedded"]["outside_vertices"] == len(pts)
    assert r.json()["embedded"]["seconds"] < 5, r.json()
    edit(t, [{"index": i, "position": [a + 0.1 * b * b, b + 0.05 * a, c * (1 + 0.1 * a)]}
             for i, (a, b, c) in enumerate(big["vertices"])], r.json()["version"])
    moved, _ = level_cells(t, 2)
    got = deformed(t, "far")
    check = list(range(0, 1000, 50)) + list(range(1000, 1064, 4)) + list(range(1064, 1264, 10))
    for i in check:
        c = nearest_cell(x, tets, pts[i])
        P = x[tets[c]]
        lam = np.linalg.solve(np.vstack([P.T, np.ones(4)]), np.append(pts[i], 1.0))
        want = lam @ moved[tets[c]]
        assert np.abs(got[i] - want).max() <= 1e-9 * np.abs(want).max(), (i, c, got[i], want)

    shell = icosphere_shell(4)                         # 15 360 tetrahedra
    h = Session(daemon)
    assert h.put_complex(shell).status_code == 200
    centre = np.random.default_rng(6).normal(size=(1000, 3)) * 1e-3
    r = h.req("PUT", "/embedded/c", json={"vertices": centre.tolist(), "level": 0,
                                          "outside": "nearest"})
    assert r.status_code == 422, r.text
    j = r.json()
    assert j["type"].endswith("/outside") and j["errors"][0]["pointer"] == "/outside", j
    assert "budget" in j["detail"] and "\"fixed\"" in j["detail"], j
    assert h.req("GET", "/embedded/c").status_code == 404
    r = h.req("PUT", "/embedded/c", json={"vertices": centre.tolist(), "level": 0,
                                          "outside": "fixed"})
    assert r.status_code == 200, r.text
    one = [0.013, -0.007, 0.004]
    r = h.req("PUT", "/embedded/one", json={"vertices": [one], "level": 0, "outside": "nearest"})
    assert r.status_code == 200, r.text
    xs, ts = np.array(shell["vertices"]), np.array(shell["simplices"])
    x0, t0 = level_cells(h, 0)
    assert np.array_equal(x0, xs) and sorted(map(sorted, t0.tolist())) == sorted(
        map(sorted, ts.tolist()))
    c = nearest_cell(x0, t0, np.array(one))
    mv = [{"index": i, "position": [a * (1 + 0.2 * b), b + 0.1 * a * c, c]}
          for i, (a, b, c) in enumerate(shell["vertices"])]
    edit(h, mv, r.json()["version"])
    moved, _ = level_cells(h, 0)
    P = x0[t0[c]]
    lam = np.linalg.solve(np.vstack([P.T, np.ones(4)]), np.append(one, 1.0))
    assert np.abs(deformed(h, "one")[0] - lam @ moved[t0[c]]).max() <= 1e-9


def test_nearest_ties_go_to_the_lowest_cell(daemon):
    """A vertex outside whose nearest point is on a boundary edge is equally near every cell with
    that edge: it goes to the lowest-numbered of them (docs: "the lowest index among equals"),
    whichever face of which cell its distance was computed through. Bent block, level 1: vertices
    0.05 off the middle of each convex boundary edge, along the bisector of the two faces'
    normals and along each normal (the sides of the edge's wedge: there the nearest point is
    reached through a face's interior for one cell and through the edge for another, the same
    distance but for rounding); after an edit each equals the extrapolation of the lowest cell holding that
    middle, found here (cells numbered as the level's JSON gives them: tetrahedra, then each
    octahedron's 4 around its major diagonal)."""
    import itertools
    s, blk, x, tets = bent(daemon, cubes(2, 2, 1), 0.08, 11, 1)
    faces = {}
    for c, t in enumerate(tets):
        for i in range(4):
            faces.setdefault(tuple(sorted(t[j] for j in range(4) if j != i)), []).append(t[i])
    boundary = {f: o[0] for f, o in faces.items() if len(o) == 1}

    def outward(f, opposite):
        a, b, c = x[list(f)]
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        return -n if np.dot(n, x[opposite] - a) > 0 else n
    edges = {}
    for f, o in boundary.items():
        for e in itertools.combinations(f, 2):
            edges.setdefault(e, []).append((f, o))
    mids, pts = [], []
    for e, ((f1, o1), (f2, o2)) in ((e, fo) for e, fo in edges.items() if len(fo) == 2):
        n1, n2 = outward(f1, o1), outward(f2, o2)
        w = next(v for v in f2 if v not in e)
        if np.dot(x[w] - x[e[0]], n1) >= -1e-9 or np.dot(n1, n2) > 0.999:
            continue                                   # flat or concave: no unique nearest edge
        m = (x[e[0]] + x[e[1]]) / 2
        for n in (n1 + n2, n1, n2):    # inside the edge's wedge, and on either side of it
            mids.append(m)
            pts.append(m + 0.05 * n / np.linalg.norm(n))
    assert len(pts) > 300
    r = s.req("PUT", "/embedded/n", json={"vertices": np.array(pts).tolist(), "level": 1,
                                          "outside": "nearest"})
    assert r.status_code == 200, r.text
    edit(s, [{"index": i, "position": [a + 0.1 * b * b, b + 0.05 * a, c * (1 + 0.1 * a)]}
             for i, (a, b, c) in enumerate(blk["vertices"])], r.json()["version"])
    moved, _ = level_cells(s, 1)
    want = []
    for m, p in zip(mids, pts):
        c, _ = locate(x, tets, m)                      # the lowest cell with the edge's middle
        P = x[tets[c]]
        lam = np.linalg.solve(np.vstack([P.T, np.ones(4)]), np.append(p, 1.0))
        want.append(lam @ moved[tets[c]])
    off = np.abs(deformed(s, "n") - np.array(want)).max(axis=1)
    assert (off <= 1e-9).all(), f"{(off > 1e-9).sum()} of {len(off)} bound to another cell"


def test_formats_list_delete_and_errors(daemon, tmp_path):
    pts = model_points(30)
    tris = [[i, i + 1, i + 2] for i in range(0, 27, 3)]
    s, v = session_with_model(daemon, pts, triangles=tris)
    j = s.req("GET", "/embedded/m").json()
    assert j["name"] == "m" and j["level"] == 2 and j["triangles"] == tris
    obj = s.req("GET", "/embedded/m", params={"format": "obj"}).text
    assert obj.count("\nv ") == 30 and obj.count("\nf ") == 9
    glb = s.req("GET", "/embedded/m", params={"format": "glb"})
    assert glb.headers["Content-Type"] == "model/gltf-binary" and glb.content[:4] == b"glTF"
    (tmp_path / "m.glb").write_bytes(glb.content)
    import subprocess
    from conftest import REPO
    out = subprocess.run(["node", str(REPO / "tests" / "tools" / "gltf_validate.js"),
                          str(tmp_path / "m.glb")], capture_output=True, text=True)
    assert out.returncode == 0 and "0 errors, 0 warnings" in out.stdout, out.stdout + out.stderr
    lst = s.req("GET", "/embedded").json()["embedded"]
    assert [e["name"] for e in lst] == ["m"] and lst[0]["vertices"] == 30
    # binary upload
    blob = struct.pack("<II", 3, 1) + struct.pack("<9d", *sum(pts[:3], [])) + struct.pack("<3I", 0, 1, 2)
    r = s.req("PUT", "/embedded/bin", data=blob, params={"level": 1},
              headers={"Content-Type": "application/octet-stream"})
    assert r.status_code == 200, r.text
    assert s.req("GET", "/embedded/bin").json()["vertices"] == pts[:3]
    bad = s.req("PUT", "/embedded/bin", data=blob[:-2], headers={"Content-Type": "application/octet-stream"})
    assert bad.status_code == 400
    # a triangle naming a vertex twice, as in the binary layout, is refused as in JSON below
    rep = blob[:-12] + struct.pack("<3I", 0, 1, 1)
    bad = s.req("PUT", "/embedded/bin", data=rep, headers={"Content-Type": "application/octet-stream"})
    assert bad.status_code == 422 and bad.json()["errors"][0]["pointer"] == "/triangles/0/2", bad.text
    # the query's level as GET /levels reads one: not a number 400 bad-level, past 12 a 422
    for lv, status, slug in (("x", 400, "bad-level"), ("2x", 400, "bad-level"),
                             ("13", 422, "level-out-of-range")):
        bad = s.req("PUT", "/embedded/bin", data=blob, params={"level": lv},
                    headers={"Content-Type": "application/octet-stream"})
        assert bad.status_code == status and bad.json()["type"] == "/errors/" + slug, bad.text
        assert bad.json()["errors"][0]["pointer"] == "level", bad.text
    for body, status, ptr in [({"vertices": [[0, 0]]}, 400, "/vertices/0"),
                              ({"vertices": pts, "triangles": [[0, 1, 99]]}, 422, "/triangles/0/2"),
                              # a vertex twice, a triangle twice (any order): as for simplices
                              ({"vertices": pts, "triangles": [[0, 0, 1]]}, 422, "/triangles/0/1"),
                              ({"vertices": pts, "triangles": [[0, 1, 2], [3, 4, 5], [2, 1, 0]]},
                               422, "/triangles/2"),
                              ({"vertices": pts, "level": 99}, 422, "/level"),
                              ({"vertices": pts, "outside": "ignore"}, 422, "/outside"),
                              ({"vertices": pts, "colour": 1}, 400, "/colour")]:
        r = s.req("PUT", "/embedded/x", json=body)
        assert r.status_code == status, (body, r.text)
        assert r.json()["errors"][0]["pointer"] == ptr, r.text
    assert s.req("PUT", "/embedded/bad%20name", json={"vertices": pts}).status_code == 400
    assert s.req("DELETE", "/embedded/m").status_code == 204
    assert s.req("GET", "/embedded/m").status_code == 404
    assert s.req("DELETE", "/embedded/m").status_code == 404
    e = Session(daemon)   # no complex yet
    assert e.req("PUT", "/embedded/m", json={"vertices": pts}).status_code == 409


def test_changes_rebind_the_rest_shape_all_or_nothing(daemon):
    pts = model_points(50)
    s, v = session_with_model(daemon, pts)
    v = edit(s, [{"index": 0, "position": [0.05, 0.0, 0.0]}], v)
    assert np.abs(deformed(s) - np.array(pts)).max() > 0        # it followed the edit
    r = s.req("PUT", "/tags", json={"singular": [[0, 1]]})      # a new model: bound anew
    assert r.status_code == 200, r.text
    assert np.abs(deformed(s) - np.array(pts)).max() <= 1e-12
    v = edit(s, [{"index": 0, "position": [0.05, 0.0, 0.0]}], r.json()["version"])
    r = s.req("POST", "/refine", json={"select": {"simplices": [BLOCK["simplices"][4]]}, "depth": 1,
                                       "positions": "midpoint"})    # a new complex: bound anew
    assert r.status_code == 200, r.text
    assert np.abs(deformed(s) - np.array(pts)).max() <= 1e-12
    n = len(s.req("GET", "/complex").json()["vertices"])
    # a complex the model does not fit in: the change is refused, naming the model
    small = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 2, 3]]}
    r = s.put_complex(small)
    assert r.status_code == 422 and '"m"' in r.json()["detail"], r.text
    assert len(s.req("GET", "/complex").json()["vertices"]) == n


def test_export_import_and_restart_keep_embedded_models(daemon, tmp_path):
    """The binding travels with the document: after edits made since the binding, the
    imported (and the restarted) session's model is the same bit for bit — re-binding the rest
    shape to the edited level would not be."""
    pts = model_points(40)
    s, v = session_with_model(daemon, pts, outside="fixed")
    v = edit(s, [{"index": 4, "position": [1.1, 0.9, 0.2]}], v)
    ex = s.req("GET", "/export").json()
    assert len(ex["embedded"]["m"]["binding"]) == 40
    assert list(ex["embedded"]) == ["m"]
    r = requests.post(daemon.url + "/v1/sessions", json={"import": ex})
    assert r.status_code == 201, r.text
    t = adopt(daemon, requests.Session(), r.json())
    assert np.array_equal(deformed(t), deformed(s))
    db = tmp_path / "e.db"
    d = store_daemon(db)
    try:
        u, v = session_with_model(d, pts)
        edit(u, [{"index": 4, "position": [1.1, 0.9, 0.2]}], v)
        before = deformed(u)
    finally:
        d.proc.kill()
        d.proc.wait()
    d = store_daemon(db)
    try:
        assert np.array_equal(deformed(on(d, u)), before)
    finally:
        d.stop()


def test_far_nearest_vertices_survive_export_and_import(daemon):
    """A "nearest" vertex as far as coordinates go (1e15) from level-2 cells of edge ~0.3 has
    weights ~1e16: the export is imported as it is (the weights were read with the coordinates'
    bound of 1e15: a 422, and a stored session could not be rebuilt after a restart, 503), and
    the import keeps the count of vertices outside (3 here, by construction; it counted the
    fixed ones: 0)."""
    pts = model_points(5) + [[1e15, 1e15, 1e15], [-1e14, 1, 0.5], [1, 1, 3]]
    s, v = session_with_model(daemon, pts, outside="nearest")
    edit(s, [{"index": 4, "position": [1.1, 0.9, 0.2]}], v)
    ex = s.req("GET", "/export").json()
    assert np.abs(ex["embedded"]["m"]["binding"][5][4:]).max() > 1e15
    r = requests.post(daemon.url + "/v1/sessions", json={"import": ex})
    assert r.status_code == 201, r.text
    t = adopt(daemon, requests.Session(), r.json())
    assert np.array_equal(deformed(t), deformed(s))
    assert t.req("GET", "/embedded").json()["embedded"][0]["outside_vertices"] == 3


def test_python_client(daemon):
    import sys
    from conftest import REPO
    sys.path.insert(0, str(REPO / "clients" / "python"))
    import subdiv
    c = subdiv.Client(daemon.url)
    with c.create_session() as s:
        s.put_complex(BLOCK)
        pts = model_points(25)
        j = s.put_embedded("m", pts, [[0, 1, 2]])
        assert j["embedded"]["vertices"] == 25
        assert s.put_embedded("b", pts[:5], binary=True)["embedded"]["vertices"] == 5
        assert [e["name"] for e in s.embedded()] == ["m", "b"]
        assert np.abs(np.array(s.get_embedded("m")["vertices"]) - pts).max() <= 1e-12
        v = s.version
        s.edit(moves=[{"index": 4, "position": [1.05, 0.95, 0.1]}])
        d = s.embedded_delta("m", v, format="json")
        assert d["version"] == s.version and len(d["indices"])
        full = np.array(s.get_embedded("m")["vertices"])
        assert np.array_equal(d["positions"], full[d["indices"]])
        b = s.embedded_delta("m", v)
        assert b["indices"].tolist() == d["indices"].tolist()
        assert s.get_embedded("m", "glb")[:4] == b"glTF" and s.get_embedded("m", "obj").startswith("#")
        s.delete_embedded("b")
        assert [e["name"] for e in s.embedded()] == ["m"]


def test_offline_deform_equals_the_daemon(daemon, tmp_path):
    """`subdivd deform` (examples/ffd) writes what the daemon answers for the same requests."""
    import json
    import subprocess
    from conftest import REPO
    from daemon import SUBDIVD
    ex = REPO / "examples" / "ffd"
    out = tmp_path / "t.json"
    r = subprocess.run([str(SUBDIVD), "deform", str(ex / "block.json"), "--embed", str(ex / "torus.obj"),
                        "--level", "2", "--moves", str(ex / "moves.json"), "-o", str(out)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    offline = json.loads(out.read_text())
    s = Session(daemon)
    v = s.put_complex(json.loads((ex / "block.json").read_text())).json()["version"]
    verts, tris = [], []
    for line in (ex / "torus.obj").read_text().splitlines():
        t = line.split()
        if t and t[0] == "v":
            verts.append([float(x) for x in t[1:4]])
        elif t and t[0] == "f":
            q = [int(x) - 1 for x in t[1:]]
            tris += [[q[0], q[k], q[k + 1]] for k in range(1, len(q) - 1)]
    r = s.req("PUT", "/embedded/model", json={"vertices": verts, "triangles": tris, "level": 2})
    assert r.status_code == 200, r.text
    edit(s, json.loads((ex / "moves.json").read_text())["moves"], r.json()["version"])
    online = s.req("GET", "/embedded/model").json()
    assert offline["vertices"] == online["vertices"] and offline["triangles"] == online["triangles"]
    assert np.abs(np.array(online["vertices"]) - np.array(verts)).max() > 0.01   # it moved
    # and `subdiv deform` (the Python client's command) through the daemon: the same vertices
    import os
    import sys
    cli = tmp_path / "cli.json"
    env = dict(os.environ, PYTHONPATH=str(REPO / "clients" / "python"))
    r = subprocess.run([sys.executable, "-m", "subdiv", "deform", str(ex / "block.json"), "--embed",
                        str(ex / "torus.obj"), "--moves", str(ex / "moves.json"), "-o", str(cli),
                        "--url", daemon.url, "-q"], capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr
    assert json.loads(cli.read_text())["vertices"] == offline["vertices"]


def test_offline_deform_reads_obj_records_exactly(tmp_path):
    """`subdivd deform`'s OBJ reader keeps every vertex in place or refuses the file with its
    line (and --level is a level or a refusal): tab-separated and indented records, comments after a face, "i/t/n" and negative
    indices, polygons as fans (OBJ); a non-finite coordinate, a non-numeric or missing index is
    refused (a vertex silently left out would shift every later index)."""
    import json
    import subprocess
    from daemon import SUBDIVD
    cx = tmp_path / "block.json"
    cx.write_text(json.dumps(BLOCK))
    pts = model_points(5, seed=4)

    def run(text):
        obj, out = tmp_path / "m.obj", tmp_path / "m.json"
        obj.write_text(text)
        out.unlink(missing_ok=True)
        r = subprocess.run([str(SUBDIVD), "deform", str(cx), "--embed", str(obj), "--level", "2",
                            "-o", str(out)], capture_output=True, text=True, timeout=60)
        return r, (json.loads(out.read_text()) if r.returncode == 0 else None)
    v = ["%r %r %r" % tuple(p) for p in pts]
    r, got = run(f"v {v[0]}\nv\t{v[1]}\n  v {v[2]} 1.0\nv {v[3]}\r\nv {v[4]}\n"
                 "vn 0 0 1\nf 1/1/1 2//1 -3 # a comment\nf\t1 2 4 5\n")
    assert r.returncode == 0, r.stderr
    assert np.abs(np.array(got["vertices"]) - np.array(pts)).max() <= 1e-12
    assert got["triangles"] == [[0, 1, 2], [0, 1, 3], [0, 3, 4]]
    for text, why in ((f"v {v[0]}\nv 0.5 nan 0.5\nv {v[2]}\n", "m.obj:2: coordinate 2"),
                      (f"v {v[0]}\nv 0.5 0.5 1e400\n", "m.obj:2: coordinate 3"),
                      (f"v {v[0]}\nv {v[1]}\nv {v[2]}\nf 1 2\n", "m.obj:4: a face needs"),
                      (f"v {v[0]}\nv {v[1]}\nv {v[2]}\nf 1 2 x\n", "m.obj:4: \"x\" is not"),
                      (f"v {v[0]}\nv 0.5 0.5 0.5q\n", "m.obj:2: a vertex is")):
        r, _ = run(text)
        assert r.returncode == 2 and why in r.stderr, (text, r.returncode, r.stderr)
    # --level is read as `subdivd refine` reads it (it was strtol: "abc" bound to level 0)
    (tmp_path / "m.obj").write_text(f"v {v[0]}\n")
    for lv, why in (("abc", "bad-level"), ("2x", "bad-level"), ("13", "level-out-of-range")):
        r = subprocess.run([str(SUBDIVD), "deform", str(cx), "--embed", str(tmp_path / "m.obj"),
                            "--level", lv, "-o", str(tmp_path / "l.json")], capture_output=True,
                           text=True, timeout=60)
        assert r.returncode == 1 and why in r.stderr and not (tmp_path / "l.json").exists(), r.stderr


def test_models_count_against_the_session_memory_limit():
    d = Daemon("--max-session-bytes", str(4 << 20))
    try:
        s = Session(d)
        assert s.put_complex(BLOCK).status_code == 200
        pts = model_points(100000)
        blob = struct.pack("<II", len(pts), 0) + np.asarray(pts, dtype="<f8").tobytes()
        r = s.req("PUT", "/embedded/big", data=blob, headers={"Content-Type": "application/octet-stream"})
        assert r.status_code == 413 and r.json()["limit_name"] == "max_session_bytes", r.text
        assert s.req("GET", "/embedded").json()["embedded"] == []
        small = s.req("PUT", "/embedded/small", json={"vertices": model_points(100)})
        assert small.status_code == 200, small.text
    finally:
        d.stop()


def test_an_import_with_a_model_and_no_complex_is_refused(daemon):
    doc = {"format": "subdivd-session", "format_version": 1, "version": 1, "complex": None,
           "embedded": {"a": {"vertices": [[0, 0, 0]], "binding": [None]}}}
    r = requests.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 409, r.text
    del doc["embedded"]["a"]["binding"]
    assert requests.post(daemon.url + "/v1/sessions", json={"import": doc}).status_code == 409
    assert requests.get(daemon.url + "/healthz").status_code == 200


def test_an_import_with_a_damaged_binding_names_the_entry(daemon):
    """A saved binding is checked against its level: a level point the level does not have, or
    weights that do not add up to 1, is a 422 out-of-range at that entry of the document (it was
    `outside`, the refusal of vertices outside every solid cell, at the whole binding). A model's
    name goes into the pointers escaped (RFC 6901) and whole (it was cut at 48 characters)."""
    s, _ = session_with_model(daemon, model_points(5))
    ex = s.req("GET", "/export").json()

    def refused(doc):
        r = requests.post(daemon.url + "/v1/sessions", json={"import": doc})
        assert r.status_code == 422 and r.headers["Content-Type"] == "application/problem+json", r.text
        j = r.json()
        return j["type"], j["errors"][0]["pointer"], j["detail"]

    doc = json.loads(json.dumps(ex))
    doc["embedded"]["m"]["binding"][3][2] = 1000000
    t, ptr, detail = refused(doc)
    assert (t, ptr) == ("/errors/out-of-range", "/import/embedded/m/binding/3/2"), detail
    assert "1000000" in detail
    doc = json.loads(json.dumps(ex))
    doc["embedded"]["m"]["binding"][1][4:8] = [1, 1, 1, 1]
    t, ptr, detail = refused(doc)
    assert (t, ptr) == ("/errors/out-of-range", "/import/embedded/m/binding/1"), detail
    assert "add up to 4" in detail
    for name, escaped in (("a/b~c", "a~1b~0c"), ("n" * 64, "n" * 64)):
        doc = json.loads(json.dumps(ex))
        doc["embedded"][name] = doc["embedded"].pop("m")
        t, ptr, _ = refused(doc)
        assert (t, ptr) == ("/errors/invalid-name", "/import/embedded/" + escaped)
    assert requests.post(daemon.url + "/v1/sessions", json={"import": ex}).status_code == 201


def test_a_models_delta_refuses_parameters_it_does_not_take(daemon):
    """GET /embedded/{name}/delta takes since and format (docs/API.md, the OpenAPI document); a
    model has no attributes, and attributes= was taken and ignored, whatever it named."""
    s, v = session_with_model(daemon, model_points(5))
    assert s.req("GET", "/embedded/m/delta", params={"since": v}).status_code == 200
    for q in ({"attributes": "nope"}, {"attributes": ""}, {"parts": "solids"}):
        r = s.req("GET", "/embedded/m/delta", params=dict({"since": v}, **q))
        assert r.status_code == 400 and r.json()["type"] == "/errors/unknown-parameter", r.text
        assert r.json()["errors"][0]["pointer"] == next(iter(q))


def test_a_second_model_keeps_the_first_ones_delta(daemon):
    """PUT of another model is a new version, not a change of the level: deltas since before it
    are still answered."""
    pts = model_points(30)
    s, v = session_with_model(daemon, pts)
    r = s.req("PUT", "/embedded/other", json={"vertices": model_points(5, seed=9)})
    assert r.status_code == 200, r.text
    v2 = edit(s, [{"index": 4, "position": [1.05, 0.95, 0.1]}], r.json()["version"])
    d = s.req("GET", "/embedded/m/delta", params={"since": v, "format": "json"})
    assert d.status_code == 200, d.text
    assert d.json()["version"] == v2
    assert s.level(2, format="json").status_code == 200
    assert s.req("GET", "/levels/2/delta", params={"since": v}).status_code == 200


def test_an_edit_that_builds_rules_again_keeps_the_models_where_they_are(daemon):
    """Ying-Zorin fins beside the block: moving a fin point builds the rules again (a new model of
    the same topology); the embedded model is carried with its binding, not bound anew from its
    rest shape — it stays where the earlier edits put it, and keeps following."""
    V = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2],
         [-.5, .8, 0], [-.5, .8, 1], [-.5, .8, 2], [-.5, -.8, 0], [-.5, -.8, 1], [-.5, -.8, 2]]
    T = []
    for a in (3, 6, 9):
        T += [[0, 1, a + 1], [0, a + 1, a], [1, 2, a + 2], [1, a + 2, a + 1]]
    off = len(V)
    body = {"vertices": V + [[x + 10, y, z] for x, y, z in BLOCK["vertices"]],
            "simplices": T + [[i + off for i in t] for t in BLOCK["simplices"]]}
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    assert s.req("PUT", "/rules", json={"nonmanifold_surface": "ying-zorin"}).status_code == 200
    assert s.req("PUT", "/tags", json={"petals": [{"vertex": 0, "triangle": [0, 4, 3],
                                                   "kind": "convex"}]}).status_code == 200
    pts = (np.array(model_points(40)) + [10, 0, 0]).tolist()
    r = s.req("PUT", "/embedded/m", json={"vertices": pts})
    assert r.status_code == 200, r.text
    c = off + BLOCK["vertices"].index([1.0, 1.0, 1.0])       # the top face's middle point
    v = edit(s, [{"index": c, "position": [11.1, 0.9, 1.2]}], r.json()["version"])
    moved = deformed(s)
    assert np.abs(moved - np.array(pts)).max() > 1e-3
    v = edit(s, [{"index": 3, "position": [1.2, 0.7, -0.1]}], v)   # rules built again
    assert s.req("GET", "/levels/2/delta", params={"since": v - 1}).status_code == 410  # a new model
    assert np.array_equal(deformed(s), moved)
    edit(s, [{"index": c, "position": [11.0, 1.0, 1.0]}], v)   # back where it was posted
    assert np.abs(deformed(s) - np.array(pts)).max() <= 1e-12
    # a "nearest" model's count of vertices outside is carried too (it was recounted as the
    # fixed ones: 0)
    r = s.req("PUT", "/embedded/n", json={"vertices": pts[:3] + [[11, 1, 5]], "outside": "nearest"})
    assert r.status_code == 200 and r.json()["embedded"]["outside_vertices"] == 1, r.text
    edit(s, [{"index": 3, "position": [1.0, 0.0, 0.0]}], r.json()["version"])  # rules built again
    assert [e["outside_vertices"] for e in s.req("GET", "/embedded").json()["embedded"]] == [0, 1]


def test_level_glb_with_parts_embedded(daemon, tmp_path):
    """GET /levels/L?parts=…,embedded: each embedded model as its own node and mesh
    "embedded/<name>" (its own POSITION, u32 indices, points drawn as points) after the level's
    parts, with the positions GET /embedded/{name} gives (as float32) after an edit; the level's
    parts unchanged; parts=embedded alone holds the models only; not without it; glb and gltf only."""
    from test_outputs import accessor_reader, split_glb, validate
    pts = model_points(30)
    tris = [[i, i + 1, i + 2] for i in range(0, 27, 3)]
    s, v = session_with_model(daemon, pts, triangles=tris)
    r = s.req("PUT", "/embedded/cloud", json={"vertices": model_points(7, seed=3), "level": 1})
    assert r.status_code == 200, r.text
    edit(s, [{"index": 4, "position": [1.2, 0.9, 1.4]}], r.json()["version"])
    want = {n: (np.array(s.req("GET", f"/embedded/{n}").json()["vertices"], dtype=np.float32), t)
            for n, t in (("m", tris), ("cloud", None))}
    assert not np.allclose(want["m"][0], np.array(pts, dtype=np.float32))   # the edit moved it
    plain = s.level(2, parts="surfaces,solids").content
    for parts, level_nodes in (("surfaces,solids,embedded", ["solids"]), ("embedded", [])):
        glb = s.level(2, parts=parts)
        assert glb.status_code == 200, glb.text
        (tmp_path / "l.glb").write_bytes(glb.content)
        validate(tmp_path / "l.glb")
        doc, bin_ = split_glb(glb.content)
        acc = accessor_reader(doc, bin_)
        root = doc["nodes"][0]
        names = [doc["nodes"][i]["name"] for i in root["children"]]
        assert names == level_nodes + ["embedded/m", "embedded/cloud"]
        for i in root["children"]:
            node = doc["nodes"][i]
            mesh = doc["meshes"][node["mesh"]]
            assert mesh["name"] == node["name"] and len(mesh["primitives"]) == 1
            prim = mesh["primitives"][0]
            if not node["name"].startswith("embedded/"):
                continue
            x, t = want[node["name"][len("embedded/"):]]
            assert np.array_equal(acc(prim["attributes"]["POSITION"]), x)
            if t is None:
                assert prim["mode"] == 0 and "indices" not in prim
            else:
                assert prim["mode"] == 4
                assert acc(prim["indices"]).reshape(-1, 3).tolist() == t
        if level_nodes:   # the level's own part is what the GLB without models holds
            pd, pb = split_glb(plain)
            pacc = accessor_reader(pd, pb)
            sol = doc["meshes"][doc["nodes"][root["children"][0]]["mesh"]]["primitives"][0]
            psol = pd["meshes"][pd["nodes"][pd["nodes"][0]["children"][0]]["mesh"]]["primitives"][0]
            for key in ("POSITION", "NORMAL"):
                assert np.array_equal(acc(sol["attributes"][key]), pacc(psol["attributes"][key]))
            assert np.array_equal(acc(sol["indices"]), pacc(psol["indices"]))
        else:             # nothing of the level: only the models' accessors
            assert len(doc["accessors"]) == 3
    gltf = s.level(2, format="gltf", parts="embedded")
    assert gltf.status_code == 200 and [n["name"] for n in gltf.json()["nodes"]][1:] == \
        ["embedded/m", "embedded/cloud"]
    default = s.level(2)
    assert b"embedded/" not in default.content[:default.content.index(b"BIN\x00")]
    for fmt in ("vtu", "vtk", "json"):
        r = s.level(2, format=fmt, parts="solids,embedded")
        assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "parts", r.text
    r = s.level(2, parts="solids,embedded,models")
    assert r.status_code == 422 and "embedded" in r.json()["detail"]
    r = s.level(2, parts="solids,embedded,embedded")
    assert r.status_code == 422 and r.json()["type"].endswith("/repeated-part"), r.text
    # a level delta with embedded in parts= is that of the level's parts named; embedded alone
    # names none of them (a model's delta is its own)
    since = v
    d1 = s.req("GET", "/levels/2/delta", params={"since": since, "format": "json", "parts": "solids"})
    d2 = s.req("GET", "/levels/2/delta", params={"since": since, "format": "json",
                                                 "parts": "solids,embedded"})
    assert d1.status_code == 200 and d1.json()["indices"] and d1.content == d2.content
    r = s.req("GET", "/levels/2/delta", params={"since": since, "parts": "embedded"})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "parts", r.text


def test_a_model_past_the_eighth_is_refused_before_it_is_bound(daemon):
    """A session holds 8 models: a ninth name is refused (422 at the path parameter `name`)
    before the model is bound, so no level is computed for it and a big one costs no binding
    (a ninth of 1 M vertices at level 3 was bound — level 3 computed, seconds of a compute slot,
    hundreds of MB — and only then refused). Replacing one of the 8 is still a change."""
    s = Session(daemon)
    assert s.put_complex(BLOCK).status_code == 200
    for i in range(8):
        r = s.req("PUT", f"/embedded/m{i}", json={"vertices": model_points(4, seed=i), "level": 1})
        assert r.status_code == 200, r.text
    before = s.req("GET", "").json()
    pts = np.array(model_points(1_000_000, seed=9))
    blob = struct.pack("<II", len(pts), 0) + pts.astype("<f8").tobytes()
    t0 = time.time()
    r = s.req("PUT", "/embedded/ninth", data=blob, params={"level": 3, "outside": "fixed"},
              headers={"Content-Type": "application/octet-stream"})
    took = time.time() - t0
    assert r.status_code == 422 and r.json()["type"] == "/errors/too-many-entries", r.text
    assert r.json()["errors"][0]["pointer"] == "name", r.text
    after = s.req("GET", "").json()
    assert after["version"] == before["version"]
    assert after["levels_cached"] == before["levels_cached"], (before, after)
    assert took < 1.0, took
    r = s.req("PUT", "/embedded/m3", json={"vertices": model_points(5, seed=3), "level": 1})
    assert r.status_code == 200 and r.json()["version"] == before["version"] + 1, r.text


def test_level_parts_embedded_without_models_validates(daemon, tmp_path):
    """parts=embedded on a session without embedded models has nothing to store: the file has
    no buffer, buffer views or accessors (glTF 2.0 forbids empty arrays and a zero byteLength;
    the Khronos validator reports EMPTY_ENTITY and VALUE_NOT_IN_RANGE for them), no BIN chunk,
    and validates (docs/OUTPUTS.md: "the file still validates")."""
    from test_outputs import validate
    s = Session(daemon)
    assert s.put_complex(BLOCK).status_code == 200
    for fmt in ("glb", "gltf"):
        r = s.level(1, format=fmt, parts="embedded")
        assert r.status_code == 200, r.text
        assert int(r.headers["Content-Length"]) == len(r.content)
        f = tmp_path / f"e.{fmt}"
        f.write_bytes(r.content)
        validate(f)
        if fmt == "glb":
            magic, version, length = struct.unpack_from("<III", r.content, 0)
            jlen, _ = struct.unpack_from("<II", r.content, 12)
            assert length == len(r.content) == 20 + jlen   # one chunk: JSON
            doc = json.loads(r.content[20:])
        else:
            doc = r.json()
        assert not {"buffers", "bufferViews", "accessors", "meshes"} & set(doc)
        assert doc["nodes"] == [{"name": "level 1 (empty)"}]
