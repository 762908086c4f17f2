"""MUMPS on the hemisphere's Jacobian: orderings, flops, factor size and time, per rank count.

    ./drape exec python3 benchmarks/bench_factorisation.py                 # full sheet, 2.5 mm
    ./drape exec mpirun -n 2 python3 benchmarks/bench_factorisation.py
    ./drape exec python3 benchmarks/bench_factorisation.py --cell-mm 5 --icntl-4 2
    ./drape exec python3 benchmarks/bench_factorisation.py --no-bending    # the truss pattern
    ./drape exec python3 benchmarks/bench_factorisation.py --travel-share 0.6 --structure
    ./drape exec python3 benchmarks/bench_factorisation.py --only CHOLMOD "PORD" "AMF"

The Jacobian is the full sheet's after one half step of punch travel (the contact and the
holder active), or after ``--travel-share`` of the travel (a curved sheet with buckled tows).
Every ordering factorises it once (analysis and factorisation), then three times more with
the analysis reused (the cost of a Newton iteration); the solve is timed too. ``INFOG(7)``
says which ordering MUMPS really used: Debian's ``libmumps-5.9`` is built with PORD only,
METIS (5) and SCOTCH (3) fall back to AMF (2) with the warning of ``--icntl-4 2``.
Debian's ``libmumps-ptscotch-5.9`` has SCOTCH and PT-Scotch under other library names; to
try it without rebuilding PETSc, extract the package (``apt-get download``, ``dpkg-deb -x``)
into a folder the command can see and put symbolic links named ``libdmumps-5.9.so``,
``libsmumps-5.9.so``, ``libmumps_common-5.9.so`` and ``libpord-5.9.so`` to its libraries first
on ``LD_LIBRARY_PATH`` (``mpirun -x LD_LIBRARY_PATH`` on several ranks). No Debian MUMPS has
METIS or ParMETIS.

``--structure`` adds preconditioned Krylov solvers that use the problem's structure instead
of one factorisation: the unknowns split into the in-plane (x, y) and out-of-plane (z)
displacements (PCFIELDSPLIT additive, symmetric multiplicative, and a Schur complement on z
with the ``selfp`` approximation; MUMPS on each block), and algebraic multigrid (GAMG). Each
is timed over setup and solve of one right-hand side (the residual) to 10⁻⁸, with its
Krylov iterations (300 at most).
"""

import argparse
import time

from mpi4py import MPI
from petsc4py import PETSc

from fenicsx_drape.fe import solver as fe_solver
from fenicsx_drape.forming import load_case, run_case

