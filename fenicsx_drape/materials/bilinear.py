"""The smooth bilinear function shared by the tow law (eq. 3) and the viscosity law (eq. 8).

Both equations have the form

    g(x) = k_∞ x + (k_o − k_∞)/α · ln(1/(1 + e^{−α(x − x̄)})) − (k_o − k_∞)/α · ln(1/(1 + e^{αx̄}))

with slope ``k_o`` well below the transition ``x̄`` and ``k_∞`` well above it (breadth ∝ 1/α),
and ``g(0) = 0``. With ``softplus(z) = ln(1 + e^z)`` and ``softplus(−z) = softplus(z) − z``
this is the same as

    g(x) = k_o x + (k_∞ − k_o)/α · [softplus(α(x − x̄)) − softplus(−αx̄)],

which :func:`numpy.logaddexp` evaluates without overflow for any ``α|x|``.
"""

from __future__ import annotations

import numpy as np
from scipy.special import expit


def smooth_bilinear(x, k_o, k_inf, x_bar, alpha) -> tuple[np.ndarray, np.ndarray]:
    """Value and slope of the smooth bilinear function ``g`` (see the module docstring).

    Args:
        x: Argument (any shape; the other arguments broadcast against it).
        k_o: Slope well below the transition.
        k_inf: Slope well above the transition.
        x_bar: Transition point.
        alpha: Inverse breadth of the transition (> 0).

    Returns:
        ``(g(x), g'(x))``, finite for every finite input.
    """
    z = alpha * (x - x_bar)
    g = k_o * x + (k_inf - k_o) / alpha * (np.logaddexp(0.0, z) - np.logaddexp(0.0, -alpha * x_bar))
    slope = k_o + (k_inf - k_o) * expit(z)
    return g, slope
