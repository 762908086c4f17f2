"""The tow bending in Newton's solve: factored whole, diagonal only, or as a preconditioner.

Forms the hemisphere (the quarter on cells of ``--cell-mm``, or ``--full-sheet``) once per
``SolverOptions.bending_jacobian`` mode given, back to back under the same load, with the
forming cases' solver options (``forming_options``: MUMPS LDLᵀ), after a JIT warm-up. Each
line: wall time, steps, cut-backs, Newton iterations, factorisations, Krylov iterations, the
time in linear solves, and the largest and mean distance of the formed nodes to the first
mode's.

    ./drape exec python3 benchmarks/bench_bending_jacobian.py --cell-mm 5
    ./drape exec python3 benchmarks/bench_bending_jacobian.py --full-sheet \\
        --modes full preconditioner
    ./drape exec python3 benchmarks/bench_bending_jacobian.py --modes preconditioner \\
        --petsc-option "-snes_lag_preconditioner 2"
"""

import argparse
import os
import time

import numpy as np

from fenicsx_drape.fe.newton import set_petsc_options
from fenicsx_drape.fe.solver import BENDING_JACOBIANS
from fenicsx_drape.forming.case.format import load_case
from fenicsx_drape.forming.running.run import forming_options, run_case
from fenicsx_drape.model import default_model

parser = argparse.ArgumentParser()
parser.add_argument("--cell-mm", type=float, default=10.0, help="cells of the quarter (mm)")
parser.add_argument("--full-sheet", action="store_true", help="the full sheet at 2.5 mm")
parser.add_argument("--modes", nargs="+", default=["full", "preconditioner"],
                    choices=BENDING_JACOBIANS)
parser.add_argument("--petsc-option", action="append", default=[], metavar="OPTION",
                    help="PETSc options for every mode, e.g. '-ksp_rtol 1e-6' (repeatable)")


def main() -> None:
    args = parser.parse_args()
    if args.petsc_option:
        set_petsc_options(args.petsc_option)
    case = (load_case("hemisphere", cell_mm=2.5, symmetry=[]) if args.full_sheet
            else load_case("hemisphere", cell_mm=args.cell_mm))
    model = default_model()
    run_case(load_case("hemisphere", cell_mm=30.0, duration_s=8.0), model,
             forming_options(model), allow_incomplete=True)  # JIT warm-up
    first = None
    for mode in args.modes:
        load = os.getloadavg()[0]
        start = time.perf_counter()
        run = run_case(case, model, forming_options(model, bending_jacobian=mode),
                       allow_incomplete=True)
        wall = time.perf_counter() - start
        steps = run.problem.steps
        distance = ""
        if first is None:
            first = run.grid.x
        elif not run.stopped:
            d = np.linalg.norm(run.grid.x - first, axis=-1)
            distance = f", nodes {np.nanmax(d):.4f} mm from the first (mean {np.nanmean(d):.4f})"
        print(f"{mode:14s} load {load:.1f}: {wall:6.1f} s, {run.steps} steps, "
              f"{run.cutbacks} cut back, {run.iterations} Newton iterations, "
              f"{sum(s.factorisations for s in steps)} Jacobians, "
              f"{sum(s.krylov_iterations for s in steps)} Krylov, linear solves and the rest "
              f"of SNES {run.problem.timings['solve']:.1f} s, max shear "
              f"{np.abs(run.grid.shear_deg()).max():.2f}°{distance}"
              + (f"; stopped at {run.travel_mm:.1f} mm" if run.stopped else ""), flush=True)


if __name__ == "__main__":
    main()
