"""Initial parameter guesses from curve features, as section 3.2 describes.

No parameter table is consulted, so a new material gets a sensible start:

- **tow law** (tensile curve, per tow against the Green-Lagrange tow strain): a two-segment
  continuous piecewise-linear fit gives the transition ``eps_bar`` (the asymptotes of eq. 3
  meet at ε̄); ε̄ and the breadth ``alpha`` are then chosen on a small grid around it, with
  the initial and final slopes ``E_o``, ``E_inf`` by linear least squares at each node (eq. 3
  is linear in them).
- **shear law** (bias curves, per tow against the diagonal strain of eq. 21): a two-segment
  fit below the lock-up of the slowest curve gives the first knee (tow bending stops) and
  with it ``E_p``. Beyond the knee the curves at the rates ε̇_i follow
  ``f_i(ε) ≈ σ_o + η(ε) ε̇_i``: at each strain, the line through the curves against the rate
  gives ``σ_o`` (intercept) and the viscosity ``η(ε)`` (slope) -- the paper's "dependence of
  stress on strain rate at low to intermediate strains". There eq. 8 makes
  ``η ≈ η_o (1 + s_o ε)`` (plus the onset of the lock-up), which gives ``η_o`` and ``s_o``.
  The lock-up of the slowest curve, the viscosity beyond that line, grows like
  ``exp(α_v ε)`` below the transition (eq. 8), which gives ``alpha_v``; ``eps_v_bar`` is placed
  at the end of the data and ``s_inf`` follows from the size of the lock-up there (the data
  below ε̄_v fix only s_∞ exp(−α_v ε̄_v); the fit and its flags say how well each is
  determined). ``E_v`` (the Maxwell spring) cannot be seen without relaxation data: it is
  started ten times stiffer than ``E_p`` so the Maxwell relaxation time is short against the
  test. With a single rate -- or curves whose spread does not grow with the rate (a dry
  fabric, or specimen sizes that differ more than their rates) -- σ_o is taken as 0.8 of the
  knee and the rise beyond it as viscous at the slowest rate.

The per-tow force of a coupon is not exactly the bar stress (eqs. 17, 20), so after the
features the force-like parameters (those in N/tow or N·s/tow) of each law are rescaled
together by the least-squares factor between measured and simulated force: the laws are
homogeneous of degree one in them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import nnls

from fenicsx_drape.measurements.bundle import Test


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


def _smooth(y: np.ndarray, window: int = 9) -> np.ndarray:
    """Local quadratic smoothing (Savitzky-Golay) of a densely sampled curve."""
    from scipy.signal import savgol_filter  # here: scipy.signal takes half a second to import

    return savgol_filter(y, window, 2) if y.size > 2 * window else y


def _loading(test: Test) -> np.ndarray:
    """Rows of the first monotonic loading up to the maximum displacement."""
    d = test.displacement_mm
    stop = int(np.argmax(d)) + 1
    keep = np.ones(stop, dtype=bool)
    keep[1:] = np.diff(d[:stop]) > 0
    return np.flatnonzero(keep)


def tow_guess(tests: Sequence[Test], decrimping: bool = True) -> dict[str, float]:
    """``E_o, E_inf, eps_bar, alpha`` (or only ``E_inf``) from tensile curves.

    The hinge of a two-segment fit gives ε̄ and the slopes; ε̄ and α are then refined on a
    small grid around it, with the two moduli by linear least squares at each node (eq. 3 is
    linear in E_o and E_∞).
    """
    xs, ys = [], []
    for test in tests:
        rows = _loading(test)
        e = test.displacement_mm[rows] / test.gauge_length_mm
        xs.append(e + 0.5 * e**2)
        ys.append(test.force_N[rows] / test.tows)
    x, y = np.concatenate(xs), np.concatenate(ys)
    if not decrimping:
        return {"E_inf": float(np.dot(x, y) / np.dot(x, x))}
    (b,), _ = hinge_fit(x, y, 1)
    best, best_sse = None, math.inf
    for eps_bar in b * np.linspace(0.6, 1.4, 17):
        for alpha in np.geomspace(2.0, 200.0, 25) / eps_bar:
            # g = E_o x + (E_∞ - E_o) h(x), h the softplus part of eq. 3
            h = (np.logaddexp(0.0, alpha * (x - eps_bar))
                 - np.logaddexp(0.0, -alpha * eps_bar)) / alpha
            basis = np.column_stack([np.ones_like(x), x - h, h])
            coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
            sse = float(np.sum((basis @ coef - y) ** 2))
            if sse < best_sse and 0 < coef[1] < coef[2]:
                best, best_sse = (coef[1], coef[2], eps_bar, alpha), sse
    if best is None:  # no stiffening seen: a linear tow
        slope = float(np.dot(x, y) / np.dot(x, x))
        return {"E_o": slope, "E_inf": 1.5 * slope, "eps_bar": float(b), "alpha": 10.0 / b}
    return dict(zip(("E_o", "E_inf", "eps_bar", "alpha"), map(float, best)))


def shear_curve(test: Test, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The major diagonal's strain and a bias-equivalent force per tow of a shear test's rows.

    Bias extension: eq. 21 and the force per tow. Picture frame: ε_d = sin γ / 2 and the
    force per tow scaled by 2 L_frame/L_fabric, which is the bias extension's per-tow force
    2(τ_1 − τ_2 cot θ) of the same cell (:func:`fenicsx_drape.unitcell.picture_frame`).
    """
    from fenicsx_drape import unitcell

    d = test.displacement_mm[rows]
    f = test.force_N[rows] / test.tows
    if test.kind == "picture_frame":
        γ = np.radians(unitcell.picture_frame_shear_angle(d, test.frame_side_mm))
        return 0.5 * np.sin(γ), 2.0 * test.frame_side_mm / test.fabric_side_mm * f
    return np.asarray(unitcell.bias_diagonal_strain(d, test.length_mm, test.width_mm)), f


