#!/bin/sh
# Prints the benchmark figures of docs/BENCHMARKS.md: subdivd against OpenSubdiv (uniform Loop,
# double precision) on the same 20k-triangle torus, and solid refinement throughput.
# Two regimes, the same for both programs:
#   cold  a fresh process, one run: every page is touched for the first time
#   warm  best of REPS runs in one process with glibc keeping freed memory (mmap_max=0), the
#         steady state of a long-running service
# This VM's speed drifts by up to 2x within minutes, so each Loop figure is taken ROUNDS times,
# subdivd (1 and 2 threads) and OpenSubdiv one right after the other, and the median of each and
# the median of the per-round ratios are printed.
set -eu
cd "$(dirname "$0")/.."
REPS=${REPS:-5}
ROUNDS=${ROUNDS:-3}
PY=/usr/bin/python3
mkdir -p build/bench-data
D=build/bench-data
$PY bench/make_mesh.py torus 100 100 > $D/torus.txt
$PY bench/make_mesh.py cubes 12 > $D/cubes12.txt
WARM="glibc.malloc.mmap_max=0:glibc.malloc.trim_threshold=4294967295"
best() { sed -E 's/.* seconds_best=([0-9.]+).*/\1/'; }
median() { sort -n | awk '{a[NR] = $1} END {print a[int((NR + 1) / 2)]}'; }
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo "== surface: uniform Loop (loop weights) of torus 100x100 (20000 triangles), $ROUNDS rounds"
T=$(mktemp)
for L in 1 2 3 4; do
    for mode in cold warm; do
        if [ $mode = cold ]; then reps=1; tun=""; else reps=$REPS; tun=$WARM; fi
        : > "$T"
        for r in $(seq "$ROUNDS"); do
            o1=$(GLIBC_TUNABLES=$tun build/bench --reps $reps -j 1 -w loop $D/torus.txt $L)
            o2=$(GLIBC_TUNABLES=$tun build/bench --reps $reps -j 2 -w loop $D/torus.txt $L)
            osd=$(GLIBC_TUNABLES=$tun build/osd_loop --time $reps -l $L $D/torus.txt)
            echo "$mode L$L  $o1"
            echo "$mode L$L  $o2"
            echo "$mode L$L  $osd"
            echo "$(echo "$o1" | best) $(echo "$o2" | best) $(echo "$osd" | best)" >> "$T"
        done
        echo "$mode L$L  median seconds: subdivd 1 thread $(awk '{print $1}' "$T" | median)," \
            "2 threads $(awk '{print $2}' "$T" | median), opensubdiv $(awk '{print $3}' "$T" | median);" \
            "median ratio subdivd/opensubdiv: 1 thread $(awk '{printf "%.2f\n", $1 / $3}' "$T" | median)," \
            "2 threads $(awk '{printf "%.2f\n", $2 / $3}' "$T" | median)"
    done
done
rm -f "$T"
# The figures above are batch refinement (the edit index made by the first edit, timed apart as
# edit_seconds_best); the daemon builds it with each level (bench --edits):
echo "== surface, the daemon's way (edit index with the levels): warm L4, 1 thread"
echo "warm L4  $(GLIBC_TUNABLES=$WARM build/bench --edits --reps $REPS -j 1 -w loop $D/torus.txt 4)"
echo "== solid: box-spline scheme on 12^3 cubes (10368 tetrahedra), one thread (and two, warm)"
for L in 1 2 3; do
    echo "cold L$L  $(build/bench --reps 1 $D/cubes12.txt $L)"
    echo "warm L$L  $(GLIBC_TUNABLES=$WARM build/bench --reps $REPS $D/cubes12.txt $L)"
    echo "warm L$L  $(GLIBC_TUNABLES=$WARM build/bench --reps $REPS -j 2 $D/cubes12.txt $L)"
done
# what a second core can gain at most where the work is writing memory
echo "== memory ceiling of two threads, and what a first touch costs:"
build/bandwidth 128 10
