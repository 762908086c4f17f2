"""Parameter identification from tensile and bias-extension tests (section 3.2).

The model's unit-cell solutions (:mod:`fenicsx_drape.unitcell`) are fitted to the measured
force of every coupon test of a bundle by ``scipy.optimize.least_squares``:

Residuals, variables and Jacobian are those of :mod:`fenicsx_drape.calibration.coupons`
(shared with the sensitivity analysis):

- **residuals**: per row, ``(simulated - measured) / σ_row / √n_test``, with ``σ_row`` the
  row's ``force_sd_N`` or, without it, the model-free noise estimate of the test
  (:mod:`fenicsx_drape.measurements.noise`). The cost is then ``Σ_tests (RMSE / noise)²``: each
  test weighs the same whatever its number of rows, and the minimum is the spec's ``normalised``
  error (1.0 = at the noise floor). The paper minimised the mean absolute force error
  instead; that error is reported too (N and %), like its 7.1 N tensile and 0.6 N bias.
- **variables**: the logarithm of each positive parameter (others are scaled linearly),
  bounded by the parameter's physical range intersected with four decades either side of the
  start, so the optimiser can neither leave the physical range nor run away along a
  direction the data do not determine.
- **Jacobian**: forward differences, all perturbed parameter sets in one vectorised unit-cell
  call per test (the laws accept parameter arrays); as that call costs about the same as one
  parameter set, every residual evaluation brings its Jacobian along.
- **blocks**: as in the paper, tow parameters are fitted to the tensile tests and shear
  parameters to the bias tests (and picture frames, which identify the shear law too) when
  the laws are decoupled. Coupling is judged from the
  data, not assumed: at the start, each parameter's effect (a Jacobian column in noise units)
  on the other kind of test must stay below 20 % of its effect on its own kind (so fitting it
  to its own kind alone costs the other kind at most a fifth of its noise); otherwise all
  parameters are fitted to all tests together. Parameters no test responds to keep their
  starting value and are flagged.
- **start**: curve features (:mod:`fenicsx_drape.calibration.features`), then the best of six
  variants along the two directions the features leave open (η_o against s_o, s_inf against
  eps_v_bar), judged in one vectorised call; values outside a law's range are brought inside
  and reported (``start_notes``). With ``initial_guess_from_features=False``, the given
  model's values (a warm start, e.g. a baseline being extended by one effect).
- **global stage** (a fresh fit; :mod:`fenicsx_drape.calibration.global_stage`): each block
  is searched from the feature guess, Table 2, the MODEL.toml values and Sobol points in
  lockstep; the :data:`POLISHED` lowest distinct minima are refined by the least squares and
  the best kept. The block's record holds every start, the spread of the minima and which
  starts reached the best (``"global"``).
- **undetermined**: parameters the kinds and conditions of the tests cannot determine (the
  tow law without a tensile test, η_o at one strain rate, E_a at one temperature;
  :mod:`fenicsx_drape.calibration.identifiability`) are held at their starting value and
  listed with the reason (``undetermined``).
- **noise**: per test as in :func:`fenicsx_drape.calibration.coupons.test_noise` (column,
  declared in bundle.toml or MODEL.toml, model-free estimate or its floor when implausible);
  ``noise`` in the report says where it came from.

After the fit, :mod:`fenicsx_drape.calibration.sensitivity` gives the Table 2 sensitivities and
the parameter uncertainties from the Jacobian at the optimum, with flags on parameters the data
cannot determine. Forming tests are not part of this fit (they are skipped with a note).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from fenicsx_drape.calibration import features, global_stage, identifiability, sensitivity
from fenicsx_drape.calibration.coupons import (
    BLOCK_ROLE,
    COUPON_KINDS,
    DECADES,
    FD_STEP,
    Residuals,
    Variables,
    declare_noise,
    law_role,
    noise_notes,
    simulate,
    test_noise,
)
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.measurements.bundle import Bundle, Test

# Cross-effect ratio above which the tow and shear blocks are fitted together: a parameter
# fitted to its own kind of test (standard deviation ~ 1/effect there, in ln p) then moves the
# other kind's curves by at most this fraction of their noise.
COUPLING_THRESHOLD = 0.2
# A parameter whose change by a factor e moves the simulated tests by less than this fraction
# of their noise (RMS over the rows, averaged over tests) is one no test responds to.
RESPONSE_FLOOR = 0.05
# The global stage refines this many of its lowest distinct minima by the local least squares.
POLISHED = 2
# Stop when an iteration lowers the cost by less than this fraction (at the noise floor the
# cost is half the number of tests, so with 100-1000 rows per test 1e-4 is a change of the
# χ² of the data by 0.03-0.3, below the 1 that matters statistically), or moves
# the log parameters by less than XTOL: this ends the slow crawl along directions the data
# do not determine (e.g. s_inf against eps_v_bar below the lock-up), which the uncertainty
# analysis then flags.
FTOL = 1e-4
XTOL = 1e-6

Progress = Callable[[str], None]


# --------------------------------------------------------------------------------------------
# Results


@dataclasses.dataclass(frozen=True)
class TestError:
    """How well a model follows one test."""

    id: str
    kind: str
    mean_abs_N: float  # mean |simulated - measured| (the paper's error)
    mean_abs_pct: float  # the same in % of the mean |measured force|
    rmse_N: float  # root-mean-square error
    noise_N: float  # the test's noise (RMS of force_sd_N, or model-free estimate)
    noise_source: str  # see calibration.coupons.test_noise
    normalised: float  # rmse_N / noise_N (1.0 = at the noise floor)

    def as_dict(self) -> dict[str, Any]:
        """A JSON-ready record."""
        return dataclasses.asdict(self)


@dataclasses.dataclass
class FitResult:
    """The outcome of :func:`fit`."""

    model: Any  # the fitted Model
    initial_model: Any  # the model the optimiser started from (after the feature guess)
    bundle: Bundle
    errors: dict[str, TestError]  # per test id
    simulated: dict[str, np.ndarray]  # fitted force (N) per row, per test id
    normalised: float  # √(mean over tests of (rmse/noise)²)
    rmse_N: float  # pooled over all rows, for information
    fitted: tuple[str, ...]  # the parameters the fit changed
    blocks: list[dict[str, Any]]  # what was fitted to what, with iterations and cost
    sensitivity: dict[str, dict[str, dict[str, float]]]  # see sensitivity.table2
    uncertainty: dict[str, dict[str, Any]]  # see sensitivity.uncertainty
    flags: list[str]  # parameters the data cannot determine, and why
    notes: list[str]  # skipped tests, coupling decision, ...
    seconds: float  # wall time of the fit
    # parameters held because the tests cannot determine them: parameter, reason, held_at
    undetermined: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    start_notes: list[str] = dataclasses.field(default_factory=list)  # starts brought inside
    noise: dict[str, dict[str, Any]] = dataclasses.field(default_factory=dict)  # per test

    def report(self) -> dict[str, Any]:
        """A JSON-ready report (errors per test, sensitivities, uncertainties, flags).

        Infinite or undefined numbers (the uncertainty of a parameter no test responds to)
        are written as null, so the file is strict JSON.
        """
        return _strict({
            "bundle": self.bundle.name,
            "effects": list(self.model.effects),
            "parameters": {k: float(v) for k, v in self.model.parameters.items()},
            "initial_parameters": {k: float(v)
                                   for k, v in self.initial_model.parameters.items()},
            "fitted": list(self.fitted),
            "error": {"normalised": self.normalised, "rmse_N": self.rmse_N,
                      "per_test": {k: e.as_dict() for k, e in self.errors.items()},
                      "per_kind": self.errors_per_kind()},
            "blocks": self.blocks,
            "undetermined": self.undetermined,
            "start_notes": self.start_notes,
            "noise": self.noise,
            "sensitivity": self.sensitivity,
            "uncertainty": self.uncertainty,
            "flags": self.flags,
            "notes": self.notes,
            "seconds": self.seconds,
        })

    def errors_per_kind(self) -> dict[str, dict[str, float]]:
        """The paper's summary: mean absolute error per test kind, in N and in %."""
        out = {}
        for kind in COUPON_KINDS:
            tests = [t for t in self.bundle.of_kind(kind) if t.id in self.simulated]
            if not tests:
                continue
            diff = np.concatenate([np.abs(self.simulated[t.id] - t.force_N) for t in tests])
            force = np.concatenate([np.abs(t.force_N) for t in tests])
            out[kind] = {"mean_abs_N": float(diff.mean()),
                         "mean_abs_pct": float(100 * diff.mean() / force.mean())}
        return out


