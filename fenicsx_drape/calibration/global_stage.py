"""The global stage of a coupon fit: many starts, searched together, before the local fit.

A least-squares fit of the paper's laws has local minima (section 3.2 warns of them), and a
fit started from one guess cannot tell a poor minimum from the best the model allows. Here:

1. **Starts.** The named starts -- the curve-feature guess, Table 2 (the defaults), the
   values given in MODEL.toml -- and the best :data:`SOBOL_STARTS` of :data:`SCREEN` points of
   a scrambled Sobol sequence (seeded: reproducible) in the *box*: in the fitting variables
   (log parameters), the span of the named starts widened by :data:`BOX_DECADES` decades
   either side, within the variables' bounds. The Sobol points are judged in one vectorised
   unit-cell call (a call for k parameter sets costs about twice one) and must lie at least
   :data:`DISTINCT` apart.
2. **Local searches, together.** From every start a bounded Levenberg-Marquardt search
   (Marquardt's diagonal scaling; steps clipped to the variables' bounds: the physical range
   and four decades around the starts) runs in lockstep with the others: each iteration
   evaluates the trial points of all starts *and* their forward-difference Jacobians in one
   vectorised call. A start stops when an accepted step lowers its cost by less than
   :data:`FTOL` (relative), when its damping exceeds :data:`LAMBDA_MAX`, or after
   :data:`ITERATIONS` iterations.
3. **Result** (:class:`Search`). The local minima, each with its start, cost and error; the
   caller (:func:`fenicsx_drape.calibration.fitting.global_stage_search`) refines the lowest
   distinct ones by the local least squares and keeps the best. The spread of the minima and
   the starts that reached the best (within :data:`SAME_MINIMUM` of its error) are reported:
   a best reached from several independent starts is the evidence that the fit is at the
   best minimum the model family allows; a best found once is said to be so.

Parameter sets the laws reject or the unit cell cannot solve get an infinite cost (the batch
is split until the failing sets are isolated), so a wild Sobol point cannot stop the search.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

SCREEN = 256  # Sobol points judged in the box
SOBOL_STARTS = 4  # of them, this many best distinct points become starts
DISTINCT = 0.5  # minimum distance (log parameters, Euclidean) between two Sobol starts
BOX_DECADES = 1.0  # the box: the named starts' span widened by this many decades
ITERATIONS = 30  # cap on the lockstep Levenberg-Marquardt iterations
FTOL = 1e-7  # a start stops when an accepted step lowers its cost by less (relative)
LAMBDA_MAX = 1e8  # ... or when its damping grows beyond this
SAME_MINIMUM = 0.02  # minima within this fraction of the best normalised error: the best
SEED = 20080216  # Sobol scrambling seed: the global stage is reproducible


@dataclasses.dataclass
class Start:
    """One start of the global stage and the local minimum it reached."""

    name: str  # "curve features", "Table 2", "MODEL.toml", "Sobol 3", ...
    x0: np.ndarray  # start (fitting variables)
    x: np.ndarray  # local minimum (fitting variables)
    cost0: float  # Σ_tests (RMSE/noise)² at the start (inf when the laws reject it)
    cost: float  # ... at the local minimum
    iterations: int = 0
    polished: bool = False  # refined by the local least squares afterwards

    def record(self, names: Sequence[str], to_p, n_tests: int) -> dict[str, Any]:
        """A JSON-ready record of the start and its minimum."""
        return {"start": self.name,
                "start_parameters": {n: float(v) for n, v in zip(names, to_p(self.x0))},
                "normalised_at_start": _normalised(self.cost0, n_tests),
                "normalised": _normalised(self.cost, n_tests), "iterations": self.iterations,
                "polished": self.polished,
                "parameters": {n: float(v) for n, v in zip(names, to_p(self.x))}}


def _normalised(cost: float, n_tests: int) -> float:
    return math.sqrt(cost / n_tests) if math.isfinite(cost) else math.inf


def robust_residuals(res, X: np.ndarray) -> np.ndarray:
    """Residuals of variable sets ``X`` (k × n); a row of NaN where a set fails."""
    from fenicsx_drape.errors import ParameterError, SolverError

    try:
        with np.errstate(all="ignore"):
            R = res.residuals_sets(X)
        return np.where(np.isfinite(R), R, np.nan)
    except (ParameterError, SolverError, FloatingPointError, ZeroDivisionError,
            OverflowError, ValueError):
        if len(X) == 1:
            return np.full((1, sum(t.n_rows for t in res.tests)), np.nan)
        half = len(X) // 2
        return np.vstack([robust_residuals(res, X[:half]), robust_residuals(res, X[half:])])


def _jacobians(res, X: np.ndarray, upper: np.ndarray, fd_step: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Residuals (s × m) and forward-difference Jacobians (s × m × n) at points ``X`` (s × n)."""
    s, n = X.shape
    h = fd_step * np.maximum(1.0, np.abs(X))
    h = np.where(X + h > upper, -h, h)
    sets = np.concatenate([np.concatenate([x[None], x + np.diag(hx)]) for x, hx in zip(X, h)])
    R = robust_residuals(res, sets).reshape(s, n + 1, -1)
    J = (R[:, 1:] - R[:, :1]) / h[:, :, None]
    return R[:, 0], np.transpose(J, (0, 2, 1))


