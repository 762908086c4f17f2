"""The fit of one set-up parameter to the forming tests: scan, Gauss-Newton, held-out folds.

The set-up stage (:mod:`~fenicsx_drape.diagnosis.setup_stage`) fits each candidate with
:func:`fit_candidate` (the same definitions as an effect's, ``diagnose``'s module doc):

1. **Scan and untestable**: each axis of the parameter is moved by the values of
   :data:`SCAN` about the stated value (one batch of runs: the error may lie either side,
   and a turned net is clipped to the blank, so the error is not smooth through θ = 0).
   On a case symmetric in a plane, a point whose mirror image in it is scanned too is not
   formed but read from the image's run, mirrored: a net turned by −δθ forms the part of
   +δθ mirrored, an offset −d across the plane that of +d (one run for both sides).
   When the smallest move changes the simulated tests by less than ``UNTESTABLE_BELOW`` ×
   their noise (normalised like the error), or the part has nothing it acts on (no holder,
   no punch), the parameter is listed as untestable with the reason, not ranked.
2. **Fit**: Gauss-Newton from the best point of the scan (per axis) on the per-coordinate
   residuals in noise units, forward differences of :data:`STEP`, at most
   :data:`MAX_ITERATIONS` iterations, steps of at most :data:`MAX_STEP` halved once when
   they do not lower the cost, stopped when the step is below :data:`CONVERGED_SD` × the
   fit's sd. ``sd_fit`` is the fit's standard deviation, √diag((JᵀJ)⁻¹ · max(1, χ²/dof));
   ``sd`` adds in quadrature the step the fit could not resolve (a step it asked for that
   did not lower the cost, or the last one when it ran out of iterations) as a uniform
   spread, step/√3, and the lack of fit in the parameter's units,
   ``|p − p0| · √((A² − 1 − 2√(2/n)) / (S² − 1))`` (p0 the stated value), A the normalised
   error after the fit
   and S the stated set-up's on the same model, n the residual coordinates (0 when A is
   within the noise's own spread): the error the
   fit leaves is a correlated one (a whole sheet's slide, a clipped net's edge), which
   χ²/dof, made for independent noise, hardly widens.
   **Nothing to gain**: when neither a scan point nor a Gauss-Newton step on the scan's
   secants (each axis's two points) would lower the stated set-up's cost by
   :data:`GAIN_BELOW`, the candidate stops there, with no further runs: its fit is the
   stated set-up, its held-out error the stated error (evidence 1), ``sd_fit`` the
   secants', and the step not taken widens ``sd`` as an unresolved one.
3. **Held-out**: every measured node is left out once, in :data:`~fenicsx_drape.diagnosis.
   folds.NODE_FOLDS` interleaved folds of each test's rows; a fold refits the parameter from
   the full fit without its rows (one Gauss-Newton step on the full fit's Jacobian, kept
   when it lowers the fold's own cost)
   and predicts them: linearised on the fit's Jacobian when the fold's step is within
   ``sd_fit`` on every axis (no run), else by a run (``sd``'s wider terms say the model is
   not linear over them: a linearised prediction there would flatter the held-out error).
   The stated set-up fits nothing: its held-out error is its error.

The runs of each round (a point and its finite differences, the folds' predictions) go to
:func:`~fenicsx_drape.runs.form_many` at once (:class:`SetupRuns`): worker
processes on every core of the pool, or all ranks under ``mpirun``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.diagnosis.comparison import compare_tests, normalised_error
from fenicsx_drape.diagnosis.folds import node_folds
from fenicsx_drape.diagnosis.kinds import kind_of
from fenicsx_drape.diagnosis.kinds.forming import case_of, forming_case_of, moved
from fenicsx_drape.diagnosis.setup_parameters import (
    BOUNDS,
    MAX_STEP,
    SCAN,
    STEP,
    applied,
    base_parameter,
    forming_tests,
    show,
    stated_point,
    step_text,
    why_not,
)
from fenicsx_drape.errors import DrapeInputError, SolverError
from fenicsx_drape.runs import form_many, runs_of

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds import Comparison
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

MAX_ITERATIONS = 4
# A Gauss-Newton step smaller than this share of the fit's sd (every axis) is not taken: the
# fit has converged within its uncertainty.
CONVERGED_SD = 0.25
# A candidate whose scan points and fit on the scan's secants lower the stated set-up's cost
# by less than this share stops there: a third of the 31 % an evidence of 1.2 needs (every
# further run is a whole blank for a ply or an offset).
GAIN_BELOW = 0.1
# A set-up error is named only when its fitted value lies this many sd from the stated one.
DISTINCT_SD = 2.0
# Or, whatever the leftover of other measurements, when it lies this many of its fit's own sd
# from the stated value and from each bound of its range (:func:`set_apart`).
SET_APART_SD = 3.0

Progress = Callable[[str], None]


@dataclasses.dataclass(frozen=True)
class SetupFit:
    """One set-up parameter fitted to the forming tests (:func:`fit_candidate`)."""

    p: np.ndarray  # the fitted point (internal units: setup_parameters.stated_point)
    start: np.ndarray  # the stated point (internal units)
    sd_internal: np.ndarray  # the honest sd: the fit's, the unresolved step's, the lack of fit's
    sd_fit: np.ndarray  # the fit's own sd, √diag((JᵀJ)⁻¹ · max(1, χ²/dof))
    after: list[Comparison]  # the fitted set-up against the tests
    heldout_normalised: float  # every node predicted by the fold that left it out
    evidence: float  # the stated set-up's held-out error on the model it needs / heldout
    sensitivity: float  # the change (× noise) of the scan's smallest move
    values: dict[str, np.ndarray]  # the simulated values at p, by test id
    stated_normalised: float  # the stated set-up's error on the model the parameter needs
    folds_formed: int  # folds predicted by a run (not linearised)
    heldout_rmse: Mapping[str, float] = dataclasses.field(default_factory=dict)  # by test id
    # the stated set-up's RMS error on the model the parameter needs, by test id
    stated_rmse: Mapping[str, float] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class Untestable:
    """A set-up parameter the tests cannot exercise (its smallest move changes too little)."""

    reason: str  # why, in words
    sensitivity: float  # the change (× noise) of the scan's smallest move


@dataclasses.dataclass(frozen=True)
class Stopped:
    """A candidate with nothing to gain, stopped at the stated set-up (:func:`nothing_to_gain`)."""

    p: np.ndarray  # the stated point (internal units)
    sd_internal: np.ndarray  # the secants' sd widened by the step not taken
    sd_fit: np.ndarray  # the secants' sd


# --------------------------------------------------------------------------------------------
# Runs


class SetupRuns:
    """Simulated values of the forming tests at set-up points, batched through form_many."""

    def __init__(self, tests: Sequence[Test], model: Model, name: str | None):
        self.tests, self.model, self.name = list(tests), model, name
        # Every measurement kind as the comparison reads it: its values, its one noise
        # function (its kind's value_sd), its regions.
        self.kinds = {t.id: kind_of(t) for t in self.tests}
        self.noise = {t.id: self.kinds[t.id].noise(t) for t in self.tests}
        self.regions = {t.id: self.kinds[t.id].regions(t) for t in self.tests}
        self.measured = {t.id: np.asarray(self.kinds[t.id].measured(t), float)
                         for t in self.tests}
        self.weights = {t.id: 1.0 / self.kinds[t.id].value_sd(t) for t in self.tests}
        # Compared values per row: a grid's x, y, z; an edge with draw-in, two; else one.
        self.per_row = {t.id: self.measured[t.id].size // max(1, t.n_rows) for t in self.tests}
        self.size = sum(v.size for v in self.measured.values())
        self.mirrorable = all(k.mirrorable for k in self.kinds.values())
        self.asked: set[tuple] = set()  # the forming runs its values were read from
        self.known: dict[tuple[float, ...], dict[str, np.ndarray]] = {}  # values by point
        # The stated cases' common symmetry planes (a case keeps them with a ply at a
        # multiple of 90° only, which mirrors to itself).
        cases = [forming_case_of(t) for t in self.tests]
        self.planes = [q for q in ("x", "y") if all(q in c.planes for c in cases)]

    @property
    def formed(self) -> int:
        """How many forming runs this parameter's values needed (whichever call formed them)."""
        return len(self.asked)

    def values(self, points: Sequence[np.ndarray], mirror: bool = False
               ) -> list[dict[str, np.ndarray]]:
        """Per point, the simulated ``x, y, z`` of every measured node of every test.

        With ``mirror``, a point whose mirror image in a symmetry plane of the stated cases
        is formed in the same batch is read from that run, mirrored (module doc, 1.).
        """
        new = list(dict.fromkeys(p for p in map(tuple, points) if p not in self.known))
        images = self._images(new) if mirror and self.mirrorable else {}
        for batch in ([p for p in new if p not in images], list(images)):
            for p, v in zip(batch, self._formed(batch, images)):
                self.known[p] = v
        return [self.known[tuple(p)] for p in points]

    def _images(self, new: list[tuple[float, ...]]) -> dict[tuple[float, ...], str]:
        """The points of ``new`` to read from their image's run, with the plane."""
        out = {}
        for p in new:
            for plane in self.planes:
                q = mirrored(self.name, p, plane)
                # the side with the moved component positive is formed, the other read
                if q is not None and sum(q) > sum(p) and q in new:
                    out[p] = plane
                    break
        return out

    def _formed(self, points: Sequence[tuple[float, ...]], images: dict[tuple, str]
                ) -> list[dict[str, np.ndarray]]:
        jobs, reads = [], []
        for p in points:
            plane = images.get(p)
            source = p if plane is None else mirrored(self.name, p, plane)
            for test in self.tests:
                t, shift = applied(test, self.name, np.array(p), self.model)
                if plane is not None:  # formed as its image, read where p's part lies
                    t, _ = applied(test, self.name, np.array(source), self.model)
                jobs.append((case_of(t), self.model))
                reads.append((test, shift, plane))
        self.asked |= runs_of(jobs)  # the tests of one part share its run
        sheets = form_many(jobs)
        out: list[dict[str, np.ndarray]] = [{} for _ in points]
        for k, (sheet, (test, shift, plane), (case, _)) in enumerate(zip(sheets, reads, jobs)):
            # A force curve is read from its own run: the test on the case it was formed as.
            formed = dataclasses.replace(test, forming_case=case, case_keys={})
            out[k // len(self.tests)][test.id] = self.kinds[test.id].on_sheet(
                moved(formed, shift), sheet, self.model, plane)
        return out

    def residual(self, values: dict[str, np.ndarray], rows: dict[str, np.ndarray] | None = None
                 ) -> np.ndarray:
        """Residuals in noise units (per coordinate), rows left out at weight 0."""
        out = []
        for test in self.tests:
            r = (values[test.id] - self.measured[test.id]) * self.weights[test.id]
            if rows is not None:
                r = np.where(self.by_value(test, rows[test.id]), r, 0.0)
            out.append(np.where(np.isfinite(r), r, 0.0) / math.sqrt(r.size))
        return np.concatenate(out)

    def by_value(self, test: Test, rows: np.ndarray) -> np.ndarray:
        """A mask over a test's rows as a mask over its compared values."""
        return np.repeat(rows, self.per_row[test.id])

    def compare(self, values: dict[str, np.ndarray]) -> list[Comparison]:
        """Simulated values (by test id) against the tests."""
        return compare_tests(self.tests, values, self.regions, self.noise)


