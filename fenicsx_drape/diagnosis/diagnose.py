"""Which physical effect is a model missing? (``drape diagnose``).

The procedure follows the diagnosis contract of ``docs/measurements.md``:

1. **Baseline.** The model is fitted to the bundle (:func:`fenicsx_drape.calibration.fit.fit`)
   and compared with every test (:mod:`fenicsx_drape.diagnosis.compare`): per-test RMSE, the
   noise floor (from ``force_sd_N`` or model-free), ``normalised`` and ``where`` the error
   sits.
2. **Candidates.** Every catalogued effect not in the model (:data:`fenicsx_drape.effects.
   EFFECTS`), and every user law the model's plugins register, is a candidate. An effect whose
   prerequisite is missing is tried together with it, under the joined name
   (``rate_dependence+temperature_dependence``).
3. **Untestable.** Each candidate is first added at its default strength to the fitted
   baseline and the tests are simulated with and without it. When the change is below
   :data:`UNTESTABLE_BELOW` times the noise (normalised like the error), the bundle cannot
   exercise the effect: it is reported with the reason and not ranked.
4. **Refit.** A testable candidate is refitted, warm-started from the baseline's fit, over its
   own parameters and those of the law it acts on, from the best (in one vectorised
   evaluation) of three starts: the effect at its default strength, the effect weak (its own
   parameters that may vanish at 1 % of their defaults: for most effects nearly the
   baseline), and the curve-feature guess. ``error_after`` is the refit's error.
5. **Held-out error.** Baseline and candidates are judged on rows their fit did not see. The
   scheme (stated in the report): for a test kind with several tests, *leave one test out*
   (fit on all other tests, predict the one left out: an unseen speed or temperature); for a
   kind with a single test, *leave every* :data:`BLOCKS` *-th row out*: each of
   :data:`BLOCKS` interleaved folds gives its rows infinite standard deviation (no weight in
   the fit; the history is still followed row by row) and predicts them. Interleaved rather
   than contiguous blocks: a contiguous end block would test the extrapolation of poorly
   determined parameters (the same for every candidate) rather than the physics; the
   physics is tested across conditions by leaving tests out.
   Every row is predicted once; ``heldout_normalised`` is the normalised error of these
   predictions. Each fold is warm-started from the full fit and refits, to the other tests of
   the held-out test's kind, the parameters that kind identifies (tow law: tension; shear
   law: bias extension), in at most :data:`FOLD_ITERATIONS` iterations.
6. **Decision.** ``evidence`` = baseline held-out / candidate held-out, over the tests of
   the kinds the candidate acts on (all tests when the bundle has only those; a forming-only
   effect in a mixed bundle is judged on its forming tests, which the coupons would dilute).
   **significant** (fixed rule, the same for every bundle): ``evidence >=
   EVIDENCE_THRESHOLD`` (1.2: the candidate predicts unseen data with an error at least 17 %
   lower). Candidates are ranked by
   ``heldout_normalised``; among those within :data:`PARSIMONY` (5 %) of the best, the one
   adding the fewest parameters ranks first. ``missing_effect`` is the first candidate if it
   is significant **and** its refit reaches ``normalised <= ADEQUATE`` (1.5), else null.
7. **Groups.** When the coupon tests come from several labs (``lab = "..."``), several sizes
   of one kind, or both shear tests (bias extension and picture frame), each such group is
   left out of the baseline's coupon fit in turn and predicted by the rest
   (:mod:`fenicsx_drape.calibration.consistency`): ``consistency`` in the report, and the
   conclusion says a lab offset, size effect or kind mismatch beside the physics.
8. **Resolution before physics** (spec version 4, :mod:`~fenicsx_drape.diagnosis.
   resolution`). Before any effect is named, each forming measurement the baseline misses is
   compared with the same model on half the cell; a measurement whose residual the net
   explains is no evidence for an effect (:func:`_evidence` leaves it out), and the conclusion
   says which net would resolve it.

**The stages, in the order** :func:`diagnose` **runs them**, each a function with its inputs
and its result: the data check (:func:`~fenicsx_drape.diagnosis.data_check.data_check`);
prepare (:func:`_prepare`: each test's noise from its kind's one noise function, its regions,
the held-out folds); the baseline fitted, with its outliers left out (:func:`_baseline_stage`);
the set-up stage on the bundle less its outliers
(:func:`~fenicsx_drape.diagnosis.setup.setup_stage`: the stated set-up's own fits are its
reference; the best set-up, when one is significant, is applied and the baseline refitted at
it, :func:`_at_setup`); the baseline's held-out error (:func:`_with_heldout`) and resolution
(:func:`~fenicsx_drape.diagnosis.resolution.check_resolution`); the effects, each candidate
refitted and judged (:func:`_try_effect`); the report and its decision (:func:`_report`).
The confirmation on a finer net is ``drape diagnose --confirm-cell-mm`` (:func:`confirm`).
Stages that do not need each other's results (the candidates; the folds; the held-out error
and resolution) run through :func:`~fenicsx_drape.diagnosis.forming_runs.together`: the same
results as one after the other, their forming runs in common batches that keep every worker
busy.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.compare import (
    compare_tests,
    error_record,
    find_outliers,
    fit_bundle,
    locate,
    model_record,
    noise_record,
    normalised_error,
    prepare,
    simulate,
    trends,
    where,
)
from fenicsx_drape.diagnosis.data_check import (
    apply_data_check,
    data_check,
    say_suspects,
    suspect_tests,
)
from fenicsx_drape.diagnosis.forming_runs import FULL_CELL_MM, together
from fenicsx_drape.diagnosis.kinds import Comparison, is_formed, kind_of, row_sd
from fenicsx_drape.diagnosis.resolution import check_resolution, explained, finer_net
from fenicsx_drape.diagnosis.resolution import sentence as resolution_sentence
from fenicsx_drape.diagnosis.setup import DISTINCT_SD as SETUP_DISTINCT_SD
from fenicsx_drape.errors import DrapeInputError

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

CONTRACT = 3  # version of the diagnosis contract the report follows
EVIDENCE_THRESHOLD = 1.2  # significant: evidence at least this (fixed for every bundle)
ADEQUATE = 1.5  # a model within this many times the noise floor explains the data
UNTESTABLE_BELOW = 0.3  # an effect changing the tests by less (× noise) is untestable
PARSIMONY = 0.05  # candidates this close to the best held-out error count as ties
BLOCKS = 3  # interleaved folds of a kind with a single test
BASELINE_ITERATIONS = 100  # iteration caps of the fits: baseline, candidates, folds
REFIT_ITERATIONS = 40
# Rounds of set-up and effect fitted in turn when a set-up error was fitted.
SETUP_ROUNDS = 4
FOLD_ITERATIONS = 8
WEAK = 0.01  # a candidate's weak start: its own vanishing parameters at 1 % of default

SIGNIFICANCE_RULE = (f"significant when evidence (baseline held-out normalised error / "
                     f"candidate held-out normalised error, on the tests of the kinds the "
                     f"candidate acts on) >= {EVIDENCE_THRESHOLD}")

Progress = Callable[[str], None]


class Report(dict):
    """The diagnosis report: a dict with the contract's fields (JSON-ready).

    It also carries, outside the dict (not written to JSON), the fitted models and their
    comparisons with the tests: ``models`` and ``comparisons``, keyed by ``"baseline"`` and
    by each ranked candidate's ``effect``.
    """

    models: dict[str, Model]
    comparisons: dict[str, list[Comparison]]
    tests: tuple[Test, ...]  # the tests compared (without the outliers' rows)


@dataclasses.dataclass(frozen=True)
class Fold:
    """One held-out fit: what it is fitted to and which rows it predicts."""

    label: str
    bundle: Bundle  # the bundle fitted (held-out rows of a single test at infinite sd)
    fitted: tuple[str, ...]  # ids of the tests fitted (of the held-out test's kind)
    predicts: str  # id of the test it predicts
    rows: np.ndarray  # boolean mask of the rows of that test it predicts


@dataclasses.dataclass(frozen=True)
class _Data:
    """The bundle in canonical order and what does not depend on the model."""

    bundle: Bundle  # comparable tests only, sorted by id (the result is order-independent)
    tests: tuple[Test, ...]
    noise: dict[str, tuple[float, str]]
    regions: dict[str, list]
    folds: tuple[Fold, ...]
    scheme: str
    notes: tuple[str, ...]

    def compare(self, simulated: dict[str, np.ndarray]) -> list[Comparison]:
        return compare_tests(self.tests, simulated, self.regions, self.noise)


def _prepare(bundle: Bundle) -> _Data:
    tests, skipped = prepare(bundle)
    tests = tuple(sorted(tests, key=lambda t: t.id))
    canonical = dataclasses.replace(bundle, tests=tests)
    noise = {t.id: kind_of(t).noise(t) for t in tests}
    regions = {t.id: kind_of(t).regions(t) for t in tests}
    folds, scheme = make_folds(canonical)
    return _Data(canonical, tests, noise, regions, folds, scheme, tuple(skipped))


def make_folds(bundle: Bundle) -> tuple[tuple[Fold, ...], str]:
    """The held-out folds of a bundle and the description of the scheme (module doc, 5.)."""
    by_kind: dict[str, list[Test]] = {}
    for test in bundle.tests:
        by_kind.setdefault(test.kind, []).append(test)
    folds: list[Fold] = []
    parts = []
    for kind, tests in sorted(by_kind.items()):
        if len(tests) > 1:
            parts.append(f"leave-one-test-out over the {len(tests)} {kind} tests")
            for test in tests:
                folds.append(Fold(f"without {test.id}", bundle,
                                  tuple(t.id for t in tests if t.id != test.id), test.id,
                                  np.ones(test.n_rows, bool)))
            continue
        (test,) = tests
        parts.append(f"leave-every-{_ordinal(BLOCKS)}-row-out ({BLOCKS} interleaved folds) "
                     f"for the single {kind} test {test.id!r}")
        for b in range(BLOCKS):
            mask = np.arange(test.n_rows) % BLOCKS == b
            held = _without_rows(test, mask)
            tests_b = tuple(held if t.id == test.id else t for t in bundle.tests)
            folds.append(Fold(f"{test.id} rows {b + 1}::{BLOCKS}",
                              dataclasses.replace(bundle, tests=tests_b), (test.id,), test.id,
                              mask))
    return tuple(folds), "; ".join(parts) + (
        ". Each row is predicted once by a fit that did not see it: warm-started from the "
        "full fit, it refits the parameters of the law the held-out test's kind identifies "
        "(tow law: tensile, shear law: bias extension) to the other tests of that kind, in at "
        f"most {FOLD_ITERATIONS} iterations.")


def _without_outliers(bundle: Bundle, outliers: Sequence[dict[str, Any]]) -> Bundle:
    """The bundle with the outliers' rows left out of their tests."""
    from fenicsx_drape.measurements.lab import without_rows

    tests = []
    for test in bundle.tests:
        rows = [o["row"] for o in outliers if o["id"] == test.id]
        tests.append(without_rows(test, rows) if rows else test)
    return dataclasses.replace(bundle, tests=tuple(tests))


