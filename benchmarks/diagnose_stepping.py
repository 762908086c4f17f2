"""Why Newton needs many iterations on the hemisphere: what switches, where the residual sits.

    ./drape exec python3 benchmarks/diagnose_stepping.py --cell-mm 10            # this solver
    ./drape exec python3 benchmarks/diagnose_stepping.py --cell-mm 10 --before   # the first
    ./drape exec python3 benchmarks/diagnose_stepping.py --cell-mm 2.5 --full --json out.json
    ./drape exec python3 benchmarks/diagnose_stepping.py --cell-mm 10 --show 73 74
    ./drape exec python3 benchmarks/diagnose_stepping.py --cell-mm 2.5 --along-step 78

A monitor on every Newton iterate (:func:`fenicsx_drape.fe.solver.monitoring`) records

- which bars switch between iterates: tows across ε = 0 (buckled/taut, eq. 4), the slider of
  the shear diagonals (elastic/plastic, eq. 7) and their dashpot (loading/unloading, eq. 8);
- which nodes enter or leave contact with each tool (φ < 0), and which friction bars of the
  holder switch between stick and slip (eq. 1); nodes that come under the holder or leave it
  (between steps);
- where the residual sits: its squared norm split over the nodes in contact, under the
  holder, on the symmetry edges and the free rest;
- the line search's step length λ.

An iteration is *wasted* when its line search cut the step (λ < 1) or it reduced ‖F‖ by less
than half, and every iteration of a failed (cut-back) attempt is wasted. A wasted iteration is
blamed on the switches in it (shared equally), or on "no switch" (the smooth nonlinearity, a
poor predictor). The table gives each cause's share of the wasted iterations.

``--before`` runs the first solver: backtracking line search (``bt``), the
exact geometric stiffness and a predictor that projected penetrating nodes onto the tool
surface (lifting pressed nodes off). The attribution is by coincidence, not cause: a switch
that happens in a wasted iteration is blamed (docs/solver-notes.md has the table; CHANGELOG.md
what removing each cause saved, each change measured alone).
"""

import argparse
import collections
import itertools
import json
import time

from mpi4py import MPI

import numpy as np

from fenicsx_drape.fe.grid import SYMMETRY_X, SYMMETRY_Y
from fenicsx_drape.fe.newton import Newton
from fenicsx_drape.fe.solver import SolverOptions, monitoring
from fenicsx_drape.forming import load_case, run_case
from fenicsx_drape.forming.running.run import NODE_ATOL_N
from fenicsx_drape.forming.terms.contact import PenaltyContact
from fenicsx_drape.forming.terms.holder import BlankHolder

CAUSES = {
    "tow": "tow buckled ↔ taut (eq. 4)",
    "slider": "shear slider elastic ↔ plastic (eq. 7)",
    "dashpot": "shear dashpot loading ↔ unloading (eq. 8)",
    "contact": "node enters/leaves contact (punch, die)",
    "slip": "holder friction stick ↔ slip (eq. 1)",
    "none": "no switch (smooth nonlinearity, predictor)",
}


class Probe:
    """Records the status of every switch and the residual's location at each iterate."""

    def __init__(self):
        self.attempts = []  # per attempt: list of iterate records
        self._current = None

    def status(self, p) -> dict[str, np.ndarray]:
        """Boolean status arrays of the switches at the problem's evaluated state."""
        st = p.state
        ε = st.strain.x.array[st.dofs]
        tows, _ = st.groups["tow"]
        shear, law = st.groups["shear"]
        history = st._history("shear")
        trial = st._trial.get("shear")
        out = {"tow": ε[tows] < 0.0}
        out["slider"] = np.abs(law.E_p * (ε[shear] - history[:, 0])) > law.sigma_o
        if trial is not None:
            new, old = trial[:, 1], history[:, 1]
            out["dashpot"] = np.sign(new) * (new - old) > 0.0
        else:
            out["dashpot"] = np.zeros(len(shear), dtype=bool)
        x = p.positions()
        contact = np.zeros(len(x), dtype=bool)
        for term in p.nodal_terms:
            if isinstance(term, PenaltyContact):
                touching = term.tool.gap(x, p.t + p.dt).phi < 0.0
                out[f"contact:{term.tool.name}"] = touching
                contact |= touching
            elif isinstance(term, BlankHolder):
                b = term.bars
                u = x[b, :2] - term.X[b, :2]
                _, dN, _ = term._law.update(np.hypot(u[:, 0], u[:, 1]), p.dt, term.state[b])
                slip = np.zeros(len(x), dtype=bool)
                slip[b] = dN == 0.0
                out["slip"] = slip
                out["_holder"] = term.under.copy()
        out["_contact"] = contact
        return out

    def __call__(self, p, iterate) -> None:
        if iterate.iteration == 0:
            self._current = []
            self.attempts.append(self._current)
        st = self.status(p)
        n = p.num_owned
        r2 = (p.newton.F.array_r.reshape(-1, 3) ** 2).sum(axis=1)
        sym = (p.node_flags[:n] & (SYMMETRY_X | SYMMETRY_Y)) != 0
        contact, holder = st.pop("_contact")[:n], st.pop("_holder", np.zeros(n, bool))[:n]
        sets = {"contact": contact, "holder": holder & ~contact,
                "symmetry": sym & ~holder & ~contact, "free": ~sym & ~holder & ~contact}
        share = {k: float(r2[m].sum()) for k, m in sets.items()}
        comm = p.comm
        share = {k: comm.allreduce(v) for k, v in share.items()}
        total = max(sum(share.values()), 1e-300)
        self._current.append({"it": iterate.iteration, "fnorm": iterate.residual_norm,
                              "lam": iterate.step_length, "status": st,
                              "share": {k: v / total for k, v in share.items()}})


