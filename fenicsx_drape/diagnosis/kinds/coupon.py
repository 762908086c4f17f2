"""Coupon tests in ``compare`` and ``diagnose``: tensile, bias extension, picture frame.

A coupon test is compared row by row on its force (N): simulated by the unit-cell solutions
(:func:`fenicsx_drape.calibration.coupons.simulate`), weighed with the same noise as in the
fit (``force_sd_N``, or the model-free estimate), and fitted by
:func:`fenicsx_drape.calibration.fit.fit` (the material's parameters).

Its **regions** are the ranges of the kinematic strain (:func:`coupon_strain`) that separate
the mechanisms of the paper's section 3.2 (bias extension: initial tow bending, friction
plateau, lock-up; tension: decrimping, then tow stretching), found by tangent intersections on
the loading curve (:func:`_knees`), and the phases of the loading history (loading, hold,
unloading).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.diagnosis.kinds import Kind, Region

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model


def _coupon_noise(test: Test) -> tuple[float, str]:
    from fenicsx_drape.calibration.coupons import test_noise

    _, noise, source = test_noise(test)  # the same noise the fit weighs the rows with
    return noise, source


def _coupon_simulate(test: Test, model: Model) -> np.ndarray:
    from fenicsx_drape.calibration.coupons import simulate as simulate_coupon

    return simulate_coupon(test, model)


def coupon_strain(test: Test) -> tuple[str, np.ndarray]:
    """The kinematic strain of a coupon's rows: ``("tow_strain" | "diagonal_strain", values)``.

    Tension: the Green-Lagrange strain of the loaded tows, ``e + e²/2`` with
    ``e = displacement / gauge length`` (eq. 13). Bias extension: the diagonal strain of the
    gauge region, eq. 21. Picture frame: the diagonal strain sin γ / 2 of the frame's shear
    angle (:func:`fenicsx_drape.unitcell.picture_frame_shear_angle`). All follow from the
    measured displacement alone.
    """
    if test.kind == "tensile":
        e = test.displacement_mm / test.gauge_length_mm
        return "tow_strain", e + 0.5 * e**2
    if test.kind == "picture_frame":
        from fenicsx_drape.unitcell import picture_frame_shear_angle

        γ = np.radians(picture_frame_shear_angle(test.displacement_mm, test.frame_side_mm))
        return "diagonal_strain", 0.5 * np.sin(γ)
    from fenicsx_drape.unitcell import bias_diagonal_strain

    return "diagonal_strain", np.asarray(
        bias_diagonal_strain(test.displacement_mm, test.length_mm, test.width_mm))


def _loading_phases(time_s: np.ndarray, displacement_mm: np.ndarray) -> np.ndarray:
    """Per row: +1 loading, 0 hold, -1 unloading (the crosshead motion ending at the row)."""
    rate = np.diff(displacement_mm) / np.diff(time_s)
    tol = 1e-3 * np.abs(rate).max() if rate.size and np.abs(rate).max() > 0 else 0.0
    phase = np.where(rate > tol, 1, np.where(rate < -tol, -1, 0))
    return np.concatenate([phase[:1], phase])


def _window_lines(x: np.ndarray, y: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Slope and intercept of the least-squares line over every ``w`` consecutive points."""
    x0 = x.mean()
    xc = x - x0

    def sums(a):
        c = np.concatenate([[0.0], np.cumsum(a)])
        return c[w:] - c[:-w]

    sx, sy, sxx, sxy = sums(xc), sums(y), sums(xc * xc), sums(xc * y)
    slope = (w * sxy - sx * sy) / np.maximum(w * sxx - sx**2, 1e-300)
    intercept = (sy - slope * sx) / w - slope * x0
    return slope, intercept