def _ordinal(n: int) -> str:
    return {2: "second", 3: "third", 4: "fourth", 5: "fifth"}.get(n, f"{n}th")


def _without_rows(test: Test, rows: np.ndarray) -> Test:
    """``test`` with the given rows at infinite standard deviation (no weight in a fit).

    The other rows keep their ``force_sd_N``, or get the test's model-free noise estimate,
    so that they weigh in the fit exactly as they do without a ``force_sd_N`` column.
    """
    columns = dict(test.columns)
    columns[kind_of(test).sd_column(test)] = np.where(rows, np.inf, row_sd(test))
    return dataclasses.replace(test, columns=columns)


# --------------------------------------------------------------------------------------------
# Fits


def _fit(bundle: Bundle, model: Model, *, tests: Sequence[str] | None = None,
         parameters: Sequence[str] | None = None, max_iterations: int,
         from_features: bool = False, details: dict | None = None) -> Model:
    return fit_bundle(bundle, model, tests=tests, parameters=parameters,
                      from_features=from_features, max_iterations=max_iterations,
                      details=details)


def _with_setup_refitted(stage: dict[str, Any], model: Model, data: _Data, noise,
                         last: dict[str, Any] | None, say: Progress
                         ) -> tuple[dict[str, Any] | None, _Data]:
    """The set-up stage's best parameter fitted again with ``model`` (a candidate's refit).

    From ``last`` (the previous round's record) or the set-up fitted alone. Returns the
    record ``{parameter, fitted, fitted_alone, p}`` and the data with that set-up applied, or
    ``(None, data)`` when the set-up does not move. The set-up is fitted on all rows; the
    held-out folds then refit the effect's parameters only.
    """
    from fenicsx_drape.calibration.coupons import declare_noise
    from fenicsx_drape.diagnosis.setup import corrected, fitted_value, refit_setup

    best, original, stated_model = stage["best"], stage["bundle"], stage["stated_model"]
    name = best["parameter"]
    before = np.asarray(last["p"] if last else best["p"], dtype=float)
    p = refit_setup(original, name, before, model, say)
    if np.allclose(p, before):
        return None, data
    # The stage's bundle is the baseline's, its outliers already left out.
    new = _prepare(declare_noise(corrected(original, name, p, stated_model), noise))
    record = {"parameter": name, "fitted": fitted_value(original, name, p, stated_model),
              "fitted_alone": fitted_value(original, name, best["p"], stated_model),
              "p": [float(v) for v in p]}
    say(f"  {name} with the effect: {record['fitted']} (alone: {record['fitted_alone']})")
    return record, new


