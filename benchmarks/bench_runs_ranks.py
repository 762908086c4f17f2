"""Runs × ranks: the same forming runs one after the other on all ranks, or at once in groups.

Forms ``--runs`` runs of the quarter hemisphere on ``--cell-mm`` cells (holder frictions
μ = 0.20, 0.21, ...: distinct runs, about the same work) through
:func:`~fenicsx_drape.runs.form_many`, as ``compare`` and ``diagnose`` do,
with ``--ranks-per-run`` K (K ranks per run, ranks / K runs at once; default: all ranks per
run), no disk cache, after a JIT warm-up. Prints the wall time and the machine's load.

    ./drape exec python3 benchmarks/bench_runs_ranks.py --runs 2                  # 1 rank
    ./drape exec mpirun -n 2 python3 benchmarks/bench_runs_ranks.py --runs 2      # 1 run × 2 ranks
    ./drape exec mpirun -n 2 python3 benchmarks/bench_runs_ranks.py --runs 2 --ranks-per-run 1
"""

import argparse
import os
import time

from mpi4py import MPI

from fenicsx_drape import runs
from fenicsx_drape.forming.case.format import load_case
from fenicsx_drape.forming.running.run import run_case
from fenicsx_drape.model import default_model

parser = argparse.ArgumentParser()
parser.add_argument("--runs", type=int, default=2)
parser.add_argument("--cell-mm", type=float, default=5.0)
parser.add_argument("--ranks-per-run", type=int, default=None)


def main() -> None:
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    run_case(load_case("hemisphere", cell_mm=30.0, duration_s=8.0), comm=MPI.COMM_SELF,
             allow_incomplete=True)  # JIT warm-up, each rank alone
    case = load_case("hemisphere", cell_mm=args.cell_mm)
    jobs = [(case, default_model().with_parameters(mu=0.2 + 0.01 * k)) for k in range(args.runs)]
    load = os.getloadavg()[0]
    comm.Barrier()
    start = time.perf_counter()
    with runs.execution(workers=1, ranks_per_run=args.ranks_per_run):
        runs.form_many(jobs)
        record = runs.execution_record()
    wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    if comm.rank == 0:
        print(f"{args.runs} runs of the quarter at {args.cell_mm:g} mm, {comm.size} rank(s), "
              f"{record['workers']} run(s) at once × {record['ranks']} rank(s) each, "
              f"load {load:.1f}: {wall:.1f} s", flush=True)


if __name__ == "__main__":
    main()
