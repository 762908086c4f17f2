"""The fits the diagnosis's stages share: a bundle's fit, a candidate's starts, held-out rows.

- :func:`fit` fits a model to a bundle (each kind's fit hook, :func:`~fenicsx_drape.
  diagnosis.compare.fit_bundle`);
- :func:`candidate_names` are the effects to try, :func:`refit_parameters` what a
  candidate's refit moves (its own parameters, which :func:`fit` hands as ``own``: on forming
  tests that no coupon test fixes them, the forming fit moves them with the friction),
  :func:`best_start` the best of its :func:`starts` (each at the baseline's, the stated and
  the default friction, in one vectorised evaluation), :func:`no_worse` keeps a refit that
  lost to its start from losing;
- :func:`sensitivity` is how much an effect at its default strength changes the tests;
- :func:`heldout` predicts every row by the fold that held it out (:mod:`~fenicsx_drape.
  diagnosis.folds`), the folds' runs together.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.diagnosis.comparison import fit_bundle, simulate
from fenicsx_drape.diagnosis.folds import FOLD_ITERATIONS
from fenicsx_drape.diagnosis.kinds import is_formed, kind_of
from fenicsx_drape.diagnosis.kinds.coupon import coupon_parameters, role_parameters
from fenicsx_drape.runs import together

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.folds import Fold
    from fenicsx_drape.diagnosis.results import Prepared
    from fenicsx_drape.measurements.bundle import Bundle
    from fenicsx_drape.model import Model

REFIT_ITERATIONS = 40  # the iteration cap of a candidate's refit
WEAK = 0.01  # a candidate's weak start: its own vanishing parameters at 1 % of default

Progress = Callable[[str], None]


def fit(bundle: Bundle, model: Model, *, tests: Sequence[str] | None = None,
        parameters: Sequence[str] | None = None, max_iterations: int,
        from_features: bool = False, details: dict | None = None,
        own: Sequence[str] = ()) -> Model:
    """``model`` fitted to ``bundle`` by each kind's fit, from its values unless ``from_features``.

    ``own``: a candidate's own parameters, which the forming tests fit too where no coupon
    test fixes them. See :func:`~fenicsx_drape.diagnosis.comparison.fit_bundle`.
    """
    return fit_bundle(bundle, model, tests=tests, parameters=parameters,
                      from_features=from_features, max_iterations=max_iterations,
                      details=details, own=own)


def heldout(data: Prepared, model: Model, say: Progress) -> dict[str, np.ndarray]:
    """Every row predicted by the fold that held it out; the folds at once.

    The folds are :mod:`~fenicsx_drape.diagnosis.folds`' (1. and 2.).
    """
    predicted = {t.id: np.full(np.shape(kind_of(t).measured(t)), np.nan) for t in data.tests}
    tests = {t.id: t for t in data.tests}

    def fold_values(fold: Fold, i: int, say: Progress) -> np.ndarray:
        say(f"    held-out fold {i + 1}/{len(data.folds)}: {fold.label}")
        test = tests[fold.predicts]
        fitted = fit(fold.bundle, model, tests=fold.fitted,
                     parameters=kind_parameters(model, test.kind),
                     max_iterations=FOLD_ITERATIONS)
        return simulate([test], fitted)[test.id]

    folds = together([functools.partial(fold_values, fold, i)
                      for i, fold in enumerate(data.folds)], say)
    for fold, values in zip(data.folds, folds):
        rows = np.repeat(fold.rows, values.size // fold.rows.size)  # forming: x, y, z per row
        predicted[fold.predicts][rows] = values[rows]
    return predicted


def costs(data: Prepared, model: Model) -> np.ndarray:
    """Squared normalised error of each parameter set of a vectorised ``model``."""
    total = 0.0
    for test in data.tests:
        values = np.atleast_2d(simulate([test], model)[test.id])
        rmse = np.sqrt(np.mean((values - kind_of(test).measured(test)) ** 2, axis=1))
        total = total + (rmse / data.noise[test.id][0]) ** 2
    return total / len(data.tests)


def starts(data: Prepared, model: Model, own: Sequence[str], names: Sequence[str],
           stated: Model | None = None) -> tuple[list[Model], list[str]]:
    """A candidate's starts for its refit, and the parameters in which they differ.

    The candidate at its default strength on the baseline's fit; the candidate weak, its own
    parameters that may vanish at 1 % of their defaults (for most effects nearly the
    baseline, while the fit still feels them: exactly zero can leave it no gradient, e.g. a
    Maxwell branch without spring); every refitted parameter at the catalogue's documented
    value (Table 2: a baseline fitted without the effect can sit far from it); the
    curve-feature guess of section 3.2. On formed tests, each of them at the friction the
    forming fit moves (:func:`~fenicsx_drape.diagnosis.kinds.forming.free_parameters`) as
    the baseline fitted it, as ``stated`` (the model as given) and at the catalogue's
    defaults: fitted without the effect, the baseline's friction may have moved to mimic it,
    and at that friction the right material can look worse than a weak one. A start met
    twice is kept once.
    """
    from fenicsx_drape.calibration.fitting import initial_guess
    from fenicsx_drape.diagnosis.kinds.forming import XTOL, free_parameters
    from fenicsx_drape.model import parameter_info

    weak = {n: WEAK * float(model.parameters[n]) for n in own
            if parameter_info(n).bounds[0] == 0.0}
    documented = {n: parameter_info(n).default for n in names
                  if parameter_info(n).default is not None}
    materials = [model, model.with_parameters(**weak), model.with_parameters(**documented)]
    try:
        materials.append(initial_guess(model, data.tests, names))
    except (ValueError, FloatingPointError, ArithmeticError):
        pass  # no feature guess for this law: the other starts remain
    friction = [n for n in free_parameters(model, [t for t in data.tests if is_formed(t)])
                if n not in names]
    at = [{n: float(model.parameters[n]) for n in friction}]
    given = stated.parameters if stated is not None else {}
    for other in ({n: float(given.get(n, model.parameters[n])) for n in friction},
                  {n: float(parameter_info(n).default) for n in friction}):
        if friction and all(max(abs(other[n] - a[n]) for n in friction) > XTOL for a in at):
            at.append(other)
    moved = [*names, *friction]
    found = {_key(m, moved): m for m in (s.with_parameters(**a) for a in at
                                          for s in materials)}
    return list(found.values()), moved


def best_start(data: Prepared, model: Model, own: Sequence[str], names: Sequence[str],
               stated: Model | None = None) -> Model:
    """The best of a candidate's :func:`starts`, judged in one vectorised call."""
    found, moved = starts(data, model, own, names, stated)
    return found[int(np.nanargmin(costs(data, vectorised(found, moved))))]