def mirrored(name: str | None, p: tuple[float, ...], plane: str) -> tuple[float, ...] | None:
    """The set-up point that forms ``p``'s part mirrored in the symmetry plane ``plane``.

    A net turned by δθ mirrors to one turned by −δθ (in either plane); an offset's
    component across the plane changes sign; the force and μ have no image.
    """
    if base_parameter(name) == "ply_angle_deg":
        return (-p[0],)
    if name in ("blank_offset_mm", "tool_offset_mm"):
        a = "xy".index(plane)
        return tuple(-v if i == a else v for i, v in enumerate(p))
    return None



# --------------------------------------------------------------------------------------------
# One candidate


def scan(name: str, start: np.ndarray) -> tuple[list[tuple[int, float]], list[np.ndarray]]:
    """The scan about ``start``: each (axis, move) of :data:`SCAN` and its point."""
    axes = [(i, v) for i in range(len(start)) for v in SCAN[name]]
    return axes, [start + v * np.eye(len(start))[i] for i, v in axes]


def first_runs(name: str, tests: Sequence[Test], test0: Test, model: Model, say: Progress
                ) -> None:
    """A candidate's first batch of runs (:func:`fit_candidate`'s stated point and scan), formed.

    Ahead of its fit, with other work; a failure is left for the fit to report.
    """
    if why_not(name, tests) is not None:
        return
    start = stated_point(name, test0, model)
    with contextlib.suppress(SolverError, DrapeInputError):
        SetupRuns(tests, model, name).values([start, *scan(name, start)[1]], mirror=True)


