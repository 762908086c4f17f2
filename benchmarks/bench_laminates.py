"""Stacks of plies against one ply: time, Newton and Krylov iterations, factorisation flops.

    ./drape exec python3 benchmarks/bench_laminates.py                       # the double dome
    ./drape exec python3 benchmarks/bench_laminates.py --plies 1 2 4 8 --solver plies
    ./drape exec python3 benchmarks/bench_laminates.py --plies 1 2 4 8 --orderings
    ./drape exec python3 benchmarks/bench_laminates.py --case hemisphere --cell-mm 20

The case at its own net (quarter model), one rank: the single ply, then stacks of two, four
and eight plies, all at 0° (a turned ply breaks the quarter symmetry), the die's gap the
stack's (the double dome's die lifted by :data:`GAP` times it), the pairs following the
plies (the default). ``--solver`` chooses the stack's linear solve
(``SolverOptions.stack_solver``: ``direct``, the default, one factorisation of the stack;
``plies``, GMRES preconditioned by each ply's factor and the stack moving as one,
fe/stack_solver.py; ``--lag`` keeps its factors over that many Newton iterations).
``--orderings`` factors each run's last Jacobian again with each of MUMPS's orderings and
with PETSc's own LU and its orderings, and prints the flops (MUMPS), the factor's entries and
the CPU time of each.

Every line: plies, nodes, wall and CPU time and their ratios to the single ply's (CPU is the
steadier figure on a shared machine), steps, cut-backs, Newton iterations, Krylov iterations,
the flops of one Jacobian's factorisations (MUMPS's estimates, RINFOG(3): the whole stack's, or
the sum of the plies' and the coarse one's) and each ply's maximum shear. The machine's load
average comes first. Every case's tools are built before its clock starts (a stack's die sits
at the stack's gap, another tool than the single ply's): the times are the forming's.
"""

import argparse
import dataclasses
import os
import time

import numpy as np

from fenicsx_drape.forming.case import PlySpec, load_case
from fenicsx_drape.forming.running.run import case_model, forming_options, run_case
from fenicsx_drape.forming.tools.build import build_tools

parser = argparse.ArgumentParser()
parser.add_argument("--case", default="double_dome")
parser.add_argument("--cell-mm", type=float, default=None)
parser.add_argument("--duration-s", type=float, default=None)
parser.add_argument("--plies", type=int, nargs="+", default=[1, 2, 4, 8])
parser.add_argument("--solver", default="direct", choices=["plies", "direct"])
parser.add_argument("--lag", type=int, default=None,
                    help="keep the preconditioner's factors over LAG Newton iterations "
                         "(-snes_lag_preconditioner; with --solver plies)")
parser.add_argument("--orderings", action="store_true",
                    help="factor each stack's last Jacobian again with MUMPS's orderings "
                         "and PETSc's")
args = parser.parse_args()

GAP = 1.25
"""The double dome's die lifted by this many times the stack's thickness (its normal gap is
less than the lift where the surface slopes)."""

ORDERINGS = {"AMD": 0, "AMF": 2, "PORD": 4, "QAMD": 6}
"""MUMPS's orderings (ICNTL(7)) in Debian's build (METIS and SCOTCH fall back to AMF)."""


PETSC_ORDERINGS = ("nd", "rcm", "qmd")
"""PETSc's own LU with its orderings (nested dissection, reverse Cuthill-McKee, quotient
minimum degree): the factor's entries and the CPU time of one factorisation."""