def vectorised(models: Sequence[Model], names: Sequence[str]) -> Model:
    """One vectorised model of ``models``, which differ in ``names`` only."""
    return models[0].with_parameters(**{n: np.array([float(m.parameters[n]) for m in models])
                                        for n in names})


def _key(model: Model, names: Sequence[str]) -> tuple[float, ...]:
    """A start's values (twice the same start is judged once)."""
    return tuple(float(model.parameters[n]) for n in names)


def no_worse(data: Prepared, fitted: Model, start: Model) -> Model:
    """The fit, or its start when the fit ended worse (a refit never loses its best start)."""
    return start if costs(data, start)[0] < costs(data, fitted)[0] else fitted


def sensitivity(data: Prepared, without: Model, with_: Model) -> tuple[float, dict[str, float]]:
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


def kind_parameters(model: Model, kind: str) -> tuple[str, ...] | None:
    """The parameters that tests of ``kind`` identify (None: all active ones, other kinds)."""
    from fenicsx_drape.calibration.coupons import BLOCK_ROLE
    from fenicsx_drape.diagnosis.kinds.interply_friction import NAME, interply_parameters

    if kind == NAME:  # the inter-ply law's
        return interply_parameters(model)
    return coupon_parameters(model, kind) if kind in BLOCK_ROLE else None


def refit_parameters(model: Model, name: str) -> tuple[str, ...]:
    """A candidate's own parameters and those of the law it acts on."""
    from fenicsx_drape.effects import describe_effect

    effect = describe_effect(name)
    active = model.active_parameters()
    own = tuple(p for p in effect.parameters if p in active)
    return tuple(dict.fromkeys((*own, *role_parameters(model, effect.acts_on))))