def _heldout(data: _Data, model: Model, say: Progress) -> dict[str, np.ndarray]:
    """Every row predicted by the fold that held it out (module doc, 5.); the folds at once."""
    predicted = {t.id: np.full(np.shape(kind_of(t).measured(t)), np.nan) for t in data.tests}
    tests = {t.id: t for t in data.tests}

    def fold_values(fold: Fold, i: int, say: Progress) -> np.ndarray:
        say(f"    held-out fold {i + 1}/{len(data.folds)}: {fold.label}")
        test = tests[fold.predicts]
        fitted = _fit(fold.bundle, model, tests=fold.fitted,
                      parameters=_kind_parameters(model, test.kind),
                      max_iterations=FOLD_ITERATIONS)
        return simulate([test], fitted)[test.id]

    folds = together([functools.partial(fold_values, fold, i)
                      for i, fold in enumerate(data.folds)], say)
    for fold, values in zip(data.folds, folds):
        rows = np.repeat(fold.rows, values.size // fold.rows.size)  # forming: x, y, z per row
        predicted[fold.predicts][rows] = values[rows]
    return predicted


def _costs(data: _Data, model: Model) -> np.ndarray:
    """Squared normalised error of each parameter set of a vectorised ``model``."""
    total = 0.0
    for test in data.tests:
        values = np.atleast_2d(simulate([test], model)[test.id])
        rmse = np.sqrt(np.mean((values - kind_of(test).measured(test)) ** 2, axis=1))
        total = total + (rmse / data.noise[test.id][0]) ** 2
    return total / len(data.tests)


def _best_start(data: _Data, model: Model, own: Sequence[str], names: Sequence[str]) -> Model:
    """The best of four starts for a candidate's refit, judged in one vectorised call.

    The starts: the candidate at its default strength on the baseline's fit; the candidate
    weak, its own parameters that may vanish at 1 % of their defaults (for most effects
    nearly the baseline, while the fit still feels them: exactly zero can leave it no
    gradient, e.g. a Maxwell branch without spring); every refitted parameter at the
    catalogue's documented value (Table 2: a baseline fitted without the effect can sit far
    from it); the curve-feature guess of section 3.2.
    """
    from fenicsx_drape.calibration.fit import initial_guess
    from fenicsx_drape.model import parameter_info

    weak = {n: WEAK * float(model.parameters[n]) for n in own
            if parameter_info(n).bounds[0] == 0.0}
    documented = {n: parameter_info(n).default for n in names
                  if parameter_info(n).default is not None}
    starts = [model, model.with_parameters(**weak), model.with_parameters(**documented)]
    try:
        starts.append(initial_guess(model, data.tests, names))
    except (ValueError, FloatingPointError, ArithmeticError):
        pass  # no feature guess for this law: the other starts remain
    sets = model.with_parameters(**{n: np.array([float(m.parameters[n]) for m in starts])
                                    for n in names})
    return starts[int(np.nanargmin(_costs(data, sets)))]


def _no_worse(data: _Data, fitted: Model, start: Model) -> Model:
    """The fit, or its start when the fit ended worse (a refit never loses its best start)."""
    return start if _costs(data, start)[0] < _costs(data, fitted)[0] else fitted


def _sensitivity(data: _Data, without: Model, with_: Model) -> tuple[float, dict[str, float]]:
    """How much the tests change when an effect is added: normalised like the error."""
    a, b = simulate(data.tests, without), simulate(data.tests, with_)
    per_test = {t.id: float(np.sqrt(np.mean((b[t.id] - a[t.id]) ** 2)) / data.noise[t.id][0])
                for t in data.tests}
    return float(np.sqrt(np.mean(np.square(list(per_test.values()))))), per_test


def candidate_names(model: Model) -> list[str]:
    """The effects to try: the catalogue's and the laws registered by the model's plugins."""
    from fenicsx_drape.effects import EFFECTS
    from fenicsx_drape.materials import registered_laws
    from fenicsx_drape.model import load_plugin

    modules = {load_plugin(p).__name__ for p in model.plugins}
    users = [name for name, cls in registered_laws().items() if cls.__module__ in modules]
    return [name for name in (*EFFECTS, *users) if name not in model.effects]


def _role_parameters(model: Model, role: str) -> tuple[str, ...]:
    """The active parameters of the law of ``role`` and of the effects acting on it."""
    from fenicsx_drape.effects import describe_effect

    laws = model.law_classes()
    names = list(laws[role].active_parameters(model.effects)) if role in laws else []
    for name in model.effects:
        effect = describe_effect(name)
        if effect.acts_on == role:
            names += effect.parameters
    active = model.active_parameters()
    return tuple(n for n in dict.fromkeys(names) if n in active)


def _kind_parameters(model: Model, kind: str) -> tuple[str, ...] | None:
    """The parameters that tests of ``kind`` identify (all active ones for other kinds)."""
    from fenicsx_drape.calibration.coupons import BLOCK_ROLE

    return _role_parameters(model, BLOCK_ROLE[kind]) if kind in BLOCK_ROLE else None


def _refit_parameters(model: Model, name: str) -> tuple[str, ...]:
    """A candidate's own parameters and those of the law it acts on."""
    from fenicsx_drape.effects import describe_effect

    effect = describe_effect(name)
    active = model.active_parameters()
    own = tuple(p for p in effect.parameters if p in active)
    return tuple(dict.fromkeys((*own, *_role_parameters(model, effect.acts_on))))


# --------------------------------------------------------------------------------------------
# Diagnosis


def setup_rules(iterations: int = BASELINE_ITERATIONS):
    """The rules the set-up stage shares with the effects.

    A :class:`~fenicsx_drape.diagnosis.setup.Rules`; ``iterations`` caps the coupon fits.
    """
    from fenicsx_drape.diagnosis.setup import Rules

    return Rules(EVIDENCE_THRESHOLD, PARSIMONY, UNTESTABLE_BELOW, iterations, ADEQUATE)


def diagnose(bundle: Bundle, model: Model, *, progress: Progress | None = None,
             candidates: Sequence[str] | None = None,
             setup: Sequence[str] | None = None) -> Report:
    """Find which effect ``model`` misses to explain ``bundle`` (the module doc's procedure).

    Args:
        bundle: The measurements.
        model: The current model (effects, plugins, starting parameters).
        progress: Called with a line of text at each stage.
        candidates: Only try these effects (default: every one not in the model).
        setup: The set-up parameters tried first on forming tests
            (:mod:`~fenicsx_drape.diagnosis.setup`); default: all of them, or none when
            ``candidates`` restricts the effects.

    Returns:
        The report: a dict with every field of the diagnosis contract (:data:`CONTRACT`) plus
        ``add_effects`` (the effects to add), ``heldout_scheme``, ``significance``,
        ``ranking``, ``trends``, ``conclusion``, ``notes`` and ``seconds``.
    """
    from fenicsx_drape.calibration.coupons import declare_noise
    from fenicsx_drape.diagnosis.setup import SETUP_PARAMETERS, setup_stage

    start = time.perf_counter()
    say = progress or (lambda line: None)
    # 0. Data before physics (spec version 4): each measurement checked against its case
    # before any fit; a suspect one is named first in the conclusion, no effect on it.
    suspects = data_check(bundle)
    say_suspects(suspects, say)
    bad = suspect_tests(bundle, suspects)
    if bad and len(bad) < len(bundle.tests):  # the others are diagnosed without them
        bundle = dataclasses.replace(bundle, tests=tuple(t for t in bundle.tests
                                                         if t.id not in bad))
    # 1. Prepare: each test's noise from its kind's one noise function, regions, folds.
    data = _prepare(declare_noise(bundle, model.noise))
    # 2. Baseline, and 3. its outliers left out (one row never decides a diagnosis).
    base = _baseline_stage(data, model, bundle.path, say)
    # 4. Set-up before physics (spec version 3), on the bundle less its outliers: the model
    # as stated against the set-up as stated; the best set-up is applied for what follows.
    parameters = SETUP_PARAMETERS if setup is None and candidates is None else setup
    stage, fixed = setup_stage(base.data.bundle, model, parameters, setup_rules(), say)
    if stage is not None:
        stage.update(parameters=list(parameters), given_model=model)
    if fixed is not base.data.bundle:
        base = _at_setup(base, _prepare(declare_noise(fixed, model.noise)), model, say)
    # The baseline's held-out error, and 5. resolution before physics (spec version 4): the
    # net's own error on each measurement. Independent of each other: their runs together.
    base, checked = together([functools.partial(_with_heldout, base), functools.partial(
        check_resolution, base.data.tests, base.model, base.compared, ADEQUATE)], say)
    resolved = explained(checked)
    if resolved:
        say(f"  the net explains the residual of {', '.join(sorted(resolved))}")
    # 6. Effects: every candidate refitted, judged on held-out rows.
    # They are independent: tried together, their runs formed in common batches.
    tried, untestable = [], []
    names = [n for n in candidate_names(model) if candidates is None or n in candidates]
    for entry in together([functools.partial(_try_effect, name, model, base, stage, resolved)
                           for name in names], say):
        (untestable if "reason" in entry else tried).append(entry)
    # 7. The report (the confirmation on a finer net is drape diagnose's --confirm-cell-mm).
    report = _report(bundle, base, tried, untestable, stage, checked, resolved, say)
    apply_data_check(report, suspects)
    report["seconds"] = time.perf_counter() - start
    say(report["conclusion"])
    return report


@dataclasses.dataclass
class _Base:
    """The baseline stage's result: the model fitted as given, on the bundle less outliers."""

    data: _Data  # the bundle compared (without the outliers' rows)
    model: Model  # fitted
    compared: list[Comparison]
    heldout: list[Comparison]  # every row predicted by the fold that held it out (last)
    outliers: list[dict[str, Any]]
    error_with_outliers: dict[str, Any]
    optimiser: dict[str, Any]
    details: dict[str, Any]  # the coupon fit's (optimiser, noise notes, groups)


def _baseline_stage(data: _Data, model: Model, path, say: Progress) -> _Base:
    """The model as given fitted to the bundle, and its outliers left out (refitted)."""
    say(f"baseline ({', '.join(model.effects) or 'no effects'}): fitting (global stage)")
    details: dict[str, Any] = {}
    baseline, compared = _baseline_fit(data, model, details)
    optimiser = optimiser_record(details.get("coupons"))
    say(f"  {optimiser['statement']}")
    # Bad and odd rows (spec version 3): one row never decides a diagnosis. The rows beyond
    # OUTLIER_SD robust sd after the fit are listed and left out; the baseline is refitted.
    outliers = find_outliers(compared, data.tests, path)
    error_with = error_record(compared)
    if outliers:
        say(f"  {len(outliers)} outlier row(s) ("
            + ", ".join(f"{o['file']}:{o['line']}" for o in outliers[:5])
            + "): left out, baseline refitted")
        data = _prepare(_without_outliers(data.bundle, outliers))
        baseline, compared = _baseline_fit(data, model, details)
    say(f"  normalised error {normalised_error(compared):.3g}")
    return _Base(data, baseline, compared, [], outliers, error_with, optimiser, details)


def _baseline_fit(data: _Data, model: Model, details: dict[str, Any]
                  ) -> tuple[Model, list[Comparison]]:
    fitted = _fit(data.bundle, model, max_iterations=BASELINE_ITERATIONS, from_features=True,
                  details=details)
    return fitted, data.compare(simulate(data.tests, fitted))


def _at_setup(base: _Base, data: _Data, model: Model, say: Progress) -> _Base:
    """The baseline refitted on the bundle with the set-up stage's best set-up applied."""
    say("baseline at the fitted set-up: fitting")
    details: dict[str, Any] = {}
    fitted, compared = _baseline_fit(data, model, details)
    say(f"  normalised error {normalised_error(compared):.3g}")
    return dataclasses.replace(base, data=data, model=fitted, compared=compared,
                               optimiser=optimiser_record(details.get("coupons")),
                               details=details)


def _with_heldout(base: _Base, say: Progress) -> _Base:
    """The baseline's held-out error: every row predicted by the fold that held it out."""
    say("baseline: held-out folds")
    heldout = base.data.compare(_heldout(base.data, base.model, say))
    say(f"  held-out normalised error {normalised_error(heldout):.3g}")
    return dataclasses.replace(base, heldout=heldout)


def _try_effect(name: str, model: Model, base: _Base, stage: dict[str, Any] | None,
                resolved: set[str], say: Progress) -> dict[str, Any]:
    """One candidate effect: its untestable entry, or its refit, held-out error and evidence."""
    from fenicsx_drape.effects import describe_effect

    data, baseline = base.data, base.model
    effect = describe_effect(name)
    prerequisites = tuple(p for p in effect.prerequisites if p not in model.effects)
    added = (*prerequisites, name)
    label = "+".join(added)
    try:
        reference = baseline.with_effects(*prerequisites)
        start_model = baseline.with_effects(*added)
    except DrapeInputError as err:
        return {"effect": label, "reason": f"cannot be added: {err}"}
    try:
        change, per_test = _sensitivity(data, reference, start_model)
    except DrapeInputError as err:  # e.g. an effect a stack of plies cannot take
        say(f"candidate {label}: untestable (its runs cannot be formed)")
        return {"effect": label, "effects": list(added),
                "reason": f"its runs cannot be formed on these tests' parts: {err}"}
    if change < UNTESTABLE_BELOW:
        say(f"candidate {label}: untestable (change {change:.2g} × noise)")
        return {"effect": label, "effects": list(added),
                "reason": _untestable_reason(effect, data, change, per_test),
                "sensitivity": change}
    say(f"candidate {label}: refitting")
    names = _refit_parameters(start_model, name)
    # Its own parameters: those it brings that the baseline does not use.
    base_active = set(baseline.active_parameters())
    own = [p for p in names if p not in base_active
           and any(p in describe_effect(a).parameters for a in added)]
    best_start = _best_start(data, start_model, own, names)
    refit = _no_worse(data, _fit(data.bundle, best_start, parameters=names,
                                 max_iterations=REFIT_ITERATIONS), best_start)
    after = data.compare(simulate(data.tests, refit))
    joint, data_c = None, data
    if stage and stage.get("best") and normalised_error(after) < normalised_error(
            base.compared):
        # The set-up fitted again with the effect, then the effect again at that set-up,
        # in turn (a set-up error and an effect can act alike).
        alone = (refit, after)
        for _ in range(SETUP_ROUNDS):
            again, data_c = _with_setup_refitted(stage, refit, data_c, model.noise,
                                                 joint, say)
            if again is None:
                break
            joint = again
            refit = _no_worse(data_c, _fit(data_c.bundle, refit, parameters=names,
                                           max_iterations=REFIT_ITERATIONS), refit)
        after = data_c.compare(simulate(data_c.tests, refit))
        if normalised_error(after) > normalised_error(alone[1]):
            # The rounds ended worse than the effect at the set-up fitted alone: keep that.
            (refit, after), joint, data_c = alone, None, data
    say(f"  normalised error {normalised_error(after):.3g}; held-out folds")
    heldout_cmp = data_c.compare(_heldout(data_c, refit, say))
    heldout = normalised_error(heldout_cmp)
    evidence = _evidence(base.heldout, heldout_cmp, added, resolved)
    say(f"  held-out normalised error {heldout:.3g}, evidence {evidence:.3g}")
    return {
        "effect": label, "effects": list(added), "acts_on": effect.acts_on,
        "summary": effect.summary,
        "parameters": {p: float(refit.parameters[p]) for p in own},
        "error_after": error_record(after), "heldout_normalised": heldout,
        "evidence": evidence, "significant": bool(evidence >= EVIDENCE_THRESHOLD),
        "sensitivity": change, "where_after": where(after)[:3],
        **({"setup_refitted": {k: v for k, v in joint.items() if k != "p"}} if joint else {}),
        "_n_parameters": len(own), "_after": after, "_model": refit, "_tests": data_c.tests,
    }


def _report(bundle: Bundle, base: _Base, tried: list[dict[str, Any]],
            untestable: list[dict[str, Any]], stage: dict[str, Any] | None,
            checked: list[dict[str, Any]], resolved: set[str], say: Progress) -> Report:
    """The contract's report from the stages' results: the decision, and its words."""
    from fenicsx_drape.diagnosis.compare import kind_metrics
    from fenicsx_drape.diagnosis.setup import add_setup, value_text

    data, compared = base.data, base.compared
    coupons = base.details.get("coupons")
    groups = _consistency(coupons, say)
    base_ho = normalised_error(base.heldout)
    ranked = rank(tried)
    best = ranked[0] if ranked else None
    missing = None
    if best and best["significant"]:
        stage = _setup_with_the_effect(stage, best, base, say)
        if _adequate_but_for_the_net(best, say):
            missing = best
    pattern = _pattern(compared)
    models, comparisons = {"baseline": base.model}, {"baseline": compared}
    for c in ranked:
        c["explanation"] = _explain(c, pattern, normalised_error(compared), base_ho)
        models[c["effect"]], comparisons[c["effect"]] = c.pop("_model"), c.pop("_after")
        del c["_n_parameters"], c["_tests"]
    report = Report({
        "contract": CONTRACT,
        "bundle": bundle.name,
        "baseline": {**model_record(base.model), "error": error_record(compared),
                     "heldout_normalised": base_ho, "optimiser": base.optimiser},
        "noise_floor": noise_record(compared) | _noise_notes(coupons),
        "outliers": base.outliers,
        "error_with_outliers": base.error_with_outliers,
        "where": where(compared),
        "trends": trends(compared),
        "candidates": ranked,
        "untestable": untestable,
        "missing_effect": missing["effect"] if missing else None,
        "add_effects": missing["effects"] if missing else [],
        "heldout_scheme": data.scheme,
        "significance": SIGNIFICANCE_RULE,
        "ranking": (f"by heldout_normalised; among candidates within {100 * PARSIMONY:g} % of "
                    "the best, the one adding the fewest parameters first"),
        "missing_rule": (f"the first candidate if significant and its refit reaches "
                         f"normalised <= {ADEQUATE} (on the measurements whose residual "
                         "its net does not explain or is within its net's own error, "
                         "resolution_after)"),
        "conclusion": resolution_sentence(checked) + (
            _groups_conclusion(groups, missing) or (
                _conclusion(missing, best, compared, pattern, base.optimiser, coupons,
                            resolved) + _groups_sentence(groups))),
        "consistency": groups,
        "resolution": checked,
        "metrics": {label: kind_metrics(data.tests, comparisons[label], models[label])
                    for label in models} if any(is_formed(t) for t in data.tests)
        else {},
        "notes": list(data.notes),
    })
    if missing and missing.get("setup_refitted") and stage and stage["setup_error"]:
        _setup_with_effect(stage, missing)
    add_setup(report, stage)
    if missing and missing.get("setup_refitted"):
        j = missing["setup_refitted"]
        report["conclusion"] += (f" With {missing['effect']} added, {j['parameter']} is fitted "
                                 f"again: {value_text(j['fitted'])}.")
        if stage and stage.get("setup_withdrawn"):
            report["conclusion"] += (f" That is within {SETUP_DISTINCT_SD:g} sd of the stated "
                                     f"set-up: the effect, not the set-up, was missing "
                                     f"(setup_error withdrawn).")
    report.models, report.comparisons = models, comparisons
    report.tests = data.tests
    return report


def _adequate_but_for_the_net(candidate: dict[str, Any], say: Progress) -> bool:
    """Whether a candidate's refit reaches the noise floor, its net's own error excused.

    ``normalised <= ADEQUATE`` on every test; else the measurements it still misses are
    checked for resolution as the baseline's were (the candidate formed on half the cell),
    and it is adequate when those its net does not excuse are within ``ADEQUATE``
    (``resolution_after`` in the candidate's entry). A measurement is excused when the net
    explains it (the baseline's rule), or when what the candidate leaves beyond the noise is
    within its net's own error e_Δ (``within_net_error``): the candidate's parameters were
    refitted on that net, so the finer net need not come nearer, and no net this coarse
    can tell that residual from the truth.
    """
    if candidate["error_after"]["normalised"] <= ADEQUATE:
        return True
    after = candidate["_after"]
    if not any(is_formed(t) for t in candidate["_tests"]):
        return False
    say(f"candidate {candidate['effect']}: is what it leaves the net's?")
    checked = check_resolution(candidate["_tests"], candidate["_model"], after, ADEQUATE, say)
    for e in checked:
        error = e.get("discretisation_error")
        e["within_net_error"] = bool(error is not None and math.sqrt(
            max(0.0, e["residual"] ** 2 - e["noise"] ** 2)) <= error)
    candidate["resolution_after"] = checked
    excused = {e["measurement"] for e in checked if e["explains"] or e["within_net_error"]}
    rest = [c for c in after if c.id not in excused]
    return bool(checked) and (not rest or normalised_error(rest) <= ADEQUATE)


def _setup_with_the_effect(stage: dict[str, Any] | None, missing: dict[str, Any], base: _Base,
                           say: Progress) -> dict[str, Any] | None:
    """The set-up stage again with the best effect in, when alone it named no set-up error.

    A missing effect can hide a set-up error: its error swamps what a turned ply or a moved
    blank changes, so the set-up alone has nothing to gain. The set-up candidates are judged
    again with the effect added to the model as given (at the catalogue's values: the
    effect's refit at the stated set-up has taken up some of the set-up's error); a set-up
    error they name is reported (``found_with_effect``) and the effect is refitted at it.
    """
    from fenicsx_drape.calibration.coupons import declare_noise
    from fenicsx_drape.diagnosis.setup import corrected, setup_stage

    if not stage or stage["setup_error"] is not None or not stage.get("parameters"):
        return stage
    say(f"set-up stage again, with {missing['effect']} in")
    with_effect = stage["given_model"].with_effects(*missing["effects"])
    again, _ = setup_stage(base.data.bundle, with_effect, stage["parameters"], setup_rules(),
                           say)
    if again is None or again["setup_error"] is None:
        return stage
    again.update(parameters=stage["parameters"], given_model=stage["given_model"],
                 found_with_effect=missing["effect"])
    again["setup"][0]["found_with_effect"] = missing["effect"]
    best = again["best"]
    data = _prepare(declare_noise(corrected(base.data.bundle, best["parameter"], best["p"],
                                            again["stated_model"]), base.model.noise))
    names = _refit_parameters(missing["_model"], missing["effects"][-1])
    refit = _no_worse(data, _fit(data.bundle, missing["_model"], parameters=names,
                                 max_iterations=REFIT_ITERATIONS), missing["_model"])
    after = data.compare(simulate(data.tests, refit))
    say(f"  {missing['effect']} refitted at that set-up: normalised error "
        f"{normalised_error(after):.3g} (at the stated set-up "
        f"{missing['error_after']['normalised']:.3g})")
    missing.update(error_after=error_record(after), where_after=where(after)[:3],
                   _after=after, _tests=data.tests, _model=refit,
                   parameters={p: float(refit.parameters[p]) for p in missing["parameters"]})
    return again


def _setup_with_effect(stage: dict[str, Any], missing: dict[str, Any]) -> None:
    """The set-up error as it stands once the missing effect is in.

    A missing effect can be taken up by a set-up parameter when the set-up is fitted alone
    (a holding force that lowers a hidden friction's error); refitted with the effect, it
    goes back to the stated value. The set-up entry records its value with the effect
    (``fitted_with_effect``), and the set-up error is withdrawn when that value lies within
    :data:`SETUP_DISTINCT_SD` of its sd from the stated one.
    """
    entry, j = stage["setup"][0], missing["setup_refitted"]
    entry["fitted_with_effect"] = j["fitted"]
    fitted, stated, sd = (np.atleast_1d(np.asarray(v, float)) for v in
                          (j["fitted"], entry["stated"], entry["sd"]))
    if np.all(np.abs(fitted - stated) <= SETUP_DISTINCT_SD * sd):
        stage["setup_error"] = None
        stage["setup_withdrawn"] = entry["parameter"]


def _evidence(baseline: list[Comparison], candidate: list[Comparison],
              effects: Sequence[str], resolved: set[str] = frozenset()) -> float:
    """Baseline / candidate held-out normalised error on the tests the effects act on.

    Tests of other kinds (coupons, for a forming effect) are predicted alike by both and
    would only dilute the ratio (module doc, 6.); with none of them, all tests count. The
    measurements whose residual the net explains (``resolved``) are no evidence: with
    nothing else, the evidence is 1.
    """
    from fenicsx_drape.effects import describe_effect

    kinds = {k for name in effects for k in describe_effect(name).test_kinds}
    pick = [i for i, c in enumerate(baseline) if c.kind in kinds] or range(len(baseline))
    pick = [i for i in pick if baseline[i].id not in resolved]
    if not pick:
        return 1.0
    after = normalised_error([candidate[i] for i in pick])
    return normalised_error([baseline[i] for i in pick]) / after if after > 0 else math.inf


def rank(candidates: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Candidates by held-out error, the most parsimonious near-best first (module doc, 6.)."""
    ranked = sorted(candidates, key=lambda c: (c["heldout_normalised"], c["effect"]))
    if ranked:
        near = [c for c in ranked
                if c["heldout_normalised"] <= (1 + PARSIMONY) * ranked[0]["heldout_normalised"]]
        first = min(near, key=lambda c: (c["_n_parameters"], c["heldout_normalised"]))
        ranked.remove(first)
        ranked.insert(0, first)
    return ranked


# --------------------------------------------------------------------------------------------
# Words


def _untestable_reason(effect, data: _Data, change: float, per_test: dict[str, float]) -> str:
    kinds = sorted({t.kind for t in data.tests})
    if change == 0.0:
        text = "adding it at its default strength changes none of the simulated tests"
    else:
        largest = max(per_test, key=per_test.get)
        text = (f"adding it at its default strength changes the simulated tests by only "
                f"{change:.2g} × their noise (at most {per_test[largest]:.2g} in {largest}; "
                f"testable from {UNTESTABLE_BELOW})")
    if not set(kinds) & set(effect.test_kinds):
        return (f"{text}: it acts on the {effect.acts_on} in {' and '.join(effect.test_kinds)} "
                f"tests, and the bundle has only {' and '.join(kinds)} tests")
    fixed = [c for c in effect.conditions if len({t.conditions.get(c) for t in data.tests}) < 2]
    if fixed:
        return f"{text}: {', '.join(fixed)} does not vary across the tests"
    return f"{text}: these tests do not exercise it"


def _pattern(base: list[Comparison]) -> str:
    """One clause on where the baseline's residual is, from trends and regions."""
    normalised = normalised_error(base)
    if normalised <= 1.2:
        return f"the residual is at the noise floor (normalised {normalised:.2f})"
    for trend in trends(base):
        if trend["says"]:
            return trend["says"]
    regions = [e for e in locate(base) if "region" in e]
    if not regions:
        return f"the residual is {normalised:.3g} × the noise"
    top = max(regions, key=lambda e: e["share_of_error"])  # a kind's sum beats its parts
    tests = (f"the {top['kind'].replace('_', ' ')} tests" if len(top["tests"]) > 1
             else f"test {top['test']}")
    return (f"{100 * top['share_of_error']:.0f} % of the residual sits in the {top['region']} "
            f"region of {tests}")


def _addition(c: dict[str, Any]) -> str:
    """How a candidate changes the model, in words."""
    from fenicsx_drape.effects import EFFECTS

    if all(e in EFFECTS for e in c["effects"]):
        return f"the model gets {c['effect']} ({c['summary']})"
    summary = c["summary"].rstrip(".")
    return (f"the user law {c['effect']} replaces the {c['acts_on']} law "
            f"({summary[:1].lower() + summary[1:]})")


def _explain(c: dict[str, Any], pattern: str, base_norm: float, base_ho: float) -> str:
    after = c["error_after"]["normalised"]
    gain = (f"error {base_norm:.3g} → {after:.3g} × noise, held-out {base_ho:.3g} → "
            f"{c['heldout_normalised']:.3g} (evidence {c['evidence']:.3g})")
    what = _addition(c)
    if c["significant"] and after <= ADEQUATE:
        return f"{pattern[:1].upper() + pattern[1:]}, and it vanishes when {what}: {gain}."
    if c["significant"]:
        remains = c["where_after"][0] if c["where_after"] else None
        rest = (f"; what remains sits in {remains['test']} ({remains['says']})"
                if remains else "")
        return (f"{pattern[:1].upper() + pattern[1:]}; it shrinks but stays above {ADEQUATE} × "
                f"noise when {what}: {gain}{rest}.")
    return (f"{pattern[:1].upper() + pattern[1:]}; no real gain when {what}: {gain}, "
            f"evidence below {EVIDENCE_THRESHOLD}.")


def optimiser_record(coupons) -> dict[str, Any]:
    """How the baseline's coupon fit knows it is at its best (the global stage's record).

    ``at_best`` is true when every block's best minimum was reached from at least two of the
    independent starts (curve features, Table 2, MODEL.toml, Sobol points); the
    ``statement`` says so in words, block by block.
    """
    if coupons is None:
        return {"global_stage": False, "at_best": None, "blocks": [],
                "statement": "no coupon fit (the baseline has no coupon test)"}
    blocks = [{"label": b["label"], **{k: b["global"][k] for k in
                                       ("best_found_by", "n_best", "spread_normalised",
                                        "statement")},
               "starts": len(b["global"]["starts"])} for b in coupons.blocks if "global" in b]
    at_best = bool(blocks) and all(b["n_best"] >= 2 for b in blocks)
    parts = [f"{b['label']}: {b['statement']}" for b in blocks]
    head = ("the baseline is at the best minimum the global stage found from independent "
            "starts" if at_best else "the baseline's best minimum was reached from a single "
            "start only, so the optimiser may have stopped short of the model's best")
    undetermined = [u["parameter"] for u in coupons.undetermined]
    tail = (f"; held (undetermined by these tests): {', '.join(undetermined)}"
            if undetermined else "")
    return {"global_stage": bool(blocks), "at_best": at_best, "blocks": blocks,
            "undetermined": coupons.undetermined,
            "statement": f"{head} ({'; '.join(parts)}){tail}"}


def _noise_notes(coupons) -> dict[str, Any]:
    """Where each coupon test's noise came from and, if so, why its estimate is implausible."""
    if coupons is None:
        return {}
    notes = {k: v["says"] for k, v in coupons.noise.items()}
    implausible = sorted(k for k, v in coupons.noise.items() if v["source"] == "relative_floor")
    return {"says": notes, "implausible": implausible}


def _consistency(coupons, say: Progress) -> dict[str, Any] | None:
    """Leave one lab, size or shear-test kind out of the coupons' fit, when there are several.

    See :mod:`fenicsx_drape.calibration.consistency`; None when there is nothing to compare.
    """
    from fenicsx_drape.calibration.consistency import consistency, informative

    if coupons is None:
        return None
    by = informative([t for t in coupons.bundle.tests if t.id in coupons.errors])
    if not by:
        return None
    say(f"consistency: leaving out one {', one '.join(by)} at a time")
    report = consistency(coupons.bundle, coupons, by=by)
    say(f"  {report['verdict']}: {report['says']}")
    return report


def _groups_conclusion(groups: dict[str, Any] | None, missing) -> str:
    """The conclusion when no effect is missing but one lab, size or kind explains the misfit.

    The rest fit at the noise without it: that group, not the physics, is the suspect.
    """
    if missing or not groups or groups["verdict"] in ("consistent", "missing_physics"):
        return ""
    return (f"Not missing physics but a {groups['verdict'].replace('_', ' ')}: "
            f"{groups['says']}. Check that group's set-up (load cell, normalisation, "
            "specimen, conditioning) or leave it out, and diagnose again.")


def _groups_sentence(groups: dict[str, Any] | None) -> str:
    """A lab offset, size effect or kind mismatch, said beside the physics' conclusion."""
    if not groups or groups["verdict"] in ("consistent", "missing_physics"):
        return ""
    return (f" Before physics, the tests' groups: {groups['verdict']}: {groups['says']} "
            "(consistency).")


def _conclusion(missing, best, base: list[Comparison], pattern: str,
                optimiser: dict[str, Any] | None = None, coupons=None,
                resolved: set[str] = frozenset()) -> str:
    normalised = normalised_error(base)
    rest = [c for c in base if c.id not in resolved]
    if resolved and not missing and (not rest or normalised_error(rest) <= ADEQUATE):
        return ("No effect is named: the residual the model leaves is its net's own "
                "discretisation error (resolution).")
    noise = ""
    floored = [k for k, v in (coupons.noise.items() if coupons is not None else ())
               if v["source"] == "relative_floor"]
    if floored:
        noise = (f" Noise: the model-free estimates of {', '.join(floored)} are implausibly "
                 "small for the curves (smoothed or digitised), so their errors are measured "
                 "against 2 % of each test's peak force; declare the noise (force_sd_N or "
                 "force_sd_rel in bundle.toml, [noise] in MODEL.toml) to judge against the "
                 "real one.")
    if missing:
        nets = [e for e in missing.get("resolution_after", ())
                if e["explains"] or e["within_net_error"]]
        rest = (f" What it leaves on {', '.join(e['measurement'] for e in nets)} is its "
                f"{nets[0]['cell_mm']:g} mm net's own error (resolution_after): "
                f"{finer_net(nets)}." if nets else "")
        return (f"Missing effect: {missing['effect']} ({missing['summary'].rstrip('.')}); adding "
                f"it brings the normalised error from {normalised:.3g} to "
                f"{missing['error_after']['normalised']:.3g}.{rest}")
    if normalised <= ADEQUATE:
        return (f"No effect is missing: the model is at {normalised:.3g} × the noise "
                f"(adequate at ≤ {ADEQUATE}).{noise}")
    if best and best["significant"]:
        return (f"No single candidate brings the error ({normalised:.3g} × the noise) to the "
                f"noise floor: the best, {best['effect']}, is a real gain (evidence "
                f"{best['evidence']:.3g}) but reaches only "
                f"{best['error_after']['normalised']:.3g} × noise. More than one effect may be "
                f"missing: add it and diagnose again.")
    closest = (f" The closest candidate, {best['effect']}, reaches "
               f"{best['error_after']['normalised']:.3g} × noise (evidence "
               f"{best['evidence']:.3g}).") if best else ""
    if optimiser is not None and optimiser.get("at_best") is False:
        return (f"None of the candidates explains the residual ({normalised:.3g} × the noise): "
                f"{pattern}. But {optimiser['statement']}: the residual may be the optimiser's, "
                f"not missing physics; give better starting values in MODEL.toml and diagnose "
                f"again.{closest}{noise}")
    how = (f" How the baseline is known to be at its best: {optimiser['statement']}."
           if optimiser is not None and optimiser.get("at_best") else "")
    return (f"None of the candidates explains the residual ({normalised:.3g} × the noise): "
            f"{pattern}. The missing physics is not in the catalogue; write it as a user law "
            f"(plugins in MODEL.toml) and diagnose again.{closest}{how}{noise}")


# --------------------------------------------------------------------------------------------
# Output


def plot_candidates(report: dict[str, Any], path: str | Path) -> Path:
    """Bars: the baseline's and each candidate's normalised and held-out errors."""
    import matplotlib.pyplot as plt

    from fenicsx_drape.provenance import save_figure

    rows = [("baseline", report["baseline"]["error"]["normalised"],
             report["baseline"]["heldout_normalised"], False)]
    rows += [(c["effect"], c["error_after"]["normalised"], c["heldout_normalised"],
              c["effect"] == report["missing_effect"]) for c in report["candidates"]]
    y = np.arange(len(rows))[::-1]
    fig, ax = plt.subplots(figsize=(8, 0.6 * len(rows) + 1.5))
    ax.barh(y + 0.18, [r[1] for r in rows], height=0.35, label="fitted (error_after)",
            color=["C3" if r[3] else "C0" for r in rows])
    ax.barh(y - 0.18, [r[2] for r in rows], height=0.35, label="held-out", color="0.6")
    ax.axvline(1.0, color="k", ls="--", lw=1, label="noise floor")
    ax.axvline(ADEQUATE, color="0.4", ls=":", lw=1, label=f"adequate ({ADEQUATE})")
    ax.set_xscale("log")
    ax.set_yticks(y, [r[0] for r in rows], fontsize=8)
    ax.set_xlabel("normalised error (RMSE / noise)")
    ax.set_title(f"missing effect: {report['missing_effect']}")
    ax.legend(fontsize=7, loc="lower right")
    return save_figure(fig, path)


def summary(report: dict[str, Any]) -> str:
    """The report as text: baseline, ranked candidates, untestable effects, conclusion."""
    base = report["baseline"]
    lines = [f"baseline ({', '.join(base['effects']) or 'no effects'}): normalised "
             f"{base['error']['normalised']:.3g}, held-out {base['heldout_normalised']:.3g} "
             f"(noise floor 1; from {report['noise_floor']['source']})"]
    if base.get("optimiser", {}).get("statement"):
        lines.append(f"optimiser: {base['optimiser']['statement']}")
    lines += [f"noise of {k}: {v}" for k, v in report["noise_floor"].get("says", {}).items()
              if k in report["noise_floor"].get("implausible", ())]
    lines.append("where the error sits:")
    lines += [f"  {100 * e['share_of_error']:5.1f} %  {e['test']}: {e['says']}"
              for e in report["where"][:5]]
    from fenicsx_drape.diagnosis.setup import setup_summary

    lines += setup_summary(report)
    lines.append(f"{'candidate':<44} {'after':>7} {'held-out':>9} {'evidence':>9}  significant")
    for c in report["candidates"]:
        lines.append(f"{c['effect']:<44} {c['error_after']['normalised']:>7.3g} "
                     f"{c['heldout_normalised']:>9.3g} {c['evidence']:>9.3g}  "
                     f"{'yes' if c['significant'] else 'no'}")
        lines.append(f"    {c['explanation']}")
    lines += [f"not testable from these tests: {u['effect']} ({u['reason']})"
              for u in report["untestable"]]
    for label, tests in report.get("metrics", {}).items():
        for test, m in tests.items():
            if "stopped_at_travel_mm" in m:
                lines.append(f"note: {label} could not form {test} to full travel (stopped at "
                             f"{m['stopped_at_travel_mm']:.1f} mm); compared as far as it got")
    for o in report.get("outliers", []):
        lines.append(f"outlier left out: {o['file']}:{o['line']} ({o['id']}), residual "
                     f"{o['residual']:.3g} × noise")
    lines.append(f"missing_effect: {report['missing_effect']}")
    lines.append(report["conclusion"])
    return "\n".join(lines)


def write_diagnosis(report: dict[str, Any], json_path: str | Path,
                    out_dir: str | Path | None = None, *, bundle: Bundle | None = None) -> Path:
    """Write ``REPORT.json`` (atomically); with ``out_dir``, the plots and provenance too.

    ``out_dir`` gets ``candidates.png`` (each candidate's fitted and held-out error),
    ``ledger.jsonl`` (the model versions: set-up as stated, fitted, effect added; ``drape
    history``),
    ``where.png`` (the baseline's error by region) and, given the ``bundle`` and a
    :class:`Report`, ``residual_<test>.png`` (the baseline and the best candidate against
    each test), plus ``provenance.json``.
    """
    from fenicsx_drape.diagnosis.compare import locate, plot_where, safe_name
    from fenicsx_drape.diagnosis.forming_runs import execution_record
    from fenicsx_drape.provenance import write_json, write_provenance

    path = write_json(json_path, report)
    if out_dir is None:
        return path
    out = Path(out_dir)
    plot_candidates(report, out / "candidates.png")
    plot_where(report["where"], out / "where.png",
               f"{report['bundle']}: baseline error by region")
    comparisons = getattr(report, "comparisons", None)
    if bundle is not None and comparisons:
        best = report["candidates"][0]["effect"] if report["candidates"] else None
        tests = {t.id: t for t in getattr(report, "tests", None) or bundle.tests}
        regions = locate(comparisons["baseline"])
        for i, base in enumerate(comparisons["baseline"]):
            shown = {"baseline": base} | ({best: comparisons[best][i]} if best else {})
            kind_of(tests[base.id]).plot(shown, tests[base.id],
                                         out / f"residual_{safe_name(base.id)}.png",
                                         [e for e in regions if e["tests"] == [base.id]])
    from fenicsx_drape.diagnosis.setup import record_history

    record_history(report, out, bundle)  # the versions, for drape history
    write_provenance(out, bundle=report["bundle"], report=str(Path(json_path).resolve()),
                     effects=report["baseline"]["effects"],
                     parameters=report["baseline"]["parameters"],
                     missing_effect=report["missing_effect"], seed=None,
                     forming_runs=execution_record())
    return path


def confirm(bundle: Bundle, report, cell_mm: float = FULL_CELL_MM,
            progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The screening's baseline and best candidate again on the full mesh (module doc, cost).

    Each model of a diagnosis :class:`Report` keeps its material;
    its forming parameters are refitted on cells of ``cell_mm`` and it is compared with the
    forming tests there.

    Returns:
        ``{"cell_mm", label: {"error", "metrics", "forming_parameters"}}`` for the baseline
        and the first-ranked candidate.
    """
    from fenicsx_drape.diagnosis.forming_runs import resolution
    from fenicsx_drape.diagnosis.kinds import find_kind
    from fenicsx_drape.diagnosis.kinds.forming import fit_forming, forming_parameters

    tests = [t for t in bundle.tests if is_formed(t)]
    labels = ["baseline"] + [c["effect"] for c in report["candidates"][:1]]
    out: dict[str, Any] = {"cell_mm": cell_mm}
    with resolution(cell_mm):
        for label in labels:
            model = fit_forming(bundle, report.models[label], kind_of=find_kind,
                                progress=progress)
            values = {t.id: kind_of(t).simulate(t, model) for t in tests}
            out[label] = {"error": error_record(compare_tests(tests, values)),
                          "metrics": {t.id: kind_of(t).metrics(t, values[t.id], model)
                                      for t in tests},
                          "forming_parameters": {n: float(model.parameters[n])
                                                 for n in forming_parameters(model)}}
    return out
