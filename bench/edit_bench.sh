#!/bin/sh
# Edit cost (docs/BENCHMARKS.md): one control-point edit pushed to level 3 of two solids, the
# second 8x larger — the cost should follow the edited region, not the mesh — and to level 4 of
# the torus; the first edit after the build beside the median of the others.
#   OLD=path/to/an/older/edit_bench [ROUNDS=5] sh bench/edit_bench.sh
# runs the older program too, one round of each after the other (this VM's speed drifts), and
# prints the median over the rounds of each figure for both.
set -eu
cd "$(dirname "$0")/.."
D=build/bench-data
mkdir -p $D
/usr/bin/python3 bench/make_mesh.py cubes 10 > $D/cubes10.txt
/usr/bin/python3 bench/make_mesh.py cubes 20 > $D/cubes20.txt
/usr/bin/python3 bench/make_mesh.py torus 100 100 > $D/torus.txt
OLD=${OLD:-}
ROUNDS=${ROUNDS:-5}
# key=value fields of a line, first_edit_s (older programs) as first_edit_ms
field() { echo "$1" | tr ' ' '\n' | awk -F= -v k="$2" '
    $1 == k { print $2; found = 1 } $1 == "first_edit_s" && k == "first_edit_ms" { print $2 * 1000; found = 1 }
    END { if (!found) print "-" }'; }
median() { sort -n | awk '{a[NR] = $1} END {print (NR ? a[int((NR + 1) / 2)] : "-")}'; }
if [ -z "$OLD" ]; then
    echo "== edits: one random control point moved, propagated to level 3 (200 edits each)"
    a=$(build/edit_bench $D/cubes10.txt 3 200)
    b=$(build/edit_bench $D/cubes20.txt 3 200)
    echo "cubes 10: $a"
    echo "cubes 20: $b"
    ma=$(field "$a" median_ms)
    mb=$(field "$b" median_ms)
    echo "median ratio (8x larger mesh) = $(echo "$ma $mb" | awk '{printf "%.2f", $2/$1}')   goal: <= 2 ms and ratio < 2"
    echo "first edit: cubes 10 $(field "$a" first_edit_ms) ms, cubes 20 $(field "$b" first_edit_ms) ms   goal: the median's order"
    exit 0
fi
T=$(mktemp -d)
for r in $(seq "$ROUNDS"); do
    for m in "cubes10.txt 3" "cubes20.txt 3" "torus.txt 4"; do
        set -- $m
        name=${1%.txt}_L$2
        build/edit_bench $D/$1 $2 200 >> "$T/new_$name"
        "$OLD" $D/$1 $2 200 >> "$T/old_$name"
    done
done
echo "== edits, $ROUNDS alternating rounds (medians over rounds): this build vs $OLD"
for name in cubes10_L3 cubes20_L3 torus_L4; do
    for who in old new; do
        out=""
        for k in first_edit_ms median_ms p90_ms build_s memory_bytes memory_after_bytes mean_points_touched; do
            v=$(while read -r line; do field "$line" $k; done < "$T/${who}_$name" | grep -v '^-$' | median)
            out="$out $k=$v"
        done
        echo "$name $who:$out"
    done
done
rm -rf "$T"