def fit_candidate(runs: SetupRuns, test0: Test, below: float, say: Progress
                  ) -> SetupFit | Untestable:
    """Fit one set-up parameter, its held-out error and evidence (module doc, 1.-4.)."""
    name, model = runs.name, runs.model
    start = stated_point(name, test0, model)
    lo, hi = BOUNDS[name]
    k = len(start)
    # 1. The scan: each axis moved by the values of SCAN, in one batch of runs with the
    # stated set-up on the model this parameter needs (the same runs when it keeps the
    # case's planes).
    axes, points = scan(name, start)
    base_values, *scanned = runs.values([start, *points], mirror=True)
    base_ho = normalised_error(runs.compare(base_values))
    r0 = runs.residual(base_values)
    first = [j for j, (i, v) in enumerate(axes) if v == min(u for u in SCAN[name] if u > 0)]
    change = float(np.sqrt(np.mean([
        np.mean((scanned[j][t.id] - base_values[t.id]) ** 2) / runs.noise[t.id][0] ** 2
        for j in first for t in runs.tests])))
    if change < below:
        return Untestable(f"moving it by {step_text(name)} changes the simulated tests by "
                          f"only {change:.2g} × their noise (testable from {below})", change)
    costs = [float(runs.residual(v) @ runs.residual(v)) for v in scanned]
    if min(costs) > (1.0 - GAIN_BELOW) * float(r0 @ r0):
        stopped = nothing_to_gain(runs, start, r0, scanned, axes, say)
        if stopped is not None:
            compared = runs.compare(base_values)
            return SetupFit(stopped.p, start, stopped.sd_internal, stopped.sd_fit,
                            compared, base_ho, 1.0, change, base_values, base_ho, 0,
                            {c.id: c.rmse for c in compared}, {c.id: c.rmse for c in compared})
    p = start.copy()
    for i in range(k):  # the best of each axis (the offsets' axes act nearly apart)
        best = min([(float(r0 @ r0), 0.0)] + [(c, v) for c, (j, v) in zip(costs, axes)
                                               if j == i])
        p[i] = start[i] + best[1]
    say(f"    {name} scan: best start {show(name, p, test0, model)}")
    # 2. Gauss-Newton from the best of the scan.
    h = np.diag(STEP[name]).astype(float)
    r, J, Jv = linearised(runs, p, h)
    sd = fit_sd(runs, J, r)
    # The step the fit could not resolve: the model's error is not smooth in the parameter
    # (a turned net is clipped to the blank cell by cell), so a step the linearised fit
    # asks for may not lower the cost. The parameter is then known only to within it.
    unresolved = np.zeros(k)
    for iteration in range(MAX_ITERATIONS):
        step = gauss_newton(J, r, name)
        if np.all(np.abs(step) < np.maximum(CONVERGED_SD * sd, 0.01 * h.diagonal())):
            unresolved[:] = 0.0  # converged within the fit's uncertainty
            break
        new, unresolved = try_step(runs, p, step, r, h, f"fit {iteration + 1}", say)
        if new is None:
            break
        p = new
        r, J, Jv = linearised(runs, p, h)
        sd = fit_sd(runs, J, r)
    fitted_values = runs.values([p])[0]
    after = runs.compare(fitted_values)
    # The honest sd, in quadrature: the fit's; the unresolved step's (the optimum lies
    # anywhere within it: a uniform spread, sd = step/√3); and the lack of fit's, the error
    # the fit leaves beyond the noise turned into the parameter by its secant from the
    # stated set-up (χ²/dof treats that error as independent noise: a whole sheet's slide is
    # one correlated error, and widened the sd by 7 % where the fit was 18 sd off).
    # Beyond the noise: A² of pure noise is 1 ± √(2/n) over n coordinates (2 sd allowed).
    sd_fit = sd
    A, S = normalised_error(after), base_ho
    floor = 1.0 + 2.0 * math.sqrt(2.0 / runs.size)
    lack = np.abs(p - start) * math.sqrt(max(0.0, A**2 - floor) / max(S**2 - 1.0, 1e-12))
    sd = np.sqrt(sd**2 + unresolved**2 / 3.0 + lack**2)
    # 3. Held-out: each fold refits from the full fit without its rows (one Gauss-Newton
    # step, kept only when it lowers the fold's own cost) and predicts its rows: linearised
    # on the fit's Jacobian when the step is within sd_fit on every axis (no run),
    # else by a run.
    masks = node_folds(runs.tests)
    steps = []
    for rows in masks:
        keep = np.concatenate([runs.by_value(t, rows[t.id]) for t in runs.tests])
        step = gauss_newton(J[keep], r[keep], name)
        steps.append(np.clip(p + step, lo, hi) - p)
    far = [b for b, step in enumerate(steps) if np.any(np.abs(step) > sd_fit)]
    formed = dict(zip(far, runs.values([p + steps[b] for b in far])))
    predicted = {t.id: np.full(runs.measured[t.id].size, np.nan) for t in runs.tests}
    for b, step in enumerate(steps):
        values = formed.get(b) or {t.id: fitted_values[t.id] + Jv[t.id] @ step
                                   for t in runs.tests}
        own, full = runs.residual(values, masks[b]), runs.residual(fitted_values, masks[b])
        chosen = values if own @ own < full @ full else fitted_values
        for t in runs.tests:
            held = runs.by_value(t, ~masks[b][t.id])
            predicted[t.id][held] = chosen[t.id][held]
    held = runs.compare(predicted)
    heldout = normalised_error(held)
    evidence = base_ho / heldout if heldout > 0 else math.inf
    return SetupFit(p, start, sd, sd_fit, after, heldout, evidence, change, fitted_values,
                    base_ho, len(far), {c.id: c.rmse for c in held},
                    {c.id: c.rmse for c in runs.compare(base_values)})


