#!/usr/bin/python3
"""Closed, consistently oriented triangle meshes (and tetrahedral blocks) in the text format of
docs/TEXT_FORMAT.md, written to stdout. Deterministic: the same arguments give the same bytes.

    make_mesh.py icosphere N      icosahedron split 1->4 N times, on the unit sphere
    make_mesh.py bumpy N          the same with a deterministic bumpy radius and unequal axes
                                  (no symmetry; valence 5, and 6 for N >= 1)
    make_mesh.py torus U V        U x V torus grid (R = 1, r = 0.35), quads split in two (U, V >= 3;
                                  every vertex has valence 6; torus 100 100 = 20000 triangles)
    make_mesh.py octahedron       the regular octahedron (valence 4)
    make_mesh.py cubes N          N^3 unit cubes, 6 tetrahedra each (a solid block)
"""
import math
import sys


def icosphere(n):
    p = (1 + 5 ** 0.5) / 2
    v = [(-1, p, 0), (1, p, 0), (-1, -p, 0), (1, -p, 0), (0, -1, p), (0, 1, p), (0, -1, -p),
         (0, 1, -p), (p, 0, -1), (p, 0, 1), (-p, 0, -1), (-p, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    v = [tuple(c / math.sqrt(sum(x * x for x in q)) for c in q) for q in v]
    for _ in range(n):
        mid = {}
        nf = []

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                q = [(v[a][i] + v[b][i]) / 2 for i in range(3)]
                r = math.sqrt(sum(x * x for x in q))
                v.append(tuple(x / r for x in q))
                mid[k] = len(v) - 1
            return mid[k]
        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = nf
    return v, f


def bumpy(n):
    v, f = icosphere(n)
    out = []
    for x, y, z in v:
        s = 1 + 0.1 * math.sin(7 * x + 1) * math.cos(5 * y) + 0.05 * math.sin(3 * z)
        out.append((s * x * 1.3, s * y, s * z * 0.8))
    return out, f


def torus(U, V):
    v, f = [], []
    for i in range(U):
        for j in range(V):
            a, b = 2 * math.pi * i / U, 2 * math.pi * j / V
            v.append(((1 + 0.35 * math.cos(b)) * math.cos(a), (1 + 0.35 * math.cos(b)) * math.sin(a),
                      0.35 * math.sin(b)))
    for i in range(U):
        for j in range(V):
            p, q = i * V + j, ((i + 1) % U) * V + j
            r, s = ((i + 1) % U) * V + (j + 1) % V, i * V + (j + 1) % V
            f += [(p, q, r), (p, r, s)]
    return v, f


def octahedron():
    return ([(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)],
            [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)])


def cubes(n):
    idx = lambda x, y, z: (z * (n + 1) + y) * (n + 1) + x
    v = [(x, y, z) for z in range(n + 1) for y in range(n + 1) for x in range(n + 1)]
    f = []
    perms = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    for z in range(n):
        for y in range(n):
            for x in range(n):
                for p in perms:
                    c = [x, y, z]
                    t = [idx(*c)]
                    for s in p:
                        c[s] += 1
                        t.append(idx(*c))
                    f.append(tuple(t))
    return v, f


MAKERS = {"icosphere": (icosphere, 1, 0), "bumpy": (bumpy, 1, 0), "torus": (torus, 2, 3),
          "octahedron": (octahedron, 0, 0), "cubes": (cubes, 1, 1)}  # name: (maker, args, minimum)


def main(argv):
    kind = argv[1] if len(argv) > 1 else ""
    if kind not in MAKERS:
        sys.exit(__doc__)
    maker, nargs, least = MAKERS[kind]
    try:
        args = [int(a) for a in argv[2:]]
    except ValueError:
        args = None
    if args is None or len(args) != nargs or any(a < least for a in args):
        sys.exit(f"make_mesh.py {kind}: expected {nargs} whole number(s) >= {least}\n{__doc__}")
    v, f = maker(*args)
    out = [f"# {' '.join(argv[1:])}: {len(v)} vertices, {len(f)} simplices"]
    out += ["v %.17g %.17g %.17g" % p for p in v]
    out += ["s " + " ".join(map(str, s)) for s in f]
    sys.stdout.write("\n".join(out) + "\n")


if __name__ == "__main__":
    main(sys.argv)