ORDERINGS = {  # name: MUMPS options (ICNTL(7) sequential, ICNTL(28)/(29) parallel analysis)
    "PORD": {"mat_mumps_icntl_7": 4},
    "AMD": {"mat_mumps_icntl_7": 0},
    "AMF": {"mat_mumps_icntl_7": 2},
    "QAMD": {"mat_mumps_icntl_7": 6},
    "METIS": {"mat_mumps_icntl_7": 5},
    "SCOTCH": {"mat_mumps_icntl_7": 3},
    "PT-Scotch": {"mat_mumps_icntl_28": 2, "mat_mumps_icntl_29": 1},
    "ParMETIS": {"mat_mumps_icntl_28": 2, "mat_mumps_icntl_29": 2},
    # Symmetric LDLᵀ without threshold pivoting (CNTL(1) = 0): the Jacobian is positive
    # definite on the forming runs once the geometric stiffness is limited.
    "PORD nopiv": {"mat_mumps_icntl_7": 4, "mat_mumps_cntl_1": 0.0},
    "AMF nopiv": {"mat_mumps_icntl_7": 2, "mat_mumps_cntl_1": 0.0},
    # Block low-rank factorisation (ICNTL(35) = 2) with dropping tolerance CNTL(7): the
    # off-diagonal blocks of the fronts compressed to that relative accuracy.
    "PORD BLR 1e-10": {"mat_mumps_icntl_7": 4, "mat_mumps_icntl_35": 2, "mat_mumps_cntl_7": 1e-10},
    "PORD BLR 1e-6": {"mat_mumps_icntl_7": 4, "mat_mumps_icntl_35": 2, "mat_mumps_cntl_7": 1e-6},
    # The factor in single precision (PETSc's mixed-precision MUMPS, -pc_precision).
    "PORD single": {"mat_mumps_icntl_7": 4, "pc_precision": "single"},
    "AMF single": {"mat_mumps_icntl_7": 2, "pc_precision": "single"},
    # Without MUMPS's scaling (ICNTL(8) = 0: none; the default 77 chooses one at every
    # factorisation), and with the analysis's amalgamation relaxed (ICNTL(6) = 0: no
    # maximum transversal).
    "PORD noscale": {"mat_mumps_icntl_7": 4, "mat_mumps_icntl_8": 0},
    "PORD notrans": {"mat_mumps_icntl_7": 4, "mat_mumps_icntl_6": 0},
    # The root front factorised by one process instead of with ScaLAPACK (ICNTL(13) = 1).
    "PORD root1": {"mat_mumps_icntl_7": 4, "mat_mumps_icntl_13": 1},
    # PETSc's own sequential factorisations with its nested dissection (one rank only).
    "PETSc nd": {"pc_factor_mat_solver_type": "petsc", "pc_factor_mat_ordering_type": "nd"},
    "PETSc rcm": {"pc_factor_mat_solver_type": "petsc", "pc_factor_mat_ordering_type": "rcm"},
    "PETSc LU nd": {"pc_type": "lu", "pc_factor_mat_solver_type": "petsc",
                    "pc_factor_mat_ordering_type": "nd"},
    # SuiteSparse in Debian's PETSc (one rank only): CHOLMOD's Cholesky LLᵀ (supernodal or
    # simplicial, its choice by default), UMFPACK's and KLU's LU (with --lu).
    "CHOLMOD": {"pc_factor_mat_solver_type": "cholmod"},
    "CHOLMOD supernodal": {"pc_factor_mat_solver_type": "cholmod",
                           "mat_cholmod_factor": "supernodal"},
    "CHOLMOD simplicial": {"pc_factor_mat_solver_type": "cholmod",
                           "mat_cholmod_factor": "simplicial"},
    "UMFPACK": {"pc_type": "lu", "pc_factor_mat_solver_type": "umfpack"},
    "KLU": {"pc_type": "lu", "pc_factor_mat_solver_type": "klu"},
}
SEQUENTIAL = ("petsc", "cholmod", "umfpack", "klu")
_BLOCKS = {f"fieldsplit_{k}_{key}": value for k in (0, 1) for key, value in
           {"ksp_type": "preonly", "pc_type": "cholesky",
            "pc_factor_mat_solver_type": "mumps"}.items()}
_XY_Z = {"pc_type": "fieldsplit", "pc_fieldsplit_block_size": 3, "pc_fieldsplit_0_fields": "0,1",
         "pc_fieldsplit_1_fields": "2", **_BLOCKS}
STRUCTURE = {  # name: KSP and PC options of a preconditioned Krylov solve
    "split xy|z additive": {"ksp_type": "gmres", **_XY_Z, "pc_fieldsplit_type": "additive"},
    "split xy|z multiplicative": {"ksp_type": "gmres", **_XY_Z,
                                  "pc_fieldsplit_type": "symmetric_multiplicative"},
    "Schur on z (selfp)": {"ksp_type": "fgmres", **_XY_Z, "pc_fieldsplit_type": "schur",
                           "pc_fieldsplit_schur_fact_type": "full",
                           "pc_fieldsplit_schur_precondition": "selfp"},
    "GAMG": {"ksp_type": "gmres", "pc_type": "gamg", "ksp_gmres_restart": 300},
}

parser = argparse.ArgumentParser()
parser.add_argument("--cell-mm", type=float, default=2.5)
parser.add_argument("--lu", action="store_true", help="LU instead of symmetric LDLᵀ")
parser.add_argument("--no-bending", action="store_true",
                    help="without the tow bending stencils (tow_bending_EI_Nmm2 = 0)")
parser.add_argument("--icntl-4", type=int, default=0, help="MUMPS print level")
parser.add_argument("--travel-share", type=float, default=0.0,
                    help="the Jacobian after this share of the punch travel (0: half a step)")
parser.add_argument("--structure", action="store_true",
                    help="also field-split and multigrid Krylov solvers")
parser.add_argument("--only", nargs="*", default=None, metavar="NAME",
                    help="only these rows of ORDERINGS (default: all)")
args = parser.parse_args()
comm = MPI.COMM_WORLD


