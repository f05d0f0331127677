#!/bin/sh
# tetgen_case.sh DIR NAME SWITCHES — regenerate DIR/mesh.txt (docs/TEXT_FORMAT.md) from DIR/NAME.smesh
# with the TetGen 1.5 command-line program (Debian package `tetgen`):
#   tetgen SWITCHES NAME.smesh, e.g. -pq1.5a0.01:
#   -p  tetrahedralise the piecewise linear complex
#   -q  radius-edge ratio bound (adds Steiner points inside and on the boundary)
#   -a  maximum tetrahedron volume
# TetGen is deterministic, so rerunning reproduces the committed mesh.txt.
# Each case has a make.sh that calls this with its own name and switches.
set -eu
here=$(cd "$1" && pwd)
name=$2
switches=$3

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cp "$here/$name.smesh" "$tmp/"
(cd "$tmp" && tetgen -Q "$switches" "$name.smesh")

# .node / .ele -> v / s lines (indices rebased to 0, coordinates printed with %.17g)
/usr/bin/python3 - "$(dirname "$0")/../python" "$tmp/$name.1" "$here/mesh.txt" \
    "tetgen $switches $name.smesh (TetGen 1.5)" <<'PY'
import sys

sys.path.insert(0, sys.argv[1])
import sdtext


def records(path):
    """Non-comment lines of a TetGen file, split into fields; the first is the header."""
    out = []
    with open(path) as fh:
        for line in fh:
            fields = line.split("#", 1)[0].split()
            if fields:
                out.append(fields)
    return out


stem, target, how = sys.argv[2], sys.argv[3], sys.argv[4]
nodes = records(stem + ".node")
n, dim = int(nodes[0][0]), int(nodes[0][1])
assert dim == 3 and len(nodes) == n + 1
base = int(nodes[1][0])  # TetGen numbers from the first index of its input (0 or 1)
verts = [[float(c) for c in r[1:4]] for r in nodes[1:]]
assert [int(r[0]) for r in nodes[1:]] == list(range(base, base + n))

eles = records(stem + ".ele")
nt, corners = int(eles[0][0]), int(eles[0][1])
assert corners == 4 and len(eles) == nt + 1
tets = [[int(i) - base for i in r[1:5]] for r in eles[1:]]

sdtext.write_input(target, verts, tets,
                   comment=f"{how}: {n} vertices, {nt} tetrahedra\nregenerate with make.sh")
PY
echo "wrote $here/mesh.txt"
