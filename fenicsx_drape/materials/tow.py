"""The tow law: non-linear elastic decrimping, eqs. 2-4.

A tow bar carries σ_t = G(ε_t) (eq. 2), with ε_t the Green-Lagrange strain and σ_t the force
per tow in N/tow. With ``decrimping`` G is eq. 3, the smooth bilinear curve of slope ``E_o``
at small strain (undulation and tow compression) and ``E_∞`` above the transition strain
``ε̄`` (the fibres), breadth ∝ 1/α; it is evaluated overflow-safe (see
:mod:`~fenicsx_drape.materials.bilinear`). Without ``decrimping`` the tow is linear with
modulus ``E_∞``. Note that G'(0) = E_o + (E_∞ − E_o)/(1 + e^{αε̄}) ≈ E_o only when αε̄ ≫ 1
(Table 2: αε̄ = 19).

Compression: with ``tow_buckling`` a compressed tow is deactivated, G = 0 for ε_t < 0 (eq. 4;
wrinkling by tow buckling). A tow at exactly ε_t = 0 counts as active (reactivation "by the
existence of tensile strain"), so its tangent there is the tension slope. Without
``tow_buckling`` the compression branch mirrors tension, G(−ε) = −G(ε) (measurement spec),
which is C¹ at 0.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from fenicsx_drape.materials.base import MaterialLaw, effect, parameter, register_law
from fenicsx_drape.materials.bilinear import smooth_bilinear


@register_law("paper_tow")
@dataclass
class TowLaw(MaterialLaw):
    """Tow bars (warp and weft), eqs. 2-4. Stateless; ``dt`` is not used."""

    role: ClassVar[str] = "tow"
    state_names: ClassVar[tuple[str, ...]] = ()

    E_o: float = parameter(unit="N/tow", bounds=(0.0, math.inf),
                           doc="decrimping modulus: slope of eq. 3 at small strain")
    E_inf: float = parameter(unit="N/tow", bounds=(0.0, math.inf),
                             doc="tow modulus: slope of eq. 3 above the transition strain")
    eps_bar: float = parameter(unit="-", bounds=(0.0, 1.0),
                               doc="transition strain ε̄ of eq. 3")
    alpha: float = parameter(unit="-", bounds=(1e-12, math.inf),
                             doc="inverse breadth α of the transition of eq. 3")
    decrimping: bool = effect(doc="non-linear (smooth bilinear) tow law, eq. 3")
    tow_buckling: bool = effect(doc="tows carry no compression, eq. 4")

    @classmethod
    def active_parameters(cls, effects: Iterable[str] = ()) -> tuple[str, ...]:
        """``E_inf``, plus ``E_o, eps_bar, alpha`` with ``decrimping``."""
        return ("E_o", "E_inf", "eps_bar", "alpha") if "decrimping" in set(effects) else ("E_inf",)

    def _update(self, strain, dt, state):
        y = np.abs(strain)
        if self.decrimping:
            g, slope = smooth_bilinear(y, self.E_o, self.E_inf, self.eps_bar, self.alpha)
        else:
            g, slope = self.E_inf * y, self.E_inf + 0.0 * y
        stress = np.sign(strain) * g
        if self.tow_buckling:
            buckled = strain < 0.0
            stress = np.where(buckled, 0.0, stress)
            slope = np.where(buckled, 0.0, slope)
        return stress, slope, np.empty((strain.shape[0], 0))
