"""Wall time, load steps, cut-backs and Newton iterations of the hemisphere, per rank count.

    ./drape exec python3 benchmarks/bench_forming.py                  # quarter 10 and 5 mm
    ./drape exec python3 benchmarks/bench_forming.py --full           # + the full 2.5 mm sheet
    ./drape --np 2 exec python3 benchmarks/bench_forming.py --full    # the same on two ranks
    ./drape exec python3 benchmarks/bench_forming.py --before         # the first solver
    ./drape exec python3 benchmarks/bench_forming.py --single-factor  # factor in single precision
    ./drape exec python3 benchmarks/bench_forming.py --bending-jacobian preconditioner
    ./drape exec python3 benchmarks/bench_forming.py --petsc-option "-snes_type newtontr"
    ./drape exec python3 benchmarks/bench_forming.py --save-nodes ref           # nodes to ref/
    ./drape exec python3 benchmarks/bench_forming.py --reference ref --petsc-option ...
    ./drape exec python3 benchmarks/bench_forming.py --max-wall-s 600 ...      # stop runs at 600 s

A JIT warm-up run (30 mm cells) comes first. ``--before`` runs the first solver
(backtracking line search, exact geometric stiffness, penetrating nodes projected onto the
tool surface; CHANGELOG.md, the solver study). Every line: nodes, unknowns, ranks, wall
time, accepted steps, cut-backs, SNES iterations (per step), Jacobians, Krylov iterations,
residual evaluations, maximum shear, the travel reached if the run stopped short, then where
its time went (the solver's timings: laws, nodal terms, residual and Jacobian assembly, and
the rest of Newton's solves: the linear solves); the machine's load average before the run;
with ``--reference`` the largest and mean node distance to the nodes that ``--save-nodes``
wrote there. ``--petsc-option`` (repeatable) passes options to SNES as
``drape form --petsc-option`` does (``docs/solver.md`` has the table these lines make).
``--max-wall-s`` stops a run after the first load step that ends past that wall time and prints
its line so far (the travel reached, its iterations and cut-backs) instead of letting it crawl.
"""

import argparse
import os
import time

from mpi4py import MPI

import numpy as np

from fenicsx_drape.errors import SolverError
from fenicsx_drape.fe.solver import SINGLE_PRECISION_FACTOR, SolverOptions
from fenicsx_drape.forming import load_case, run_case
from fenicsx_drape.forming.running.run import NODE_ATOL_N

parser = argparse.ArgumentParser()
parser.add_argument("--full", action="store_true", help="also the full sheet at 2.5 mm")
parser.add_argument("--only-full", action="store_true", help="only the full sheet at 2.5 mm")
parser.add_argument("--cells", type=float, nargs="*", default=[10.0, 5.0],
                    help="cell sizes of the quarter model (mm)")
parser.add_argument("--before", action="store_true", help="the first solver")
parser.add_argument("--petsc-option", action="append", default=[], metavar="OPTION",
                    help="PETSc options for SNES, e.g. '-snes_type newtontr' (repeatable)")
parser.add_argument("--save-nodes", metavar="DIR", help="write the formed nodes to DIR")
parser.add_argument("--reference", metavar="DIR", help="node distance to those in DIR")
parser.add_argument("--node-atol-N", type=float, default=None,
                    help=f"per-node force tolerance (N; default {NODE_ATOL_N}, 0: the 2-norm only)")
parser.add_argument("--line-search", default=None, help="line search (fe/newton.py)")
parser.add_argument("--single-factor", action="store_true",
                    help="MUMPS factor in single precision, GMRES to 1e-3 on it (fe/solver.py)")
parser.add_argument("--bending-jacobian", choices=("full", "diagonal", "preconditioner"),
                    default=None, help="SolverOptions.bending_jacobian (default: full)")
parser.add_argument("--max-wall-s", type=float, default=None,
                    help="stop each run after the load step that ends past this wall time (s)")
args = parser.parse_args()
comm = MPI.COMM_WORLD


def wall_limit(start):
    """A step hook that stops the run (as a failed step would) once it ran ``--max-wall-s``."""
    def check(problem):
        if comm.allreduce(time.perf_counter() - start > args.max_wall_s, op=MPI.LOR):
            raise SolverError(f"stopped by --max-wall-s {args.max_wall_s:g}")
    return None if args.max_wall_s is None else check


