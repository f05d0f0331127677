"""PUT /tags (000 Sec. 4.1): a cube made of tetrahedra with its 12 edges tagged keeps straight
creases and fixed corners at every level; tags show in GET /complex; they must name simplices of
the complex; a new complex drops them and a rule change keeps them."""
import numpy as np
import pytest

from daemon import Daemon, Session
from meshes import kuhn_grid

# the unit cube as 6 tetrahedra around its main diagonal 0-7 (vertex id = x + 2y + 4z)
CUBE_V = [[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)]
CUBE_T = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]]
CUBE_EDGES = [[a, b] for a in range(8) for b in range(a + 1, 8) if (a ^ b) in (1, 2, 4)]


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


def on_cube_edge(p):
    return sum(abs(c) < 1e-12 or abs(c - 1) < 1e-12 for c in p) >= 2


def test_cube_creases(daemon):
    s = Session(daemon)
    assert s.put_complex({"vertices": CUBE_V, "simplices": CUBE_T}).status_code == 200
    r = s.req("PUT", "/tags", json={"singular": CUBE_EDGES})
    assert r.status_code == 200 and r.json()["version"] == 2
    c = s.req("GET", "/complex").json()
    assert c["tags"] == {"singular": CUBE_EDGES}
    assert all(v["singular"] and v["rule"] == "corner" for v in c["classes"]["vertices"])
    sing = {tuple(sorted(e["vertices"])) for e in c["classes"]["edges"] if e["singular"]}
    assert sing == {tuple(e) for e in CUBE_EDGES}
    for level in (1, 2, 3):
        j = s.level(level, format="json").json()
        p = np.array(j["vertices"])
        np.testing.assert_array_equal(p[:8], np.array(CUBE_V, dtype=float))  # fixed corners
        crease = [i for i, r in enumerate(j["rules"]) if r == "curve"]
        assert len(crease) == 12 * (2 ** level - 1)
        assert all(on_cube_edge(p[i]) for i in crease)                       # straight creases
    # without tags the corners move (the tag is what fixes them)
    t = Session(daemon)
    assert t.put_complex({"vertices": CUBE_V, "simplices": CUBE_T}).status_code == 200
    assert not np.allclose(np.array(t.level(1, format="json").json()["vertices"])[:8], CUBE_V)


def test_tags_survive_rules_not_a_new_complex(daemon):
    s = Session(daemon)
    body = {"vertices": CUBE_V, "simplices": CUBE_T}
    assert s.put_complex(body).status_code == 200
    assert s.req("PUT", "/tags", json={"singular": [[0], [1, 3]]}).status_code == 200
    assert s.req("PUT", "/rules", json={"solid_scheme": "averaged"}).status_code == 200
    assert s.req("GET", "/complex").json()["tags"] == {"singular": [[0], [1, 3]]}
    assert s.put_complex(body).status_code == 200
    assert s.req("GET", "/complex").json()["tags"] == {"singular": []}


@pytest.mark.parametrize("tags,pointer", [
    ([[1, 2]], "/singular/0"),            # 1-2 is not an edge of the cube's tetrahedra
    ([[0, 1], [1, 2, 4]], "/singular/1"),  # not a triangle
    ([[0, 0]], "/singular/0/1"),           # repeated vertex
    ([[0, 1], [3], [1, 0]], "/singular/2"),  # the same edge twice (docs/API.md: each once)
    ([[0, 1, 3], [3], [3, 1, 0]], "/singular/2"),
    ([[1, 3], [0, 1], [3, 1], [1, 0]], "/singular/2"),  # two repeats: the earlier one is named
])
def test_tags_must_name_simplices(daemon, tags, pointer):
    s = Session(daemon)
    assert s.put_complex({"vertices": CUBE_V, "simplices": CUBE_T}).status_code == 200
    r = s.req("PUT", "/tags", json={"singular": tags})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == pointer
    assert s.req("GET").json()["version"] == 1


def test_import_takes_a_repeated_tag_once(daemon):
    """Documents exported before repeats were refused may hold one: an import (and so a stored
    session's restore) takes each singular simplex once, and the levels are those of the tags
    given once."""
    s = Session(daemon)
    assert s.put_complex({"vertices": CUBE_V, "simplices": CUBE_T}).status_code == 200
    assert s.req("PUT", "/tags", json={"singular": [[0, 1], [3]]}).status_code == 200
    doc = s.req("GET", "/export").json()
    want = s.level(2, format="json").json()["vertices"]
    doc["tags"]["singular"] = [[0, 1], [3], [1, 0], [3]]
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 201, r.text
    j = r.json()
    t = Session.__new__(Session)   # the session the import made (as test_persist.adopt)
    t.d, t.http, t.id, t.token = daemon, s.http, j["id"], j["token"]
    t.base = f"{daemon.url}/v1/sessions/{t.id}"
    t.auth = {"Authorization": f"Bearer {t.token}"}
    assert sorted(map(sorted, t.req("GET", "/complex").json()["tags"]["singular"])) == [[0, 1], [3]]
    assert t.level(2, format="json").json()["vertices"] == want


def test_import_error_names_the_entry_after_dropped_repeats(daemon):
    """An import that drops a repeated singular simplex still names, in an error about a later
    tag, that tag's entry in the document (not its place among the tags kept)."""
    s = Session(daemon)
    assert s.put_complex({"vertices": CUBE_V, "simplices": CUBE_T}).status_code == 200
    doc = s.req("GET", "/export").json()
    # entry 2 repeats entry 0 and is dropped; entry 3 (1-2) is no edge of the cube's tetrahedra
    doc["tags"] = {"singular": [[0, 1], [3], [1, 0], [1, 2]]}
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 422, r.text
    assert r.json()["errors"][0]["pointer"] == "/import/tags/singular/3", r.json()
    assert "1-2 is not an edge" in r.json()["detail"], r.json()


def test_an_import_keeps_the_first_of_a_repeated_tag_in_its_place(daemon):
    """Of a simplex tagged twice, an import keeps the first entry where it is, wherever the
    repeat is in the list (entries 1 and 256: their numbers' bytes order them the other way)."""
    verts, tets = kuhn_grid(7)                       # 512 vertices
    s = Session(daemon)
    assert s.put_complex({"vertices": verts, "simplices": tets}).status_code == 200
    doc = s.req("GET", "/export").json()
    tags = [[i] for i in range(300)]
    tags[256] = [1]
    doc["tags"] = {"singular": tags}
    r = s.http.post(daemon.url + "/v1/sessions", json={"import": doc})
    assert r.status_code == 201, r.text
    j = r.json()
    got = s.http.get(f"{daemon.url}/v1/sessions/{j['id']}/complex",
                     headers={"Authorization": f"Bearer {j['token']}"}).json()["tags"]["singular"]
    assert got == tags[:256] + tags[257:]