def _knees(x: np.ndarray, y: np.ndarray, pattern: str) -> tuple[float, ...]:
    """Where the mechanisms of a loading curve ``y(x)`` hand over, by tangent intersections.

    The classic onset construction: straight lines fitted over windows of 1/8 of the rows at
    the start and at the end of the curve and, for ``pattern = "stiff-soft-stiff"`` (bias
    extension), over the window of least slope in between (the plateau); each knee is where
    two neighbouring lines cross. A knee is NaN (its two regions merge) when the stiffer line
    is not at least 1.5 times as steep as the softer one. ``pattern = "soft-stiff"`` (tension)
    has one knee, between the start and end lines.
    """
    order = np.argsort(x, kind="stable")
    x, y = x[order], y[order]
    w = max(5, x.size // 8)
    slope, intercept = _window_lines(x, y, w)
    lines = [(slope[0], intercept[0])]
    if pattern == "stiff-soft-stiff":
        j = int(np.argmin(slope[1:-1])) + 1 if slope.size > 2 else 0
        lines.append((slope[j], intercept[j]))
    lines.append((slope[-1], intercept[-1]))
    knees = []
    for i, ((s1, b1), (s2, b2)) in enumerate(itertools.pairwise(lines)):
        stiff, soft = (s1, s2) if (pattern == "stiff-soft-stiff" and i == 0) else (s2, s1)
        if stiff > 0 and stiff > 1.5 * max(soft, 0.0):
            knees.append(float(np.clip((b1 - b2) / (s2 - s1), x[0], x[-1])))
        else:
            knees.append(math.nan)
    return tuple(knees)


# The strain ranges of each coupon kind, in order, and the shape of its loading curve:
# bias extension stiff - soft - stiff, tension soft - stiff (section 3.2).
_STRAIN_REGIONS = {
    "bias_extension": (("initial tow bending", "friction plateau", "lock-up"),
                       "stiff-soft-stiff"),
    "tensile": (("decrimping", "tow stretching"), "soft-stiff"),
    "picture_frame": (("initial tow bending", "friction plateau", "lock-up"),
                      "stiff-soft-stiff"),
}


def _coupon_regions(test: Test) -> list[Region]:
    variable, strain = coupon_strain(test)
    phases = _loading_phases(test.time_s, test.displacement_mm)
    regions: list[Region] = []
    names, pattern = _STRAIN_REGIONS[test.kind]
    loading = phases > 0
    knees = _knees(strain[loading], test.force_N[loading], pattern) \
        if loading.sum() >= 24 else (math.nan,) * (len(names) - 1)
    # A missing knee merges its two regions; the merged region keeps the later name.
    edges, kept = [-math.inf], []
    for name, knee in zip(names, knees):
        if not math.isnan(knee) and knee > edges[-1]:
            kept.append(name)
            edges.append(knee)
    kept.append(names[-1])
    edges.append(math.inf)
    for name, lo, hi in zip(kept, edges[:-1], edges[1:]):
        rows = (strain >= lo) & (strain < hi)
        if rows.any():
            regions.append(Region(variable, (float(strain[rows].min()),
                                             float(strain[rows].max())), name, rows))
    if len(np.unique(phases)) > 1:
        labels = {1: "loading", 0: "hold (relaxation)", -1: "unloading"}
        starts = np.flatnonzero(np.diff(phases, prepend=phases[0] + 1) != 0)
        for start, stop in zip(starts, [*starts[1:], len(phases)]):
            rows = np.zeros(len(phases), bool)
            rows[start:stop] = True
            t = test.time_s[rows]
            regions.append(Region("time_s", (float(t[0]), float(t[-1])),
                                  labels[int(phases[start])], rows))
    return regions


def _coupon_fit(bundle: Bundle, model: Model, *, tests: Sequence[str] | None = None,
                parameters: Sequence[str] | None = None, max_iterations: int = 200,
                from_features: bool = True, progress: Callable[[str], None] | None = None,
                details: dict | None = None) -> Model:
    """The coupons' fit (:class:`~fenicsx_drape.diagnosis.kinds.FitHook`): the material.

    The coupon tests fix the material (:func:`fenicsx_drape.calibration.fit.fit`) when some
    of ``parameters`` (all when None) act on them. A fit from the features has the global
    stage; ``details["coupons"]`` receives the :class:`~fenicsx_drape.calibration.fit.
    FitResult` (its starts, undetermined parameters, noise) when ``details`` is given.
    """
    from fenicsx_drape.calibration.coupons import COUPON_KINDS
    from fenicsx_drape.calibration.fit import fit

    if parameters is not None and not set(parameters) & set(
            model.active_parameters(COUPON_KINDS)):
        return model
    result = fit(bundle, model, tests=tests, parameters=parameters,
                 initial_guess_from_features=from_features, max_iterations=max_iterations,
                 progress=progress, analyse=False)
    if details is not None:
        details["coupons"] = result
    return result.model


COUPON = Kind(unit="N", measured=lambda test: test.force_N, noise=_coupon_noise,
              simulate=_coupon_simulate, regions=_coupon_regions, abscissa=coupon_strain,
              sd_column="force_sd_N", fit=_coupon_fit)
