"""Speed of the truss FE core, and the effect of its regularising options.

Speed: the 240 × 240 mm sheet at Δ = 10, 5 and 2.5 mm under a prescribed in-plane history
(the border follows x ↦ F(t) X with 1 % stretch along the warp and a 0.2 simple shear in 10 s,
then holds 5 s while the rate-dependent shear law relaxes; interior nodes free in the plane).
Prints wall time, Newton iterations and where the time goes, and the exponent p of
time ∝ nodes^p. Run serially and on 2 ranks::

    ./drape exec python3 benchmarks/bench_fe.py
    ./drape exec mpirun -n 2 python3 benchmarks/bench_fe.py

Regularisation (``--study regularisation``): a quarter sheet whose centre is lifted 40 mm by a
soft spherical cap while its border is held in z and by in-plane springs (0.2 N/mm per node,
a stand-in for the blank holder) as it draws in, so tows buckle (wrinkling) around the cap.
The tow bending stiffness and the buckled-tow stiffness (both part of the model) are halved in
turn; the change of node positions and of the maximum shear angle is printed against the
stated tolerances, and the total wrinkling strain as a band over the runs. Runs with the
numerical drag show how much it would bias the result.
"""

import argparse
import dataclasses
import time

from mpi4py import MPI

import numpy as np

from fenicsx_drape.fe import SolverOptions, TrussProblem, truss_sheet
from fenicsx_drape.model import default_model

comm = MPI.COMM_WORLD


def say(*args):
    if comm.rank == 0:
        print(*args, flush=True)


def speed(cells_mm):
    say(f"In-plane stretch history of the 240 mm sheet on {comm.size} rank(s)")
    say(f"{'Δ mm':>6} {'nodes':>6} {'dofs':>6} {'steps':>5} {'Newton':>6} {'wall s':>7} "
        f"{'s/Newton':>8} {'material':>8} {'residual':>8} {'jacobian':>8} {'LU+rest':>8}")
    G = np.array([[0.01, 0.2], [0.0, 0.0]])
    rows = []
    for cell in cells_mm:
        start = time.perf_counter()
        sheet = truss_sheet(240.0, cell)
        problem = TrussProblem(sheet, default_model())
        problem.fix("all", (2,))
        problem.fix("border", (0, 1), lambda t, X: min(t, 10.0) / 10.0 * X[:, :2] @ G.T)
        setup = time.perf_counter() - start
        start = time.perf_counter()
        report = problem.run(15.0, 0.5)
        wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
        t = problem.timings
        rest = t["solve"] - t["material"] - t["nodal"] - t["residual"] - t["jacobian"]
        nodes = sheet.num_nodes_global
        its = report.iterations
        rows.append((nodes, wall))
        res = problem.results()
        say(f"{sheet.cell_mm:6.2f} {nodes:6d} {3 * nodes:6d} {len(report.accepted):5d} {its:6d} "
            f"{wall:7.2f} {wall / its:8.4f} {t['material']:8.2f} {t['residual']:8.2f} "
            f"{t['jacobian']:8.2f} {rest:8.2f}   (setup {setup:.1f} s, max shear "
            f"{res.max_shear_deg:.2f}°)")
    if len(rows) > 1:
        n, w = np.log(np.array(rows)).T
        say(f"wall time ∝ nodes^{np.polyfit(n, w, 1)[0]:.2f}")


class SoftCap:
    """A spherical cap (radius 60 mm) rising at constant speed, acting on nodes by a penalty (a
    NodalTerm; the forming cases use the exact tools of ``fenicsx_drape.forming``)."""

    R, k = 60.0, 200.0  # mm, N/mm

    def __init__(self, rise_mm, duration_s):
        self.speed = rise_mm / duration_s

    def bind(self, X, owned, comm):
        pass

    def forces(self, x, t, dt):
        centre = np.array([0.0, 0.0, self.speed * t - self.R])
        r = x - centre
        d = np.linalg.norm(r, axis=1)
        n = r / d[:, None]
        gap = self.R - d  # > 0: inside the cap
        inside = gap > 0
        f = np.where(inside[:, None], self.k * gap[:, None] * n, 0.0)
        # K = -df/dx = k (n n^T - gap/d (I - n n^T)) inside
        nn = n[:, :, None] * n[:, None, :]
        K = self.k * (nn - (gap / d)[:, None, None] * (np.eye(3) - nn))
        return f, np.where(inside[:, None, None], K, 0.0)

    def commit(self):
        pass

    def revert(self):
        pass


