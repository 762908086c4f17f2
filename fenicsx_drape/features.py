"""Initial parameter guesses from curve features, as section 3.2 describes.

No parameter table is consulted, so a new material gets a sensible start:

- **tow law** (tensile curve, per tow against the Green-Lagrange tow strain): a two-segment
  continuous piecewise-linear fit gives ``E_o`` (initial slope), ``E_inf`` (final slope) and
  ``eps_bar`` (the intersection of the two asymptotes of eq. 3 is at ε̄); the breadth ``alpha``
  follows from the curve's rise above the corner, ``(E_∞ - E_o) ln 2 / α`` by eq. 3.
- **shear law** (bias curves, per tow against the diagonal strain of eq. 21): a three-segment
  fit of the slowest curve gives the first knee (tow bending stops: ``sigma_o``, ``E_p``),
  the plateau slope and the lock-up. The spread of the curves with the strain rate in the
  plateau gives the viscosity there; with the plateau slope of the slowest curve this splits
  into ``eta_o`` and ``s_o`` (plateau: ``f ≈ σ_o + η_o (1 + s_o ε) ε̇``). The lock-up above the
  plateau grows like ``exp(α_v (ε - ε̄_v))`` below ``ε̄_v`` (eq. 8), which gives ``alpha_v``;
  ``eps_v_bar`` is placed at the end of the data and ``s_inf`` matched to the excess force
  there. ``E_v`` (the Maxwell spring) cannot be seen without relaxation data: it is started
  ten times stiffer than ``E_p`` so the Maxwell relaxation time is short against the test.

The per-tow force of a coupon is not exactly the bar stress (eqs. 17, 20), so after the
features the force-like parameters (those in N/tow or N·s/tow) of each law are rescaled
together by the least-squares factor between measured and simulated force: the laws are
homogeneous of degree one in them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fenicsx_drape.bundle import Test


def hinge_fit(x: np.ndarray, y: np.ndarray, n_breaks: int,
              n_grid: int = 40) -> tuple[tuple[float, ...], np.ndarray]:
    """Continuous piecewise-linear least-squares fit of ``y(x)`` with ``n_breaks`` knees.

    Returns:
        The breakpoints (increasing) and the coefficients ``(c, k_1, Δk_1, ..., Δk_n)`` of
        ``c + k_1 x + Σ Δk_i (x - b_i)_+`` (so the slope after knee i is k_1 + ΣΔk).
    """
    grid = np.quantile(x, np.linspace(0.05, 0.95, n_grid))
    best, best_sse = None, math.inf
    for combo in _increasing(grid, n_breaks):
        basis = np.column_stack([np.ones_like(x), x] + [np.maximum(x - b, 0.0) for b in combo])
        coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
        sse = float(np.sum((basis @ coef - y) ** 2))
        if sse < best_sse:
            best, best_sse = (tuple(combo), coef), sse
    return best


def _increasing(grid: np.ndarray, n: int):
    if n == 1:
        yield from ([b] for b in grid)
        return
    for i, b in enumerate(grid):
        for rest in _increasing(grid[i + 2:], n - 1):  # knees at least two cells apart
            yield [b, *rest]


def _loading(test: Test) -> np.ndarray:
    """Rows of the first monotonic loading up to the maximum displacement."""
    d = test.displacement_mm
    stop = int(np.argmax(d)) + 1
    keep = np.ones(stop, dtype=bool)
    keep[1:] = np.diff(d[:stop]) > 0
    return np.flatnonzero(keep)


def tow_guess(tests: Sequence[Test], decrimping: bool = True) -> dict[str, float]:
    """``E_o, E_inf, eps_bar, alpha`` (or only ``E_inf``) from tensile curves."""
    xs, ys = [], []
    for test in tests:
        rows = _loading(test)
        e = test.displacement_mm[rows] / test.gauge_length_mm
        xs.append(e + 0.5 * e**2)
        ys.append(test.force_N[rows] / test.tows)
    x, y = np.concatenate(xs), np.concatenate(ys)
    order = np.argsort(x)
    x, y = x[order], y[order]
    if not decrimping:
        return {"E_inf": float(np.dot(x, y) / np.dot(x, x))}
    (b,), (c, k1, dk) = hinge_fit(x, y, 1)
    E_o = max(k1, 1e-3 * abs(k1 + dk))
    E_inf = max(k1 + dk, 1.05 * E_o)
    # rise of the data above the corner of the asymptotes, averaged near the corner
    near = np.abs(x - b) <= 0.1 * (x.max() - x.min())
    rise = float(np.mean(y[near] - (c + E_o * np.minimum(x[near], b)
                                    + E_inf * np.maximum(x[near] - b, 0.0))))
    width = 0.05 * b if rise <= 0 else (E_inf - E_o) * math.log(2.0) / rise
    alpha = 1.0 / min(max(width, 0.01 * b), b)
    return {"E_o": float(E_o), "E_inf": float(E_inf), "eps_bar": float(b), "alpha": alpha}


def shear_guess(tests: Sequence[Test]) -> dict[str, float]:
    """``sigma_o, eta_o, s_o, s_inf, alpha_v, eps_v_bar, E_v, E_p`` from bias curves."""
    from fenicsx_drape.unitcell import bias_diagonal_strain

    curves = []
    for test in tests:
        rows = _loading(test)
        x = np.asarray(bias_diagonal_strain(test.displacement_mm[rows], test.length_mm,
                                            test.width_mm))
        f = test.force_N[rows] / test.tows
        rate = float(np.median(np.diff(x) / np.diff(test.time_s[rows])))
        curves.append((rate, x, f))
    curves.sort(key=lambda c: c[0])
    rate_s, x, f = curves[0]
    (b1, b2), (c, k1, dk1, dk2) = hinge_fit(x, f, 2)
    k2 = k1 + dk1
    level = c + k1 * b1  # the first knee: tow bending stops
    E_p = max(level / b1, 1e-6)

    # viscosity in the plateau from the spread of the curves with the strain rate
    x_a = b1 + 0.25 * (b2 - b1)
    if len(curves) > 1:
        rates = np.array([r for r, _, _ in curves])
        at_a = np.array([np.interp(x_a, xc, fc) for _, xc, fc in curves])
        eta_a = float(np.polyfit(rates, at_a, 1)[0])
    else:
        eta_a = 0.0
    if eta_a <= 0:  # one rate, or no visible rate effect: let the plateau slope be viscous
        eta_a = max(k2, 0.1 * level / x_a) * x_a / rate_s
    eta_o = max(eta_a - max(k2, 0.0) * x_a / rate_s, 0.2 * eta_a)
    s_o = max(k2 / (eta_o * rate_s), 0.1)
    sigma_o = max(level - eta_o * (1.0 + s_o * b1) * rate_s, 0.2 * level)

    # lock-up: excess over the plateau line grows like exp(α_v ε) below ε̄_v
    plateau = c + k1 * x + dk1 * np.maximum(x - b1, 0.0)
    excess = f - plateau
    up = (x > b2) & (excess > 0)
    x_max = float(x.max())
    if up.sum() >= 3 and dk2 > 0:
        slope, intercept = np.polyfit(x[up], np.log(excess[up]), 1, w=np.sqrt(excess[up]))
        alpha_v = float(min(max(slope, 2.0), 200.0))
        excess_end = math.exp(intercept + slope * x_max)
    else:
        alpha_v, excess_end = 10.0 / max(x_max - b2, 1e-3), max(dk2, 0.0) * (x_max - b2)
    s_inf = s_o + alpha_v * max(excess_end, 1e-3 * level) / (eta_o * rate_s)
    return {"sigma_o": float(sigma_o), "eta_o": float(eta_o), "s_o": float(s_o),
            "s_inf": float(max(s_inf, 2.0 * s_o)), "alpha_v": alpha_v, "eps_v_bar": x_max,
            "E_v": 10.0 * E_p, "E_p": float(E_p)}
