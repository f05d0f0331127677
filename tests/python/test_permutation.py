"""The same complex posted in another order gives the same points at every level.

The level-0 major diagonals (001 Algorithm 2, docs/DECISIONS.md 1) are a function of the
topology: permuting the simplices, or the vertices inside each (odd permutations make the core
reorient a tetrahedron), must not change any level. Points are matched by where they come from
(`origin` of the level's JSON, level by level), not by sorting positions: a level-0 point is its
vertex id, a vertex point ("v", its parent), an edge point ("e", {its edge's two ends}), a cell
point ("c", {the parent octahedron's 6 vertices}). The expectation is the invariance itself, not
an earlier answer of the daemon."""
import itertools
import random

import numpy as np
import pytest

from daemon import Daemon, Session
from meshes import kuhn_grid

LEVELS = (1, 2, 3)


def block_complex():
    """A 2x2x2 block of cubes, 6 tetrahedra each (Kuhn split, so half of them have negative
    volume as written and are reoriented), on a slightly jittered grid; a fan of 3 triangles
    hinged on edges of the block's boundary and a free apex; a 3-segment curve from a corner."""
    rng = random.Random(7)
    n = 2
    grid, simplices = kuhn_grid(n)
    verts = [[x + rng.uniform(-0.1, 0.1), y + rng.uniform(-0.1, 0.1), z + rng.uniform(-0.1, 0.1)]
             for x, y, z in grid]

    def vid(x, y, z):
        return z * (n + 1) ** 2 + y * (n + 1) + x

    h = len(verts)
    verts.append([1.0, -0.8, 2.6])
    top = [vid(0, 0, 2), vid(1, 0, 2), vid(2, 0, 2), vid(2, 1, 2)]
    for a, b in zip(top, top[1:]):
        simplices.append([h, a, b])
    c0 = len(verts)
    verts += [[2.6, 2.4, 2.5], [3.1, 2.2, 3.0], [3.4, 2.9, 3.6]]
    curve = [vid(2, 2, 2), c0, c0 + 1, c0 + 2]
    for a, b in zip(curve, curve[1:]):
        simplices.append([a, b])
    return {"vertices": verts, "simplices": simplices}


def is_odd(p):
    return sum(1 for i in range(len(p)) for j in range(i + 1, len(p)) if p[i] > p[j]) % 2 == 1


def permuted(body, seed):
    """The same vertices and simplices: the simplex list shuffled; each tetrahedron's vertices
    permuted (all 24 permutations in turn, so odd ones too), each triangle rotated or reversed,
    each segment reversed every other time."""
    rng = random.Random(seed)
    perms = list(itertools.permutations(range(4)))
    rng.shuffle(perms)
    out, k = [], 0
    for s in body["simplices"]:
        if len(s) == 4:
            p = perms[k % 24]
            k += 1
            out.append([s[i] for i in p])
        elif len(s) == 3:
            r = rng.randrange(3)
            t = s[r:] + s[:r]
            out.append(t[::-1] if rng.random() < 0.5 else t)
        else:
            out.append(s[::-1] if len(out) % 2 else list(s))
    rng.shuffle(out)
    assert any(is_odd(p) for p in perms[:k]) and out != body["simplices"]
    return {"vertices": body["vertices"], "simplices": out}


def labelled_levels(session, levels):
    """{level: {label: position}} for level 0..max(levels), labels by origin."""
    top = max(levels)
    js = [session.level(l, format="json") for l in range(top + 1)]
    for r in js:
        assert r.status_code == 200, r.text
    js = [r.json() for r in js]
    labels = [list(range(len(js[0]["vertices"])))]
    for l in range(1, top + 1):
        prev, o = labels[l - 1], js[l]["origin"]
        octs = js[l - 1]["cells"].get("octahedra", [])
        lab = []
        for i in range(len(js[l]["vertices"])):
            if o["vertex_of"][i] >= 0:
                lab.append(("v", prev[o["vertex_of"][i]]))
            elif o["edge_of"][i] is not None:
                a, b = o["edge_of"][i]
                lab.append(("e", frozenset((prev[a], prev[b]))))
            else:
                assert o["cell_of"][i] >= 0, i
                lab.append(("c", frozenset(prev[v] for v in octs[o["cell_of"][i]])))
        assert len(set(lab)) == len(lab), f"level {l}: two points of the same origin"
        labels.append(lab)
    return {l: dict(zip(labels[l], np.asarray(js[l]["vertices"], dtype=float))) for l in levels}


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    d.stop()


def posted(daemon, body):
    s = Session(daemon)
    r = s.put_complex(body)
    assert r.status_code == 200, r.text
    return s


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_permuted_input_gives_the_same_points(daemon, seed):
    body = block_complex()
    a = labelled_levels(posted(daemon, body), LEVELS)
    b = labelled_levels(posted(daemon, permuted(body, seed)), LEVELS)
    for l in LEVELS:
        assert set(a[l]) == set(b[l]), f"level {l}: the points differ in origin"
        worst = max(float(np.max(np.abs(a[l][k] - b[l][k]))) for k in a[l])
        assert worst <= 1e-12, f"level {l}: positions differ by {worst}"


def test_permuted_input_keeps_the_octahedra_diagonals(daemon):
    """Level 1's octahedra list the major diagonal first (docs/API.md): the same vertex pairs."""
    body = block_complex()
    got = []
    for b in (body, permuted(body, 4)):
        s = posted(daemon, b)
        lab = labelled_levels(s, (1,))[1]
        names = list(lab)  # level-1 labels in vertex order (dicts keep insertion order)
        octs = s.level(1, format="json").json()["cells"]["octahedra"]
        got.append({frozenset((names[o[0]], names[o[1]])) for o in octs})
    assert len(got[0]) == 2 * 2 * 2 * 6 and got[0] == got[1]
