#!/usr/bin/python3
"""subdivd-mpi on one machine (issue 21): a ~100k-tetrahedron block to level 3 on 1 and 2 ranks.

    bench/mpi_bench.py [N [LEVEL]]     N^3 cubes of 6 tetrahedra (default 26: 105 456 tets), level 3

Each configuration runs with --no-write (compute alone: partition, halo, distribution, build,
refinement, global ids) and --stats, three times, the fastest kept; then once with the pieces
written, for the writing time. Prints per rank: compute wall and CPU seconds, peak resident
memory, owned and halo cells, and the speed-up and memory ratio of 2 ranks against 1. The
figures and the command are in docs/BENCHMARKS.md ("Partitioned refinement on MPI")."""
import json
import os
import pathlib
import subprocess
import sys
import tempfile

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
from make_mesh import cubes  # noqa: E402

MPI = REPO / "build" / "subdivd-mpi"
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_btl="self,vader,tcp", OMPI_MCA_btl_tcp_if_include="lo",
           OMPI_MCA_oob_tcp_if_include="lo")


def run(n, mesh, level, d, write=False):
    stats = d / f"s{n}.json"
    args = ["mpirun", "-n", str(n), "--bind-to", "none", str(MPI), "refine", str(mesh), "--level",
            str(level), "--stats", str(stats), "-q"]
    args += ["-o", str(d / f"out{n}.pvtu")] if write else ["--no-write"]
    r = subprocess.run(args, capture_output=True, text=True, env=ENV)
    if r.returncode:
        sys.exit(r.stderr)
    return json.loads(stats.read_text())


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 26
    level = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    v, t = cubes(n)
    with tempfile.TemporaryDirectory() as tmp:
        d = pathlib.Path(tmp)
        mesh = d / "cubes.json"
        mesh.write_text(json.dumps({"vertices": v, "simplices": t}))
        print(f"{n}^3 cubes: {len(v)} vertices, {len(t)} tetrahedra, level {level}")
        res = {}
        for ranks in (1, 2):
            best = min((run(ranks, mesh, level, d) for _ in range(3)),
                       key=lambda s: max(p["compute_s"] for p in s["per_rank"]))
            w = run(ranks, mesh, level, d, write=True)
            res[ranks] = best
            lc = best["level_counts"]
            print(f"\n{ranks} rank(s): level {level} has {lc['tetrahedra'] + lc['octahedra']} cells, "
                  f"{lc['points']} points; write {max(p['write_s'] for p in w['per_rank']):.2f} s, "
                  f"{sum(p['write_bytes'] for p in w['per_rank']) / 1e9:.2f} GB")
            print("rank  compute_s  cpu_s  partition_s  refine_s  ids_s  peak_MB  owned_cells  "
                  "local_cells  halo")
            for p in best["per_rank"]:
                halo = 1 - p["owned_cells"] / p["local_cells"]
                print(f"{p['rank']:4d}  {p['compute_s']:9.2f}  {p['compute_cpu_s']:5.2f}  "
                      f"{p['partition_s'] + p['cut_s']:11.2f}  {p['refine_s']:8.2f}  "
                      f"{p['ids_s']:5.2f}  {p['peak_rss_bytes'] / 2**20:7.0f}  "
                      f"{p['owned_cells']:11d}  {p['local_cells']:11d}  {100 * halo:4.1f}%")
        one, two = res[1]["per_rank"], res[2]["per_rank"]
        t1 = one[0]["compute_s"]
        t2 = max(p["compute_s"] for p in two)
        c1 = one[0]["compute_cpu_s"]
        c2 = max(p["compute_cpu_s"] for p in two)
        m1 = one[0]["peak_rss_bytes"]
        m2 = max(p["peak_rss_bytes"] for p in two)
        print(f"\nspeed-up of 2 ranks: {t1 / t2:.2f}x wall, {c1 / c2:.2f}x CPU of the slowest rank; "
              f"peak memory per rank {m2 / m1:.2f}x of one rank's")


if __name__ == "__main__":
    main()
