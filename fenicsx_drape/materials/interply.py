"""Inter-ply friction of prepregs: tack, regularised Coulomb friction and a viscous film.

The shear traction between two plies sliding against each other under a normal pressure p
(prepregs slide in a mixed regime of boundary and hydrodynamic friction, Pasco et al., J.
Compos. Mater. 53 (2019) 227-243; a tack term dominates cold AS4/8552, Erland et al., Compos.
A (2015) 210-218; tool-ply friction as Coulomb plus viscous, ten Thije, ESAFORM 2008 and
Harrison et al., World J. Eng. 7 (2010) 5-22; a pull-out needs a uniform pressure, ten Thije &
Akkerman, Int. J. Mater. Form. (2009) 197-200)::

    τ = τ₀ + μ p + η_f v        (steady sliding at speed v)

- τ₀ (``tau0_MPa``): tack, a shear strength at zero pressure;
- μ (``mu_ply``): the Coulomb (boundary) coefficient;
- η_f = η / h (``eta_f_MPa_s_per_mm``): the resin film's viscosity over its thickness.

The tack and Coulomb parts are regularised over a small slip ε (``slip_mm``) as the blank
holder's eq. 1 bars are (:mod:`fenicsx_drape.materials.friction`): elastic with stiffness
k = (τ₀ + μ p)/ε up to the yield traction τ_y = τ₀ + μ p, then perfectly plastic, by an exact
return mapping in the plane of the interface (the plastic slip is the state). The film term
is η_f (s − sₙ)/Δt, the slip rate over the step. Units: traction and pressure in MPa
(N/mm²), slip in mm, time in s.

Limits: μ = τ₀ = η_f = 0 is a frictionless interface (τ = 0); without the effect
``interply_friction`` the plies are *bonded*: τ = k_b s, elastic with the stiffness
``bond_MPa_per_mm`` (no sliding).

Starting values (published ranges, not one material): μ ≈ 0.1-0.3 (Pasco et al. 2019);
η of an epoxy resin at forming temperature 10-100 Pa·s over a film of 10-20 µm gives
η_f ≈ 0.5-10 MPa·s/m = 0.0005-0.01 MPa·s/mm; τ₀ = 0 to start (Erland et al. 2015 measure a
tack term when cold).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np

from fenicsx_drape.materials.base import MaterialLaw, condition, effect, parameter

__all__ = ["InterplyLaw", "Traction"]


class Traction(NamedTuple):
    """The interface's traction and its consistent derivatives at n points."""

    tau: np.ndarray  # (n, d) shear traction on the interface (MPa), along the slip
    dtau_ds: np.ndarray  # (n, d, d) ∂τ/∂s (MPa/mm)
    dtau_dp: np.ndarray  # (n, d) ∂τ/∂p (-)
    state: np.ndarray  # (n, 2 d) new state: plastic slip, slip at the end of the step


