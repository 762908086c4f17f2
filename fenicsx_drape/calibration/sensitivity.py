"""Sensitivities as in the paper's Table 2, and parameter uncertainties from the fit.

**Table 2** (section 3.2): each parameter is raised by 2.5 %; the relative change of the
fitting error (the mean absolute force error) and of the mean force over all tests of a kind,
divided by the relative change of the parameter, are that parameter's error and force
sensitivities for that kind. All perturbed parameter sets run in one vectorised unit-cell call
per test. The fit minimises squared errors, not the paper's mean absolute error, so at its
optimum a parameter the data barely determine can show a small negative error sensitivity.

**Uncertainty** (beyond the paper): with residuals ``r_i = (simulated - measured)/σ_i`` and
their Jacobian ``J`` in the log parameters at the optimum, the covariance of the log
parameters is ``s² (JᵀJ)⁺`` with ``s² = max(1, χ²/(m - n))`` (inflated when the model misses
the data by more than the noise). The standard deviation of a log parameter is its relative
uncertainty. A parameter is flagged as not determined by the data when that relative
uncertainty exceeds :data:`UNDETERMINED_SD` (one standard deviation of more than a factor
e^0.5 = 1.65), and parameters whose estimates are correlated beyond :data:`CORRELATED` are
reported as determined only in combination.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fenicsx_drape.calibration.coupons import (
    COUPON_KINDS,
    Residuals,
    Variables,
    simulate,
    test_noise,
)
from fenicsx_drape.measurements.bundle import Test

STEP = 0.025  # the paper's +2.5 %
UNDETERMINED_SD = 0.5  # standard deviation of ln(parameter) above which it is flagged
CORRELATED = 0.98  # |correlation| above which two estimates are reported as a combination


def used_parameters(model) -> tuple[str, ...]:
    """The parameters that shape the model's coupon tests, fixed ones included."""
    return dataclasses.replace(model, fixed=()).active_parameters(COUPON_KINDS)


def table2(model, tests: Sequence[Test], names: Sequence[str] | None = None,
           step: float = STEP) -> dict[str, dict[str, dict[str, float]]]:
    """Error and force sensitivities per parameter and test kind (the paper's Table 2).

    Returns:
        ``{parameter: {kind: {"error": S_error, "force": S_force}}}``.
    """
    names = tuple(used_parameters(model) if names is None else names)
    base = np.array([float(model.parameters[n]) for n in names])
    P = np.tile(base, (len(names) + 1, 1))
    P[1:] *= 1.0 + step * np.eye(len(names))
    sets = model.with_parameters(**{n: P[:, j] for j, n in enumerate(names)})
    kinds = sorted({t.kind for t in tests})
    abs_err = {k: [] for k in kinds}
    force = {k: [] for k in kinds}
    for test in tests:
        F = np.atleast_2d(simulate(test, sets))
        abs_err[test.kind].append(np.abs(F - test.force_N))
        force[test.kind].append(F)
    out: dict[str, dict[str, dict[str, float]]] = {n: {} for n in names}
    for kind in kinds:
        E = np.concatenate(abs_err[kind], axis=1).mean(axis=1)
        M = np.concatenate(force[kind], axis=1).mean(axis=1)
        for j, n in enumerate(names):
            out[n][kind] = {"error": float((E[j + 1] - E[0]) / E[0] / step),
                            "force": float((M[j + 1] - M[0]) / M[0] / step)}
    return out


def to_csv(table: Mapping[str, Mapping[str, Mapping[str, float]]]) -> str:
    """Table 2 as CSV: ``parameter, kind, error_sensitivity, force_sensitivity``."""
    lines = ["parameter,kind,error_sensitivity,force_sensitivity"]
    for name, kinds in table.items():
        lines += [f"{name},{kind},{s['error']:.6g},{s['force']:.6g}" for kind, s in kinds.items()]
    return "\n".join(lines) + "\n"


def format_table(table: Mapping[str, Mapping[str, Mapping[str, float]]]) -> str:
    """Table 2 as aligned text, one row per parameter, error then force columns per kind."""
    kinds = sorted({k for row in table.values() for k in row})
    head = f"{'parameter':<10}" + "".join(f"{k[:8] + ' err':>14}{k[:8] + ' force':>16}"
                                          for k in kinds)
    rows = [head]
    for name, row in table.items():
        rows.append(f"{name:<10}" + "".join(
            f"{row[k]['error']:>14.3g}{row[k]['force']:>16.3g}" if k in row else " " * 30
            for k in kinds))
    return "\n".join(rows)


def uncertainty(model, tests: Sequence[Test], names: Sequence[str],
                errors: Mapping[str, Any] | None = None
                ) -> tuple[dict[str, dict[str, Any]], list[str]]:
    """Relative uncertainties of the fitted parameters and flags (see the module docstring).

    Returns:
        ``{parameter: {"value", "sd_log", "ci95", "determined", "correlated_with"}}`` and the
        flags as sentences.
    """
    if not names:
        return {}, []
    variables = Variables.make(model, names)
    res = Residuals(model, tests, variables)
    # statistical weights: 1/σ per row (the fit's 1/√n per test scaling removed)
    res.weights = [1.0 / test_noise(t)[0] for t in tests]
    x = variables.to_x(np.array([float(model.parameters[n]) for n in names]))
    r, J = res.jacobian(x)
    m, n = J.shape
    s2 = max(1.0, float(r @ r) / max(m - n, 1))
    _, sv, Vt = np.linalg.svd(J, full_matrices=False)
    tiny = sv <= sv.max() * 1e-12
    inv = np.zeros_like(sv)
    inv[~tiny] = 1.0 / sv[~tiny] ** 2
    cov = s2 * (Vt.T * inv) @ Vt
    # directions the data do not see at all count as undetermined
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    blind = (np.abs(Vt[tiny]) > 0.1).any(axis=0) if tiny.any() else np.zeros(n, dtype=bool)
    sd = np.where(blind, np.inf, sd)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    out, flags = {}, []
    for j, name in enumerate(names):
        value = float(model.parameters[name])
        partners = [names[i] for i in range(n) if i != j and np.isfinite(corr[j, i])
                    and abs(corr[j, i]) > CORRELATED]
        determined = bool(np.isfinite(sd[j]) and sd[j] <= UNDETERMINED_SD)
        if variables.log[j]:
            with np.errstate(over="ignore"):
                ci = [value * float(np.exp(-1.96 * sd[j])), value * float(np.exp(1.96 * sd[j]))]
        else:
            half = 1.96 * sd[j] * variables.scale[j]
            ci = [value - half, value + half]
        out[name] = {"value": value, "sd_log": float(sd[j]), "ci95": ci,
                     "determined": determined, "correlated_with": partners}
        if not determined:
            what = ("the tests do not respond to it" if not np.isfinite(sd[j]) else
                    f"one standard deviation is a factor {np.exp(min(sd[j], 700.0)):.3g}")
            flags.append(f"{name}: not determined by these tests ({what})"
                         + (f"; correlated with {', '.join(partners)}" if partners else ""))
        elif partners:
            flags.append(f"{name}: determined only in combination with {', '.join(partners)} "
                         f"(|correlation| > {CORRELATED})")
    return out, flags
