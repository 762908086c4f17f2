"""The inter-ply law fitted to inter-ply friction tests (``kind = "interply_friction"``).

A test (measurement spec, version 4) pulls one ply between two others (pull-out, two
interfaces) or over one (pull-through) under a normal pressure p and records the pulling force
against the ply's displacement relative to the held plies. It is simulated with the law's
scalar update (:class:`~fenicsx_drape.materials.interply.InterplyLaw`) along the measured
history: the slip is the displacement, the pressure the test's (or its ``pressure_kPa``
column), and the force

    F = n A τ(s, p, v),   A = contact_length_mm × contact_width_mm,

with n the interfaces. The overlap is taken as constant, ``contact_length_mm`` as given (a
pulled ply longer than the pressure plates under a uniform pressure, as ten Thije & Akkerman,
Int. J. Mater. Form. (2009) 197-200 ask of a pull-out); the spec reads it as the overlap at
zero displacement.

The fit is a bounded least squares over τ₀, μ and η_f (the slip ε stays the law's: a
regularisation), each residual over the row's noise (``force_sd_N``, a declared noise, else
1 % of the test's peak force). What the tests cannot tell apart is held and said: τ₀ and μ need
two pressures, η_f two speeds.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.materials.base import fields_of
from fenicsx_drape.materials.interply import InterplyLaw

__all__ = ["InterplyFit", "fit_interply", "simulate_interply"]

FITTED = ("tau0_MPa", "mu_ply", "eta_f_MPa_s_per_mm")


def simulate_interply(test, law: InterplyLaw) -> np.ndarray:
    """The pulling force (N) of an ``interply_friction`` test along its history."""
    setup = test.interply
    area = setup["contact_length_mm"] * setup["contact_width_mm"]
    column = test.column("pressure_kPa")
    p = 1e-3 * (column if column is not None else np.full(len(test.time_s),
                                                           setup["pressure_kPa"]))
    t, d = test.time_s, test.displacement_mm
    state = law.initial_state(1)
    force = np.zeros(len(t))
    for k in range(len(t)):  # the law's traction at the row's pressure (one point, one axis)
        dt = float(t[k] - t[k - 1]) if k else 0.0
        out = law.traction(np.array([[d[k]]]), p[k:k + 1], dt, state)
        state = out.state
        force[k] = setup["interfaces"] * area * out.tau[0, 0]
    return force


def _noise(test) -> np.ndarray:
    """One standard deviation of every row's force (N)."""
    if test.force_sd_N is not None:
        return np.maximum(test.force_sd_N, 1e-12)
    peak = max(float(np.max(np.abs(test.force_N))), 1e-12)
    if test.noise_sd_N is not None:
        return np.full(len(test.force_N), test.noise_sd_N)
    rel = test.noise_rel if test.noise_rel is not None else 0.01
    return np.full(len(test.force_N), rel * peak)


@dataclasses.dataclass
class InterplyFit:
    """The fitted inter-ply law and how well it meets each test."""

    law: InterplyLaw
    rms_N: dict[str, float]  # RMS force error of each test (N)
    normalised: float  # RMS of the residuals over their noise (1 = the noise floor)
    held: dict[str, str]  # parameters the tests cannot determine, and why

    def report(self) -> dict:
        """The fit as plain data (``interply.json``)."""
        return {"parameters": {n: float(getattr(self.law, n)) for n in FITTED},
                "slip_mm": self.law.slip_mm, "rms_N": self.rms_N,
                "normalised_error": self.normalised, "held": self.held}

    def toml(self) -> str:
        """An ``[interply]`` table for a case file."""
        from fenicsx_drape.provenance import toml_text

        values = {n: float(getattr(self.law, n)) for n in FITTED}
        return toml_text({"interply": {**values, "slip_mm": float(self.law.slip_mm)}})


def fit_interply(tests: Sequence, start: InterplyLaw | None = None, *,
                 parameters: Sequence[str] | None = None,
                 noise: Sequence[np.ndarray] | None = None,
                 max_evaluations: int | None = None) -> InterplyFit:
    """Fit τ₀, μ and η_f to ``interply_friction`` tests (module docstring).

    Args:
        tests: The tests (other kinds are ignored).
        start: The law to start from (its other values are kept); InterplyLaw's defaults
            when None.
        parameters: Only these of :data:`FITTED` (the others held at ``start``'s); all when
            None.
        noise: Each test's row sd (N), in the order of the interply_friction tests among
            ``tests`` (``inf``: a row without weight); the module's noise when None.
        max_evaluations: Cap on the least-squares' residual evaluations (its default: None).

    Raises:
        DrapeInputError: no interply_friction test among ``tests``.
    """
    from scipy.optimize import least_squares

    tests = [t for t in tests if t.kind == "interply_friction"]
    if not tests:
        raise DrapeInputError("no interply_friction test to fit")
    start = start or InterplyLaw()
    pressures = {round(t.interply["pressure_kPa"], 9) for t in tests}
    speeds = {round(float(np.max(np.abs(np.gradient(t.displacement_mm, t.time_s)))), 6)
              for t in tests if len(t.time_s) > 1}
    held = {}
    if len(pressures) < 2:
        held["tau0_MPa"] = "one pressure: tack and Coulomb friction are not told apart"
    if len(speeds) < 2:
        held["eta_f_MPa_s_per_mm"] = "one speed: the film term is not told from the rest"
    names = [n for n in FITTED if n not in held and (parameters is None or n in parameters)]
    bounds = {f.name: f.metadata["bounds"] for f in fields_of(InterplyLaw, "parameter")}
    # Scales: the published orders of each parameter (materials/interply.py).
    scale = {"tau0_MPa": 0.01, "mu_ply": 0.1, "eta_f_MPa_s_per_mm": 0.001}
    x0 = np.array([max(getattr(start, n), 1e-3 * scale[n]) / scale[n] for n in names])
    lo = np.array([bounds[n][0] / scale[n] for n in names])
    hi = np.array([bounds[n][1] / scale[n] for n in names])
    noise = [_noise(t) for t in tests] if noise is None else [np.asarray(s) for s in noise]

    def law_at(x) -> InterplyLaw:
        return dataclasses.replace(start, **{n: float(v * scale[n]) for n, v in zip(names, x)})

    def residuals(x) -> np.ndarray:
        law = law_at(x)
        return np.concatenate([(simulate_interply(t, law) - t.force_N) / s
                               for t, s in zip(tests, noise)])

    if names:
        solution = least_squares(residuals, np.clip(x0, lo, hi), bounds=(lo, hi), x_scale=1.0,
                                 max_nfev=max_evaluations)
        law, r = law_at(solution.x), solution.fun
    else:  # nothing the tests can move: the start, judged
        law, r = start, residuals(np.array([]))
    rms = {t.id: float(np.sqrt(np.mean((simulate_interply(t, law) - t.force_N) ** 2)))
           for t in tests}
    return InterplyFit(law, rms, float(np.sqrt(np.mean(r**2))), held)