class BorderSprings:
    """In-plane springs (N/mm per node) holding the border nodes back: a stand-in holder."""

    k = 0.2

    def bind(self, X, owned, comm):
        self.X = X
        self.on = np.zeros(len(X), dtype=bool)

    def forces(self, x, t, dt):
        f = np.zeros_like(x)
        f[self.on, :2] = -self.k * (x - self.X)[self.on, :2]
        K = np.zeros((len(x), 3, 3))
        K[self.on, 0, 0] = K[self.on, 1, 1] = self.k
        return f, K

    def commit(self):
        pass

    def revert(self):
        pass


def lifted(options, cell_mm=10.0, duration_s=15.0):
    sheet = truss_sheet(240.0, cell_mm, quarter=True)
    springs = BorderSprings()
    problem = TrussProblem(sheet, default_model(), [SoftCap(40.0, duration_s), springs],
                           options)
    springs.on = problem.nodes("border")
    problem.symmetry()
    problem.fix("border", (2,))
    report = problem.run(duration_s, 0.5, dt_max_s=0.5)
    return problem.results(), report


def regularisation(cell_mm):
    base = SolverOptions()
    half = {"tow bending EI / 2": {"tow_bending_EI_Nmm2": base.tow_bending_EI_Nmm2 / 2},
            "buckled tow stiffness / 2": {
                "buckled_tow_stiffness_N": base.buckled_tow_stiffness_N / 2},
            # The numerical drag, for comparison (not in the reference model):
            "+ drag 0.02 N/mm": {"drag_N_per_mm": 0.02},
            "+ drag 0.01 N/mm": {"drag_N_per_mm": 0.01}}
    say(f"Centre lifted 40 mm by a soft cap, quarter sheet, Δ = {cell_mm} mm, {comm.size} "
        f"rank(s); reference: tow bending EI {base.tow_bending_EI_Nmm2} N·mm², buckled tow "
        f"stiffness {base.buckled_tow_stiffness_N} N/tow, no drag")
    say(f"{'variant':>26} {'Newton':>6} {'max shear °':>11} {'total wrinkling':>15} "
        f"{'min wrinkling':>13} {'max |Δx| mm':>11} {'Δ max shear °':>13}")
    results = {}
    for name, change in {"reference": {}, **half}.items():
        res, report = lifted(dataclasses.replace(base, **change), cell_mm)
        results[name] = res
        ref = results["reference"]
        dx = np.abs(res.x - ref.x).max()
        dshear = res.max_shear_deg - ref.max_shear_deg
        say(f"{name:>26} {report.iterations:6d} {res.max_shear_deg:11.3f} "
            f"{100 * res.total_wrinkling_strain:14.4f}% {res.min_wrinkling_strain:13.4f} "
            f"{dx:11.4f} {dshear:13.4f}")
    total = [100 * results[k].total_wrinkling_strain for k in list(results)[:3]]
    say(f"tolerances: node positions 0.1 Δ = {0.1 * cell_mm:g} mm, max shear 0.5°; total "
        f"wrinkling band over the model's halvings {min(total):.4f}% .. {max(total):.4f}%")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", choices=["speed", "regularisation"], default="speed")
    parser.add_argument("--cells", type=float, nargs="+", default=[10.0, 5.0, 2.5],
                        help="unit-cell sizes Δ (mm)")
    args = parser.parse_args()
    if args.study == "speed":
        speed(args.cells)
    else:
        regularisation(args.cells[0])
