#!/bin/sh
# Edit cost (docs/BENCHMARKS.md): one control-point edit pushed to level 3 of two solids, the
# second 8x larger — the cost should follow the edited region, not the mesh.
set -eu
cd "$(dirname "$0")/.."
D=build/bench-data
mkdir -p $D
/usr/bin/python3 bench/make_mesh.py cubes 10 > $D/cubes10.txt
/usr/bin/python3 bench/make_mesh.py cubes 20 > $D/cubes20.txt
echo "== edits: one random control point moved, propagated to level 3 (200 edits each)"
a=$(build/edit_bench $D/cubes10.txt 3 200)
b=$(build/edit_bench $D/cubes20.txt 3 200)
echo "cubes 10: $a"
echo "cubes 20: $b"
ma=$(echo "$a" | sed -E 's/.*median_ms=([0-9.]+).*/\1/')
mb=$(echo "$b" | sed -E 's/.*median_ms=([0-9.]+).*/\1/')
echo "median ratio (8x larger mesh) = $(echo "$ma $mb" | awk '{printf "%.2f", $2/$1}')   goal: <= 2 ms and ratio < 2"
