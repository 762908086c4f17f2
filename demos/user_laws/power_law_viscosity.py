# # A user shear law: power-law (shear-thinning) viscosity
#
# This file is written as a user of fenicsx_drape would write it, outside the package and
# with its public API only. It registers the law ``"power_law_viscosity"``: the paper's shear
# diagonal (elastic-plastic branch in parallel with a Maxwell branch, eqs. 5-9) whose dashpot
# viscosity also follows a power law of its strain rate,
#
#     η = η_o f(|ε_v|) |ε̇_v / ε̇_ref|^(n−1),
#
# with f the lock-up factor of eq. 8 (loading; 1 in unloading). With n < 1 the resin is
# shear-thinning: the viscous stress grows like ε̇^n instead of ε̇, which the package's law
# cannot follow. With n = 1 the law is the package's ``paper_shear`` with rate dependence and
# strain-dependent viscosity.
#
# Use it by naming it in a model (MODEL.toml)::
#
#     effects = ["power_law_viscosity", "decrimping", "tow_buckling"]
#     plugins = ["power_law_viscosity.py"]
#     [parameters]
#     n_power = 0.5
#
# It then replaces the built-in shear law everywhere: unit-cell tests, fitting, the FE solver.

from dataclasses import dataclass

import numpy as np

from fenicsx_drape.materials import MaterialLaw, parameter, register_law


@register_law("power_law_viscosity")
@dataclass
class PowerLawViscosityShear(MaterialLaw):
    """Shear diagonal whose dashpot viscosity follows a power law of its strain rate.

    Stress and moduli in N/tow, viscosity in N·s/tow. Integration: return mapping for the
    slider; backward Euler for the dashpot, x − a = Δt ε̇_ref sign(σ_v) (|σ_v|/(η ε̇_ref))^(1/n)
    with σ_v = E_v (ε − x) and η = η(x) taken at the end of the step, solved by a bracketed
    Newton iteration (the residual is increasing in x); the tangent follows from the implicit
    function theorem. Loading (η = η_o f) when the dashpot moves away from zero.
    """

    role = "shear"
    state_names = ("eps_p", "eps_v")

    sigma_o: float = parameter(unit="N/tow", doc="yield stress of the elastic-plastic branch")
    eta_o: float = parameter(unit="N·s/tow", bounds=(1e-12, np.inf),
                             doc="viscosity at the reference rate and zero viscous strain")
    s_o: float = parameter(unit="-", doc="slope of η/η_o at small viscous strain")
    s_inf: float = parameter(unit="-", doc="slope of η/η_o at large viscous strain")
    alpha_v: float = parameter(unit="-", bounds=(1e-12, np.inf), doc="transition breadth⁻¹")
    eps_v_bar: float = parameter(unit="-", doc="viscous strain of the transition")
    E_v: float = parameter(unit="N/tow", doc="Maxwell spring modulus")
    E_p: float = parameter(unit="N/tow", bounds=(1e-12, np.inf), doc="elastic-plastic modulus")
    rate_ref_per_s: float = parameter(unit="1/s", bounds=(1e-12, np.inf),
                                      doc="reference strain rate of the power law")
    n_power: float = parameter(0.5, unit="-", bounds=(0.05, 1.0),
                               doc="power-law exponent (1: Newtonian, < 1: shear-thinning)")

    @classmethod
    def active_parameters(cls, effects=()):
        # η_o and ε̇_ref only appear as η_o ε̇_ref^(1-n): fit η_o, keep the reference rate.
        return tuple(n for n in super().active_parameters(effects) if n != "rate_ref_per_s")

    def _lockup(self, y):
        """f(y) of eq. 8 and f'(y), written overflow-safe with logaddexp."""
        z = self.alpha_v * (y - self.eps_v_bar)
        soft = np.logaddexp(0.0, z) - np.logaddexp(0.0, -self.alpha_v * self.eps_v_bar)
        f = 1.0 + self.s_o * y + (self.s_inf - self.s_o) / self.alpha_v * soft
        return f, self.s_o + (self.s_inf - self.s_o) / (1.0 + np.exp(-np.clip(z, -700, 700)))

    def _update(self, strain, dt, state):
        ε, ε_p, a = strain, state[:, 0], state[:, 1]
        # Elastic-plastic branch (return mapping).
        trial = self.E_p * (ε - ε_p)
        plastic = np.abs(trial) > self.sigma_o
        σ_ep = np.where(plastic, np.sign(trial) * self.sigma_o, trial)
        ε_p = np.where(plastic, ε - σ_ep / self.E_p, ε_p)
        tangent = np.where(plastic, 0.0, self.E_p)
        # Dashpot: root x of R(x) = x − a − g(σ_v(x), η(x)) in the bracket [a, ε].
        s = np.sign(ε - a)
        lo, hi = np.minimum(a, ε), np.maximum(a, ε)
        x = a + 0.0 * ε
        for _ in range(200):
            R, R_x, _ = self._residual(x, ε, a, s, dt)
            lo = np.where(R < 0.0, x, lo)
            hi = np.where(R > 0.0, x, hi)
            x_new = x - R / R_x
            x_new = np.where((x_new >= lo) & (x_new <= hi), x_new, 0.5 * (lo + hi))
            if np.all(np.abs(x_new - x) <= 1e-15 * (1.0 + np.abs(x))):
                break
            x = x_new
        _, R_x, loading_term = self._residual(x, ε, a, s, dt)
        σ_v = self.E_v * (ε - x)
        tangent = tangent + self.E_v * (1.0 + loading_term) / R_x
        return σ_ep + σ_v, tangent, np.stack([ε_p + 0.0 * ε, x], axis=1)

    def _residual(self, x, ε, a, s, dt):
        """R, dR/dx and the viscosity term (g/(nη)) dη/dx of the dashpot residual."""
        n, rate = self.n_power, self.rate_ref_per_s
        loading = x * s > 0.0
        f, df = self._lockup(np.abs(x))
        η = self.eta_o * np.where(loading, f, 1.0)
        dη = self.eta_o * np.where(loading, df * np.sign(x), 0.0)
        σ = self.E_v * (ε - x)
        ratio = np.abs(σ) / (η * rate)
        g = dt * rate * np.sign(σ) * ratio ** (1.0 / n)
        g_σ = dt / (n * η) * ratio ** (1.0 / n - 1.0)  # ∂g/∂σ, finite for n <= 1
        loading_term = g * dη / (n * η)
        return x - a - g, 1.0 + self.E_v * g_σ + loading_term, loading_term