def distinct(c: SetupFit) -> bool:
    """Whether a fitted set-up lies more than :data:`DISTINCT_SD` sd from the stated one.

    A set-up error is named only when its value is told apart from the stated one: a fit
    that lowers the error by wandering within its own uncertainty (a missing effect taken up
    by the force, 8 ± 59 N against 100 N stated) sizes nothing.
    """
    return bool(np.any(np.abs(c.p - c.start) > DISTINCT_SD * c.sd_internal))


# The set-up parameters a fit's own sd can set apart: the placements (:func:`set_apart`).
SET_APART_PARAMETERS = ("ply_angle_deg", "blank_offset_mm", "tool_offset_mm")


def set_apart(c: SetupFit, name: str) -> bool:
    """Whether a fitted set-up lies :data:`SET_APART_SD` sd_fit from stated and bounds.

    From the stated value on some axis, and from each bound of its range
    (:data:`~fenicsx_drape.diagnosis.setup_parameters.BOUNDS`) on every axis.
    The fit's own sd (``sd_fit``) leaves out the lack of fit, the leftover of the other
    measurements (a net's own error on an edge, a missing effect elsewhere): a value set
    apart by it is one the data fix. A fit that ends at, or within that many sd of, a bound
    of its range (a holding force taken to 5 N of 100 N stated by a missing tow buckling,
    5 ± 14 N) has no value of its own: it compensates for something the parameter does not
    describe. The set-up stage asks evidence besides (:mod:`~fenicsx_drape.diagnosis.
    setup_stage`). Only the placements (:data:`SET_APART_PARAMETERS`) are set apart: a
    holding force or μ acts as their product (eq. 1), a restraint that any missing restraint
    (a tool friction, a viscosity) can stand in for, so they are named only when significant
    on their honest sd (a tow buckling hidden on the double dome took the force to 120 ± 67 N,
    by its fit ± 12, for 200 N stated).
    """
    if name.split("/")[0] not in SET_APART_PARAMETERS:  # a stack's ply: "ply_angle_deg/2"
        return False
    lo, hi = BOUNDS[name]
    room = SET_APART_SD * np.asarray(c.sd_fit, float)
    if not np.all(np.isfinite(room)):
        return False
    p, start = np.asarray(c.p, float), np.asarray(c.start, float)
    return bool(np.any(np.abs(p - start) >= room) and np.all(p - lo >= room)
                and np.all(hi - p >= room))