@dataclass
class InterplyLaw(MaterialLaw):
    """τ = τ₀ + μ p + η_f v between two plies; the Coulomb part elastic-plastic over ε.

    :meth:`traction` works on slip vectors (n, d) in the interface; the scalar
    :meth:`~fenicsx_drape.materials.base.MaterialLaw.update` (strain = slip in mm, stress =
    traction in MPa) slides along one direction at the condition ``pressure_MPa``, as a
    pull-out test does.
    """

    role: ClassVar[str] = "interply"
    state_names: ClassVar[tuple[str, ...]] = ("slip_p", "slip_n")

    tau0_MPa: float = parameter(0.0, unit="MPa", bounds=(0.0, 10.0),
                                doc="tack τ₀: shear strength at zero pressure")
    mu_ply: float = parameter(0.2, unit="-", bounds=(0.0, 10.0),
                              doc="inter-ply Coulomb coefficient μ (0.1-0.3, Pasco 2019)")
    eta_f_MPa_s_per_mm: float = parameter(
        0.002, unit="MPa·s/mm", bounds=(0.0, 100.0),
        doc="film viscosity over thickness η_f = η/h (0.0005-0.01 MPa·s/mm)")
    slip_mm: float = parameter(0.1, unit="mm", bounds=(1e-9, math.inf),
                               doc="slip ε over which τ₀ + μp is reached (regularisation)")
    bond_MPa_per_mm: float = parameter(1e4, unit="MPa/mm", bounds=(1e-9, math.inf),
                                       doc="stiffness of bonded plies (without the effect)")
    pressure_MPa: float = condition(0.0, unit="MPa",
                                    doc="normal pressure of the scalar update (a pull-out)")
    interply_friction: bool = effect(doc="plies slide under τ₀ + μp + η_f v; else bonded")

    def __post_init__(self) -> None:
        super().__post_init__()
        if np.any(np.asarray(self.pressure_MPa) < 0.0):
            from fenicsx_drape.errors import ParameterError

            raise ParameterError(f"InterplyLaw: condition pressure_MPa = {self.pressure_MPa} "
                                 "must be >= 0")

    def yield_traction(self, pressure: np.ndarray) -> np.ndarray:
        """τ_y = τ₀ + μ p (MPa), the traction at which the plies slide (slowly)."""
        return self.tau0_MPa + self.mu_ply * np.asarray(pressure, dtype=float)

    def initial_state(self, n: int, dim: int = 1) -> np.ndarray:
        """Zero plastic slip and slip for ``n`` points of a ``dim``-dimensional interface."""
        return np.zeros((n, 2 * dim))

    def traction(self, slip: np.ndarray, pressure: np.ndarray, dt: float,
                 state: np.ndarray) -> Traction:
        """Traction (n, d) at the slip vectors ``slip`` (n, d) and pressures (n,) ≥ 0.

        Args:
            slip: Relative tangential displacement of the two plies since contact (mm).
            pressure: Normal pressure (MPa), ≥ 0.
            dt: Step length (s); 0 switches the film term off.
            state: (n, 2 d) plastic slip and slip of the last converged step.

        Returns:
            The traction, ∂τ/∂s, ∂τ/∂p and the new state (:class:`Traction`).

        Raises:
            ValueError: on non-finite input, a negative pressure or a wrong state shape.
        """
        s = np.asarray(slip, dtype=float)
        p = np.asarray(pressure, dtype=float)
        state = np.asarray(state, dtype=float)
        if s.ndim != 2:
            raise ValueError(f"InterplyLaw.traction: slip must be shaped (n, d), got {s.shape}")
        n, d = s.shape
        if p.shape != (n,) or state.shape != (n, 2 * d):
            raise ValueError(f"InterplyLaw.traction: pressure shaped {p.shape} and state "
                             f"{state.shape}, expected ({n},) and ({n}, {2 * d})")
        if not (np.isfinite(s).all() and np.isfinite(p).all()):
            raise ValueError("InterplyLaw.traction: slip or pressure is not finite")
        if (p < 0.0).any():
            raise ValueError(f"InterplyLaw.traction: negative pressure {p.min()} MPa")
        if not (math.isfinite(dt) and dt >= 0.0):
            raise ValueError(f"InterplyLaw.traction: time step dt = {dt} s must be >= 0")
        s_p, s_n = state[:, :d], state[:, d:]
        eye = np.broadcast_to(np.eye(d), (n, d, d))
        if not self.interply_friction:  # bonded: elastic, no sliding
            k_b = self.bond_MPa_per_mm
            return Traction(k_b * s, k_b * eye.copy(), np.zeros((n, d)),
                            np.concatenate([np.zeros((n, d)), s], axis=1))
        τ_y = np.broadcast_to(self.yield_traction(p), (n,))
        k = τ_y / self.slip_mm
        elastic = s - s_p
        trial = k[:, None] * elastic
        size = np.linalg.norm(trial, axis=1)
        sliding = size > τ_y
        t̂ = trial / np.where(sliding, size, 1.0)[:, None]
        τ = np.where(sliding[:, None], τ_y[:, None] * t̂, trial)
        s_p_new = np.where(sliding[:, None], s - τ / np.where(k > 0, k, 1.0)[:, None], s_p)
        # Stick: k I and ∂k/∂p e; slide: τ_y/|e| (I − t̂t̂) and μ t̂.
        e_norm = np.linalg.norm(elastic, axis=1)
        slide_k = τ_y / np.where(sliding, e_norm, 1.0)
        dτ_ds = np.where(sliding[:, None, None],
                         slide_k[:, None, None] * (eye - np.einsum("ni,nj->nij", t̂, t̂)),
                         k[:, None, None] * eye)
        dτ_dp = np.where(sliding[:, None], self.mu_ply * t̂,
                         (self.mu_ply / self.slip_mm) * elastic)
        if dt > 0.0 and self.eta_f_MPa_s_per_mm:
            c = self.eta_f_MPa_s_per_mm / dt
            τ = τ + c * (s - s_n)
            dτ_ds = dτ_ds + c * eye
        return Traction(τ, dτ_ds, dτ_dp, np.concatenate([s_p_new, s], axis=1))

    def _update(self, strain, dt, state):
        p = np.broadcast_to(np.asarray(self.pressure_MPa, dtype=float), strain.shape)
        out = self.traction(strain[:, None], p, dt, state)
        return out.tau[:, 0], out.dtau_ds[:, 0, 0], out.state
