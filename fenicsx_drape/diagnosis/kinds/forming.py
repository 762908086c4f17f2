"""The forming kind as ``compare`` and ``diagnose`` see it, and the fit of its parameters.

A forming test holds a measured grid (:mod:`~fenicsx_drape.diagnosis.forming_kind`) or a lab
measurement (:mod:`~fenicsx_drape.diagnosis.lab_kind`: shear points, a scan, the blank's
edge, the press force; spec version 3). :data:`FORMING` hands each test to the module that
knows its measurement; :func:`fit_forming` fits the model's forming parameters (the friction
coefficients) to all of a bundle's forming tests together, whichever they hold (the method:
:mod:`~fenicsx_drape.diagnosis.forming_kind`'s module docstring, "Fitting").
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis import forming_kind as fk
from fenicsx_drape.diagnosis import lab_kind
from fenicsx_drape.diagnosis.forming_kind import (
    FD_STEP,
    FORMING_PARAMETERS,
    MAX_ITERATIONS,
    MAX_STEP,
    MU_BOUNDS,
    XTOL,
    holder_mu_free,
)
from fenicsx_drape.diagnosis.forming_runs import Deferred, spare
from fenicsx_drape.diagnosis.kinds import Kind

if TYPE_CHECKING:
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model


# --------------------------------------------------------------------------------------------
# The kind: a grid's hooks or a lab measurement's


def _lab(test: Test) -> Any:
    """The lab module's hooks when ``test`` holds a lab measurement, else None."""
    if getattr(test, "lab", None) is None or test.lab.measurement == "file":
        return None
    return lab_kind


def _by_measurement(grid_hook: Callable, name: str) -> Callable:
    """A hook of the forming kind: the grid's, or a lab measurement's.

    A test holding a lab measurement (spec version 3) goes to the lab module's
    function ``name`` (:mod:`~fenicsx_drape.diagnosis.lab_kind`).
    """

    def hook(test: Test, *args, **kwargs):
        lab = _lab(test)
        if lab is not None:
            return getattr(lab, name)(test, *args, **kwargs)
        return grid_hook(test, *args, **kwargs)

    hook.__name__ = hook.__qualname__ = getattr(grid_hook, "__name__", name)
    hook.__doc__ = grid_hook.__doc__
    return hook


def measured_values(test: Test) -> np.ndarray:
    """The measured values of a forming test: x, y, z of every node (flattened)."""
    return fk.measured_positions(test).ravel()


def value_noise(test: Test) -> np.ndarray:
    """Per compared value, the noise (``inf``: not fitted).

    The grid's x, y, z of a node share its ``position_sd_mm``.
    """
    return np.repeat(fk.row_noise(test), 3)


def value_sd(test: Test) -> np.ndarray:
    """Per compared value of any forming measurement, the noise it is weighed with.

    The one noise function of each measurement kind (its column, else its key, else its
    model-free estimate: the grid's :func:`~fenicsx_drape.diagnosis.forming_kind.noise`, a
    lab measurement's :func:`~fenicsx_drape.diagnosis.lab_kind.noise`), shared by the set-up
    stage, the effects' fits and the comparison; ``inf``: not fitted.
    """
    return _by_measurement(value_noise, "row_sd")(test)


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


def mirrorable(test: Test) -> bool:
    """Whether a measurement can be read from a mirrored run (:func:`on_sheet`'s ``plane``)."""
    return _lab(test) is None


