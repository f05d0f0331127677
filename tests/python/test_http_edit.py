"""PATCH /control-points (docs/API.md "Control-point edits"): edits pushed through the cached matrices equal a full
recomputation from the edited control complex; If-Match is required; a refused edit leaves the
session byte-identical."""
import copy
import random

import numpy as np
import pytest

from conftest import REPO
from daemon import Daemon, Session, complex_from_text

CUBE = REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt"
MIXED = REPO / "examples" / "mixed.txt"


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


def with_attrs(body, seed):
    rnd = random.Random(seed)
    b = copy.deepcopy(body)
    n = len(b["vertices"])
    b["attributes"] = {"t": [rnd.random() for _ in range(n)],
                       "v": [[rnd.random(), rnd.random()] for _ in range(n)]}
    return b


@pytest.mark.parametrize("mesh", [MIXED, CUBE])
def test_random_edits_equal_recomputation(daemon, mesh):
    rnd = random.Random(7)
    body = with_attrs(complex_from_text(mesh), 1)
    s = Session(daemon)
    r = s.put_complex(body)
    assert r.status_code == 200
    etag = r.headers["ETag"]
    for level in range(4):                       # cache levels 0..3
        assert s.level(level, format="json").status_code == 200
    n = len(body["vertices"])
    for rnd_edit in range(4):
        pts = rnd.sample(range(n), min(3, n))
        moves = []
        for i in pts:
            p = [x + rnd.uniform(-0.05, 0.05) for x in body["vertices"][i]]
            body["vertices"][i] = p
            moves.append({"index": i, "position": p})
        j = rnd.randrange(n)
        body["attributes"]["t"][j] = rnd.random()
        body["attributes"]["v"][j] = [rnd.random(), rnd.random()]
        edit = {"moves": moves, "attributes": {
            "t": [{"index": j, "value": body["attributes"]["t"][j]}],
            "v": [{"index": j, "value": body["attributes"]["v"][j]}]}}
        r = s.req("PATCH", "/control-points", json=edit, headers={"If-Match": etag})
        assert r.status_code == 200, r.text
        assert r.headers["ETag"] == f'"{r.json()["version"]}"'
        etag = r.headers["ETag"]
        up = r.json()["updated_points"]
        # per level, the points rewritten in the largest channel: here the 3 moved points
        assert set(up) == {"0", "1", "2", "3"} and up["0"] == len(pts)
    fresh = Session(daemon)
    assert fresh.put_complex(body).status_code == 200
    for level in range(4):
        a = s.level(level, format="json").json()
        b = fresh.level(level, format="json").json()
        np.testing.assert_allclose(a["vertices"], b["vertices"], rtol=0, atol=1e-12)
        for name in ("t", "v"):
            np.testing.assert_allclose(a["attributes"][name], b["attributes"][name], rtol=0, atol=1e-12)
    # GET /complex shows the edited control points
    assert s.req("GET", "/complex").json()["vertices"] == body["vertices"]


def test_if_match_required(daemon):
    s = Session(daemon)
    assert s.put_complex(complex_from_text(MIXED)).status_code == 200
    edit = {"moves": [{"index": 0, "position": [0, 0, 0.1]}]}
    r = s.req("PATCH", "/control-points", json=edit)
    assert r.status_code == 428 and r.headers["Content-Type"] == "application/problem+json"
    r = s.req("PATCH", "/control-points", json=edit, headers={"If-Match": '"5"'})
    assert r.status_code == 412
    r = s.req("PATCH", "/control-points", json=edit, headers={"If-Match": '"1"'})
    assert r.status_code == 200 and r.json()["version"] == 2