def shear_guess(tests: Sequence[Test], eta_ref: float | None = None) -> dict[str, float]:
    """``sigma_o, eta_o, s_o, s_inf, alpha_v, eps_v_bar, E_v, E_p`` from bias curves.

    Forces are per tow and not yet scaled to bar stresses (see the module docstring).

    Args:
        tests: Bias-extension or picture-frame tests, at one or more rates.
        eta_ref: For a rate-independent shear law (no ``rate_dependence``), the fixed scale
            η_o·ε̇_ref of its lock-up term: ``s_o`` and ``s_inf`` are then expressed in it at
            the tests' mean rate.
    """
    curves = []
    for test in tests:
        rows = _loading(test)
        x, f = shear_curve(test, rows)
        rate = float(np.median(np.diff(x) / np.diff(test.time_s[rows])))
        curves.append((rate, x, f))
    curves.sort(key=lambda c: c[0])
    rates = np.array([c[0] for c in curves])
    rate_s, x, f = curves[0]
    x_max = min(float(c[1].max()) for c in curves)

    # the first knee (tow bending stops): a two-segment fit up to the flattest part of the
    # slowest curve, which lies between the knee and the lock-up
    centres = np.linspace(0.1, 0.7, 25) * x_max
    slopes = [np.polyfit(x[near], f[near], 1)[0] if (near := np.abs(x - xc) < 0.06 * x_max)
              .sum() >= 3 else np.inf for xc in centres]
    low = x <= max(centres[int(np.argmin(slopes))], float(np.sort(x)[min(5, x.size - 1)]))
    (b1,), (c, k1, _) = hinge_fit(x[low], f[low], 1)
    level = max(c + k1 * b1, 1e-12)

    # beyond the knee f_i(ε) ≈ σ_o + η(ε) ε̇_i: the spread with rate gives η(ε)
    grid = np.linspace(min(1.5 * b1, 0.5 * x_max), 0.98 * x_max, 40)
    F = np.array([np.interp(grid, xc, _smooth(fc)) for _, xc, fc in curves])
    rate_spread = len(curves) > 1 and np.ptp(rates) > 1e-6 * rates.max()
    if rate_spread:
        V, intercept = np.polyfit(rates, F, 1)
        sigma_o = float(np.median(intercept[: len(grid) // 2]))
        if not 0.05 * level < sigma_o < level:
            sigma_o = 0.5 * level
        # Curves that do not rise with the rate (a dry fabric; sizes that differ more than
        # the rates do) say nothing about the viscosity: read them as at one rate instead.
        rate_spread = float(np.median(V)) > 0.0
    if not rate_spread:
        sigma_o = 0.8 * level
        V = (F[0] - sigma_o) / rate_s
        intercept = np.full_like(grid, sigma_o)
    # Low-intermediate strains, where the intercept σ_o holds (beyond, the Maxwell spring of
    # the fast tests stretches and their viscous strain lags: f is no longer linear in the
    # rate): η ≈ A (1 + s_o ε) + C exp(α (ε − ε_max)), eq. 8 below its transition, fitted on
    # a grid of (s_o, α) with non-negative least squares for the amplitudes A, C.
    steady = np.ones_like(grid, dtype=bool)
    if rate_spread:
        steady = intercept < 1.5 * np.median(intercept[: len(grid) // 4])
        steady[: len(grid) // 4] = True
    g, v = grid[steady], V[steady]
    best, best_sse = (1.0, max(float(np.median(v)), 1e-12) / (1.0 + np.median(g))), math.inf
    for s_o in np.geomspace(0.3, 100.0, 20):
        for alpha in np.geomspace(2.0, 200.0, 20):
            basis = np.column_stack([1.0 + s_o * g, np.exp(alpha * (g - x_max))])
            (A, _), sse = nnls(basis, v)
            if A > 0 and sse < best_sse:
                best, best_sse = (s_o, A), sse
    s_o, A = best
    # The lock-up, from the slowest curve (its viscous strain lags least): the viscosity
    # beyond A (1 + s_o ε) grows like exp(α_v ε) below the transition, which is placed at the
    # end of the data (ε̄_v = ε_max); the data there fix only s_∞ exp(−α_v ε̄_v) (the fit and
    # its flags say how well each is determined).
    excess = (np.interp(grid, x, _smooth(f)) - sigma_o) / rate_s - A * (1.0 + s_o * grid)
    up = (grid > 0.5 * x_max) & (excess > 0.5 * A * (1.0 + s_o * grid))
    if up.sum() >= 3:
        alpha_v, ln_c = np.polyfit(grid[up], np.log(excess[up]), 1)
        alpha_v = float(min(max(alpha_v, 2.0), 200.0))
        s_inf = s_o + alpha_v * math.exp(ln_c + alpha_v * x_max) / A
    else:  # no lock-up within the data: a mild one just beyond
        alpha_v, s_inf = 10.0 / x_max, 10.0 * s_o
    guess = {"sigma_o": sigma_o, "eta_o": A, "s_o": s_o, "s_inf": s_inf,
             "alpha_v": float(alpha_v), "eps_v_bar": x_max, "E_v": 10.0 * level / b1,
             "E_p": level / b1}
    if eta_ref is not None:  # rate-independent lock-up η_o ε̇_ref (f(ε) - 1) at the mean rate
        scale = A * float(np.exp(np.mean(np.log(rates)))) / eta_ref
        guess |= {"s_o": s_o * scale, "s_inf": s_inf * scale}
    return {k: float(v) for k, v in guess.items()}
