"""Meshes several test files build."""
import itertools

import numpy as np


def kuhn_grid(n):
    """n^3 unit cubes, each as the 6 tetrahedra around its main diagonal (Kuhn's split): the
    grid points (x fastest, then y, then z) and the tetrahedra, cube by cube (x fastest)."""
    vid = lambda x, y, z: x + (n + 1) * (y + (n + 1) * z)
    verts = [[x, y, z] for z in range(n + 1) for y in range(n + 1) for x in range(n + 1)]
    tets = []
    for z, y, x in itertools.product(range(n), repeat=3):
        for perm in itertools.permutations(range(3)):
            c = [x, y, z]
            t = [vid(*c)]
            for a in perm:
                c[a] += 1
                t.append(vid(*c))
            tets.append(t)
    return verts, tets


def icosphere(levels):
    """The unit sphere: an icosahedron's triangles split `levels` times, the new points pushed
    out to the sphere; (vertices, triangles)."""
    t = (1 + 5 ** 0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
         [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    v = [list(np.array(p) / np.linalg.norm(p)) for p in v]
    for _ in range(levels):
        mid = {}

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                p = (np.array(v[a]) + np.array(v[b])) / 2
                mid[k] = len(v)
                v.append(list(p / np.linalg.norm(p)))
            return mid[k]
        g = []
        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            g += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = g
    return [list(map(float, p)) for p in v], f
