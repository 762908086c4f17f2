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
XTOL = 0.002  # a Gauss-Newton step smaller than this (in μ) ends the fit
MAX_ITERATIONS = 4  # Gauss-Newton iterations of a forming fit at most
MAX_STEP = 0.3  # largest change of a friction coefficient in one iteration
MU_BOUNDS = (0.0, 2.0)  # friction coefficients fitted within (prepreg on steel: 0.1-0.5)


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


def fit_forming(bundle: Bundle, model: Model, *, kind_of: Callable[[Test], Kind | None],
                tests: Sequence[str] | None = None, max_iterations: int = MAX_ITERATIONS,
                progress: Callable[[str], None] | None = None) -> Model:
    """Fit the model's forming parameters to the forming tests of ``bundle`` (module doc).

    Args:
        bundle: The measurements (coupon tests are ignored here).
        model: The model, material parameters as fitted to the coupons (or given).
        kind_of: Each test's kind (:func:`~fenicsx_drape.diagnosis.kinds.kind_of`; None: no
            kind compares it).
        tests: Only these test ids; all forming tests when None.
        max_iterations: Gauss-Newton iterations at most (capped at :data:`MAX_ITERATIONS`).
        progress: Called with a line of text per iteration.

    Returns:
        The model with its forming parameters fitted.
    """
    from fenicsx_drape.model import parameter_info

    say = progress or (lambda line: None)
    chosen = [t for t in bundle.tests if (kind := kind_of(t)) is not None and kind.formed
              and (tests is None or t.id in tests)]
    kinds = [kind_of(t) for t in chosen]
    names = forming_parameters(model)
    if not any(holder_mu_free(t) for t in chosen):
        names = tuple(n for n in names if n != "mu")
    model = model.with_parameters(**given_interply(chosen, names))
    names = tuple(n for n in names if n not in MODEL_INTERPLY
                  or any(interply_free(t, n) for t in chosen))
    if not chosen or not names:
        return model
    scale = np.array([SCALE.get(n, 1.0) for n in names])
    p = np.array([float(model.parameters[n]) for n in names]) / scale
    k = len(names)
    fd = np.array([FD_STEPS.get(n, FD_STEP) for n in names])
    h = np.diag(fd)

    def residuals(*points: np.ndarray) -> np.ndarray:
        return _residuals(chosen, kinds, model, names, np.vstack(points) * scale)

    def values(q: np.ndarray) -> dict[str, float]:
        return {n: round(float(v), 4 - round(math.log10(c)))
                for n, v, c in zip(names, q * scale, scale)}

    def slopes(p: np.ndarray, r: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
        R = residuals(*(p + h)) if R is None else R
        return (R - r).T / fd

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

    # The starts, judged in the first batch of runs: the model's values, the parameters'
    # defaults (a warm start from a model without the right physics can sit far off) and
    # η_f's scan (STARTS: its runs are not smooth enough for Gauss-Newton to cross its range).
    default = np.clip([parameter_info(n).default for n in names] / scale, *MU_BOUNDS)
    starts = [p] + ([default] if np.abs(default - p).max() > XTOL else [])
    for i, n in enumerate(names):
        for factor in STARTS.get(n, ()):
            starts.append(p.copy())
            starts[-1][i] = np.clip(p[i] * factor, *MU_BOUNDS)
    R, Js = evaluate(*starts)
    r, J = R[0], Js[0]
    best = int(np.argmin([q @ q for q in R]))
    if best:
        which = "the defaults " if starts[best] is default else ""
        say(f"  forming fit: starting from {which}{values(starts[best])} "
            f"(cost {R[best] @ R[best]:.4g}, was {r @ r:.4g})")
        p, r, J = starts[best], R[best], Js[best]
    for iteration in range(min(max_iterations, MAX_ITERATIONS)):
        J = slopes(p, r) if J is None else J
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        step /= max(1.0, float(np.abs(step).max()) / MAX_STEP)
        for attempt in range(2):  # the Gauss-Newton step, then half of it
            trial = np.clip(p + step / 2**attempt, *MU_BOUNDS)
            if np.abs(trial - p).max() < XTOL:
                break
            (r_new,), (J_new,) = evaluate(trial)
            say(f"  forming fit {iteration + 1}: {values(trial)}, "
                f"cost {r_new @ r_new:.4g} (was {r @ r:.4g})")
            if r_new @ r_new < r @ r:
                break
        else:
            break
        if np.abs(trial - p).max() < XTOL:
            break
        p, r, J = trial, r_new, J_new
    return model.with_parameters(**{n: float(v) for n, v in zip(names, p * scale)})


def fit_friction(bundle: Bundle, model: Model, *, kind_of: Callable[[Test], Kind | None],
                 tests: Sequence[str] | None = None, parameters: Sequence[str] | None = None,
                 max_iterations: int = MAX_ITERATIONS, from_features: bool = True,
                 progress: Callable[[str], None] | None = None, details: dict | None = None
                 ) -> Model:
    """The forming kinds' fit hook (:class:`~fenicsx_drape.diagnosis.kinds.base.FitHook`).

    The forming parameters only (:func:`fit_forming`), the material held as the coupons (or
    the model) left it: ``parameters``, ``from_features`` and ``details`` concern the
    material.
    """
    return fit_forming(bundle, model, kind_of=kind_of, tests=tests, progress=progress,
                       max_iterations=max_iterations)
