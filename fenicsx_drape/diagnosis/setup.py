"""Process set-up before physics: the diagnosis's set-up candidates (spec version 3).

When a formed part disagrees with the model, its set-up is the first suspect. Before any
physics effect is tried, :func:`fit_setup` fits each set-up parameter of
:data:`SETUP_PARAMETERS` to the forming tests of a bundle, as a candidate of its own:

- ``ply_angle_deg``: the warp's angle to x as laid (the net turned by δθ);
- ``blank_offset_mm``: the blank (with its net) placed [x, y] mm off where the case puts it.
  The measured grid's flat positions are where the *stated* set-up puts the material, so the
  model with an offset d is read at (x0, y0) + d;
- ``holder_force_N``: the holding force that acted (a factor on each test's stated force);
- ``mu``: the holder's friction coefficient (eq. 1; the case's ``[holder] mu`` if it has
  one, else the model's);
- ``tool_offset_mm``: the punch misaligned by [x, y] mm relative to the die and holder.

All start from the test's stated value (the case's, with the test's keys; offsets 0) and are
shared by the bundle's forming tests. The model's material and friction stay as stated (as
given, or as the coupons fitted them): the reference is the **stated set-up**, fitted to
nothing. A set-up that breaks a symmetry plane of the case is formed without it
(:func:`~fenicsx_drape.forming.case.format.with_overrides` drops the plane): the full or half model
is chosen by the set-up, not by the user.

Per candidate (the same definitions as an effect's, ``diagnose``'s module doc):

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
3. **Held-out**: every measured node is left out once, in :data:`FOLDS` interleaved folds
   of each test's rows; a fold refits the parameter from the full fit without its rows (one
   Gauss-Newton step on the full fit's Jacobian, kept when it lowers the fold's own cost)
   and predicts them: linearised on the fit's Jacobian when the fold's step is within
   ``sd_fit`` on every axis (no run), else by a run (``sd``'s wider terms say the model is
   not linear over them: a linearised prediction there would flatter the held-out error).
   The stated set-up fits nothing: its held-out error is its error.
4. **Decision**: ``evidence`` = stated held-out / candidate held-out on the forming tests
   (the stated set-up on the case's own model), ``evidence_on_model`` the same against the
   stated set-up on the model the candidate needs (a whole blank may form a little unlike the
   mirrored quarter: that difference is not the set-up's); significant when both are
   ``>= EVIDENCE_THRESHOLD`` (the effects' rule) and the fitted value lies more than
   :data:`DISTINCT_SD` sd from the stated one (a missing effect that a set-up parameter takes
   up by wandering within its own uncertainty names no set-up error). Ranked by held-out error;
   near-ties (``PARSIMONY``) go to the fewer parameters, then to the order of
   :data:`SETUP_PARAMETERS`. ``setup_error`` is the first if significant.

``holder_force_N`` and ``mu`` act on the part only through their product μF (eq. 1: a
friction bar yields at F μ / n_s; the clamping does not depend on F), so the data cannot
tell them apart: when both are tried, ``mu`` is not formed again but reported from the
force's fit (μ · F'/F, the same errors and evidence, ``tied_to`` and ``confounded_with``).

Each round's runs (a point and its finite differences, the folds' predictions) go to
:func:`~fenicsx_drape.diagnosis.forming_runs.form_many` at once: worker processes on every
core of the pool, or all ranks under ``mpirun``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.compare import compare_tests, error_record, normalised_error
from fenicsx_drape.diagnosis.forming_runs import form_many, runs_of, together
from fenicsx_drape.diagnosis.kinds import is_formed, kind_of, row_sd
from fenicsx_drape.diagnosis.kinds.forming import case_of, forming_case_of, moved, names_case
from fenicsx_drape.diagnosis.resolution import check_resolution, explained
from fenicsx_drape.errors import DrapeInputError, SolverError
from fenicsx_drape.forming.case.format import FormingCase, broken_planes, with_overrides

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

SETUP_PARAMETERS = ("ply_angle_deg", "blank_offset_mm", "holder_force_N", "mu", "tool_offset_mm")
# On a stack (spec version 4), ``ply_angle_deg/<k>`` is the k-th ply's angle within it (a ply
# laid at the wrong angle), tried with ``ply_angle_deg`` (the whole stack turned); its tables'
# entries are ``ply_angle_deg``'s.
PLY = "ply_angle_deg/"


def ply_index(name: str) -> int | None:
    """The ply k of a set-up parameter ``ply_angle_deg/<k>`` (on a stack), else None."""
    tail = name[len(PLY):] if name.startswith(PLY) else ""
    return int(tail) if tail.isdigit() and int(tail) >= 1 else None


def base_parameter(name: str) -> str:
    """The set-up parameter whose tables a name uses (``ply_angle_deg/<k>``: the ply angle's)."""
    return "ply_angle_deg" if ply_index(name) else name


class _Table(dict):
    """A table of the set-up parameters that answers ``ply_angle_deg/<k>`` as the ply angle."""

    def __missing__(self, name: str):
        if base_parameter(name) == name:
            raise KeyError(name)
        return self[base_parameter(name)]

    def get(self, name: str, default=None):
        return super().get(base_parameter(name), default)


def setup_names(names: Sequence[str], tests: Sequence[Test]) -> list[str]:
    """The set-up parameters to try: ``names``, with each ply's angle after the stack's.

    When the forming tests are on stacks, ``ply_angle_deg`` brings ``ply_angle_deg/<k>``
    for every ply k that all their stacks have.
    """
    plies = min((len(forming_case_of(t).plies) for t in tests), default=0)
    out = []
    for name in names:
        out.append(name)
        if name == "ply_angle_deg" and plies > 1:
            out += [f"{PLY}{k}" for k in range(1, plies + 1) if f"{PLY}{k}" not in names]
    return out


# The scan of each parameter about its stated value, per axis (one batch of runs: a set-up
# error may lie either side, and a turned net is clipped to the blank, so that the error is
# not smooth through θ = 0): degrees, mm, a change of the factor on the force, μ. The
# smallest positive move is the sensitivity's probe.
# Two points per axis, the Gauss-Newton fit moving from the best (four per axis
# were a quarter of the set-up stage's runs, all on the whole blank for a ply or an offset).
# A punch moved past its clearance to a matched die clashes with it (the double dome's die is
# 0.3 mm off the punch): at 3 mm its runs took 2.4× as long, with cut-backs; 1 mm is the
# finite-difference step, so a fit from the stated point reuses the scan's runs.
SCAN = _Table({"ply_angle_deg": (-4.0, 4.0), "blank_offset_mm": (-8.0, 8.0),
               "holder_force_N": (-0.4, 0.8), "mu": (-0.15, 0.3), "tool_offset_mm": (-1.0, 1.0)})
# The finite-difference step of the Gauss-Newton fit, per axis.
STEP = _Table({"ply_angle_deg": (1.0,), "blank_offset_mm": (1.5, 1.5), "holder_force_N": (0.2,),
               "mu": (0.05,), "tool_offset_mm": (1.0, 1.0)})
BOUNDS = _Table({"ply_angle_deg": (-45.0, 45.0), "blank_offset_mm": (-60.0, 60.0),
                 "holder_force_N": (0.05, 20.0), "mu": (0.0, 2.0),
                 "tool_offset_mm": (-30.0, 30.0)})
MAX_STEP = _Table({"ply_angle_deg": 10.0, "blank_offset_mm": 15.0, "holder_force_N": 2.0,
                   "mu": 0.3, "tool_offset_mm": 10.0})
# A value of each parameter that breaks every plane it can break (the model it needs).
GENERIC = _Table({"ply_angle_deg": 1.0, "blank_offset_mm": (1.0, 1.0),
                  "tool_offset_mm": (1.0, 1.0)})
MAX_ITERATIONS = 4
# A Gauss-Newton step smaller than this share of the fit's sd (every axis) is not taken: the
# fit has converged within its uncertainty.
CONVERGED_SD = 0.25
FOLDS = 3
# A candidate whose scan points and fit on the scan's secants lower the stated set-up's cost
# by less than this share stops there: a third of the 31 % an evidence of 1.2 needs (every
# further run is a whole blank for a ply or an offset).
GAIN_BELOW = 0.1
CONFOUNDED = {"holder_force_N": "mu", "mu": "holder_force_N"}
# A set-up error is named only when its fitted value lies this many sd from the stated one.
DISTINCT_SD = 2.0

Progress = Callable[[str], None]


@dataclasses.dataclass(frozen=True)
class Rules:
    """The diagnosis's fixed rules the set-up stage shares (given by ``diagnose``)."""

    evidence: float  # significant: evidence at least this
    parsimony: float  # held-out errors this close count as ties
    untestable_below: float  # a change (× noise) below this: untestable
    iterations: int  # the coupon fit's iteration cap (the stated model's material)
    # a measurement within this × its noise has nothing to explain (no resolution check);
    # None: no resolution check of the stated set-up
    adequate: float | None = None


# --------------------------------------------------------------------------------------------
# A set-up applied to a test


def forming_tests(bundle: Bundle) -> list[Test]:
    """The bundle's forming tests, each naming its case (a hemisphere test gets its case)."""
    out = []
    for test in bundle.tests:
        if not is_formed(test):
            continue
        if not names_case(test):
            test = dataclasses.replace(test, forming_case=case_of(test))
        out.append(test)
    return out


def stated(test: Test, name: str, model: Model) -> float | list[float]:
    """The test's stated value of a set-up parameter (offsets: [0, 0], where the case puts it)."""
    case = forming_case_of(test)
    if name == "ply_angle_deg":
        return case.blank.ply_angle_deg
    if ply_index(name):  # the ply's warp angle to x as laid: the stack's plus its own
        return case.blank.ply_angle_deg + case.plies[ply_index(name) - 1].angle_deg
    if name == "holder_force_N":
        return case.holder.force_N if case.holder is not None else math.nan
    if name == "mu":
        given = case.holder.mu if case.holder is not None else None
        return float(given if given is not None else np.max(model.parameters.get("mu", 0.0)))
    return [0.0, 0.0]


def applied(test: Test, name: str | None, p: Sequence[float], model: Model
            ) -> tuple[Test, np.ndarray]:
    """The test with set-up parameter ``name`` at ``p`` (internal units), and its read shift.

    ``p``: δθ (deg) for the ply angle, [x, y] (mm) for the offsets, the factor on the stated
    force for ``holder_force_N``, μ itself for ``mu``. The shift (mm) is added to the
    measured grid's flat positions where the model is read (a moved blank).
    """
    case = forming_case_of(test)
    shift = np.zeros(2)
    if name is None:  # the set-up as stated, on the case's own model
        return test, shift
    if name == "ply_angle_deg":
        changes = {"ply_angle_deg": case.blank.ply_angle_deg + float(p[0])}
    elif ply_index(name):  # one ply turned within the stack
        k = ply_index(name) - 1
        plies = list(case.plies)
        plies[k] = dataclasses.replace(plies[k], angle_deg=plies[k].angle_deg + float(p[0]))
        case = dataclasses.replace(case, plies=tuple(plies))
        changes = {}
    elif name == "blank_offset_mm":
        changes = {"blank_offset_mm": [float(p[0]), float(p[1])]}
        shift = np.array([float(p[0]), float(p[1])])
    elif name == "tool_offset_mm":
        changes = {"tool_offset_mm": [float(p[0]), float(p[1])]}
    elif name == "holder_force_N":
        changes = {"holder_force_N": case.holder.force_N * float(p[0])}
    elif name == "mu":
        changes = {"mu": float(p[0])}
    else:
        raise DrapeInputError(f"set-up parameter {name!r} is not one of "
                              f"{', '.join(SETUP_PARAMETERS)}")
    # The model the parameter needs at every value, its stated one too (the full or half
    # model, which may not form quite as the quarter does): the candidate is judged against
    # the stated set-up on that model.
    keep = [q for q in case.planes
            if q not in broken_planes({base_parameter(name): GENERIC.get(name)})]
    new = with_overrides(case, symmetry=keep, **changes)
    return dataclasses.replace(test, forming_case=new, case_keys={}), shift


def _start(name: str, test: Test, model: Model) -> np.ndarray:
    """The stated point in internal units."""
    if name == "holder_force_N":
        return np.array([1.0])
    if name == "mu":
        return np.array([float(stated(test, name, model))])
    return np.zeros(len(STEP[name]))


def _why_not(name: str, tests: Sequence[Test]) -> str | None:
    """Why the part cannot have this set-up error at all (nothing it acts on), else None."""
    cases = [forming_case_of(t) for t in tests]
    if name in ("holder_force_N", "mu") and all(c.holder is None for c in cases):
        return "the part has no blank holder"
    if name == "tool_offset_mm" and all(not any(s.role == "punch" for s in c.tools)
                                        for c in cases):
        return "the part has no punch"
    if ply_index(name) and any(len(c.plies) < ply_index(name) for c in cases):
        return f"the part is not a stack of {ply_index(name)} or more plies"
    if name == "holder_force_N" and all(c.holder is None or c.holder.force_N == 0 for c in cases):
        return "the stated holding force is 0 (a factor on it changes nothing)"
    return None


# --------------------------------------------------------------------------------------------
# Runs


class _Runs:
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
                q = _mirrored(self.name, p, plane)
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
            source = p if plane is None else _mirrored(self.name, p, plane)
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

    def compare(self, values: dict[str, np.ndarray]):
        return compare_tests(self.tests, values, self.regions, self.noise)


def _mirrored(name: str | None, p: tuple[float, ...], plane: str) -> tuple[float, ...] | None:
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


def _scan(name: str, start: np.ndarray) -> tuple[list[tuple[int, float]], list[np.ndarray]]:
    """The scan about ``start``: each (axis, move) of :data:`SCAN` and its point."""
    axes = [(i, v) for i in range(len(start)) for v in SCAN[name]]
    return axes, [start + v * np.eye(len(start))[i] for i, v in axes]


def _first_runs(name: str, tests: Sequence[Test], test0: Test, model: Model, say: Progress
                ) -> None:
    """A candidate's first batch of runs (:func:`_candidate`'s stated point and scan), formed.

    Ahead of its fit, with other work; a failure is left for the fit to report.
    """
    if _why_not(name, tests) is not None:
        return
    start = _start(name, test0, model)
    with contextlib.suppress(SolverError, DrapeInputError):
        _Runs(tests, model, name).values([start, *_scan(name, start)[1]], mirror=True)


def _candidate(runs: _Runs, test0: Test, below: float, say: Progress) -> dict[str, Any]:
    """Fit one set-up parameter, its held-out error and evidence (module doc, 1.-4.)."""
    name, model = runs.name, runs.model
    start = _start(name, test0, model)
    lo, hi = BOUNDS[name]
    k = len(start)
    # 1. The scan: each axis moved by the values of SCAN, in one batch of runs with the
    # stated set-up on the model this parameter needs (the same runs when it keeps the
    # case's planes).
    axes, points = _scan(name, start)
    base_values, *scanned = runs.values([start, *points], mirror=True)
    base_ho = normalised_error(runs.compare(base_values))
    r0 = runs.residual(base_values)
    first = [j for j, (i, v) in enumerate(axes) if v == min(u for u in SCAN[name] if u > 0)]
    change = float(np.sqrt(np.mean([
        np.mean((scanned[j][t.id] - base_values[t.id]) ** 2) / runs.noise[t.id][0] ** 2
        for j in first for t in runs.tests])))
    if change < below:
        return {"untestable": True, "sensitivity": change,
                "reason": (f"moving it by {_step_text(name)} changes the simulated tests by "
                           f"only {change:.2g} × their noise (testable from "
                           f"{below})")}
    costs = [float(runs.residual(v) @ runs.residual(v)) for v in scanned]
    if min(costs) > (1.0 - GAIN_BELOW) * float(r0 @ r0):
        stopped = _nothing_to_gain(runs, start, r0, scanned, axes, say)
        if stopped is not None:
            return {**stopped, "start": start, "after": runs.compare(base_values),
                    "sensitivity": change,
                    "values": base_values, "heldout_normalised": base_ho,
                    "stated_normalised": base_ho}
    p = start.copy()
    for i in range(k):  # the best of each axis (the offsets' axes act nearly apart)
        best = min([(float(r0 @ r0), 0.0)] + [(c, v) for c, (j, v) in zip(costs, axes)
                                               if j == i])
        p[i] = start[i] + best[1]
    say(f"    {name} scan: best start {_show(name, p, test0, model)}")
    # 2. Gauss-Newton from the best of the scan.
    h = np.diag(STEP[name]).astype(float)
    r, J, Jv = _linearised(runs, p, h)
    sd = _sd_of(runs, J, r)
    # The step the fit could not resolve: the model's error is not smooth in the parameter
    # (a turned net is clipped to the blank cell by cell), so a step the linearised fit
    # asks for may not lower the cost. The parameter is then known only to within it.
    unresolved = np.zeros(k)
    for iteration in range(MAX_ITERATIONS):
        step = _gauss_newton(J, r, name)
        if np.all(np.abs(step) < np.maximum(CONVERGED_SD * sd, 0.01 * h.diagonal())):
            unresolved[:] = 0.0  # converged within the fit's uncertainty
            break
        new, unresolved = _try(runs, p, step, r, h, f"fit {iteration + 1}", say)
        if new is None:
            break
        p = new
        r, J, Jv = _linearised(runs, p, h)
        sd = _sd_of(runs, J, r)
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
    masks = [{t.id: np.arange(t.n_rows) % FOLDS != b for t in runs.tests} for b in range(FOLDS)]
    steps = []
    for rows in masks:
        keep = np.concatenate([runs.by_value(t, rows[t.id]) for t in runs.tests])
        step = _gauss_newton(J[keep], r[keep], name)
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
    heldout = normalised_error(runs.compare(predicted))
    evidence = base_ho / heldout if heldout > 0 else math.inf
    return {"untestable": False, "p": p, "start": start, "sd_internal": sd, "sd_fit": sd_fit,
            "after": after,
            "heldout_normalised": heldout, "evidence": evidence, "sensitivity": change,
            "values": fitted_values, "stated_normalised": base_ho,
            "folds_formed": len(far)}


def _distinct(c: dict[str, Any]) -> bool:
    """Whether a fitted set-up lies more than :data:`DISTINCT_SD` sd from the stated one.

    A set-up error is named only when its value is told apart from the stated one: a fit
    that lowers the error by wandering within its own uncertainty (a missing effect taken up
    by the force, 8 ± 59 N against 100 N stated) sizes nothing.
    """
    return bool(np.any(np.abs(c["p"] - c["start"]) > DISTINCT_SD * c["sd_internal"]))


def _nothing_to_gain(runs: _Runs, start: np.ndarray, r0: np.ndarray,
                     scanned: list[dict[str, np.ndarray]], axes: list[tuple[int, float]],
                     say: Progress) -> dict[str, Any] | None:
    """The candidate stopped at the stated set-up when the scan finds nothing (module doc, 2.).

    Called when no scan point lowers the cost by :data:`GAIN_BELOW`. The scan's two points
    of each axis give a secant Jacobian about the stated point; when
    the Gauss-Newton step on it would lower the cost by less than :data:`GAIN_BELOW` too, the
    fit is the stated set-up (held-out = error, evidence 1: it fits nothing), ``sd_fit`` the
    secant's and ``sd`` wider by the step not taken (an unresolved one). None: go on.
    """
    k = len(start)
    J = np.zeros((r0.size, k))
    for i in range(k):
        (a, va), (b, vb) = [(v, runs.residual(scanned[j]))
                            for j, (axis, v) in enumerate(axes) if axis == i]
        J[:, i] = (vb - va) / (b - a)
    step = _gauss_newton(J, r0, runs.name)
    rest = r0 + J @ step
    if float(rest @ rest) <= (1.0 - GAIN_BELOW) * float(r0 @ r0):
        return None
    sd = _sd_of(runs, J, r0)
    say(f"    {runs.name}: nothing to gain (neither the scan nor a step on its secants "
        f"lowers the cost by {100 * GAIN_BELOW:g} %): the stated set-up, no further runs")
    return {"untestable": False, "p": start.copy(), "sd_internal": np.sqrt(sd**2 + step**2 / 3),
            "sd_fit": sd, "evidence": 1.0, "folds_formed": 0}


def _gauss_newton(J: np.ndarray, r: np.ndarray, name: str) -> np.ndarray:
    """The Gauss-Newton step of residuals ``r`` with Jacobian ``J``, at most MAX_STEP long."""
    step = np.linalg.lstsq(J, -r, rcond=None)[0]
    return step / max(1.0, float(np.abs(step).max()) / MAX_STEP[name])


def _try(runs: _Runs, p: np.ndarray, step: np.ndarray, r: np.ndarray, h: np.ndarray,
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
        say(f"    {name} {label}: {_show(name, trial, test0, runs.model)}, cost "
            f"{r_new @ r_new:.4g} (was {r @ r:.4g})")
        if r_new @ r_new < r @ r:
            return trial, move
    return None, move


def _linearised(runs: _Runs, p: np.ndarray, h: np.ndarray):
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


def _sd_of(runs: _Runs, J: np.ndarray, r: np.ndarray) -> np.ndarray:
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


def _step_text(name: str) -> str:
    v = min(u for u in SCAN[name] if u > 0)
    return {"ply_angle_deg": f"{v:g}°", "holder_force_N": f"a factor {1 + v:g}",
            "mu": f"{v:g}"}.get(base_parameter(name), f"{v:g} mm along x and along y")


def _fitted(name: str, p: np.ndarray, test: Test, model: Model):
    """The fitted value in the report's units (and the stated one)."""
    s = stated(test, name, model)
    if base_parameter(name) == "ply_angle_deg":
        return s + float(p[0])
    if name == "holder_force_N":
        return s * float(p[0])
    if name == "mu":
        return float(p[0])
    return [float(p[0]), float(p[1])]


def _sd(name: str, sd: np.ndarray, test: Test, model: Model):
    if name == "holder_force_N":
        return float(stated(test, name, model) * sd[0])
    if name in ("blank_offset_mm", "tool_offset_mm"):
        return [float(sd[0]), float(sd[1])]
    return float(sd[0])


def _show(name: str, p: np.ndarray, test: Test, model: Model) -> str:
    v = _fitted(name, p, test, model)
    return f"[{v[0]:.3g}, {v[1]:.3g}]" if isinstance(v, list) else f"{v:.4g}"


# --------------------------------------------------------------------------------------------
# The set-up stage


def _setup_candidate(name: str, tests: Sequence[Test], test0: Test, model: Model,
                     base_ho: float, rules: Rules, say: Progress
                     ) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """One set-up candidate: its report entry and internal values, or (untestable entry, None).

    ``base_ho`` is the stated set-up's held-out error (its evidence's numerator).
    """
    reason = _why_not(name, tests)
    if reason is not None:
        return {"effect": name, "setup": True, "reason": reason}, None
    runs = _Runs(tests, model, name)
    start = _start(name, test0, model)
    say(f"set-up candidate {name}: from {_show(name, start, test0, model)}")
    try:
        c = _candidate(runs, test0, rules.untestable_below, say)
    except (SolverError, DrapeInputError) as err:
        return {"effect": name, "setup": True,
                "reason": f"the part cannot be formed so: {err}"}, None
    if c["untestable"]:
        say(f"  untestable: {c['reason']}")
        return {"effect": name, "setup": True, "reason": c["reason"],
                "sensitivity": c["sensitivity"]}, None
    ratio = base_ho / c["heldout_normalised"] if c["heldout_normalised"] > 0 else math.inf
    entry = {"parameter": name, "stated": stated(test0, name, model),
             "fitted": _fitted(name, c["p"], test0, model),
             "sd": _sd(name, c["sd_internal"], test0, model),
             "sd_fit": _sd(name, c["sd_fit"], test0, model),
             "error_after": error_record(c["after"]),
             "heldout_normalised": c["heldout_normalised"],
             "evidence": ratio,
             "evidence_on_model": c["evidence"],
             "significant": bool(min(ratio, c["evidence"]) >= rules.evidence and _distinct(c)),
             "sensitivity": c["sensitivity"],
             "stated_on_model": c["stated_normalised"],
             "n_parameters": len(c["p"]),
             "model": "full" if not _planes(tests, name, c["p"], model) else
                      "/".join(_planes(tests, name, c["p"], model)) + " symmetry"}
    if name in CONFOUNDED:
        entry["confounded_with"] = CONFOUNDED[name]
    entry["runs"] = runs.formed
    say(f"  fitted {_show(name, c['p'], test0, model)} ± {value_text(entry['sd'])} "
        f"(fit alone ± {value_text(entry['sd_fit'])}), normalised "
        f"{entry['error_after']['normalised']:.3g}, held-out "
        f"{c['heldout_normalised']:.3g}, evidence {c['evidence']:.3g}; "
        f"{runs.formed} forming runs ({c['folds_formed']} for the folds)")
    return entry, c


def fit_setup(bundle: Bundle, model: Model, rules: Rules, *,
              parameters: Sequence[str] | None = None,
              progress: Progress | None = None) -> dict[str, Any]:
    """Try every set-up candidate on the bundle's forming tests (module doc).

    Args:
        bundle: The measurements (only the forming tests count here).
        model: The model as stated: material as given or coupon-fitted, friction as given.
        rules: The diagnosis's fixed rules (``diagnose``'s :data:`RULES`).
        parameters: The set-up parameters to try (default :data:`SETUP_PARAMETERS`).
        progress: Called with a line of text per stage.

    Returns:
        A dict: ``setup`` (the candidates' report entries), ``setup_error`` (a name or None),
        ``untestable``, ``stated_error`` (the stated set-up's error record),
        ``stated_heldout_normalised``, ``best`` (the chosen candidate's internal values),
        ``scheme`` and ``rule``.
    """
    say = progress or (lambda line: None)
    names = list(parameters if parameters is not None else SETUP_PARAMETERS)
    unknown = [n for n in names if base_parameter(n) not in SETUP_PARAMETERS]
    if unknown:
        raise DrapeInputError(f"set-up parameters {unknown}: not among "
                              f"{', '.join(SETUP_PARAMETERS)} (and {PLY}<k> on a stack)")
    tests = forming_tests(bundle)
    names = setup_names(names, tests)
    out: dict[str, Any] = {"setup": [], "setup_error": None, "untestable": [], "best": None}
    if not tests:
        out["untestable"] = [{"effect": n, "setup": True, "reason": "no forming test in the "
                              "bundle"} for n in names]
        return out
    test0 = tests[0]
    base_cmp = _stated(tests, model)
    # The candidates are independent (but μ after the force: it is tied to it, eq. 1): tried
    # together, their runs formed in common batches; the outcomes taken in order.
    tied = "mu" in names and "holder_force_N" in names[:names.index("mu")]
    own = [n for n in names if not (n == "mu" and tied)]
    if rules.adequate is not None:
        # Resolution before the set-up, too: a measurement whose residual at the stated
        # set-up is the net's own error is no evidence of a set-up error. Its verdict weighs
        # the candidates' runs, not which they are: their first batch is formed with its run.
        out["resolution"], *_ = together([
            functools.partial(check_resolution, tests, model, base_cmp, rules.adequate),
            *(functools.partial(_first_runs, name, tests, test0, model) for name in own)], say)
        resolved = explained(out["resolution"])
        if resolved:
            # They still count: a set-up that moves the part far from them must pay for it.
            # Their noise is widened by the net's own error (what the net cannot resolve).
            say(f"  set-up stage: the net explains the residual of {', '.join(sorted(resolved))}"
                "; their noise is widened by the net's own error")
            error = {e["measurement"]: e["discretisation_error"] for e in out["resolution"]
                     if e["explains"]}
            tests = [widened(t, error[t.id]) if t.id in error else t for t in tests]
            test0 = tests[0]
            base_cmp = _stated(tests, model)
    base_ho = normalised_error(base_cmp)  # nothing is fitted: held-out = the error
    say(f"set-up as stated: normalised error {base_ho:.3g} on {len(tests)} forming test(s)")
    out.update(stated_error=error_record(base_cmp), stated_heldout_normalised=base_ho,
               scheme=(f"leave-every-{FOLDS}-node-out: {FOLDS} interleaved folds of each "
                       "forming test's nodes, each predicted by one Gauss-Newton step from "
                       "the full fit without them; the stated set-up fits nothing (its "
                       "held-out error is its error)"),
               rule=(f"significant when evidence (stated held-out / candidate held-out, on "
                     f"the forming tests) and evidence_on_model (the same with the stated "
                     f"set-up on the model the candidate needs) are >= {rules.evidence} "
                     f"and the fitted value lies more than {DISTINCT_SD:g} sd from the "
                     f"stated one; "
                     f"ranked by held-out error, "
                     f"near-ties ({100 * rules.parsimony:g} %) to fewer parameters, then to the "
                     f"order {', '.join(SETUP_PARAMETERS)}"))
    outcomes = dict(zip(own, together([functools.partial(
        _setup_candidate, name, tests, test0, model, base_ho, rules) for name in own], say)))
    tried = []
    for name in names:
        if name in outcomes:
            entry, c = outcomes[name]
            if c is None:
                out["untestable"].append(entry)
            else:
                tried.append((entry, c))
            continue
        reason = _why_not(name, tests)
        force = [ec for ec in tried if ec[0]["parameter"] == "holder_force_N"]
        if reason is not None:
            out["untestable"].append({"effect": name, "setup": True, "reason": reason})
        elif force:  # eq. 1: μ acts through μF only, as the force does
            tried.append(_tied_mu(*force[0], test0, model))
            say(f"set-up candidate mu: tied to holder_force_N (μF, eq. 1), "
                f"{value_text(tried[-1][0]['fitted'])}, no runs of its own")
        else:  # the force was untestable: so is μ
            untestable = [u for u in out["untestable"] if u["effect"] == "holder_force_N"]
            out["untestable"].append({**untestable[0], "effect": "mu", "reason": (
                f"as holder_force_N (μ acts through μF only, eq. 1): "
                f"{untestable[0]['reason']}")})
    order = {n: i for i, n in enumerate(dict.fromkeys(setup_names(SETUP_PARAMETERS, tests)
                                                       + names))}
    tried.sort(key=lambda ec: (ec[0]["heldout_normalised"], order[ec[0]["parameter"]]))
    if tried:
        top = tried[0][0]["heldout_normalised"]
        near = [ec for ec in tried
                if ec[0]["heldout_normalised"] <= (1 + rules.parsimony) * top]
        first = min(near, key=lambda ec: (ec[0]["n_parameters"], order[ec[0]["parameter"]]))
        tried.remove(first)
        tried.insert(0, first)
    out["setup"] = [e for e, _ in tried]
    out["model_note"] = _model_note(tried, base_ho)
    if out["model_note"]:
        say(out["model_note"])
    if tried and tried[0][0]["significant"]:
        entry, c = tried[0]
        out["setup_error"] = entry["parameter"]
        out["best"] = {"parameter": entry["parameter"], "p": [float(v) for v in c["p"]]}
    return out


# The stated set-up on the model a candidate needs, this many times further from the data than
# on the case's own model (and beyond the noise): the two models differ, not the set-up.
MODELS_DIFFER = 2.0


def _model_note(tried: list, stated_ho: float) -> str | None:
    """A note when the stated set-up forms unlike the case's model on another.

    A whole blank on frictionless tools can slide on them as a whole: only the holder's
    friction holds it, and once that yields (eq. 1) the translation is free, so where it
    ends is set by small differences (a quarter's symmetry planes fix it). The candidates
    on that model are then judged against the stated set-up on it (``evidence_on_model``).
    """
    other = [e for e, _ in tried if e["stated_on_model"] > MODELS_DIFFER * max(1.0, stated_ho)]
    if not other:
        return None
    worst = max(other, key=lambda e: e["stated_on_model"])
    where = "whole-blank" if worst["model"] == "full" else worst["model"]
    return (f"the stated set-up on the {where} model is "
            f"{worst['stated_on_model']:.3g} × the noise from the forming tests, against "
            f"{stated_ho:.3g} on the case's own model: the models differ, not the set-up (a "
            "whole blank on frictionless tools may slide on them as a whole once the holder's "
            "friction yields); candidates on it are judged against the stated set-up on the "
            "same model too (evidence_on_model)")


def _stated(tests: Sequence[Test], model: Model):
    """The comparisons of the stated set-up with the tests (nothing fitted)."""
    runs = _Runs(tests, model, None)
    return runs.compare(runs.values([np.zeros(0)])[0])


def _tied_mu(entry: dict[str, Any], c: dict[str, Any], test: Test, model: Model):
    """The ``mu`` candidate from the fitted ``holder_force_N`` one (μF fitted: no runs).

    Eq. 1: a friction bar yields at F μ / n_s and F acts nowhere else, so μ' = μ · (F'/F)
    forms the same part as F' with μ: the same errors and evidence, μ's sd scaled likewise.
    """
    mu = float(stated(test, "mu", model))
    factor, sd = float(c["p"][0]), float(c["sd_internal"][0])
    tied = {**entry, "parameter": "mu", "stated": mu, "fitted": mu * factor, "sd": mu * sd,
            "sd_fit": mu * float(c["sd_fit"][0]),
            "confounded_with": "holder_force_N", "tied_to": "holder_force_N", "runs": 0}
    return tied, {**c, "p": np.array([mu * factor]), "start": np.array([mu]),
                  "sd_internal": np.array([mu * sd])}


def widened(test: Test, extra: float) -> Test:
    """``test`` with ``extra`` (in its unit) added in quadrature to every row's noise.

    A model error of known size weighed as noise: the net's own error on a measurement whose
    residual it explains (:mod:`~fenicsx_drape.diagnosis.resolution`).
    """
    column = kind_of(test).sd_column(test)
    columns = dict(test.columns)
    columns[column] = np.hypot(np.asarray(row_sd(test), float), float(extra))
    return dataclasses.replace(test, columns=columns)


def _planes(tests: Sequence[Test], name: str, p, model: Model) -> tuple[str, ...]:
    return forming_case_of(applied(tests[0], name, p, model)[0]).planes


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
    runs = _Runs(forming_tests(bundle), model, name)
    h = np.diag(STEP[name]).astype(float)
    start = _start(name, runs.tests[0], model)
    k = len(start)
    points = [np.asarray(p, dtype=float), start,
              *(start + v * np.eye(k)[i] for i in range(k) for v in SCAN[name])]
    costs = [float(r @ r) for r in map(runs.residual, runs.values(points))]
    p = points[int(np.argmin(costs))]
    r, J, _ = _linearised(runs, p, h)
    for iteration in range(MAX_ITERATIONS):
        new, _ = _try(runs, p, _gauss_newton(J, r, name), r, h,
                      f"refit with the effect {iteration + 1}", say)
        if new is None:
            break
        p = new
        r, J, _ = _linearised(runs, p, h)
    return p


def fitted_value(bundle: Bundle, name: str, p: Sequence[float], model: Model):
    """A set-up point ``p`` (internal units) in the report's units."""
    return _fitted(name, np.asarray(p, dtype=float), forming_tests(bundle)[0], model)


def corrected(bundle: Bundle, name: str, p: Sequence[float], model: Model) -> Bundle:
    """The bundle with a fitted set-up applied to its forming tests.

    Each forming test names its case with the set-up applied (a hemisphere test, its case);
    for a blank offset the measured grid's flat positions are moved by it (the model is read
    where the material lay). Other tests are unchanged.
    """
    named = {t.id: t for t in forming_tests(bundle)}
    tests = []
    for test in bundle.tests:
        if test.id in named:
            test = moved(*applied(named[test.id], name, p, model))
        tests.append(test)
    return dataclasses.replace(bundle, tests=tuple(tests))


def setup_summary(report: dict[str, Any]) -> list[str]:
    """Lines of text on the set-up candidates of a report."""
    lines = []
    if not report.get("setup"):
        return lines
    lines.append(f"{'set-up candidate':<20} {'stated':>12} {'fitted':>18} {'after':>7} "
                 f"{'held-out':>9} {'evidence':>9}  significant")
    show = value_text
    for s in report["setup"]:
        fitted = f"{show(s['fitted'])} ± {show(s['sd'])}"
        lines.append(f"{s['parameter']:<20} {show(s['stated']):>12} {fitted:>18} "
                     f"{s['error_after']['normalised']:>7.3g} {s['heldout_normalised']:>9.3g} "
                     f"{s['evidence']:>9.3g}  {'yes' if s['significant'] else 'no'}")
    lines.append(f"setup_error: {report.get('setup_error')}")
    return lines


def value_text(v) -> str:
    """A fitted set-up value as text: a number, or ``[x, y]`` for an offset."""
    return f"[{v[0]:.3g}, {v[1]:.3g}]" if isinstance(v, list) else f"{v:.4g}"


def fitted_case(case: FormingCase, entry: dict[str, Any]) -> FormingCase:
    """A case with a report's fitted set-up applied (``entry``: one of ``report["setup"]``)."""
    name, value = entry["parameter"], entry["fitted"]
    if ply_index(name):  # the ply's angle within the stack: the fitted one less the stack's
        k = ply_index(name) - 1
        plies = list(case.plies)
        plies[k] = dataclasses.replace(plies[k], angle_deg=value - case.blank.ply_angle_deg)
        return with_overrides(dataclasses.replace(case, plies=tuple(plies)),
                              symmetry=[q for q in case.planes
                                        if q not in broken_planes({PLY[:-1]: value})])
    return with_overrides(case, **{name: value})


# --------------------------------------------------------------------------------------------
# In the diagnosis


def setup_stage(bundle: Bundle, model: Model, parameters: Sequence[str] | None, rules: Rules,
                progress: Progress | None = None) -> tuple[dict[str, Any] | None, Bundle]:
    """The diagnosis's set-up stage: the candidates, and the bundle with the best applied.

    The model is taken as stated: its material fitted to the bundle's coupon tests (if any),
    its friction as given. Returns ``(None, bundle)`` when nothing is to be tried (no
    parameters, or no forming test).
    """
    from fenicsx_drape.diagnosis.compare import fit_bundle

    if not parameters or not any(is_formed(t) for t in bundle.tests):
        return None, bundle
    say = progress or (lambda line: None)
    stated_model = model
    coupons = tuple(t for t in bundle.tests if not is_formed(t))
    if coupons:
        say("set-up: the material fitted to the coupon tests first")
        stated_model = fit_bundle(dataclasses.replace(bundle, tests=coupons), model,
                                  max_iterations=rules.iterations, from_features=True)
    stage = fit_setup(bundle, stated_model, rules, parameters=parameters, progress=say)
    if stage["best"] is None:
        return stage, bundle
    best = stage["best"]
    say(f"set-up error: {best['parameter']}; the physics candidates are tried with it fitted")
    stage.update(bundle=bundle, stated_model=stated_model)  # for refit_setup
    return stage, corrected(bundle, best["parameter"], best["p"], stated_model)


def add_setup(report: dict[str, Any], stage: dict[str, Any] | None) -> None:
    """The set-up stage's fields in a diagnosis report (spec version 3) and its words."""
    if stage is None:
        report.update(setup=[], setup_error=None)
        return
    report.update(setup=stage["setup"], setup_error=stage["setup_error"],
                  setup_stated={"error": stage.get("stated_error"),
                                "heldout_normalised": stage.get("stated_heldout_normalised")},
                  setup_scheme=stage.get("scheme"), setup_rule=stage.get("rule"))
    report["untestable"] = list(report.get("untestable", [])) + stage["untestable"]
    if "resolution" in stage:
        report["setup_resolution"] = stage["resolution"]
    if stage.get("model_note"):
        report["notes"] = [*report.get("notes", []), f"set-up: {stage['model_note']}"]
    if stage["setup_error"] is None:
        return
    s = stage["setup"][0]
    show = value_text
    also = (f" (equivalently {s['confounded_with']}: the holder's friction acts through μF)"
            if "confounded_with" in s else "")
    words = (f"Set-up error: {s['parameter']} fitted {show(s['fitted'])} ± {show(s['sd'])} "
             f"(stated {show(s['stated'])}){also}, bringing the forming tests' normalised "
             f"error from {report['setup_stated']['error']['normalised']:.3g} to "
             f"{s['error_after']['normalised']:.3g} (evidence {s['evidence']:.3g}). "
             + (f"It shows once {stage['found_with_effect']} is in (alone, that effect's "
                "error hid it). " if stage.get("found_with_effect") else
                "The physics candidates were tried with it fitted. "))
    report["conclusion"] = words + report.get("conclusion", "")


def record_history(report: dict[str, Any], out_dir, bundle: Bundle | None = None) -> list[dict]:
    """Record a diagnosis's model versions in ``out_dir``'s ledger (``drape history``).

    In order: the model with the set-up as stated (when set-up candidates were tried), with
    the set-up error fitted, and with the missing effect added: the error falls version by
    version as the set-up is corrected, then as the effect is added.
    """
    from fenicsx_drape.diagnosis.ledger import record_version

    if "error" not in report.get("baseline", {}) or "noise_floor" not in report:
        return []
    base = report["baseline"]
    model = {k: base[k] for k in ("effects", "plugins", "parameters") if k in base}
    noise = report["noise_floor"]
    name = report.get("bundle", bundle.name if bundle else "")
    entries = []
    setup = None
    if report.get("setup"):
        stated = report["setup_stated"]["error"]
        entries.append(record_version(out_dir, name, model, stated, noise, bundle=bundle))
        if report.get("setup_error"):
            best = report["setup"][0]
            setup = {best["parameter"]: best["fitted"]}
    if setup or not entries:
        entries.append(record_version(out_dir, name, model, base["error"], noise,
                                      bundle=bundle, setup=setup))
    if report.get("missing_effect"):
        c = report["candidates"][0]
        added = {**model, "effects": list(dict.fromkeys([*model.get("effects", []),
                                                         *c["effects"]]))}
        entries.append(record_version(out_dir, name, added, c["error_after"], noise,
                                      bundle=bundle, setup=setup))
    return entries
