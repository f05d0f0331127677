"""PUT /complex {"repair": true} (docs/API.md "Control complex", DECISIONS 41): the simplices the
daemon refuses one at a time (a vertex twice, degenerate, the vertices of an earlier simplex) are
dropped, reported in summary.repaired with their posted indices, and the rest subdivides exactly
as the cleaned mesh posted without repair; without repair the same mesh is the 422 it was."""
import json
import subprocess
import sys

import pytest

from daemon import SUBDIVD, Daemon, Session


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


def grid(n=4):
    """An n x n grid of squares in z = 0, two triangles each, plus a bump in the middle."""
    v = [[float(x), float(y), 0.3 if (x, y) == (n // 2, n // 2) else 0.0]
         for y in range(n + 1) for x in range(n + 1)]
    t = []
    for y in range(n):
        for x in range(n):
            a = y * (n + 1) + x
            t += [[a, a + 1, a + n + 2], [a, a + n + 2, a + n + 1]]
    return v, t


def dirty():
    """The grid's triangles with bad ones inserted: (vertices, posted, cleaned, report)."""
    v, clean = grid()
    c5 = clean[5]
    posted = (clean[0:3] + [[0, 1, 2]]                 # 3: three collinear vertices of row 0
              + clean[3:6] + [[5, 5, 6]]               # 7: a vertex twice
              + [clean[2][::-1]]                       # 8: an OBJ's second face on posted 2
              + clean[6:9] + [[c5[1], c5[2], c5[0]]]   # 12: posted 6 (clean[5]) again
              + clean[9:] + [[0, 1]])                  # an edge of a triangle: absorbed, kept
    report = [{"index": 3, "reason": "degenerate"}, {"index": 7, "reason": "repeated-vertex"},
              {"index": 8, "reason": "duplicate", "of": 2},
              {"index": 12, "reason": "duplicate", "of": 6}]
    return v, posted, clean + [[0, 1]], report


def test_report_and_levels_equal_the_cleaned_mesh(daemon):
    v, posted, cleaned, report = dirty()
    # the duplicates repeat posted simplices 2 and 6, which are clean[2] and clean[5]
    assert posted[2] == cleaned[2] and posted[6] == cleaned[5]
    s = Session(daemon)
    r = s.put_complex({"vertices": v, "simplices": posted, "repair": True})
    assert r.status_code == 200, r.text
    summ = r.json()["summary"]
    assert summ["repaired"] == report
    assert summ["repaired_count"] == 4 and "repaired_ignored" not in summ
    c = Session(daemon)
    rc = c.put_complex({"vertices": v, "simplices": cleaned})
    assert rc.status_code == 200
    assert "repaired" not in rc.json()["summary"]
    for level in (1, 2):
        a, b = s.level(level, format="json"), c.level(level, format="json")
        assert a.status_code == b.status_code == 200
        assert a.json() == b.json()
    # the stored complex is the repaired one: GET /complex and the export
    g = s.req("GET", "/complex").json()
    assert g["simplices"] == cleaned and g["summary"]["repaired_count"] == 4
    assert s.req("GET", "/export").json()["complex"]["simplices"] == cleaned
    # a change of tags keeps the complex and its report
    assert s.req("PUT", "/tags", json={"singular": [[0, 1]]}).status_code == 200
    assert s.req("GET", "/complex").json()["summary"]["repaired_count"] == 4


def test_without_repair_still_refused(daemon):
    v, posted, _, _ = dirty()
    for body in ({"vertices": v, "simplices": posted},
                 {"vertices": v, "simplices": posted, "repair": False}):
        s = Session(daemon)
        r = s.put_complex(body)
        assert r.status_code == 422 and r.json()["type"].endswith("/invalid-complex")
        assert r.json()["errors"][0]["pointer"] == "/simplices/3"  # the first bad one
        assert s.req("GET").json()["version"] == 0


@pytest.mark.parametrize("value", ["yes", 1, None, [True]])
def test_repair_is_a_boolean(daemon, value):
    v, t = grid()
    r = Session(daemon).put_complex({"vertices": v, "simplices": t, "repair": value})
    assert r.status_code == 400 and r.json()["errors"][0]["pointer"] == "/repair"


def test_whole_complex_refusals_stay(daemon):
    v, t = grid()
    s = Session(daemon)
    r = s.put_complex({"vertices": v, "simplices": t + [[0, 99]], "repair": True})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/simplices/32/1"
    r = s.put_complex({"vertices": v, "simplices": [[0, 0, 1], [2, 2]], "repair": True})
    assert r.status_code == 422  # nothing left: no simplices
    # a fill's tetrahedra are not repaired: one that repeats a posted one is the fill's 422
    tet = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    r = s.put_complex({"vertices": tet, "simplices": [[0, 1, 2, 3]], "repair": True,
                       "fill": [{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]}]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/fill/0", r.text
    assert s.req("GET").json()["version"] == 0


CUBE_V = [[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)]
CUBE_T = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]]


def test_tetrahedra_and_diagonals(daemon):
    # posted: 0..1 tets, 2 a duplicate of 1 (reordered), 3 a flat tetrahedron, 4..7 the rest
    flat = [0, 1, 2, 3]  # the four corners of z = 0: zero volume
    posted = CUBE_T[:2] + [[7, 5, 1, 0], flat] + CUBE_T[2:]
    diagonals = [[2, 1], [5, 2], [1, 0]]  # on the dropped duplicate, on posted 5 = CUBE_T[3], on 1
    s = Session(daemon)
    r = s.put_complex({"vertices": CUBE_V, "simplices": posted, "diagonals": diagonals,
                       "repair": True})
    assert r.status_code == 200, r.text
    summ = r.json()["summary"]
    assert summ["repaired"] == [{"index": 2, "reason": "duplicate", "of": 1},
                                {"index": 3, "reason": "degenerate"}]
    assert summ["repaired_ignored"] == ["/diagonals/0"] and summ["repaired_ignored_count"] == 1
    c = Session(daemon)
    assert c.put_complex({"vertices": CUBE_V, "simplices": CUBE_T,
                          "diagonals": [[3, 2], [1, 0]]}).status_code == 200
    for level in (1, 2):
        assert s.level(level, format="json").json() == c.level(level, format="json").json()
    assert s.req("GET", "/complex").json()["diagonals"] == c.req("GET", "/complex").json()["diagonals"]


def test_report_is_bounded(daemon):
    v, t = grid()
    posted = t + [t[0][::-1]] * 1500
    r = Session(daemon).put_complex({"vertices": v, "simplices": posted, "repair": True})
    assert r.status_code == 200
    summ = r.json()["summary"]
    assert summ["repaired_count"] == 1500 and len(summ["repaired"]) == 1000
    assert summ["repaired"][0] == {"index": len(t), "reason": "duplicate", "of": 0}
    assert summ["repaired"][-1]["index"] == len(t) + 999


def test_offline_repair(tmp_path):
    v, posted, cleaned, _ = dirty()
    src, ref = tmp_path / "dirty.json", tmp_path / "clean.json"
    src.write_text(json.dumps({"vertices": v, "simplices": posted}))
    ref.write_text(json.dumps({"vertices": v, "simplices": cleaned}))
    out_a, out_b = tmp_path / "a.json", tmp_path / "b.json"
    r = subprocess.run([str(SUBDIVD), "refine", str(src), "--repair", "--level", "2", "-o",
                        str(out_a)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "4 simplices dropped" in r.stderr
    r = subprocess.run([str(SUBDIVD), "refine", str(ref), "--level", "2", "-o", str(out_b)],
                       capture_output=True, text=True)
    assert r.returncode == 0
    assert json.loads(out_a.read_text()) == json.loads(out_b.read_text())
    r = subprocess.run([str(SUBDIVD), "refine", str(src), "--level", "2", "-o", str(out_a)],
                       capture_output=True, text=True)
    assert r.returncode == 1 and "/simplices/3" in r.stderr


def write_obj(path, verts, faces):
    path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in verts)
                    + "".join("f " + " ".join(str(i + 1) for i in f) + "\n" for f in faces))


def test_python_cli_obj_repair(daemon, tmp_path):
    """An OBJ with two faces on the same three vertices and a degenerate one, through the Python
    client's `subdiv refine --repair`: the level is the cleaned OBJ's."""
    from conftest import REPO
    subdiv = REPO / "build" / "subdiv"
    v, clean = grid()
    faces = clean[:4] + [clean[1][::-1], [0, 1, 2]] + clean[4:]
    write_obj(tmp_path / "dirty.obj", v, faces)
    write_obj(tmp_path / "clean.obj", v, clean)

    def refine(name, *flags):
        out = tmp_path / (name + ".json")
        r = subprocess.run([str(subdiv), "refine", str(tmp_path / (name + ".obj")), "--url",
                            daemon.url, "--level", "2", "-o", str(out), *flags],
                           capture_output=True, text=True, timeout=120)
        return r, out
    r, a = refine("dirty", "--repair")
    assert r.returncode == 0, r.stderr
    assert "dirty.obj: repaired: 2 simplices dropped" in r.stderr
    r, b = refine("clean")
    assert r.returncode == 0, r.stderr
    assert json.loads(a.read_text()) == json.loads(b.read_text())
    r, _ = refine("dirty")
    # refused as before: per-simplex checks come before the duplicates (the degenerate 5)
    assert r.returncode == 1 and "/simplices/5" in r.stderr
    # the client's method says the same
    sys.path.insert(0, str(REPO / "clients" / "python"))
    from subdiv import Client
    with Client(daemon.url).create_session() as s:
        summ = s.put_complex({"vertices": v, "simplices": faces}, repair=True)["summary"]
        assert summ["repaired"] == [{"index": 4, "reason": "duplicate", "of": 1},
                                    {"index": 5, "reason": "degenerate"}]


def test_store_keeps_the_cleaned_complex(tmp_path):
    """The store holds the repaired complex: after a restart the levels are the same bytes, the
    simplices the cleaned ones, and there is no report (nothing was repaired by the import)."""
    v, posted, cleaned, _ = dirty()
    db = f"sqlite:{tmp_path / 's.db'}"
    d = Daemon("--store", db)
    s = Session(d)
    assert s.put_complex({"vertices": v, "simplices": posted, "repair": True}).status_code == 200
    level = s.level(2, format="json").content
    assert d.stop() == 0
    d2 = Daemon("--store", db)
    try:
        s.base = s.base.replace(d.url, d2.url)
        g = s.req("GET", "/complex").json()
        assert g["simplices"] == cleaned and "repaired" not in g["summary"]
        assert s.level(2, format="json").content == level
    finally:
        assert d2.stop() == 0