def switches(probe: Probe, comm) -> list[list[dict[str, int]]]:
    """Per attempt and iteration: how many of each kind switched (all ranks)."""
    out = []
    for its in probe.attempts:
        rows = []
        for a, b in itertools.pairwise(its):
            row = {}
            for key in b["status"]:
                k = "contact" if key.startswith("contact") else key
                row[k] = row.get(k, 0) + comm.allreduce(
                    int(np.count_nonzero(a["status"][key] != b["status"][key])))
            rows.append(row)
        out.append(rows)
    return out


def blame(probe: Probe, steps, sw) -> tuple[collections.Counter, int, int, int]:
    """Shares of the wasted iterations by cause; (counter, wasted, in failed, total)."""
    causes = collections.Counter()
    wasted = failed = total = 0
    for its, rows, step in zip(probe.attempts, sw, steps):
        for k, row in enumerate(rows, start=1):
            total += 1
            f0, f1, lam = its[k - 1]["fnorm"], its[k]["fnorm"], its[k]["lam"]
            bad = (not step.converged) or lam < 0.999 or f1 > 0.5 * f0
            if not bad:
                continue
            wasted += 1
            failed += not step.converged
            who = [c for c in ("tow", "slider", "dashpot", "contact", "slip") if row.get(c)]
            for c in who or ["none"]:
                causes[c] += 1.0 / max(len(who), 1)
    return causes, wasted, failed, total


def show(probe: Probe, sw, steps, which) -> None:
    for a in which:
        its, rows, step = probe.attempts[a - 1], sw[a - 1], steps[a - 1]
        print(f"attempt {a}: t = {step.time_s:.3f} s, dt = {step.dt_s:.3f} s, "
              f"{step.iterations} iterations, {step.reason}")
        for k, it in enumerate(its):
            row = rows[k - 1] if k else {}
            changes = " ".join(f"{c}:{v}" for c, v in row.items() if v)
            where = " ".join(f"{c} {v:.2f}" for c, v in it["share"].items() if v > 0.05)
            print(f"  {k:2d} |F| {it['fnorm']:9.2e}  λ {it['lam']:5.3f}  {changes:45s} {where}")