def ordering_flops(A) -> str:
    """MUMPS's flops (RINFOG(3)) and its factor's entries (INFOG(29)) for each ordering, and
    PETSc's own LU's factor entries and CPU time for each of its orderings."""
    from petsc4py import PETSc

    out = []
    for name, code in [*ORDERINGS.items(), *((o, None) for o in PETSC_ORDERINGS)]:
        ksp = PETSc.KSP().create(A.getComm())
        ksp.setOperators(A)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType("mumps" if code is not None else "petsc")
        if code is None:
            pc.setFactorOrdering(name)
        pc.setFactorSetUpSolverType()
        F = pc.getFactorMatrix()
        if code is not None:
            F.setMumpsIcntl(7, code)
        cpu = time.process_time()
        ksp.setUp()
        cpu = time.process_time() - cpu
        if code is not None:
            out.append(f"{name} {F.getMumpsRinfog(3) / 1e6:.1f} Mflop, "
                       f"{F.getMumpsInfog(29) / 1e3:.0f} k entries, {1e3 * cpu:.0f} ms")
        else:
            entries = pc.getFactorMatrix().getInfo()["nz_used"]
            out.append(f"PETSc {name} {entries / 1e3:.0f} k entries, {1e3 * cpu:.0f} ms")
        ksp.destroy()
    return "; ".join(out)


def flops(problem) -> float:
    """MUMPS's flops of the last factorisations of the problem's Jacobian (all its factors)."""
    ksps = [problem.newton.snes.getKSP()]
    pre = getattr(problem, "stack_preconditioner", None)
    if pre is not None:
        ksps = [*pre._solvers, pre._coarse_solver]
    total = 0.0
    for ksp in ksps:
        factor = ksp.getPC().getFactorMatrix()
        total += factor.getMumpsRinfog(3) if factor.getType() == "mumps" else float("nan")
    return total


base = load_case(args.case, cell_mm=args.cell_mm, duration_s=args.duration_s)
run_case(load_case(args.case, cell_mm=30.0))  # JIT warm-up
print(f"load average {os.getloadavg()[0]:.2f}; case {base.name}, cell {base.blank.cell_mm:g} mm, "
      f"stack solver {args.solver}" + (f", preconditioner lagged {args.lag}" if args.lag else ""))
single = cpu_single = None
for n in args.plies:
    # The die's gap is the stack's thickness (the builtin tools' ply_thickness_mm): a die
    # closing on one ply's gap would squeeze the stack. The double dome's die is the punch
    # lifted by offset_mm, whose normal gap narrows on its slopes (0.96 of the lift at 1.2 mm,
    # 0.82 at 2.4 mm): lifted by GAP × the stack's thickness, one ply or eight.
    gap = {k: 0.3 * n * (GAP if k == "offset_mm" else 1.0)
           for k in ("offset_mm", "ply_thickness_mm") if any(k in t.params for t in base.tools)}
    case = load_case(args.case, cell_mm=args.cell_mm, duration_s=args.duration_s, **gap)
    if n > 1:
        case = dataclasses.replace(case, plies=(PlySpec(0.0, 0.3),) * n)
    build_tools(case)  # kept in the process (a meshed tool is read once)
    # A lagged factor only with GMRES (the plies' solver; one ply is factored, not lagged).
    lag = {"snes_lag_preconditioner": str(args.lag)} if args.lag and n > 1 else {}
    options = forming_options(case_model(case), stack=case.stack, stack_solver=args.solver,
                              petsc_options=lag)
    start, cpu = time.perf_counter(), time.process_time()
    run = run_case(case, options=options)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    single, cpu_single = single or wall, cpu_single or cpu
    grids = run.plies or [run.grid]
    shear = ", ".join(f"{np.nanmax(np.abs(g.shear_deg())):.1f}" for g in grids)
    krylov = sum(s.krylov_iterations for s in run.problem.steps)
    print(f"{n} plies: {run.problem.num_owned} nodes, wall {wall:.1f} s ({wall / single:.2f}x), "
          f"CPU {cpu:.1f} s ({cpu / cpu_single:.2f}x); {run.steps} steps, {run.cutbacks} "
          f"cut-backs, {run.iterations} Newton ({run.iterations / run.steps:.2f} a step), "
          f"{krylov} Krylov; {flops(run.problem) / 1e6:.1f} Mflop a Jacobian's factors "
          f"({run.problem.bending_jacobian}); max shear per ply {shear} deg", flush=True)
    if args.orderings:
        print(f"    the last Jacobian's factor by ordering: {ordering_flops(run.problem._A)}",
              flush=True)
