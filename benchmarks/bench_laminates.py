"""Stacks of plies against one ply: wall time, Newton iterations and time per iteration.

    ./drape exec python3 benchmarks/bench_laminates.py                       # the double dome
    ./drape exec python3 benchmarks/bench_laminates.py --case hemisphere --cell-mm 20

The case at its own net (quarter model), one rank: the single ply, then stacks of two and four
plies, all at 0° (a turned ply breaks the quarter symmetry), the die's gap the stack's. Every
line: plies, nodes, wall time, steps, cut-backs, Newton iterations (per step), time per
iteration, the ratio of the wall time to the single ply's, the process's CPU time and its
ratio (steadier than the wall time on a shared machine), the factorisation's flops (MUMPS's
estimate, RINFOG(3)) and which bending Jacobian the size chose, and each ply's maximum shear. The
machine's load average comes first. Every case's tools are built before its clock starts
(a stack's die sits at the stack's gap, another tool than the single ply's): the times are
the forming's.
"""

import argparse
import dataclasses
import os
import time

import numpy as np

from fenicsx_drape.forming.case.format import PlySpec, build_tools, load_case
from fenicsx_drape.forming.running.run import run_case

parser = argparse.ArgumentParser()
parser.add_argument("--case", default="double_dome")
parser.add_argument("--cell-mm", type=float, default=None)
parser.add_argument("--duration-s", type=float, default=None)
args = parser.parse_args()

base = load_case(args.case, cell_mm=args.cell_mm, duration_s=args.duration_s)
run_case(load_case(args.case, cell_mm=30.0))  # JIT warm-up
print(f"load average {os.getloadavg()[0]:.2f}; case {base.name}, cell {base.blank.cell_mm:g} mm")
single = cpu_single = None
for angles in ((0.0,), (0.0, 0.0), (0.0, 0.0, 0.0, 0.0)):
    # The die's gap is the stack's thickness (the double dome's offset_mm, the builtin tools'
    # ply_thickness_mm): a die closing on one ply's gap would squeeze the stack.
    gap = {k: 0.3 * len(angles) for k in ("offset_mm", "ply_thickness_mm")
           if any(k in t.params for t in base.tools)}
    case = load_case(args.case, cell_mm=args.cell_mm, duration_s=args.duration_s, **gap)
    if len(angles) > 1:
        case = dataclasses.replace(case, plies=tuple(PlySpec(a, 0.3) for a in angles))
    build_tools(case)  # kept in the process (a meshed tool is read once)
    start, cpu = time.perf_counter(), time.process_time()
    run = run_case(case)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    single, cpu_single = single or wall, cpu_single or cpu
    grids = run.plies or [run.grid]
    shear = ", ".join(f"{np.nanmax(np.abs(g.shear_deg())):.1f}" for g in grids)
    nodes = run.problem.num_owned
    factor = run.problem.newton.snes.getKSP().getPC().getFactorMatrix()
    flops = factor.getMumpsRinfog(3) if factor.getType() == "mumps" else float("nan")
    print(f"{len(angles)} plies: {nodes} nodes, {wall:.1f} s, {run.steps} steps, "
          f"{run.cutbacks} cut-backs, {run.iterations} Newton ({run.iterations / run.steps:.2f} "
          f"per step), {1e3 * wall / run.iterations:.1f} ms per iteration, "
          f"{wall / single:.2f}x the single ply; CPU {cpu:.1f} s, {cpu / cpu_single:.2f}x; "
          f"{flops / 1e6:.1f} Mflop a factorisation ({run.problem.bending_jacobian}); "
          f"max shear per ply {shear} deg")