def nothing_to_gain(runs: SetupRuns, start: np.ndarray, r0: np.ndarray,
                     scanned: list[dict[str, np.ndarray]], axes: list[tuple[int, float]],
                     say: Progress) -> Stopped | None:
    """The candidate stopped at the stated set-up when the scan finds nothing (module doc, 2.).

    Called when no scan point lowers the cost by :data:`GAIN_BELOW`. The scan's two points
    of each axis give a secant Jacobian about the stated point; when
    the Gauss-Newton step on it would lower the cost by less than :data:`GAIN_BELOW` too, the
    fit is the stated set-up (held-out = error, evidence 1: it fits nothing), ``sd_fit`` the
    secant's and ``sd`` wider by the step not taken (an unresolved one). None: go on.
    """
    k = len(start)
    J = np.zeros((r0.size, k))
    for i in range(k):  # the secant of the axis's two innermost points, one either side
        on = [(v, j) for j, (axis, v) in enumerate(axes) if axis == i]
        (a, ja), (b, jb) = (max(p for p in on if p[0] < 0), min(p for p in on if p[0] > 0))
        J[:, i] = (runs.residual(scanned[jb]) - runs.residual(scanned[ja])) / (b - a)
    step = gauss_newton(J, r0, runs.name)
    rest = r0 + J @ step
    if float(rest @ rest) <= (1.0 - GAIN_BELOW) * float(r0 @ r0):
        return None
    sd = fit_sd(runs, J, r0)
    say(f"    {runs.name}: nothing to gain (neither the scan nor a step on its secants "
        f"lowers the cost by {100 * GAIN_BELOW:g} %): the stated set-up, no further runs")
    return Stopped(start.copy(), np.sqrt(sd**2 + step**2 / 3), sd)


