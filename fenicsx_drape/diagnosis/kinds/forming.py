"""What the forming kinds share: the case a test forms, its runs, and the fit of the friction.

Every forming measurement (the measured grid, :mod:`~fenicsx_drape.diagnosis.kinds.grid`, and
the lab's, :mod:`~fenicsx_drape.diagnosis.kinds.shear_points`, ``surface``, ``outline``,
``punch_force``) is compared with the run of the case its test names
(:func:`forming_case_of`, on the cells of :func:`case_of`), one run per parameter set of a
vectorised model (:func:`parameter_sets`); a blank placed off-centre moves the flat
positions it is read at (:func:`moved`). They share one fit hook, :func:`fit_friction`
(:func:`fit_forming`).

**Fitting.** In a forming test only the forming parameters are fitted
(:func:`fit_forming`):
the friction coefficients of the model's forming effects (``mu`` of ``holder_friction``,
``mu_tool`` of ``tool_friction``, ``mu_ply`` and the film's ``eta_f_MPa_s_per_mm`` of
``interply_friction`` on a stack), the material parameters staying at their coupon-fitted (or
given) values. The fit is Gauss-Newton on the per-coordinate residuals in noise units, with
forward differences of :data:`FD_STEP` (η_f: :data:`FD_STEPS`), from the best start (the
model's values, the parameters' defaults and η_f's multiples :data:`STARTS`, judged in the
first batch of runs: a warm start from a model lacking the right physics can sit far off,
e.g. a holder μ driven up by a model whose tows carry compression), steps of at most
:data:`MAX_STEP` within :data:`MU_BOUNDS` and halved once when they do not lower the cost;
every forming run is cached by its case and parameters. The runs of one iteration (the
point and its perturbations) go to the workers at once (:mod:`~fenicsx_drape.runs`) when the
point fits in the perturbations' last batch for no extra time (one parameter on two
workers); else a point's perturbations are formed only once the fit takes the point (a
rejected step's are not needed: on one worker, a fifth of the lab README diagnosis's runs).
The fit is the same either way.

The holder's μ is fitted only where a test's holder does not fix it (a case's
``[holder] mu``), and the inter-ply μ and η_f only on a stack whose ``[interply]`` table does
not give them (:func:`interply_free`).

In a candidate's refit the fit also moves the candidate's **own** parameters (``own`` of the
fit hook: η_o and E_v of ``rate_dependence``, ...; not a friction's regularisation slip,
:data:`REGULARISATION`) that no coupon test of the fit fixes: on a bundle of forming tests
only, nothing else can move them, and a refit held at its start's material is no measure of
the candidate. They are fitted with the friction in their logarithms (forward differences of
:data:`LOG_STEP`, steps of at most :data:`MAX_LOG_STEP`, within the parameters' bounds, at
most :data:`MAX_MATERIAL_ITERATIONS` iterations, ending when one lowers the cost by less
than :data:`MATERIAL_FTOL` of it): one more run per parameter, test and iteration.

**Cost.** A forming run costs seconds (4 s for the 10 mm quarter), and a diagnosis makes
a few dozen: only the friction coefficients are fitted (one or two parameters, Gauss-Newton
in at most :data:`MAX_ITERATIONS` iterations), every run is cached, the runs of an iteration
go to persistent worker processes, and the held-out folds (every third node of the grid
left out, three folds) start from the full fit, so a fold costs a run only when its step
moves the parameters by more than :data:`XTOL`. The hemisphere runs use cells of
:data:`~fenicsx_drape.runs.FULL_CELL_MM` (the paper's Δ) and a case its
blank's ``cell_mm``; :func:`~fenicsx_drape.runs.resolution` sets another
for both. A coarser screening mesh
(:data:`~fenicsx_drape.runs.SCREEN_CELL_MM`, 4× cheaper) is only sound
when its discretisation error is below the noise: against a grid formed on 10 mm cells, the
20 mm mesh misses by 2.9 × the 0.3 mm noise (at the tow axes over the fillet), which hides a
tool friction that the 10 mm mesh finds; :func:`~fenicsx_drape.diagnosis.pipeline.confirm`
refits the baseline and the winner on another mesh to check a verdict.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case import FormingCase, case_file, case_for_test, with_overrides
from fenicsx_drape.forming.case.spec import MODEL_INTERPLY
from fenicsx_drape.runs import Deferred, cell_override, memo, spare

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds.base import Kind
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

# What a forming test fits: the friction coefficients (holder, tools, between plies) and the
# inter-ply film's η_f.
FORMING_PARAMETERS = ("mu", "mu_tool", "mu_ply", "eta_f_MPa_s_per_mm")
# The fit works on each parameter over its scale (a friction coefficient as it is; η_f in
# units of 0.01 MPa·s/mm, so that the steps and bounds below span its published range,
# 0.0005-0.01, as they span a μ's).
SCALE = {"eta_f_MPa_s_per_mm": 0.01}
FD_STEP = 0.02  # forward-difference step in a friction coefficient (scaled units)
# A stack's runs are not smooth in η_f on the scale of 0.0002 MPa·s/mm (the hemisphere's
# [0/90, ±45] at 30 mm cells: the cost 17.2, 28.0, 16.5 at 0.0031, 0.0033, 0.0035, falling
# from 80 at 0.002 to 1.8 at 0.006): its difference is taken over 0.001 MPa·s/mm.
FD_STEPS = {"eta_f_MPa_s_per_mm": 0.1}
# And the fit starts from the best of η_f's model value and these multiples of it, formed in
# its first batch (η_f spans a factor 20 between published films).
STARTS = {"eta_f_MPa_s_per_mm": (0.5, 2.0, 4.0)}
# Held in a candidate's refit: the slip over which a friction is regularised (sticking below
# it), a numerical choice the forming tests do not decide (the coefficient acts alike).
REGULARISATION = ("holder_slip_mm", "tool_slip_mm")
XTOL = 0.002  # a Gauss-Newton step smaller than this (in μ) ends the fit
MAX_ITERATIONS = 4  # Gauss-Newton iterations of a forming fit at most
MAX_STEP = 0.3  # largest change of a friction coefficient in one iteration
MU_BOUNDS = (0.0, 2.0)  # friction coefficients fitted within (prepreg on steel: 0.1-0.5)
# A candidate's own material parameters, fitted with the friction in their logarithms:
LOG_STEP = 0.05  # forward-difference step in the logarithm (5 %)
LOG_XTOL = 0.02  # a step smaller than this in every logarithm (2 %, and XTOL in μ) ends the fit
MAX_LOG_STEP = math.log(10.0)  # largest change in one iteration: a factor of 10
MAX_MATERIAL_ITERATIONS = 6  # Gauss-Newton iterations at most when material is fitted
MATERIAL_FTOL = 0.01  # with material: an iteration lowering the cost by less (share) ends it


# --------------------------------------------------------------------------------------------
# The case a test forms


def names_case(test: Test) -> bool:
    """Whether a forming test names its case file (else it is the paper's hemisphere)."""
    return test.case is not None or test.forming_case is not None


def forming_case_of(test: Test) -> FormingCase:
    """The case a test forms, with the test's keys applied.

    A test that names its case file: that case (as the bundle loader read it, else read here);
    a test with ``geometry = "hemisphere"``: the paper's, ``meshes/hemisphere/case.toml`` (a
    symmetric quarter), with the test's tool sizes, travel, duration and holding force. Read
    once per file and keys.
    """
    if test.forming_case is not None:
        return test.forming_case
    if test.case_path is not None:
        path, keys = test.case_path, test.case_keys
    elif test.geometry == "hemisphere":
        path, keys = case_file("hemisphere"), test.forming
    else:
        raise DrapeInputError(f"test {test.id!r}: forming geometry {test.geometry!r} cannot be "
                              "simulated (known: hemisphere; or name the forming case with "
                              "case = \"case.toml\")")
    # Read once per command: a file edited between two commands is read again.
    cases = memo("forming.cases", 64)
    key = (str(path), tuple(sorted((k, str(v)) for k, v in keys.items())))
    hit = cases.get(key)
    return hit if hit is not None else cases.put(key, case_for_test(path, keys)[0])


@functools.lru_cache(maxsize=64)
def _with_cell(case: FormingCase, cell_mm: float) -> FormingCase:
    return case if case.blank.cell_mm == cell_mm else with_overrides(case, cell_mm=cell_mm)


def case_of(test: Test, cell_mm: float | None = None) -> FormingCase:
    """The case a forming test is simulated with (:func:`forming_case_of`), on its cells.

    The cells are ``cell_mm``, else the :func:`~fenicsx_drape.runs.
    resolution`'s, else the case's own (the hemisphere's: the paper's 10 mm).
    """
    case = forming_case_of(test)
    cell = cell_mm or cell_override()
    return _with_cell(case, float(cell)) if cell else case


def model_planes(test: Test) -> tuple[str, ...]:
    """The symmetry planes of the part the test's runs model (the hemisphere: a quarter)."""
    return forming_case_of(test).planes


def parameter_sets(model: Model) -> list[Model] | None:
    """The models of each parameter set of a vectorised model (None: not vectorised)."""
    sizes = {np.size(v) for v in model.parameters.values() if np.ndim(v) > 0}
    if not sizes:
        return None
    (k,) = sizes
    return [model.with_parameters(**{n: float(v[i]) for n, v in model.parameters.items()
                                     if np.ndim(v) > 0}) for i in range(k)]


def moved(test: Test, shift: np.ndarray) -> Test:
    """``test`` with its flat-blank positions moved by ``shift`` (mm): a blank offset.

    The flat positions of a grid or of shear points at flat positions are where the stated
    set-up puts the material; on a blank moved by d the same material lies d further. Formed
    positions (a scan, an edge, shear points on the formed part) and forces are in the tools'
    frame and do not move.
    """
    if not np.any(shift) or "x0_mm" not in test.columns:
        return test
    columns = dict(test.columns)
    columns["x0_mm"] = np.asarray(columns["x0_mm"], float) + shift[0]
    columns["y0_mm"] = np.asarray(columns["y0_mm"], float) + shift[1]
    return dataclasses.replace(test, columns=columns)


# --------------------------------------------------------------------------------------------
# Fitting the forming parameters


def holder_mu_free(test: Test) -> bool:
    """Whether the model's holder μ acts in a test (a case may fix it, or have no holder)."""
    if not names_case(test):
        return True
    holder = forming_case_of(test).holder
    return holder is not None and holder.mu is None


def interply_free(test: Test, name: str) -> bool:
    """Whether the model's inter-ply ``name`` (μ_ply, η_f) acts in a test.

    On a stack whose ``[interply]`` table does not give it (the case's value wins, as a
    holder's μ).
    """
    case = forming_case_of(test)
    return case.stack and not case.interply_given(name)


def given_interply(tests: Sequence[Test], names: Sequence[str]) -> dict[str, float]:
    """The inter-ply values of ``names`` that every test's case gives alike (the ones that act).

    The fitted model carries them, so that its report says what acted, not a start of the
    refit that never formed (the runs leave a given value out of their key).
    """
    out = {}
    for name in (n for n in names if n in MODEL_INTERPLY):
        cases = [forming_case_of(t) for t in tests]
        values = {dict(c.interply).get(name) for c in cases if c.stack}
        if values and None not in values and len(values) == 1:
            out[name] = float(values.pop())
    return out


def forming_parameters(model: Model) -> tuple[str, ...]:
    """The forming parameters the model fits: those of :data:`FORMING_PARAMETERS` it uses."""
    active = model.active_parameters()
    return tuple(n for n in FORMING_PARAMETERS if n in active)


def free_parameters(model: Model, tests: Sequence[Test]) -> tuple[str, ...]:
    """The forming parameters a fit to the formed ``tests`` moves.

    The holder's μ only where a test's holder does not fix it; the inter-ply μ and η_f only on
    a stack whose ``[interply]`` table does not give them.
    """
    names = forming_parameters(model) if tests else ()
    if not any(holder_mu_free(t) for t in tests):
        names = tuple(n for n in names if n != "mu")
    return tuple(n for n in names if n not in MODEL_INTERPLY
                 or any(interply_free(t, n) for t in tests))


def _residuals(tests: Sequence[Test], kinds: Sequence[Kind], model: Model,
               names: Sequence[str], sets: np.ndarray) -> np.ndarray:
    """Residuals in noise units, cost = Σ_tests (RMSE / noise)², one row per parameter set."""
    vectorised = model.with_parameters(**{n: sets[:, i] for i, n in enumerate(names)})
    out = []
    for test, kind in zip(tests, kinds):
        values = np.atleast_2d(kind.simulate(test, vectorised))
        sd = kind.value_sd(test)
        w = 1.0 / sd / math.sqrt(sd.size)
        r = (values - kind.measured(test)) * w
        out.append(np.where(np.isfinite(r), r, 0.0))
    return np.concatenate(out, axis=1)


def _transforms(names: Sequence[str], material: Sequence[str]):
    """The fit's coordinates: friction over its :data:`SCALE`, material in logarithms.

    Returns the values of a point (rows of coordinates), the forward-difference steps, the
    largest step, the step that ends the fit and the bounds, each per coordinate.
    """
    from fenicsx_drape.model import parameter_info

    is_log = np.array([n in material for n in names])
    scale = np.array([1.0 if log else SCALE.get(n, 1.0) for n, log in zip(names, is_log)])
    lo, hi = [], []
    for n, log in zip(names, is_log):
        a, b = parameter_info(n).bounds if log else MU_BOUNDS
        if log:  # a parameter at 0 is not fitted (see fit_forming): its bounds in logarithms
            a, b = (math.log(a) if a > 0 else -math.inf), (math.log(b) if b < math.inf
                                                           else math.inf)
        lo.append(a)
        hi.append(b)
    h = np.where(is_log, LOG_STEP, [FD_STEPS.get(n, FD_STEP) for n in names])
    largest = np.where(is_log, MAX_LOG_STEP, MAX_STEP)
    tol = np.where(is_log, LOG_XTOL, XTOL)

    def values(x: np.ndarray) -> np.ndarray:
        return np.where(is_log, np.exp(np.where(is_log, x, 0.0)), x * scale)

    def coordinates(v: np.ndarray) -> np.ndarray:
        return np.where(is_log, np.log(np.where(is_log, v, 1.0)), v / scale)

    return values, coordinates, h, largest, tol, (np.array(lo), np.array(hi))


def fit_forming(bundle: Bundle, model: Model, *, kind_of: Callable[[Test], Kind | None],
                tests: Sequence[str] | None = None, material: Sequence[str] = (),
                max_iterations: int = MAX_ITERATIONS,
                progress: Callable[[str], None] | None = None) -> Model:
    """Fit the model's forming parameters to the forming tests of ``bundle`` (module doc).

    Args:
        bundle: The measurements (coupon tests are ignored here).
        model: The model, material parameters as fitted to the coupons (or given).
        kind_of: Each test's kind (:func:`~fenicsx_drape.diagnosis.kinds.kind_of`; None: no
            kind compares it).
        tests: Only these test ids; all forming tests when None.
        material: Material parameters fitted with the friction, in their logarithms (a
            candidate's own parameters that no coupon test fixes); each costs one more run
            per test and iteration.
        max_iterations: Gauss-Newton iterations at most (capped at :data:`MAX_ITERATIONS`,
            :data:`MAX_MATERIAL_ITERATIONS` with ``material``).
        progress: Called with a line of text per iteration.

    Returns:
        The model with its forming parameters fitted.
    """
    from fenicsx_drape.model import parameter_info

    say = progress or (lambda line: None)
    chosen = [t for t in bundle.tests if (kind := kind_of(t)) is not None and kind.formed
              and (tests is None or t.id in tests)]
    kinds = [kind_of(t) for t in chosen]
    model = model.with_parameters(**given_interply(chosen, forming_parameters(model)))
    names = free_parameters(model, chosen)
    active = model.active_parameters()
    material = tuple(n for n in dict.fromkeys(material) if n in active and n not in names
                     and float(model.parameters[n]) > 0.0)
    names = (*names, *material)
    if not chosen or not names:
        return model
    values, coordinates, step_h, largest, tol, (lo, hi) = _transforms(names, material)
    p = coordinates(np.array([float(model.parameters[n]) for n in names]))
    k = len(names)
    h = np.diag(step_h)
    cap = MAX_MATERIAL_ITERATIONS if material else MAX_ITERATIONS

    def shown(x: np.ndarray) -> dict[str, float]:
        return {n: float(f"{v:.4g}") for n, v in zip(names, values(x))}

    def residuals(*points: np.ndarray) -> np.ndarray:
        return _residuals(chosen, kinds, model, names, values(np.vstack(points)))

    def slopes(p: np.ndarray, r: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
        R = residuals(*(p + h)) if R is None else R
        return (R - r).T / step_h

    def evaluate(*points: np.ndarray) -> tuple[np.ndarray, list[np.ndarray | None]]:
        """The residuals at ``points`` and each one's Jacobian where its runs were at hand.

        A point's finite differences are spare runs (runs.spare): formed with it where
        the batch leaves a worker free (one parameter on two workers), else only once the fit
        takes the point (a rejected step's would be wasted). The same numbers either way.
        """
        m = len(points)
        try:
            with spare(m):
                R = residuals(*points, *(q + h for q in points))
            return R[:m], [slopes(q, R[i], R[m + i * k:m + (i + 1) * k])
                           for i, q in enumerate(points)]
        except Deferred:  # the points are formed: their slopes where their runs are
            R = residuals(*points)
        Js = []
        for i, q in enumerate(points):
            try:
                with spare(0):
                    Js.append(slopes(q, R[i]))
            except Deferred:
                Js.append(None)
        return R, Js

    # The starts, judged in the first batch of runs: the model's values, the friction
    # coefficients' defaults (a warm start from a model without the right physics can sit far
    # off) and η_f's scan (STARTS: its runs are not smooth enough for Gauss-Newton to cross its
    # range); the material stays at the model's values in each.
    friction = np.array([n not in material for n in names])
    default = np.clip(coordinates(np.array([
        float(parameter_info(n).default) if f else float(model.parameters[n])
        for n, f in zip(names, friction)])), lo, hi)
    starts = [p] + ([default] if np.any(np.abs(default - p) > tol) else [])
    for i, n in enumerate(names):
        for factor in STARTS.get(n, ()) if friction[i] else ():
            starts.append(p.copy())
            starts[-1][i] = np.clip(p[i] * factor, lo[i], hi[i])
    R, Js = evaluate(*starts)
    r, J = R[0], Js[0]
    best = int(np.argmin([q @ q for q in R]))
    if best:
        which = "the defaults " if starts[best] is default else ""
        say(f"  forming fit: starting from {which}{shown(starts[best])} "
            f"(cost {R[best] @ R[best]:.4g}, was {r @ r:.4g})")
        p, r, J = starts[best], R[best], Js[best]
    for iteration in range(min(max_iterations, cap)):
        J = slopes(p, r) if J is None else J
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        step /= max(1.0, float(np.max(np.abs(step) / largest)))
        for attempt in range(2):  # the Gauss-Newton step, then half of it
            trial = np.clip(p + step / 2**attempt, lo, hi)
            if np.all(np.abs(trial - p) < tol):
                break
            (r_new,), (J_new,) = evaluate(trial)
            say(f"  forming fit {iteration + 1}: {shown(trial)}, "
                f"cost {r_new @ r_new:.4g} (was {r @ r:.4g})")
            if r_new @ r_new < r @ r:
                break
        else:
            break
        if np.all(np.abs(trial - p) < tol):
            break
        gain = 1.0 - (r_new @ r_new) / (r @ r)
        p, r, J = trial, r_new, J_new
        if material and gain < MATERIAL_FTOL:
            break  # each iteration costs 1 + k runs a test: a step gaining little ends it
    return model.with_parameters(**{n: float(v) for n, v in zip(names, values(p))})


def fit_friction(bundle: Bundle, model: Model, *, kind_of: Callable[[Test], Kind | None],
                 tests: Sequence[str] | None = None, parameters: Sequence[str] | None = None,
                 max_iterations: int = MAX_ITERATIONS, from_features: bool = True,
                 progress: Callable[[str], None] | None = None, details: dict | None = None,
                 own: Sequence[str] = ()) -> Model:
    """The forming kinds' fit hook (:class:`~fenicsx_drape.diagnosis.kinds.base.FitHook`).

    The forming parameters (:func:`fit_forming`), the material held as the coupons (or the
    model) left it, but for ``own``: a candidate's own parameters that no coupon test of the
    fit fixes, fitted with the friction (on a bundle of forming tests only, the forming
    tests are all that can move them), but for a friction's regularisation slip
    (:data:`REGULARISATION`). ``from_features`` and ``details`` concern the material;
    ``parameters``, when given, limits ``own``.
    """
    from fenicsx_drape.diagnosis.kinds.coupon import coupon_parameters
    from fenicsx_drape.diagnosis.kinds.interply_friction import NAME, interply_parameters

    fixed: set[str] = set()
    for test in bundle.tests:
        kind = kind_of(test)
        if kind is not None and not kind.formed and (tests is None or test.id in tests):
            # a pull-out fixes the inter-ply law; a coupon the law it loads
            fixed |= set(interply_parameters(model) if test.kind == NAME
                         else coupon_parameters(model, test.kind))
    material = [n for n in own if n not in fixed and n not in REGULARISATION
                and (parameters is None or n in parameters)]
    return fit_forming(bundle, model, kind_of=kind_of, tests=tests, progress=progress,
                       max_iterations=max_iterations, material=material)

