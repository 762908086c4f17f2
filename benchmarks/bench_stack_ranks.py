"""A stack of plies formed on one rank or several: wall time, Newton iterations, results.

    ./drape exec python3 benchmarks/bench_stack_ranks.py
    ./drape --np 2 exec python3 benchmarks/bench_stack_ranks.py

The [0/90, ±45] stack on the hemisphere (``meshes/hemisphere/stack_0_45.toml``, the whole
blank) at ``--cell-mm`` (default the case's 10 mm) in 8 s, on every rank of ``COMM_WORLD``.
Rank 0 prints the machine's load average, the ranks and nodes, wall time, steps, Newton
iterations, time per iteration, the slowest rank's time in the solve's parts
(``TrussProblem.timings``), each ply's maximum shear and the interface's largest sliding and
pressure (the numbers one rank must repeat). The JIT is warmed up on a coarse net first.
"""

import argparse
import os
import time
from pathlib import Path

from mpi4py import MPI

import numpy as np

from fenicsx_drape.forming.case.format import build_tools, load_case
from fenicsx_drape.forming.running.outputs import interply_maps
from fenicsx_drape.forming.running.run import run_case

CASE = Path(__file__).resolve().parents[1] / "meshes" / "hemisphere" / "stack_0_45.toml"

parser = argparse.ArgumentParser()
parser.add_argument("--case", default=str(CASE))
parser.add_argument("--cell-mm", type=float, default=None)
parser.add_argument("--duration-s", type=float, default=8.0)
args = parser.parse_args()
comm = MPI.COMM_WORLD

run_case(load_case(args.case, cell_mm=30.0, duration_s=args.duration_s))  # JIT warm-up
case = load_case(args.case, cell_mm=args.cell_mm, duration_s=args.duration_s)
build_tools(case)
comm.Barrier()
start = time.perf_counter()
run = run_case(case, comm=comm)
wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
parts = {k: comm.allreduce(v, op=MPI.MAX) for k, v in run.problem.timings.items()}
faces = interply_maps(run)
nodes = comm.allreduce(run.problem.num_owned)
if comm.rank == 0:
    shear = ", ".join(f"{np.nanmax(np.abs(g.shear_deg())):.6f}" for g in run.plies)
    print(f"load average {os.getloadavg()[0]:.2f}; case {case.name}, cell "
          f"{case.blank.cell_mm:g} mm, {comm.size} rank(s), {nodes} nodes")
    print(f"{wall:.1f} s, {run.steps} steps, {run.cutbacks} cut-backs, {run.iterations} Newton, "
          f"{1e3 * wall / run.iterations:.1f} ms per iteration; slowest rank: "
          + ", ".join(f"{k} {v:.1f} s" for k, v in parts.items())
          + f" (the factorisations and the rest of Newton: "
          f"{parts['solve'] - sum(v for k, v in parts.items() if k != 'solve'):.1f} s)")
    print(f"max shear per ply {shear} deg; " + "; ".join(
        f"{f['interface']}: sliding up to {f['max_sliding_mm']:.6f} mm, pressure up to "
        f"{f['max_pressure_MPa']:.6f} MPa" for f in faces))