def gauss_newton(J: np.ndarray, r: np.ndarray, name: str) -> np.ndarray:
    """The Gauss-Newton step of residuals ``r`` with Jacobian ``J``, at most MAX_STEP long."""
    step = np.linalg.lstsq(J, -r, rcond=None)[0]
    return step / max(1.0, float(np.abs(step).max()) / MAX_STEP[name])


def try_step(runs: SetupRuns, p: np.ndarray, step: np.ndarray, r: np.ndarray, h: np.ndarray,
         label: str, say: Progress):
    """``p + step``, else the half step, kept when it lowers the cost.

    One run per trial (its finite differences are the caller's, when it is taken). Returns
    ``(p', the last move)``, or ``(None, the last move)`` when neither lowers the cost (a
    move of zero when the step is below a hundredth of the difference step).
    """
    name, test0 = runs.name, runs.tests[0]
    lo, hi = BOUNDS[name]
    for attempt in range(2):
        trial = np.clip(p + step / 2**attempt, lo, hi)
        move = np.abs(trial - p)
        if move.max() < 0.01 * float(h.diagonal().min()):
            return None, np.zeros_like(move)
        (at_trial,) = runs.values([trial])
        r_new = runs.residual(at_trial)
        say(f"    {name} {label}: {show(name, trial, test0, runs.model)}, cost "
            f"{r_new @ r_new:.4g} (was {r @ r:.4g})")
        if r_new @ r_new < r @ r:
            return trial, move
    return None, move