def _strict(obj: Any) -> Any:
    """``obj`` with non-finite floats replaced by None (JSON has no inf or NaN)."""
    if isinstance(obj, dict):
        return {k: _strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_strict(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def test_errors(tests: Sequence[Test], simulated: Mapping[str, np.ndarray]
                ) -> dict[str, TestError]:
    """Per-test errors of simulated forces against the measured ones."""
    out = {}
    for test in tests:
        diff = np.asarray(simulated[test.id]) - test.force_N
        _, noise, source = test_noise(test)
        rmse = float(np.sqrt(np.mean(diff**2)))
        out[test.id] = TestError(
            id=test.id, kind=test.kind, mean_abs_N=float(np.mean(np.abs(diff))),
            mean_abs_pct=float(100 * np.mean(np.abs(diff)) / np.mean(np.abs(test.force_N))),
            rmse_N=rmse, noise_N=noise, noise_source=source, normalised=rmse / noise)
    return out


def normalised_error(errors: Mapping[str, TestError]) -> float:
    """The spec's normalised error: √(mean over tests of (test RMSE / test noise)²)."""
    return float(np.sqrt(np.mean([e.normalised**2 for e in errors.values()])))


# --------------------------------------------------------------------------------------------
# Blocks


def _laws_parameters(model) -> dict[str, tuple[str, ...]]:
    """The active parameters of each law role of ``model`` (fixed ones included)."""
    return {role: tuple(cls.active_parameters(model.effects))
            for role, cls in model.law_classes().items()}


def plan_blocks(model, tests: Sequence[Test], names: Sequence[str],
                alive: Sequence[str] = ()
                ) -> tuple[list[tuple[tuple[str, ...], tuple[Test, ...]]], list[str], list[str]]:
    """Decide what is fitted to what (see the module docstring).

    Returns:
        The blocks ``(parameter names, tests)``, the parameters no test responds to, and
        notes on the decision.
    """
    variables = Variables.make(model, names)
    res = Residuals(model, tests, variables)
    _, J = res.jacobian(variables.to_x(np.array([float(model.parameters[n]) for n in names])))
    # tests are grouped by the law they identify: bias extension and picture frame together
    kinds = sorted({law_role(t.kind) for t in tests})
    rows = np.cumsum([0] + [t.n_rows for t in tests])
    effect = np.zeros((len(kinds), len(names)))
    for i, t in enumerate(tests):
        effect[kinds.index(law_role(t.kind))] += np.sum(J[rows[i]:rows[i + 1]] ** 2, axis=0)
    effect = np.sqrt(effect)
    strongest = effect.max(axis=0)
    dead = [n for n, s in zip(names, strongest) if not s > RESPONSE_FLOOR and n not in alive]
    notes = []
    if dead:
        notes.append("no test responds to " + ", ".join(dead) + ": kept at the start value")
    live = [j for j, n in enumerate(names) if n not in dead]
    if len(kinds) == 1:
        return [(tuple(names[j] for j in live), tuple(tests))], dead, notes
    home = {j: int(np.argmax(effect[:, j])) for j in live}
    cross = max((np.delete(effect[:, j], home[j]).max() / effect[home[j], j] for j in live
                 if effect[home[j], j] > 0),
                default=0.0)
    if cross > COUPLING_THRESHOLD:
        notes.append(f"tow and shear laws coupled in these tests (cross effect {cross:.2g} > "
                     f"{COUPLING_THRESHOLD}): all parameters fitted to all tests together")
        return [(tuple(names[j] for j in live), tuple(tests))], dead, notes
    notes.append(f"tow and shear laws decoupled (largest cross effect {cross:.2g} ≤ "
                 f"{COUPLING_THRESHOLD}): each parameter fitted to the tests of its kind")
    blocks = []
    for k, kind in enumerate(kinds):
        block = tuple(names[j] for j in live if home[j] == k)
        if block:
            blocks.append((block, tuple(t for t in tests if law_role(t.kind) == kind)))
    return blocks, dead, notes


# --------------------------------------------------------------------------------------------
# Initial guess


def initial_guess(model, tests: Sequence[Test], names: Sequence[str],
                  notes: list[str] | None = None):
    """``model`` with the parameters ``names`` started from curve features (section 3.2).

    A feature value outside its law's allowed range (e.g. η_o from bias curves at one rate)
    is brought inside (:func:`~fenicsx_drape.calibration.identifiability.inside_ranges`),
    before and after the force rescaling; each change is appended to ``notes``.
    """
    from fenicsx_drape.model import parameter_info

    notes = [] if notes is None else notes
    guess: dict[str, float] = {}
    tensile = [t for t in tests if t.kind == "tensile"]
    bias = [t for t in tests if law_role(t.kind) == "shear"]  # bias and picture frame
    rate_independent = "rate_dependence" not in model.effects
    try:
        if tensile:
            guess |= features.tow_guess(tensile, decrimping="decrimping" in model.effects)
        if bias:
            eta_ref = (float(model.parameters["eta_o"])
                       * float(model.parameters["rate_ref_per_s"])
                       if rate_independent and "rate_ref_per_s" in model.parameters else None)
            guess |= features.shear_guess(bias, eta_ref=eta_ref)
    except (ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError) as err:
        # curves too short or too odd for the features: the other starts remain
        notes.append(f"curve features failed ({type(err).__name__}: {err}); the feature "
                     "start is the given values")
        return model
    guess = {n: v for n, v in guess.items() if math.isfinite(v)}
    chosen = {n: float(v) for n, v in guess.items() if n in names}
    chosen |= _inside(chosen, "curve features", notes)
    model = model.with_parameters(**chosen)
    # Rescale the force-like parameters of each law together (degree-one homogeneity); the
    # rate-independent lock-up η_o ε̇_ref (f - 1) scales with s_o and s_inf.
    roles = _laws_parameters(model)
    scaled = ("s_o", "s_inf") if rate_independent else ()
    for kind, group in (("tensile", tensile), ("bias_extension", bias)):  # by law role
        force_like = [n for n in roles.get(BLOCK_ROLE[kind], ()) if n in names
                      and (parameter_info(n).unit.startswith("N") or n in scaled)]
        if not group or not force_like:
            continue
        sim = np.concatenate([np.ravel(simulate(t, model)) for t in group])
        meas = np.concatenate([t.force_N for t in group])
        c = float(np.dot(sim, meas) / np.dot(sim, sim)) if np.dot(sim, sim) > 0 else 1.0
        if c > 0 and math.isfinite(c):
            values = {n: float(model.parameters[n]) * c for n in force_like}
            values |= _inside(values, "curve features (rescaled)", notes)
            model = model.with_parameters(**values)
    return _best_start(model, bias, names) if bias else model


def _inside(values: Mapping[str, float], what: str, notes: list[str]) -> dict[str, float]:
    """The values of ``values`` that must change to lie inside their ranges (notes added)."""
    changed, more = identifiability.inside_ranges(dict(values), list(values), what)
    notes += more
    return changed


def _best_start(model, tests: Sequence[Test], names: Sequence[str]):
    """The best of a few variants of the shear guess, judged in one vectorised call per test.

    The features fix η(ε) at low strain and the lock-up seen in the data, not how each splits
    (η_o against s_o, s_inf against eps_v_bar): the variants move along those two directions
    keeping what the data fix (η_o (1 + s_o ε) at ε = 0.2; s_∞ exp(−α_v ε̄_v)).
    """
    p = {n: float(model.parameters[n]) for n in ("eta_o", "s_o", "s_inf", "alpha_v",
                                                  "eps_v_bar")}
    variants = []
    for k in (1.0, 0.5, 2.0):
        s_o = max(((1.0 + 0.2 * p["s_o"]) / k - 1.0) / 0.2, 0.1)
        for shift in (0.0, 0.1):
            s_inf = p["s_inf"] * math.exp(p["alpha_v"] * shift)
            variants.append({"eta_o": k * p["eta_o"], "s_o": s_o, "s_inf": s_inf,
                             "eps_v_bar": p["eps_v_bar"] + shift})
    varied = [n for n in variants[0] if n in names]
    variants = [v for v in variants  # variants a law would reject are left out
                if not identifiability.inside_ranges({n: v[n] for n in varied}, varied, "")[0]]
    if not varied or not variants:
        return model
    sets = model.with_parameters(**{n: np.array([v[n] for v in variants]) for n in varied})
    cost = sum(np.sum(((np.atleast_2d(simulate(t, sets)) - t.force_N) / test_noise(t)[0]) ** 2,
                      axis=1) / t.n_rows for t in tests)
    best = variants[int(np.nanargmin(cost))]
    return model.with_parameters(**{n: best[n] for n in varied})


# --------------------------------------------------------------------------------------------
# The fit


def fit(bundle: Bundle, model=None, *, progress: Progress | None = None,
        initial_guess_from_features: bool = True, tests: Sequence[str] | None = None,
        parameters: Sequence[str] | None = None, max_iterations: int = 200,
        analyse: bool = True, global_stage: bool | None = None) -> FitResult:
    """Fit ``model``'s active parameters to the coupon tests of ``bundle``.

    Args:
        bundle: The measurements (forming tests are skipped with a note).
        model: The model to fit (effects, plugins, start values, fixed parameters, declared
            noise); the default model when None.
        progress: Called with one line of text per iteration and stage.
        initial_guess_from_features: Start from curve features (section 3.2); False starts
            from ``model``'s own values (a warm start).
        tests: Only these test ids (e.g. to hold some out); all coupon tests when None.
        parameters: Only these parameters; the model's active parameters when None.
        max_iterations: Cap on the optimiser's iterations per block.
        analyse: Also compute the Table 2 sensitivities and the uncertainties.
        global_stage: Search from several starts before the local least squares
            (:mod:`~fenicsx_drape.calibration.global_stage`); by default with the feature
            guess (a fresh fit) and not for a warm start.

    Returns:
        The :class:`FitResult`.
    """
    from fenicsx_drape.model import default_model

    start = time.perf_counter()
    say = progress or (lambda line: None)
    model = default_model() if model is None else model
    bundle = declare_noise(bundle, getattr(model, "noise", None))
    global_stage = initial_guess_from_features if global_stage is None else global_stage
    coupons = [t for t in bundle.tests if t.kind in COUPON_KINDS
               and (tests is None or t.id in tests)]
    notes = [f"forming test {t.id!r} not used by the coupon fit" for t in bundle.tests
             if t.kind == "forming"]
    if tests is not None:
        unknown = set(tests) - {t.id for t in bundle.tests}
        if unknown:
            raise DrapeInputError(f"bundle {bundle.name!r} has no test(s) "
                                  f"{', '.join(sorted(unknown))}")
    if not coupons:
        raise DrapeInputError(f"bundle {bundle.name!r}: no tensile or bias-extension test to "
                              "fit")
    active = tuple(model.active_parameters(COUPON_KINDS))
    names = active if parameters is None else tuple(n for n in parameters if n in active)
    if parameters is not None and set(parameters) - set(active):
        notes.append("not fitted (fixed or not used by the model's effects): "
                     + ", ".join(sorted(set(parameters) - set(active))))
    held = identifiability.undetermined(model, coupons, names)
    undetermined = [{"parameter": n, "reason": r, "held_at": float(model.parameters[n])}
                    for n, r in held.items()]
    for u in undetermined:
        say(f"  undetermined: {u['parameter']} held at {u['held_at']:.4g} ({u['reason']})")
    names = tuple(n for n in names if n not in held)
    given, start_notes = model, []
    if initial_guess_from_features:
        say("initial guess from curve features (section 3.2)")
        model = initial_guess(model, coupons, names, start_notes)
    initial = model
    blocks, dead, block_notes = plan_blocks(model, coupons, names)
    if global_stage and dead:
        # dead at this start may live at another (a viscosity too small here to be felt)
        alive = set()
        for other in (given, _table2_start(given, names)):
            alive |= set(dead) - set(plan_blocks(other, coupons, names)[1])
        if alive:
            blocks, dead, block_notes = plan_blocks(model, coupons, names, sorted(alive))
    notes += block_notes
    records = []
    for block_names, block_tests in blocks:
        label = f"{'+'.join(sorted({t.kind for t in block_tests}))} ← {', '.join(block_names)}"
        if global_stage:
            say(f"global stage for {label}")
            starts = [("MODEL.toml", given), ("Table 2", _table2_start(given, block_names))]
            if initial_guess_from_features:
                starts.insert(0, ("curve features", initial))
            model, record = global_stage_search(model, block_names, block_tests, starts,
                                                max_iterations, say)
        else:
            say(f"fitting {label}")
            model, record = _fit_block(model, block_names, block_tests, max_iterations, say)
        record["label"] = label
        records.append(record)
    simulated = {t.id: np.ravel(simulate(t, model)) for t in coupons}
    errors = test_errors(coupons, simulated)
    normalised = normalised_error(errors)
    rmse = float(np.sqrt(np.mean(np.concatenate([(simulated[t.id] - t.force_N) ** 2
                                                   for t in coupons]))))
    for e in errors.values():
        say(f"  {e.id}: mean |error| {e.mean_abs_N:.3g} N ({e.mean_abs_pct:.2g} %), "
            f"RMSE {e.rmse_N:.3g} N = {e.normalised:.3g} × noise ({e.noise_source})")
    fitted = tuple(n for block, _ in blocks for n in block)
    sens, unc, flags = {}, {}, [f"{n}: no test responds to it (not determined)" for n in dead]
    flags += [f"{u['parameter']}: undetermined, held at {u['held_at']:.4g} ({u['reason']})"
              for u in undetermined]
    for record in records:
        flags += [f"{n}: at the bound of its search range (the data push it beyond; "
                  "not determined)" for n in record["at_bound"]]
    if analyse:
        say("sensitivities (Table 2) and uncertainties")
        sens = sensitivity.table2(model, coupons)
        unc, more = sensitivity.uncertainty(model, coupons, fitted, errors)
        flags += more
    for flag in flags:
        say(f"  flag: {flag}")
    for note in start_notes:
        say(f"  start: {note}")
    return FitResult(model=model, initial_model=initial, bundle=bundle, errors=errors,
                     simulated=simulated, normalised=normalised, rmse_N=rmse, fitted=fitted,
                     blocks=records, sensitivity=sens, uncertainty=unc, flags=flags,
                     notes=notes, seconds=time.perf_counter() - start,
                     undetermined=undetermined, start_notes=start_notes,
                     noise=noise_notes(coupons))


def _table2_start(model, names: Sequence[str]):
    """``model`` with ``names`` at the paper's values (Table 2) or their laws' defaults."""
    from fenicsx_drape.model import default_parameters

    defaults = default_parameters()
    return model.with_parameters(**{n: defaults[n] for n in names if n in defaults})


def global_stage_search(model, names: Sequence[str], tests: Sequence[Test],
                        named: Sequence[tuple[str, Any]], max_iterations: int,
                        say: Progress):
    """The global stage of one block and the local least squares from its best minima.

    ``named`` are the named starts (label, model); a start equal to an earlier one is dropped
    (a MODEL.toml without [parameters] is Table 2). After the lockstep search
    (:mod:`~fenicsx_drape.calibration.global_stage`), the :data:`POLISHED` lowest distinct
    minima are each refined by the local least squares (:func:`_fit_block`); the best of
    those is the fit. Returns the model and the block's record, with the search under
    ``"global"``.
    """
    points, labels = [], []
    for label, start in named:
        p = np.array([float(start.parameters[n]) for n in names])
        if not any(np.allclose(p, q, rtol=1e-12, atol=0.0) for q in points):
            points.append(p)
            labels.append(label)
    variables = Variables.make(model, names)
    for p in points:  # the search may go wherever any start's own range reaches
        other = Variables.make(model.with_parameters(**dict(zip(names, map(float, p)))),
                               names)
        variables = dataclasses.replace(variables,
                                        lower=np.minimum(variables.lower, other.lower),
                                        upper=np.maximum(variables.upper, other.upper))
    res = Residuals(model, tests, variables)
    search = global_stage.search(res, [variables.to_x(p) for p in points], labels, FD_STEP)
    best_model, best_record = None, None
    order = sorted((s for s in search.starts if math.isfinite(s.cost)), key=lambda s: s.cost)
    refined: list[tuple[np.ndarray, global_stage.Start]] = []  # (minimum before, refined)
    for start in order:
        twin = next((r for x, r in refined if np.linalg.norm(start.x - x) < 1e-6), None)
        if twin is not None:  # the same minimum as one refined already
            start.x, start.cost, start.polished = twin.x, twin.cost, True
            continue
        if len(refined) == POLISHED:
            break
        before = start.x.copy()
        trial = model.with_parameters(**{n: float(v) for n, v in
                                         zip(names, variables.to_p(start.x))})
        trial, record = _fit_block(trial, names, tests, max_iterations, lambda line: None)
        start.x = variables.to_x(np.array([float(trial.parameters[n]) for n in names]))
        start.cost = 2.0 * record["cost"]
        start.iterations += record["iterations"]
        start.polished = True
        refined.append((before, start))
        if best_record is None or record["cost"] < best_record["cost"]:
            best_model, best_record = trial, record
    if best_model is None:  # every start failed: the local fit from the model itself
        best_model, best_record = _fit_block(model, names, tests, max_iterations, say)
    best_record["global"] = search.record(names, variables.to_p, len(tests))
    say(f"  {search.statement()}")
    return best_model, best_record


def _fit_block(model, names: Sequence[str], tests: Sequence[Test], max_iterations: int,
               say: Progress):
    """Least-squares fit of ``names`` to ``tests``; returns the model and a record."""
    variables = Variables.make(model, names)
    res = Residuals(model, tests, variables)
    x0 = np.clip(variables.to_x(np.array([float(model.parameters[n]) for n in names])),
                 variables.lower, variables.upper)
    # A unit-cell call costs about the same for one parameter set as for n + 1 (its cost is
    # per row), so every residual evaluation brings its Jacobian along.
    cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
    iteration = [0]

    def both(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = res.jacobian(x)
        return cache[key]

    def fun(x):
        return both(x)[0]

    def jac(x):
        r, J = both(x)
        iteration[0] += 1
        cost = float(r @ r)
        say(f"  iteration {iteration[0]:3d}: cost {0.5 * cost:.6g}, normalised "
            f"{math.sqrt(cost / len(tests)):.4g}")
        return J

    sol = least_squares(fun, x0, jac=jac, bounds=(variables.lower, variables.upper),
                        method="trf", x_scale=1.0, ftol=FTOL, xtol=XTOL, gtol=1e-10,
                        max_nfev=max_iterations)
    p = variables.to_p(sol.x)
    model = model.with_parameters(**{n: float(v) for n, v in zip(names, p)})
    at_bound = [n for n, x, lo, hi in zip(names, sol.x, variables.lower, variables.upper)
                if np.isclose(x, lo, atol=1e-6) or np.isclose(x, hi, atol=1e-6)]
    record = {"parameters": list(names), "tests": [t.id for t in tests],
              "iterations": iteration[0], "evaluations": res.evaluations,
              "cost": float(sol.cost), "normalised": math.sqrt(2 * sol.cost / len(tests)),
              "status": sol.message, "at_bound": at_bound}
    return model, record


# --------------------------------------------------------------------------------------------
# Output


def write_fit(result: FitResult, out_dir: str | Path) -> Path:
    """Write the outputs of a fit into ``out_dir``; returns the folder.

    Files: ``model.toml`` (loadable by ``load_model``), ``report.json``, ``sensitivity.csv``,
    ``fit_<test>.png`` per test (measured vs fitted, residual below), ``provenance.json``.
    """
    from fenicsx_drape.provenance import atomic_write_text, write_json, write_provenance

    out = Path(out_dir)
    atomic_write_text(out / "model.toml", result.model.to_toml(relative_to=out))
    write_json(out / "report.json", result.report())
    atomic_write_text(out / "sensitivity.csv", sensitivity.to_csv(result.sensitivity))
    for test in result.bundle.tests:
        if test.id in result.simulated:
            plot_fit(test, result.simulated[test.id], result.errors[test.id],
                     out / f"fit_{_safe(test.id)}.png")
    write_provenance(out, bundle=str(result.bundle.path), model_effects=list(
        result.model.effects), parameters={k: float(v) for k, v in
                                           result.model.parameters.items()},
                     initial_parameters={k: float(v) for k, v in
                                         result.initial_model.parameters.items()},
                     fitted=list(result.fitted), blocks=result.blocks,
                     settings={"ftol": FTOL, "xtol": XTOL, "fd_step": FD_STEP,
                               "decades": DECADES, "coupling_threshold": COUPLING_THRESHOLD,
                               "response_floor": RESPONSE_FLOOR}, seed=None)
    return out


def _safe(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)


def plot_fit(test: Test, simulated: np.ndarray, error: TestError, path: Path) -> Path:
    """Measured and fitted force against displacement, the residual below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fenicsx_drape.provenance import save_figure

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6, 5),
                                      gridspec_kw={"height_ratios": [3, 1]})
    d = test.displacement_mm
    top.plot(d, test.force_N, ".", ms=3, color="0.4", label="measured")
    top.plot(d, simulated, "-", color="C0", label="fitted model")
    top.set_ylabel("force (N)")
    top.set_title(f"{test.id} ({test.kind}): mean |error| {error.mean_abs_N:.3g} N "
                  f"({error.mean_abs_pct:.2g} %)", fontsize=9)
    top.legend(fontsize=8)
    bottom.plot(d, simulated - test.force_N, ".", ms=3, color="C3")
    bottom.axhspan(-error.noise_N, error.noise_N, color="0.85", label="± noise")
    bottom.axhline(0.0, color="0.3", lw=0.8)
    bottom.set_xlabel("crosshead displacement (mm)")
    bottom.set_ylabel("residual (N)")
    bottom.legend(fontsize=7, loc="upper left")
    return save_figure(fig, path)
