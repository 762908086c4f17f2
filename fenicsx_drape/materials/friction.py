"""The blank-holder friction law: a perfectly plastic bar per holder node, eq. 1.

The paper restrains each node under the blank holder with a bar fixed at its far end, elastic
then perfectly plastic with yield stress σ_y = F_tot μ / (A_f n_s) (eq. 1): F_tot the total
clamping force, μ the textile-tool friction coefficient, A_f the bar's cross-section and n_s
the number of friction bars (nodes under the holder). The cross-section only converts force
to stress, so this law works with the bar's force and elongation directly:

- ``strain``: the elongation of the friction bar in mm, i.e. the slip of the node from its
  position when it came under the holder (the paper's bar acts along the node's total
  displacement, not along the slip velocity);
- ``stress``: the bar force in N, |F| ≤ F_y = μ F_tot / n_s (= σ_y A_f);
- stiffness before sliding: F_y / ``holder_slip_mm`` (the slip at which sliding starts, so
  the stick stiffness scales with the normal force, like a regularised Coulomb law);
- state: the plastic (sliding) slip, integrated by an exact return mapping.

``holder_force_N`` (F_tot of the modelled part: a quarter model carries a quarter of the
press force) and ``holder_nodes`` (n_s) are conditions; the forming case updates them as the
sheet draws in, e.g. ``dataclasses.replace(law, holder_nodes=n)``. Without
``holder_friction`` the bars carry no force.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.materials.base import MaterialLaw, condition, effect, parameter, register_law


@register_law("paper_friction")
@dataclass
class FrictionLaw(MaterialLaw):
    """Friction bars at the blank holder (eq. 1); strain in mm, stress in N."""

    role: ClassVar[str] = "friction"
    state_names: ClassVar[tuple[str, ...]] = ("slip_p",)

    mu: float = parameter(unit="-", bounds=(0.0, 10.0),
                          doc="textile-tool friction coefficient μ of eq. 1")
    holder_slip_mm: float = parameter(unit="mm", bounds=(1e-12, math.inf),
                                      doc="slip at which a holder node starts to slide")
    holder_force_N: float = condition(133.0, unit="N",
                                      doc="clamping force F_tot on the modelled part")
    holder_nodes: float = condition(1.0, unit="-", doc="number n_s of nodes under the holder")
    holder_friction: bool = effect(doc="perfectly plastic friction bars, eq. 1")

    def __post_init__(self) -> None:
        super().__post_init__()
        if np.any(np.asarray(self.holder_force_N) < 0.0):
            raise ParameterError(f"FrictionLaw: condition holder_force_N = "
                                 f"{self.holder_force_N} N must be >= 0")
        if np.any(np.asarray(self.holder_nodes) <= 0.0):
            raise ParameterError(f"FrictionLaw: condition holder_nodes = {self.holder_nodes} "
                                 "must be > 0")

    @classmethod
    def active_parameters(cls, effects: Iterable[str] = ()) -> tuple[str, ...]:
        """``mu`` with ``holder_friction`` (the stick slip is a regularisation, not fitted)."""
        return ("mu",) if "holder_friction" in set(effects) else ()

    @property
    def yield_force_N(self) -> float | np.ndarray:
        """F_y = μ F_tot / n_s, the force at which a node slides (N); 0 without the effect."""
        if not self.holder_friction:
            return 0.0
        return self.mu * self.holder_force_N / self.holder_nodes

    def _update(self, strain, dt, state):
        F_y = self.yield_force_N
        k = F_y / self.holder_slip_mm
        trial = k * (strain - state[:, 0])
        sliding = np.abs(trial) > F_y
        force = np.where(sliding, np.sign(trial) * F_y, trial)
        slip_p = np.where(sliding, strain - force / np.where(sliding, k, 1.0), state[:, 0])
        tangent = np.where(sliding, 0.0, k + 0.0 * strain)
        return force, tangent, slip_p[:, None]