def on_sheet(test: Test, sheet: FormedGrid, model: Model, shift: np.ndarray | None = None,
             plane: str | None = None) -> np.ndarray:
    """A forming measurement's model values on one formed sheet (as :data:`FORMING` compares).

    Args:
        test: The measurement (a grid or a lab measurement).
        sheet: The formed part (:func:`~fenicsx_drape.diagnosis.forming_runs.form_many`'s).
        model: The model it was formed with (a force curve is read from its run).
        shift: A blank offset (mm) the flat positions are read at (:func:`moved`).
        plane: The sheet is the run of the mirror image in this symmetry plane ("x" or "y"):
            the grid is read at its image and mirrored back (grids only: :func:`mirrorable`).
    """
    test = moved(test, np.zeros(2) if shift is None else np.asarray(shift, float))
    if _lab(test) is not None:
        if plane is not None:
            raise ValueError(f"test {test.id!r}: a lab measurement is not read mirrored")
        return np.asarray(lab_kind.match(test, sheet, model)["values"], float)
    sheet = sheet.ply(test.ply)  # a stack: the ply measured
    M = np.ones(3) if plane is None else np.where(np.arange(3) == "xy".index(plane), -1.0, 1.0)
    P = fk.reference_points(test) * M[:2]
    part = sheet if all(bool((P[:, "xy".index(q)] >= -1e-9).all()) for q in sheet.planes) \
        else sheet.full()
    return (fk.sample(part, P, test.id) * M).ravel()


def widened(test: Test, extra: float) -> Test:
    """``test`` with ``extra`` (in its unit) added in quadrature to every row's noise.

    A model error of known size weighed as noise: the net's own error on a measurement whose
    residual it explains (:mod:`~fenicsx_drape.diagnosis.resolution`).
    """
    column = _sd_column(test)
    sd = test.column(column)
    if sd is None:
        lab = _lab(test)
        sd = np.full(test.n_rows, lab.noise(test)[0]) if lab is not None else fk.row_noise(test)
    columns = dict(test.columns)
    columns[column] = np.hypot(np.asarray(sd, float), float(extra))
    return dataclasses.replace(test, columns=columns)


def _sd_column(test: Test) -> str:
    from fenicsx_drape.measurements.lab import SD_COLUMN, measurement_of

    return SD_COLUMN.get(measurement_of(test) or "file", "position_sd_mm")


# --------------------------------------------------------------------------------------------
# Fitting the forming parameters


def forming_parameters(model: Model) -> tuple[str, ...]:
    """The forming parameters the model fits: those of :data:`FORMING_PARAMETERS` it uses."""
    active = model.active_parameters()
    return tuple(n for n in FORMING_PARAMETERS if n in active)


def _residuals(tests: Sequence[Test], model: Model, names: Sequence[str],
               sets: np.ndarray) -> np.ndarray:
    """Residuals in noise units, cost = Σ_tests (RMSE / noise)², one row per parameter set."""
    vectorised = model.with_parameters(**{n: sets[:, i] for i, n in enumerate(names)})
    out = []
    for test in tests:
        values = np.atleast_2d(FORMING.simulate(test, vectorised))
        sd = value_sd(test)
        w = 1.0 / sd / math.sqrt(sd.size)
        r = (values - FORMING.measured(test)) * w
        out.append(np.where(np.isfinite(r), r, 0.0))
    return np.concatenate(out, axis=1)