def linearised(runs: SetupRuns, p: np.ndarray, h: np.ndarray):
    """Residuals at ``p``, their Jacobian and the simulated values' (forward differences).

    Axis i is moved by ``h[i, i]`` (a shorter secant to a point formed already would save a
    run, but a turned net's error is rough at a tenth of a degree: its slope, and so the
    fit's sd, would follow the secant's length).
    """
    k = len(p)
    batch = runs.values([p] + [p + h[i] for i in range(k)])
    r = runs.residual(batch[0])
    J = np.column_stack([(runs.residual(v) - r) / h[i, i] for i, v in enumerate(batch[1:])])
    Jv = {t.id: np.column_stack([(v[t.id] - batch[0][t.id]) / h[i, i]
                                 for i, v in enumerate(batch[1:])]) for t in runs.tests}
    return r, J, {k: np.where(np.isfinite(d), d, 0.0) for k, d in Jv.items()}


def fit_sd(runs: SetupRuns, J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The fit's sd per axis: √diag((JᵀJ)⁻¹ · max(1, χ²/dof)), residuals per coordinate."""
    n, k = runs.size, J.shape[1]
    # Undo the residuals' 1/√n (per test) to have them in noise units per coordinate.
    scale = np.concatenate([np.full(v.size, math.sqrt(v.size)) for v in runs.measured.values()])
    Jn, rn = J * scale[:, None], r * scale
    try:
        cov = np.linalg.inv(Jn.T @ Jn) * max(1.0, float(rn @ rn) / max(1, n - k))
    except np.linalg.LinAlgError:
        return np.full(k, math.inf)
    return np.sqrt(np.abs(np.diag(cov)))


def refit_setup(bundle: Bundle, name: str, p: Sequence[float], model: Model,
                progress: Progress | None = None) -> np.ndarray:
    """The fitted set-up parameter fitted again with another model (a candidate effect's).

    A set-up error and a missing effect can act alike: a turned ply fitted without the tool
    friction the part had takes some of the friction's error (the study's 4.17° came out at
    4.94°), and the effect refitted at that angle then gains little. Gauss-Newton steps from
    ``p`` (internal units) on the original ``bundle``, each kept only when it lowers the
    cost (a half step tried once), up to :data:`MAX_ITERATIONS`, from the best of ``p``,
    the stated value and the scan's points about it (the set-up fitted alone may sit in
    another valley); no folds.
    """
    say = progress or (lambda line: None)
    runs = SetupRuns(forming_tests(bundle), model, name)
    h = np.diag(STEP[name]).astype(float)
    start = stated_point(name, runs.tests[0], model)
    k = len(start)
    points = [np.asarray(p, dtype=float), start,
              *(start + v * np.eye(k)[i] for i in range(k) for v in SCAN[name])]
    costs = [float(r @ r) for r in map(runs.residual, runs.values(points))]
    p = points[int(np.argmin(costs))]
    r, J, _ = linearised(runs, p, h)
    for iteration in range(MAX_ITERATIONS):
        new, _ = try_step(runs, p, gauss_newton(J, r, name), r, h,
                      f"refit with the effect {iteration + 1}", say)
        if new is None:
            break
        p = new
        r, J, _ = linearised(runs, p, h)
    return p
