#!/usr/bin/python3
"""subdivd-mpi on one machine (issue 21): a ~100k-tetrahedron block to level 3 on 1 and 2 ranks.

    bench/mpi_bench.py [N [LEVEL]]     N^3 cubes of 6 tetrahedra (default 26: 105 456 tets), level 3

Each configuration runs with --no-write (compute alone: partition, halo, distribution, build,
refinement, global ids) and --stats, three times interleaved, the fastest kept; then once with
the pieces written, for the writing time. Configurations: 1 rank, 2 ranks at once, and 2 ranks
one at a time (--one-at-a-time: each rank's compute timed as if alone on its machine, for a
machine whose cores are shared). Prints per rank: compute wall and CPU seconds, peak resident
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


def run(n, mesh, level, d, write=False, one_at_a_time=False):
    stats = d / f"s{n}.json"
    args = ["mpirun", "-n", str(n), "--bind-to", "none", str(MPI), "refine", str(mesh), "--level",
            str(level), "--stats", str(stats), "-q"]
    args += ["-o", str(d / f"out{n}.pvtu")] if write else ["--no-write"]
    args += ["--one-at-a-time"] if one_at_a_time else []
    r = subprocess.run(args, capture_output=True, text=True, env=ENV)
    if r.returncode:
        sys.exit(r.stderr)
    return json.loads(stats.read_text())


def slowest(s, key):
    return max(p[key] for p in s["per_rank"])


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 26
    level = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    reps = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    v, t = cubes(n)
    configs = [("1 rank", 1, False), ("2 ranks", 2, False), ("2 ranks, one at a time", 2, True)]
    with tempfile.TemporaryDirectory() as tmp:
        d = pathlib.Path(tmp)
        mesh = d / "cubes.json"
        mesh.write_text(json.dumps({"vertices": v, "simplices": t}))
        print(f"{n}^3 cubes: {len(v)} vertices, {len(t)} tetrahedra, level {level}; "
              f"best of {reps} (interleaved)")
        runs = {c[0]: [] for c in configs}
        for _ in range(reps):   # interleaved, so a busy minute hits every configuration
            for name, ranks, one in configs:
                runs[name].append(run(ranks, mesh, level, d, one_at_a_time=one))
        best = {name: min(rs, key=lambda s: slowest(s, "compute_s")) for name, rs in runs.items()}
        cpu = {name: min(slowest(s, "compute_cpu_s") for s in rs) for name, rs in runs.items()}
        for name, ranks, one in configs:
            b = best[name]
            lc = b["level_counts"]
            w = run(ranks, mesh, level, d, write=True) if not one else None
            print(f"\n{name}: level {level} has {lc['tetrahedra'] + lc['octahedra']} cells, "
                  f"{lc['points']} points" +
                  (f"; write {slowest(w, 'write_s'):.2f} s, "
                   f"{sum(p['write_bytes'] for p in w['per_rank']) / 1e9:.2f} GB" if w else ""))
            print("rank  compute_s  cpu_s  partition_s  build_s  refine_s  ids_s  peak_MB  "
                  "owned_cells  local_cells  halo")
            for p in b["per_rank"]:
                halo = 1 - p["owned_cells"] / p["local_cells"]
                print(f"{p['rank']:4d}  {p['compute_s']:9.2f}  {p['compute_cpu_s']:5.2f}  "
                      f"{p['partition_s'] + p['cut_s']:11.2f}  {p['build_s']:7.2f}  "
                      f"{p['refine_s']:8.2f}  {p['ids_s']:5.2f}  "
                      f"{p['peak_rss_bytes'] / 2**20:7.0f}  {p['owned_cells']:11d}  "
                      f"{p['local_cells']:11d}  {100 * halo:4.1f}%")
        t1 = slowest(best["1 rank"], "compute_s")
        m1 = slowest(best["1 rank"], "peak_rss_bytes")
        for name in ("2 ranks", "2 ranks, one at a time"):
            print(f"{name}: speed-up {t1 / slowest(best[name], 'compute_s'):.2f}x wall, "
                  f"{cpu['1 rank'] / cpu[name]:.2f}x CPU of the slowest rank; peak memory per rank "
                  f"{slowest(best[name], 'peak_rss_bytes') / m1:.2f}x of one rank's")


if __name__ == "__main__":
    main()