def fit_forming(bundle: Bundle, model: Model, *, tests: Sequence[str] | None = None,
                max_iterations: int = MAX_ITERATIONS,
                progress: Callable[[str], None] | None = None) -> Model:
    """Fit the model's forming parameters to the forming tests of ``bundle`` (module doc).

    Args:
        bundle: The measurements (coupon tests are ignored here).
        model: The model, material parameters as fitted to the coupons (or given).
        tests: Only these test ids; all forming tests when None.
        max_iterations: Gauss-Newton iterations at most (capped at :data:`MAX_ITERATIONS`).
        progress: Called with a line of text per iteration.

    Returns:
        The model with its forming parameters fitted.
    """
    from fenicsx_drape.model import parameter_info

    say = progress or (lambda line: None)
    chosen = [t for t in bundle.tests if t.kind == "forming" and (tests is None or t.id in tests)]
    names = forming_parameters(model)
    if not any(holder_mu_free(t) for t in chosen):
        names = tuple(n for n in names if n != "mu")
    if not chosen or not names:
        return model
    p = np.array([float(model.parameters[n]) for n in names])
    k = len(names)
    h = FD_STEP * np.eye(k)

    def residuals(*points: np.ndarray) -> np.ndarray:
        return _residuals(chosen, model, names, np.vstack(points))

    def slopes(p: np.ndarray, r: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
        R = residuals(*(p + h)) if R is None else R
        return (R - r).T / FD_STEP

    def evaluate(*points: np.ndarray) -> tuple[np.ndarray, list[np.ndarray | None]]:
        """The residuals at ``points`` and each one's Jacobian where its runs were at hand.

        A point's finite differences are spare runs (forming_runs.spare): formed with it where
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

    # Two starts, judged in the first batch of runs: the model's values and the parameters'
    # defaults (a warm start from a model without the right physics can sit far off).
    default = np.clip([parameter_info(n).default for n in names], *MU_BOUNDS)
    R, Js = evaluate(p, *([default] if np.abs(default - p).max() > XTOL else []))
    r, J = R[0], Js[0]
    if len(R) > 1 and R[1] @ R[1] < r @ r:
        say(f"  forming fit: starting from the defaults "
            f"{ {n: round(float(v), 4) for n, v in zip(names, default)} } "
            f"(cost {R[1] @ R[1]:.4g}, was {r @ r:.4g})")
        p, r, J = default, R[1], Js[1]
    for iteration in range(min(max_iterations, MAX_ITERATIONS)):
        J = slopes(p, r) if J is None else J
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        step /= max(1.0, float(np.abs(step).max()) / MAX_STEP)
        for attempt in range(2):  # the Gauss-Newton step, then half of it
            trial = np.clip(p + step / 2**attempt, *MU_BOUNDS)
            if np.abs(trial - p).max() < XTOL:
                break
            (r_new,), (J_new,) = evaluate(trial)
            say(f"  forming fit {iteration + 1}: "
                f"{ {n: round(float(v), 4) for n, v in zip(names, trial)} }, "
                f"cost {r_new @ r_new:.4g} (was {r @ r:.4g})")
            if r_new @ r_new < r @ r:
                break
        else:
            break
        if np.abs(trial - p).max() < XTOL:
            break
        p, r, J = trial, r_new, J_new
    return model.with_parameters(**{n: float(v) for n, v in zip(names, p)})


def _fit(bundle: Bundle, model: Model, *, tests: Sequence[str] | None = None,
         parameters: Sequence[str] | None = None, max_iterations: int = MAX_ITERATIONS,
         from_features: bool = True, progress: Callable[[str], None] | None = None) -> Model:
    """The forming kind's fit (:class:`~fenicsx_drape.diagnosis.kinds.FitHook`).

    The forming parameters only (:func:`fit_forming`), the material held as the coupons (or
    the model) left it: ``parameters`` and ``from_features`` concern the material.
    """
    return fit_forming(bundle, model, tests=tests, progress=progress,
                       max_iterations=max_iterations)


def _plot(comparisons, test: Test, path: Path, shares=()) -> Path:
    """The forming kind's picture: the grid's error map, or a lab measurement's own."""
    lab = _lab(test)
    if lab is not None:
        return lab.plot(comparisons, test, path, shares)
    return fk.plot_error_map(comparisons, test, path, shares)


FORMING = Kind(unit=_by_measurement(lambda test: "mm", "unit"),
               measured=_by_measurement(measured_values, "measured"),
               noise=_by_measurement(fk.noise, "noise"),
               simulate=_by_measurement(fk.simulate, "simulate"),
               regions=_by_measurement(fk.part_regions, "regions"),
               abscissa=_by_measurement(fk.abscissa, "abscissa"),
               sd_column=_sd_column, fit=_fit,
               metrics=_by_measurement(fk.metrics, "metrics"),
               plot=_plot)
