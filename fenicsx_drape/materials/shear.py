"""The shear-diagonal law: elastic-viscoplastic with strain-dependent viscosity, eqs. 5-9.

Rheology (Fig. 2a): an elastic-plastic branch (spring ``E_p`` in series with a slider of
yield stress ``σ_o``, plastic strain ε_p) in parallel with a Maxwell branch (spring ``E_v``
in series with a dashpot of viscosity η, dashpot strain ε_v)::

    σ = σ_ep + σ_v,   σ_ep = E_p (ε − ε_p), |σ_ep| ≤ σ_o,   σ_v = E_v (ε − ε_v) = η ε̇_v.

Summing the branches gives the paper's eq. 6 (elastic: σ + σ̇ η/E_v = E_p ε^ve +
(E_p + E_v)/E_v η ε̇, with η/E_v where the text prints η/E_p, see NOTES.md) and eq. 7 (plastic
flow: σ + σ̇ η/E_v = ±σ_o + η ε̇); eq. 9 is ε_v = ε − σ_v/E_v. Tension and compression are
symmetric. Stresses are forces per tow (N/tow), strains Green-Lagrange.

Viscosity, eq. 8 (corrected per NOTES.md: the linear coefficient is ``s_∞`` and the log
coefficient ``(s_o − s_∞)/α_v``, so the slope of η/η_o is ``s_o`` at small and ``s_∞`` at
large |ε_v|, as the text under eq. 9 says; evaluated overflow-safe)::

    η = η_o f(|ε_v|)  when the dashpot is loading,   η = η_o  when it is unloading,
    f(y) = 1 + s_o y + (s_∞ − s_o)/α_v [softplus(α_v(y − ε̄_v)) − softplus(−α_v ε̄_v)].

*Loading condition (our choice).* Eq. 8 switches on the sign of ε_v·ε̇ without saying whose
rate. We take the dashpot's own rate: loading when ε_v ε̇_v > 0, i.e. the dashpot moves away
from its origin (equivalently σ_v has the sign of ε_v, since ε̇_v = σ_v/η). Reasons: it is
the strain of the element whose viscosity it is; it is a function of the state, so it is
defined at ε̇ = 0; and it gives the behaviour of Fig. 2b: during a hold (ε̇ = 0) the dashpot
keeps extending, so the stress relaxes with the time constant η(ε_v)/E_v of the loading
branch (long at large strain) towards the elastic-plastic level; on reloading the
stiff Maxwell spring raises the stress at once; on unloading σ_v changes sign after a short
elastic stretch, the dashpot then moves back with η_o and the stress falls quickly to the
compressive yield −σ_o of the elastic-plastic branch.

*Integration (unconditionally stable).* Each step integrates the rheology directly:
exact return mapping for the slider (backward Euler of a rate-independent branch), and
backward Euler for the dashpot with the viscosity taken at the end of the step,

    η(ε_v) (ε_v − ε_v,n) = Δt E_v (ε − ε_v).

The left side is continuous and strictly increasing in ε_v (η ≥ η_o > 0; f(0) = 1 joins the
branches), so the root is unique for every Δt: the unloading branch has it in closed form,
the loading branch is solved by Newton's method started from the explicit-η estimate (an
upper bound: monotone convergence when s_∞ ≥ s_o makes f convex; bracketed otherwise). The
consistent tangent follows from the implicit function theorem on that residual:
dσ_v/dε = E_v D / (D + Δt E_v) with D = η + η' (ε_v − ε_v,n). With Δt = 0 the Maxwell branch
is elastic (dashpot locked).

*Without* ``rate_dependence`` (the measurement spec's rate-independent limit): no Maxwell
branch; the diagonal is the elastic-plastic branch plus a non-linear elastic lock-up term of
the eq. 8 shape in the total strain, σ_lock = η_o ε̇_ref (f(|ε|) − 1) sign(ε): the stress the
viscous branch would add, beyond its constant part, at the reference rate ``rate_ref_per_s``
with ε_v ≈ ε. It vanishes without ``strain_dependent_viscosity`` (f = 1): a rate-independent
model can lock up only with that effect, and it cannot depend on rate.

``temperature_dependence``: an Arrhenius factor on the viscosity amplitude,
η_o(T) = η_o exp(E_a/R (1/T − 1/T_ref)) with T_ref = 20 °C (:data:`T_REF_C`), T from the
test condition ``temperature_C``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.materials.base import MaterialLaw, condition, effect, parameter, register_law
from fenicsx_drape.materials.bilinear import smooth_bilinear

T_REF_C = 20.0
"""Reference temperature of the Arrhenius factor (°C): Table 2 holds at room temperature."""

R_GAS = 8.314462618e-3
"""Gas constant in kJ/(mol·K)."""

_MAX_ITERATIONS = 60


@register_law("paper_shear")
@dataclass
class ShearLaw(MaterialLaw):
    """Shear diagonals, eqs. 5-9 (see the module docstring for the scheme and choices)."""

    role: ClassVar[str] = "shear"
    state_names: ClassVar[tuple[str, ...]] = ("eps_p", "eps_v")

    sigma_o: float = parameter(unit="N/tow", bounds=(0.0, math.inf),
                               doc="yield stress of the elastic-plastic branch (eq. 7)")
    eta_o: float = parameter(unit="N·s/tow", bounds=(1e-12, math.inf),
                             doc="viscosity amplitude (eq. 8)")
    s_o: float = parameter(unit="-", bounds=(0.0, math.inf),
                           doc="slope of η/η_o at small viscous strain (eq. 8)")
    s_inf: float = parameter(unit="-", bounds=(0.0, math.inf),
                             doc="slope of η/η_o at large viscous strain (eq. 8)")
    alpha_v: float = parameter(unit="-", bounds=(1e-12, math.inf),
                               doc="inverse breadth of the viscosity transition (eq. 8)")
    eps_v_bar: float = parameter(unit="-", bounds=(0.0, math.inf),
                                 doc="viscous strain of the viscosity transition (eq. 8)")
    E_v: float = parameter(unit="N/tow", bounds=(0.0, math.inf),
                           doc="spring modulus of the Maxwell branch")
    E_p: float = parameter(unit="N/tow", bounds=(1e-12, math.inf),
                           doc="spring modulus of the elastic-plastic branch")
    Ea_kJ_per_mol: float = parameter(unit="kJ/mol", bounds=(0.0, 1000.0),
                                     doc="activation energy of the viscosity (Arrhenius)")
    rate_ref_per_s: float = parameter(unit="1/s", bounds=(1e-12, math.inf),
                                      doc="reference strain rate of the rate-independent "
                                          "lock-up term (used without rate_dependence)")
    temperature_C: float = condition(T_REF_C, unit="°C", doc="test temperature")
    rate_dependence: bool = effect(doc="Maxwell branch with a dashpot, eqs. 5-7")
    strain_dependent_viscosity: bool = effect(doc="viscosity grows with viscous strain, eq. 8")
    temperature_dependence: bool = effect(doc="Arrhenius factor on the viscosity")

    def __post_init__(self) -> None:
        super().__post_init__()
        if np.any(np.asarray(self.temperature_C) <= -273.15):
            raise ParameterError(f"ShearLaw: condition temperature_C = {self.temperature_C} °C "
                                 "is not above absolute zero")

    @classmethod
    def active_parameters(cls, effects: Iterable[str] = ()) -> tuple[str, ...]:
        """The parameters that shape the response with these effects (see the module doc).

        Without ``rate_dependence`` the lock-up amplitude is η_o ε̇_ref (s_o, s_∞), so η_o and
        the reference rate are a fixed scale and only s_o, s_∞ are fitted.
        """
        effects = set(effects)
        names = ["sigma_o", "E_p"]
        if "rate_dependence" in effects:
            names += ["eta_o", "E_v"]
        if "strain_dependent_viscosity" in effects:
            names += ["s_o", "s_inf", "alpha_v", "eps_v_bar"]
        acts = "rate_dependence" in effects or "strain_dependent_viscosity" in effects
        if "temperature_dependence" in effects and acts:
            names.append("Ea_kJ_per_mol")
        return tuple(names)

    def viscosity_factor(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """f(y) of eq. 8 and f'(y) for y = |ε_v| ≥ 0 (1 and 0 without the effect)."""
        if not self.strain_dependent_viscosity:
            return np.ones_like(y), np.zeros_like(y)
        g, slope = smooth_bilinear(y, self.s_o, self.s_inf, self.eps_v_bar, self.alpha_v)
        return 1.0 + g, slope

    def viscosity_amplitude(self) -> float | np.ndarray:
        """η_o at the test temperature (N·s/tow)."""
        if not self.temperature_dependence:
            return self.eta_o
        T, T_ref = self.temperature_C + 273.15, T_REF_C + 273.15
        return self.eta_o * np.exp(self.Ea_kJ_per_mol / R_GAS * (1.0 / T - 1.0 / T_ref))

    def _update(self, strain, dt, state):
        ε = strain
        ε_p, ε_v = state[:, 0], state[:, 1]
        # Elastic-plastic branch: exact return mapping of the slider.
        trial = self.E_p * (ε - ε_p)
        plastic = np.abs(trial) > self.sigma_o
        σ_ep = np.where(plastic, np.sign(trial) * self.sigma_o, trial)
        ε_p = np.where(plastic, ε - σ_ep / self.E_p, ε_p)
        tangent = np.where(plastic, 0.0, self.E_p)
        η_o = self.viscosity_amplitude()
        if self.rate_dependence:
            ε_v, D = self._dashpot(ε, dt, ε_v, η_o)
            σ_v = self.E_v * (ε - ε_v)
            tangent = tangent + self.E_v * D / (D + dt * self.E_v)
        else:
            f, df = self.viscosity_factor(np.abs(ε))
            scale = η_o * self.rate_ref_per_s
            σ_v = scale * (f - 1.0) * np.sign(ε)
            tangent = tangent + scale * df
            ε_v = ε_v + 0.0 * ε
        return σ_ep + σ_v, tangent, np.stack([ε_p + 0.0 * ε, ε_v], axis=1)

    def _dashpot(self, ε, dt, a, η_o):
        """Backward Euler of the dashpot: ε_v at the end of the step and D = ∂(η·Δε_v)/∂ε_v."""
        k = dt * self.E_v
        # Unloading branch (η = η_o), in closed form.
        x = (η_o * a + k * ε) / (η_o + k)
        D = η_o + 0.0 * ε
        loading = x * (x - a) > 0.0
        if not (self.strain_dependent_viscosity and loading.any()):
            return x, D
        # Loading branch in y = |ε_v| along the direction s of motion: φ(y) = 0 with
        # φ(y) = η_o f(y) (y − b) + k (y − e), root in [max(b, 0), y_0].
        s = np.where(loading, np.sign(x), 0.0)
        b, e = s * a, s * ε
        lo = np.maximum(b, 0.0)
        f_lo, _ = self.viscosity_factor(lo)
        hi = np.maximum((η_o * f_lo * b + k * e) / (η_o * f_lo + k), lo)
        y = hi
        # φ is convex when f is (s_∞ ≥ s_o: lock-up stiffens), and Newton from the upper
        # bound then converges monotonically; otherwise it is kept inside the bracket.
        bracketed = not np.all(self.s_inf >= self.s_o)
        for _ in range(_MAX_ITERATIONS):
            f, df = self.viscosity_factor(y)
            y_b = y - b
            φ = η_o * f * y_b + k * (y - e)
            D_y = η_o * (f + df * y_b)
            step = φ / (D_y + k)
            if np.all(np.abs(step) <= 1e-8 * (1.0 + y)):
                y = y - step  # Newton converges quadratically: its error is now ~step²
                break
            if bracketed:
                lo = np.where(φ < 0.0, y, lo)
                hi = np.where(φ > 0.0, y, hi)
                y_new = y - step
                y = np.where((y_new >= lo) & (y_new <= hi), y_new, 0.5 * (lo + hi))
            else:
                y = y - step
        return np.where(loading, s * y, x), np.where(loading, D_y, D)
