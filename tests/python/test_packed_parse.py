"""The big arrays of a PUT /complex or PUT /tags body read packed (api/packed.c, api/rows.c) give the answers
they give read from jansson's tree: the packer against jansson (tests/fuzz/fuzz_packed.c) and
the parsers on both (tests/api/packed_parse.c) over the error catalogue's bodies, valid complexes
and their mutations. Under make sanitize they are the ASan builds."""
import json
import os
import random
import subprocess

from conftest import REPO
from test_http_errors import CASES, FIN, TET

FUZZ = os.environ.get("FUZZ_PACKED", str(REPO / "build" / "fuzz_packed"))
PARSE = os.environ.get("PACKED_PARSE", str(REPO / "build" / "packed_parse"))


def test_the_packer_agrees_with_jansson():
    r = subprocess.run([FUZZ, "30000", "7"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "agree with jansson" in r.stdout


def valid_bodies():
    rnd = random.Random(3)
    n = 40
    V = [[rnd.uniform(-1, 1), rnd.uniform(-1, 1), rnd.uniform(-1, 1)] for _ in range(n)]
    S = [[i, i + 1, i + 2, i + 3] for i in range(0, n - 4, 4)] + [[i, i + 1, i + 2] for i in range(0, n - 3, 5)] \
        + [[i, i + 1] for i in range(1, n - 1, 7)] + [[n - 1]]
    yield TET
    yield FIN
    yield {"vertices": V, "simplices": S, "attributes": {"t": [rnd.random() for _ in V],
                                                         "v": [[rnd.random(), 1] for _ in V]},
           "diagonals": [[0, 1], [1, 2]]}
    yield {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]],
           "simplices": [[0, 1, 2, 3]],
           "fill": [{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [1, 2, 4]]}]}


def mutations(body, rnd, k):
    """k copies of body with one number of one big array replaced by something else."""
    wild = ["1", "-0", "0.0", "1e2", "-1e400", "3e15", "-3e15", "9007199254740993", "1.5", "true",
            "null", '"1"', "[]", "[1,2]", "{}", "1e-320", "2147483648", "-1", "4294967296"]
    text = json.dumps(body)
    for _ in range(k):
        spots = [i for i, c in enumerate(text) if c.isdigit() and not text[i - 1].isdigit()
                 and text[i - 1] not in ".e-"]
        i = rnd.choice(spots)
        j = i
        while j < len(text) and (text[j].isdigit() or text[j] in ".e-+"):
            j += 1
        yield text[:i] + rnd.choice(wild) + text[j:]


def test_parsers_answer_the_same_packed_or_not():
    rnd = random.Random(11)
    bodies = []
    for case in CASES:
        _, method, path, body, _, _, _ = case
        if method == "PUT" and path == "/complex":
            bodies.append(body.decode("utf-8", "replace") if isinstance(body, bytes) else json.dumps(body))
    for b in valid_bodies():
        bodies.append(json.dumps(b))
        bodies.append(json.dumps(b, indent=1))   # newlines and blanks inside the arrays
        bodies += list(mutations(b, rnd, 150))
    stdin = "".join(json.dumps(b) + "\n" for b in bodies)
    r = subprocess.run([PARSE], input=stdin, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    last = r.stdout.strip().splitlines()[-1]
    assert last.endswith("0 differ"), last
    assert int(last.split()[3]) > 300, "most bodies should have arrays to pack"


def test_tags_answer_the_same_packed_or_not():
    """PUT /tags's "singular" on the complex of tests/api/packed_parse.c (a fan of 6 triangles
    around 0 with a tetrahedron and a curve): the catalogue's tag bodies, valid ones and
    mutations."""
    rnd = random.Random(5)
    bodies = [json.dumps(b) for (_, m, path, b, _, _, _) in CASES if m == "PUT" and path == "/tags"]
    valid = [{"singular": [[0], [0, 1], [1, 2], [0, 1, 2], [8, 9], [8]]},
             {"singular": [[0, 2], [0, 3], [0, 4]], "petals": []},
             {"singular": [[i, i + 1] for i in range(1, 6)] + [[6, 1]]}]
    for b in valid:
        bodies.append(json.dumps(b))
        bodies += list(mutations(b, rnd, 120))
    stdin = "".join(json.dumps(b) + "\n" for b in bodies)
    r = subprocess.run([PARSE, "tags"], input=stdin, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    last = r.stdout.strip().splitlines()[-1]
    assert last.endswith("0 differ"), last
    assert int(last.split()[3]) > 150, "most bodies should have an array to pack"