def _cost(R: np.ndarray) -> np.ndarray:
    c = np.sum(R**2, axis=-1)
    return np.where(np.isfinite(c), c, np.inf)


def box(variables, starts: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The search box in the fitting variables (module doc, 1.)."""
    X = np.array(starts)
    width = np.where(variables.log, BOX_DECADES * math.log(10.0), 1.0)
    lo = np.maximum(X.min(axis=0) - width, variables.lower)
    hi = np.minimum(X.max(axis=0) + width, variables.upper)
    return lo, hi


def sobol_starts(res, lo: np.ndarray, hi: np.ndarray, avoid: Sequence[np.ndarray]
                 ) -> list[tuple[np.ndarray, float]]:
    """The best distinct points of a scrambled Sobol sequence in the box, with their costs."""
    from scipy.stats import qmc

    n = lo.size
    points = lo + (hi - lo) * qmc.Sobol(n, scramble=True, seed=SEED).random(SCREEN)
    cost = _cost(robust_residuals(res, points))
    chosen: list[tuple[np.ndarray, float]] = []
    taken = [np.asarray(a) for a in avoid]
    for i in np.argsort(cost):
        if not math.isfinite(cost[i]) or len(chosen) == SOBOL_STARTS:
            break
        if all(np.linalg.norm(points[i] - t) >= DISTINCT for t in taken):
            chosen.append((points[i], float(cost[i])))
            taken.append(points[i])
    return chosen


def lockstep_lm(res, X0: np.ndarray, lo: np.ndarray, hi: np.ndarray, fd_step: float,
                iterations: int = ITERATIONS) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                       np.ndarray]:
    """Bounded Levenberg-Marquardt from every row of ``X0`` at once (module doc, 2.).

    Returns:
        The minima (s × n), their costs, their starting costs and the iterations per start.
    """
    x = np.clip(X0, lo, hi)
    R, J = _jacobians(res, x, hi, fd_step)
    cost = _cost(R)
    cost0 = cost.copy()
    s = x.shape[0]
    lam = np.full(s, 1e-3)
    active = np.isfinite(cost)
    its = np.zeros(s, int)
    for _ in range(iterations):
        if not active.any():
            break
        trial = x.copy()
        for k in np.flatnonzero(active):
            Jk = np.nan_to_num(J[k])
            A = Jk.T @ Jk
            g = Jk.T @ R[k]
            D = np.diag(np.maximum(np.diag(A), 1e-12 * max(np.trace(A), 1e-300)))
            try:
                step = np.linalg.solve(A + lam[k] * D, -g)
            except np.linalg.LinAlgError:
                step = -g / (lam[k] * np.diag(D))
            trial[k] = np.clip(x[k] + step, lo, hi)
        idx = np.flatnonzero(active)
        Rt, Jt = _jacobians(res, trial[idx], hi, fd_step)
        ct = _cost(Rt)
        for j, k in enumerate(idx):
            its[k] += 1
            if ct[j] < cost[k]:
                gain = (cost[k] - ct[j]) / cost[k]
                x[k], R[k], J[k], cost[k] = trial[k], Rt[j], Jt[j], ct[j]
                lam[k] = max(lam[k] / 3.0, 1e-9)
                if gain < FTOL:
                    active[k] = False
            else:
                lam[k] *= 4.0
                if lam[k] > LAMBDA_MAX:
                    active[k] = False
    return x, cost, cost0, its


@dataclasses.dataclass
class Search:
    """The starts of a global stage and the local minima they reached."""

    starts: list[Start]
    n_tests: int

    @property
    def best(self) -> Start:
        """The start that reached the lowest cost."""
        return min(self.starts, key=lambda s: s.cost)

    def found_best(self) -> list[str]:
        """The starts that reached the best error (within :data:`SAME_MINIMUM` of it)."""
        best = self.best.cost
        return [s.name for s in self.starts if s.cost <= best * (1.0 + SAME_MINIMUM) ** 2]

    def spread(self) -> dict[str, float]:
        """Best, median and worst error of the local minima, √(cost / tests).

        The fit's own measure: each row weighed by its own standard deviation. With a constant
        noise per test it is the spec's ``normalised``; with a ``force_sd_N`` column that
        varies along a test it is not (the spec divides the RMS error by the RMS noise).
        """
        costs = np.array([s.cost for s in self.starts])
        finite = costs[np.isfinite(costs)]
        return {"best": _normalised(float(finite.min()), self.n_tests) if finite.size
                else math.inf,
                "median": _normalised(float(np.median(finite)), self.n_tests)
                if finite.size else math.inf,
                "worst": _normalised(float(finite.max()), self.n_tests) if finite.size
                else math.inf}

    def statement(self) -> str:
        """One sentence: how the best was found and how far apart the minima are."""
        found, spread = self.found_best(), self.spread()
        n = len(self.starts)
        what = (f"the best minimum (weighted error {spread['best']:.3g} × noise) was reached "
                f"from {len(found)} of {n} starts ({', '.join(found)})")
        rest = (f"; the local minima range from {spread['best']:.3g} to {spread['worst']:.3g} "
                f"(median {spread['median']:.3g})")
        verdict = ("" if len(found) >= 2 else
                   ": found once only, a better minimum may exist")
        return what + rest + verdict

    def record(self, names: Sequence[str], to_p, n_tests: int) -> dict[str, Any]:
        """A JSON-ready record of the search."""
        return {"starts": [s.record(names, to_p, n_tests) for s in self.starts],
                "best_found_by": self.found_best(), "n_best": len(self.found_best()),
                "spread_normalised": self.spread(), "statement": self.statement(),
                "settings": {"screened": SCREEN, "sobol_starts": SOBOL_STARTS,
                             "box_decades": BOX_DECADES, "iterations": ITERATIONS,
                             "same_minimum": SAME_MINIMUM, "seed": SEED}}


def search(res, named: Sequence[np.ndarray], labels: Sequence[str], fd_step: float,
           ) -> Search:
    """The global stage (module doc) from the named starts ``named`` (fitting variables)."""
    v = res.v
    lo, hi = box(v, named)
    starts_x, names = [np.clip(x, v.lower, v.upper) for x in named], list(labels)
    for i, (x, _) in enumerate(sobol_starts(res, lo, hi, starts_x)):
        starts_x.append(x)
        names.append(f"Sobol {i + 1}")
    X, cost, cost0, its = lockstep_lm(res, np.array(starts_x), v.lower, v.upper, fd_step)
    n_tests = len(res.tests)
    return Search([Start(n, x0, x, float(c0), float(c), int(i)) for n, x0, x, c0, c, i
                   in zip(names, starts_x, X, cost0, cost, its)], n_tests)