def study(problem) -> None:
    problem._jacobian(problem._x)
    A = problem._A
    b = A.createVecLeft()
    b.set(1.0)
    y = b.duplicate()
    for k, (name, options) in enumerate(ORDERINGS.items()):
        if args.only is not None and name not in args.only:
            continue
        if options.get("pc_factor_mat_solver_type") in SEQUENTIAL and comm.size > 1:
            continue  # PETSc's own factorisations and SuiteSparse's are sequential
        prefix = f"bench_factor_{k}_"
        db = PETSc.Options()
        settings = {"ksp_type": "preonly", "pc_type": "lu" if args.lu else "cholesky",
                    "pc_factor_mat_solver_type": "mumps", **options}
        if settings["pc_factor_mat_solver_type"] == "mumps":
            settings["mat_mumps_icntl_4"] = args.icntl_4
        for key, value in settings.items():
            db[prefix + key] = value
        ksp = PETSc.KSP().create(comm)
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(A)
        ksp.setFromOptions()
        comm.Barrier()
        start = time.perf_counter()
        try:
            ksp.setUp()
        except PETSc.Error:
            if comm.rank == 0:
                print(f"{name:10s} {comm.size} rank(s): not available (MUMPS error)", flush=True)
            ksp.destroy()
            continue
        first = time.perf_counter() - start
        F = ksp.getPC().getFactorMatrix()
        mumps = ksp.getPC().getFactorSolverType() == "mumps"
        if mumps and F.getMumpsInfog(1) < 0:
            if comm.rank == 0:
                print(f"{name:10s} {comm.size} rank(s): MUMPS error INFOG(1) = "
                      f"{F.getMumpsInfog(1)}, INFOG(2) = {F.getMumpsInfog(2)}", flush=True)
            ksp.destroy()
            continue
        numeric = []
        for rep in range(3):  # a changed matrix, the same analysis
            A.scale(1.0 + 1e-12 * (rep + 1))
            ksp.setOperators(A)
            comm.Barrier()
            start = time.perf_counter()
            ksp.setUp()
            numeric.append(time.perf_counter() - start)
        comm.Barrier()
        start = time.perf_counter()
        for _ in range(5):
            ksp.solve(b, y)
        solve = (time.perf_counter() - start) / 5
        r = b.duplicate()
        A.mult(y, r)
        r.axpy(-1.0, b)
        error = r.norm() / b.norm()  # relative residual of the direct solve
        if comm.rank == 0:
            try:
                what = (f"used ordering {F.getMumpsInfog(7)}, {F.getMumpsRinfog(3):.3g} flops, "
                        f"{F.getMumpsInfog(29):.3g} factor entries" if mumps else
                        f"{F.getInfo()['nz_used']:.3g} factor entries")
            except PETSc.Error:
                what = ksp.getPC().getFactorSolverType()
            print(f"{name:10s} {comm.size} rank(s): {what}, first {first:.3f} s, "
                  f"factorisation {min(numeric):.3f} s, solve {1e3 * solve:.1f} ms, "
                  f"relative residual {error:.1e}", flush=True)
        ksp.destroy()
    if args.structure:
        krylov(A, problem)
    raise SystemExit


def krylov(A: PETSc.Mat, problem) -> None:
    """Setup and solve time and Krylov iterations of the ``STRUCTURE`` solvers."""
    b = problem._x.duplicate()  # ghosted, as the residual assembly expects
    problem._residual(problem._x, b)
    y = A.createVecLeft()
    for k, (name, options) in enumerate(STRUCTURE.items()):
        prefix = f"bench_krylov_{k}_"
        db = PETSc.Options()
        for key, value in {"ksp_rtol": 1e-8, "ksp_max_it": 300, **options}.items():
            db[prefix + key] = value
        ksp = PETSc.KSP().create(comm)
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(A)
        ksp.setFromOptions()
        ksp.solve(b, y)  # the analyses
        times = []
        for rep in range(3):  # a changed matrix: setup and solve, as in a Newton iteration
            A.scale(1.0 + 1e-12 * (rep + 1))
            ksp.setOperators(A)
            comm.Barrier()
            start = time.perf_counter()
            ksp.solve(b, y)
            times.append(time.perf_counter() - start)
        if comm.rank == 0:
            print(f"{name:26s} {comm.size} rank(s): setup and solve {min(times):.3f} s, "
                  f"{ksp.getIterationNumber()} Krylov iterations, reason "
                  f"{ksp.getConvergedReason()}", flush=True)
        ksp.destroy()


def run_then_study(self, duration_s, dt_s, **kwargs):
    if args.travel_share > 0:
        step_for(self, duration_s * args.travel_share, dt_s, **kwargs)
        if comm.rank == 0:
            print(f"the Jacobian at {100 * args.travel_share:.0f} % of the travel", flush=True)
    else:
        self.step(self.t + dt_s / 2)
    study(self)


step_for = fe_solver.TrussProblem.run
fe_solver.TrussProblem.run = run_then_study
options = fe_solver.SolverOptions(tow_bending_EI_Nmm2=0.0) if args.no_bending else None
run_case(load_case("hemisphere", cell_mm=args.cell_mm, symmetry=[]), options=options)