@pytest.mark.parametrize("edit,status,pointer", [
    ({"moves": [{"index": 99, "position": [0, 0, 0]}]}, 422, "/moves/0/index"),
    ({"moves": [{"index": 1, "position": [0, 0, 0]}, {"index": 1, "position": [1, 0, 0]}]}, 422, "/moves/1/index"),
    ({"moves": [{"index": 1, "position": [0, 0]}]}, 400, "/moves/0/position"),
    ({"moves": [{"index": 1, "position": [0, 0, "x"]}]}, 400, "/moves/0/position/2"),
    ({"moves": [{"index": 1, "position": [0, 0, 1e300]}]}, 422, "/moves/0/position/2"),
    ({"moves": [{"index": 1}]}, 400, "/moves/0/position"),
    ({"moves": [{"index": 1, "position": [0, 0, 0], "x": 1}]}, 400, "/moves/0/x"),
    ({"moves": {}}, 400, "/moves"),
    ({"attributes": {"nope": [{"index": 1, "value": 1}]}}, 422, "/attributes/nope"),
    ({"attributes": {"t": [{"index": 1, "value": [1, 2]}]}}, 400, "/attributes/t/0/value"),
    ({"moves": [{"index": 0, "position": [0, 0, 0.5]}], "attributes": {"t": [{"index": 2, "value": "hot"}]}}, 400, "/attributes/t/0/value"),
    ({}, 400, None),
    ({"scale": 2}, 400, "/scale"),
])
def test_refused_edit_changes_nothing(daemon, edit, status, pointer):
    s = Session(daemon)
    body = with_attrs(complex_from_text(MIXED), 3)
    assert s.put_complex(body).status_code == 200
    before = (s.req("GET", "/complex").content, s.level(2, format="json").content, s.level(2).content)
    r = s.req("PATCH", "/control-points", json=edit, headers={"If-Match": '"1"'})
    assert r.status_code == status, r.text
    if pointer:
        assert r.json()["errors"][0]["pointer"] == pointer
    assert s.req("GET").json()["version"] == 1
    after = (s.req("GET", "/complex").content, s.level(2, format="json").content, s.level(2).content)
    assert after == before


def test_edit_then_glb_and_rules(daemon, tmp_path):
    import subprocess
    s = Session(daemon)
    body = complex_from_text(CUBE)
    assert s.put_complex(body).status_code == 200
    g0 = s.level(2).content
    r = s.req("PATCH", "/control-points", json={"moves": [{"index": 0, "position": [0.2, 0.3, -0.4]}]},
              headers={"If-Match": '"1"'})
    assert r.status_code == 200
    g1 = s.level(2).content
    assert g1 != g0
    f = tmp_path / "e.glb"
    f.write_bytes(g1)
    v = subprocess.run(["node", str(REPO / "tests" / "tools" / "gltf_validate.js"), str(f)],
                       capture_output=True, text=True)
    assert v.returncode == 0, v.stdout
    # a later rule change rebuilds from the edited control points
    assert s.req("PUT", "/rules", json={"solid_scheme": "averaged"}).status_code == 200
    body["vertices"][0] = [0.2, 0.3, -0.4]
    fresh = Session(daemon)
    assert fresh.req("PUT", "/rules", json={"solid_scheme": "averaged"}).status_code == 200
    assert fresh.put_complex(body).status_code == 200
    np.testing.assert_allclose(s.level(1, format="json").json()["vertices"],
                               fresh.level(1, format="json").json()["vertices"], atol=1e-12)


def test_a_move_that_grows_the_box_keeps_the_complex_importable(daemon):
    """The degeneracy test of PUT /complex (and so of an import and of a stored session's
    restore) is relative to the bounding box's diagonal (docs/API.md): an edge shorter than 1e-12
    of it is degenerate. A move that grows the box so far that an untouched simplex fails that
    test is refused (422 at the move's position, nothing changed), as PUT /complex refuses the
    complex it would make; a move that stays within the test is taken, and the session's export
    imports."""
    s = Session(daemon)
    tet = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    assert s.put_complex({"vertices": tet + [[5, 5, 5]],
                          "simplices": [[0, 1, 2, 3], [4]]}).status_code == 200
    far = [1e13, 0, 0]
    assert s.put_complex({"vertices": tet + [far],
                          "simplices": [[0, 1, 2, 3], [4]]}).status_code == 422  # the rule
    assert s.put_complex({"vertices": tet + [[5, 5, 5]],
                          "simplices": [[0, 1, 2, 3], [4]]}).status_code == 200
    v = s.req("GET").json()["version"]
    r = s.req("PATCH", "/control-points", json={"moves": [{"index": 4, "position": far}]},
              headers={"If-Match": f'"{v}"'})
    assert r.status_code == 422, r.text
    assert r.json()["errors"][0]["pointer"] == "/moves/0/position"
    assert "bounding box" in r.json()["detail"]
    assert s.req("GET").json()["version"] == v
    r = s.req("PATCH", "/control-points", json={"moves": [{"index": 4, "position": [1e9, 0, 0]}]},
              headers={"If-Match": f'"{v}"'})
    assert r.status_code == 200, r.text
    doc = s.req("GET", "/export").json()
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 201, r.text