def along_step(newton, x, problem) -> None:
    """At the predictor ``x``: the exact Jacobian against central differences along the
    Newton step d, ‖F(x + λd)‖ along it, how far d moves the nodes, and the tows' strains."""
    F, G, H, d = (x.duplicate() for _ in range(4))
    newton.residual(x, F)
    newton.jacobian(x, True)
    A, ksp = newton.snes.getJacobian()[0], newton.snes.getKSP()
    ksp.setOperators(A)
    ksp.solve(F, d)
    d.scale(-1.0)
    Jd = d.duplicate()
    A.mult(d, Jd)
    for ε in (1e-5, 1e-7):
        for sign, V in ((1.0, G), (-1.0, H)):
            y = x.copy()
            y.axpy(sign * ε, d)
            newton.residual(y, V)
        G.axpy(-1.0, H)
        G.scale(0.5 / ε)
        G.axpy(-1.0, Jd)
        print(f"  central difference (ε = {ε:g}) against J d: relative error "
              f"{G.norm() / Jd.norm():.1e}")
    along = []
    for λ in (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0):
        y = x.copy()
        y.axpy(λ, d)
        newton.residual(y, G)
        along.append(f"{λ:g}: {G.norm():.3g}")
    print("  ‖F(x + λd)‖ (N):", ", ".join(along))
    n = problem.num_owned
    moved = np.linalg.norm(d.array_r[: 3 * n].reshape(-1, 3), axis=1)
    print(f"  the step moves {np.sum(moved > 0.1)} of {n} nodes by more than 0.1 mm "
          f"(largest {moved.max():.2f} mm, median {np.median(moved):.3f} mm)")
    points, _ = problem.state.groups["tow"]
    ε_t = problem.state.strain.x.array[problem.state.dofs[points]]
    slight = np.sum((ε_t < 0) & (ε_t > -0.01))
    print(f"  tows: {np.sum(ε_t < 0)} of {len(ε_t)} compressed, {slight} of them by less "
          "than 1 %")
    newton.residual(x, F)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cell-mm", type=float, default=10.0)
    parser.add_argument("--full", action="store_true", help="the full sheet (else a quarter)")
    parser.add_argument("--step-mm", type=float, default=1.0, help="punch travel per step")
    parser.add_argument("--before", action="store_true",
                        help="the first solver: bt line search, contact projected onto the tool")
    parser.add_argument("--show", type=int, nargs="*", default=[],
                        help="print the iterates of these attempts (1-based)")
    parser.add_argument("--json", help="write the per-attempt records here")
    parser.add_argument("--along-step", type=int, default=0,
                        help="at the predictor of this attempt (1-based; one rank): the "
                             "Jacobian against differences, ‖F‖ along the Newton step")
    parser.add_argument("--options", default="{}", help="SolverOptions fields as JSON")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    options = SolverOptions(**{"snes_atol": 1e-6, "node_atol_N": NODE_ATOL_N,
                               "petsc_options": {"pc_type": "cholesky"},
                               **json.loads(args.options)})
    if args.before:
        options.line_search, options.limit_geometric_stiffness = "bt", False
        options.node_atol_N = 0.0

        def project(self, x, t):  # the first solver's predictor
            g = self.tool.gap(x, t)
            return x - np.minimum(g.phi, 0.0)[:, None] * g.normal

        PenaltyContact.project = project
    if args.along_step:
        solve, attempts = Newton.solve, itertools.count(1)

        def solve_and_look(self, x):
            if next(attempts) == args.along_step:
                print(f"attempt {args.along_step}, at the predictor:")
                along_step(self, x, self.residual.__self__)
            return solve(self, x)

        Newton.solve = solve_and_look
    probe = Probe()
    start = time.perf_counter()
    with monitoring(probe):
        case = load_case("hemisphere", cell_mm=args.cell_mm, step_mm=args.step_mm,
                         symmetry=[] if args.full else None)
        run = run_case(case, options=options, allow_incomplete=True)
    wall = time.perf_counter() - start
    steps = run.problem.steps
    sw = switches(probe, comm)
    causes, wasted, failed, total = blame(probe, steps, sw)
    if comm.rank != 0:
        return
    name = f"{'full' if args.full else 'quarter'} {args.cell_mm:g} mm"
    print(f"{name} ({'before' if args.before else 'this solver'}): {run.steps} steps, "
          f"{run.cutbacks} cut back, {total} iterations ({total / max(run.steps, 1):.2f} per "
          f"step), {wasted} wasted ({failed} in cut-back attempts), {wall:.1f} s")
    print(f"  {'cause':45s} share of wasted iterations")
    for c, label in CAUSES.items():
        print(f"  {label:45s} {100 * causes[c] / max(wasted, 1):5.1f} %")
    first = [its[0]["fnorm"] for its in probe.attempts]
    print(f"  residual after the predictor: median {np.median(first):.3g} N, "
          f"max {np.max(first):.3g} N")
    where = collections.Counter()
    for its, step in zip(probe.attempts, steps):
        if not step.converged:
            share = its[-1]["share"]
            where[max(share, key=share.get)] += 1
    if where:
        print(f"  where the residual sat when a step failed: {dict(where)}")
    show(probe, sw, steps, args.show)
    if args.json:
        records = [{"time_s": s.time_s, "converged": s.converged, "iterations": s.iterations,
                    "fnorm": [i["fnorm"] for i in its], "lam": [i["lam"] for i in its],
                    "switches": rows, "share": [i["share"] for i in its]}
                   for its, rows, s in zip(probe.attempts, sw, steps)]
        with open(args.json, "w") as f:
            json.dump({"causes": dict(causes), "wasted": wasted, "total": total,
                       "attempts": records}, f)


if __name__ == "__main__":
    main()
