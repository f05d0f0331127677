#!/bin/sh
# Prints the benchmark figures of docs/BENCHMARKS.md: subdivd against OpenSubdiv (uniform Loop,
# double precision) on the same 20k-triangle torus, and solid refinement throughput.
# Two regimes, the same for both programs:
#   cold  a fresh process, one run: every page is touched for the first time
#   warm  best of REPS runs in one process with glibc keeping freed memory (mmap_max=0), the
#         steady state of a long-running service
set -eu
cd "$(dirname "$0")/.."
REPS=${REPS:-5}
PY=/usr/bin/python3
mkdir -p build/bench-data
D=build/bench-data
$PY bench/make_mesh.py torus 100 100 > $D/torus.txt
$PY bench/make_mesh.py cubes 12 > $D/cubes12.txt
WARM="glibc.malloc.mmap_max=0:glibc.malloc.trim_threshold=4294967295"
best() { sed -E 's/.*seconds_best=([0-9.]+).*/\1/'; }
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo "== surface: uniform Loop (loop weights) of torus 100x100 (20000 triangles)"
for L in 1 2 3 4; do
    for mode in cold warm; do
        if [ $mode = cold ]; then reps=1; tun=""; else reps=$REPS; tun=$WARM; fi
        ours=$(GLIBC_TUNABLES=$tun build/bench --reps $reps -w loop $D/torus.txt $L)
        osd=$(GLIBC_TUNABLES=$tun build/osd_loop --time $reps -l $L $D/torus.txt)
        a=$(echo "$ours" | best); b=$(echo "$osd" | best)
        echo "$mode L$L  $ours"
        echo "$mode L$L  $osd"
        echo "$mode L$L  time ratio subdivd/opensubdiv = $(echo "$a $b" | awk '{printf "%.2f", $1/$2}')"
    done
done
echo "== solid: box-spline scheme on 12^3 cubes (10368 tetrahedra)"
for L in 1 2 3; do
    echo "cold L$L  $(build/bench --reps 1 $D/cubes12.txt $L)"
    echo "warm L$L  $(GLIBC_TUNABLES=$WARM build/bench --reps $REPS $D/cubes12.txt $L)"
done
