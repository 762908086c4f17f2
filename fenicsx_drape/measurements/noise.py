"""The measurement noise of a test, from its data alone (the noise floor of a comparison).

The diagnosis contract (``docs/measurements.md``) defines the noise of a test as the
RMS of its ``force_sd_N`` column when given, otherwise a model-free estimate from the data
alone -- never from a model's residuals, so that a model cannot lower its own bar.

The model-free estimate uses second differences of successive rows. For rows
``y_i = f(t_i) + e_i`` with a smooth ``f`` and independent noise ``e_i`` of standard deviation
``s``, the deviation of ``y_i`` from the straight line through its neighbours,

    d_i = y_i - (w_i y_{i-1} + (1 - w_i) y_{i+1}),   w_i = (t_{i+1} - t_i) / (t_{i+1} - t_{i-1}),

has variance ``s² (1 + w_i² + (1 - w_i)²)`` plus the square of the curvature term
``f''(t) h²/2`` (``h`` the row spacing), negligible for densely sampled curves. The estimate is
the RMS of ``z_i = d_i / sqrt(1 + w_i² + (1 - w_i)²)`` over the ``z_i`` within three robust
deviations (the normalised median absolute deviation) of their median, corrected for the cut:
nearly as precise as the plain RMS, while the few rows at a kink of the history (start of a
hold, of unloading) do not inflate it. When readings are quantised so coarsely that the
median deviation is zero, the plain RMS of the ``z_i`` is used instead.

**Implausible estimates.** A curve that was smoothed, filtered, resampled or digitised from a
figure has second differences that measure its smoothness, not its noise (a digitised
fabric curve gives 0.04 N where repeat tests scatter by 0.4 N). :func:`implausible` says when
an estimate cannot be a measurement noise: second differences that are not white (their
lag-1 autocorrelation, -2/3 for white noise, above :data:`SMOOTH_LAG1`) or an estimate below
:data:`MIN_RELATIVE` of the peak. The calibration then uses at least :data:`FLOOR_RELATIVE`
of the peak force unless a noise is declared, and says so.
"""

from __future__ import annotations

import numpy as np

# The median absolute deviation of a normal variable times this is its standard deviation.
_MAD_TO_SD = 1.482602218505602
# Rows beyond this many robust deviations are outliers (kinks); a standard normal variable
# cut at ±3 keeps a variance of 1 - 6 φ(3) / (2 Φ(3) - 1).
_CUT = 3.0
_CUT_VARIANCE = 0.9733369246625415


def noise_from_sd(sd: np.ndarray) -> float:
    """The RMS of a per-row standard-deviation column (e.g. ``force_sd_N``), same unit."""
    sd = np.asarray(sd, dtype=float)
    return float(np.sqrt(np.mean(sd**2)))


def noise_from_second_differences(t: np.ndarray, y: np.ndarray) -> float:
    """A model-free estimate of the standard deviation of the noise of ``y(t)``.

    Args:
        t: The abscissa of the rows (e.g. ``time_s``), strictly increasing.
        y: The measured values (e.g. ``force_N``), same length, at least 5 rows.

    Returns:
        The estimated standard deviation of one row's noise, in the unit of ``y``.

    Raises:
        ValueError: with fewer than 5 rows or a non-increasing abscissa.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.shape != y.shape or t.ndim != 1 or t.size < 5:
        raise ValueError(f"noise estimate needs two equal 1-D columns of at least 5 rows, "
                         f"got shapes {t.shape} and {y.shape}")
    h = np.diff(t)
    if not (h > 0).all():
        raise ValueError("noise estimate needs a strictly increasing abscissa")
    w = h[1:] / (h[:-1] + h[1:])
    d = (y[1:-1] - (w * y[:-2] + (1.0 - w) * y[2:])) / np.sqrt(1.0 + w**2 + (1.0 - w) ** 2)
    d = d - np.median(d)
    robust = _MAD_TO_SD * np.median(np.abs(d))
    if robust == 0:
        # Readings quantised coarser than the noise make most differences zero: the plain
        # RMS is then the only information left.
        return float(np.sqrt(np.mean(d**2)))
    kept = d[np.abs(d) < _CUT * robust]
    return float(np.sqrt(np.mean(kept**2) / _CUT_VARIANCE))


# White noise gives second differences whose lag-1 autocorrelation is -2/3 (uniform rows); a
# smoothed, filtered, resampled or digitised curve gives differences dominated by curvature
# and interpolation, correlated positively or not at all. Beyond this value the estimate
# measures the curve's smoothness, not its noise (100 rows of white noise scatter the lag-1
# value by about 0.07: -0.35 is more than four of those from -2/3).
SMOOTH_LAG1 = -0.35
# A coupon test whose rows scatter by less than this fraction of its peak force is smoothed or
# digitised: repeat tests of fabrics scatter by 1.5-4 % (Cao et al. 2008, the error bars of
# Figs. 38 and 43, in demos/bundles/cao2008-*), a load cell's own noise is rarely below 0.1 %
# of a fabric coupon's peak, and a digitiser reads a plotted curve to about 0.1-0.2 %.
MIN_RELATIVE = 0.0025
# When the estimate is implausible and nothing is declared, the noise used is at least this
# fraction of the test's peak force: the median scatter of repeat fabric coupons (Cao et al.
# 2008, Figs. 38, 43: 1.5, 1.9, 2.1, 2.1, 3.8 % of peak) -- a stand-in, said so in the report.
FLOOR_RELATIVE = 0.02


def second_difference_lag1(t: np.ndarray, y: np.ndarray) -> float:
    """Lag-1 autocorrelation of the normalised second differences of ``y(t)`` (white: -2/3)."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    h = np.diff(t)
    w = h[1:] / (h[:-1] + h[1:])
    d = (y[1:-1] - (w * y[:-2] + (1.0 - w) * y[2:])) / np.sqrt(1.0 + w**2 + (1.0 - w) ** 2)
    d = d - d.mean()
    denominator = float(np.sum(d * d))
    return float(np.sum(d[1:] * d[:-1]) / denominator) if denominator > 0 else 0.0


def implausible(t: np.ndarray, y: np.ndarray, noise: float) -> str | None:
    """Why a model-free noise estimate cannot be the measurement noise of ``y(t)``, or None.

    Two signs, either enough: second differences that are not white (lag-1 autocorrelation
    above :data:`SMOOTH_LAG1`: the curve was smoothed, filtered, resampled or digitised), or
    an estimate below :data:`MIN_RELATIVE` of the peak |y|.
    """
    lag1 = second_difference_lag1(t, y)
    peak = float(np.max(np.abs(y)))
    reasons = []
    if lag1 > SMOOTH_LAG1:
        reasons.append(f"its second differences are not white noise (lag-1 autocorrelation "
                       f"{lag1:.2f}; white noise gives -0.67): the curve looks smoothed, "
                       "filtered, resampled or digitised")
    if peak > 0 and noise < MIN_RELATIVE * peak:
        reasons.append(f"it is {100 * noise / peak:.2g} % of the peak force, below the "
                       f"{100 * MIN_RELATIVE:g} % a measured fabric coupon scatters by")
    return "; ".join(reasons) or None