options = {"snes_atol": 1e-6, "node_atol_N": NODE_ATOL_N,
           "petsc_options": {"pc_type": "cholesky"}}
if args.petsc_option:
    from fenicsx_drape.fe.newton import set_petsc_options

    set_petsc_options(args.petsc_option)
if args.line_search is not None:
    options["line_search"] = args.line_search
if args.single_factor:
    options["petsc_options"].update(SINGLE_PRECISION_FACTOR)
if args.node_atol_N is not None:
    options["node_atol_N"] = args.node_atol_N
if args.bending_jacobian is not None:
    options["bending_jacobian"] = args.bending_jacobian
if args.before:
    from fenicsx_drape.forming.terms.contact import PenaltyContact

    options.update(line_search="bt", limit_geometric_stiffness=False, node_atol_N=0.0)

    def project(self, x, t):  # the first solver's predictor: penetrating nodes onto the surface
        g = self.tool.gap(x, t)
        return x - np.minimum(g.phi, 0.0)[:, None] * g.normal

    PenaltyContact.project = project

cases = [] if args.only_full else [load_case("hemisphere", cell_mm=c)
                                   for c in args.cells]
if args.full or args.only_full:
    cases.append(load_case("hemisphere", cell_mm=2.5, symmetry=[]))
run_case(load_case("hemisphere", cell_mm=30.0, duration_s=8.0),
         options=SolverOptions(**options), allow_incomplete=True)  # JIT warm-up
rows = []
for case in cases:
    load = os.getloadavg()[0]
    comm.Barrier()
    start = time.perf_counter()
    run = run_case(case, options=SolverOptions(**options), allow_incomplete=True,
                   on_step=wall_limit(start))
    wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    steps = run.problem.steps
    nodes = run.grid.X[..., 0].size
    rows.append((nodes, wall))
    part = 'quarter' if case.planes else 'full'
    name = f"{part}_{case.blank.cell_mm:g}.npz"
    distance = ""
    if args.save_nodes and comm.rank == 0:
        os.makedirs(args.save_nodes, exist_ok=True)
        np.savez(os.path.join(args.save_nodes, name), x=run.grid.x)
    if args.reference and not run.stopped:  # a run stopped short is not at the same travel
        d = np.linalg.norm(run.grid.x - np.load(os.path.join(args.reference, name))["x"], axis=-1)
        distance = f", nodes {np.nanmax(d):.3f} mm from the reference (mean {np.nanmean(d):.3f})"
    if comm.rank == 0:
        print(f"{part} {case.blank.cell_mm:5.2f} mm: {nodes:6d} nodes "
              f"{3 * nodes:6d} unknowns, {comm.size} rank(s), load {load:.1f}: {wall:7.1f} s, "
              f"{run.steps} steps, {run.cutbacks} cut back, {run.iterations} Newton iterations "
              f"({run.iterations / max(run.steps, 1):.2f} per step), "
              f"{sum(s.factorisations for s in steps)} Jacobians, "
              f"{sum(s.krylov_iterations for s in steps)} Krylov, "
              f"{sum(s.residual_evaluations for s in steps)} residuals, max shear "
              f"{np.abs(run.grid.shear_deg()).max():.2f}°{distance}"
              + (f"; stopped at {run.travel_mm:.1f} mm: {run.stopped}" if run.stopped else ""),
              flush=True)
        spent = dict(run.problem.timings)
        newton = spent.pop("solve")  # Newton's solves, with the parts below inside
        parts = ", ".join(f"{k} {v:.1f} s" for k, v in spent.items())
        print(f"    where the time went (rank 0): Newton {newton:.1f} s, of it {parts}, "
              f"linear solves and SNES {newton - sum(spent.values()):.1f} s", flush=True)
if comm.rank == 0 and len(rows) > 1:
    n, t = np.array(rows, dtype=float).T
    slope = np.polyfit(np.log(n), np.log(t), 1)[0]
    print(f"wall time grows as nodes^{slope:.2f} over {int(n.min())}-{int(n.max())} nodes")
