"""Numerical stabilisation of the flat, slack sheet: a spring to the extrapolated motion.

A flat pin-jointed net has no stiffness out of its plane, and where tows buckle (eq. 4) or the
sheet hangs slack between punch and holder it has mechanisms; a static Newton solve then
stalls (``shared/NUMERICS.md``; here at 13.6 mm of travel without it, with or without the
die, with or without ``tow_buckling``). The FE core's tow bending (``tow_bending_EI_Nmm2``)
does not carry the run through the closing die either.

A pseudo-viscous drag ``c (x − x_n)`` towards the last converged positions does, but it
resists *all* motion: the sheet is drawn in by up to 45 mm, ~1 mm per step, so the drag is a
force of c × 1 mm per node where the holder's friction is ≈ 0.1 N per node, and it set the
results (c = 2.5 → 1.25 N/mm moved the total wrinkling from 0.45 % to 0.72 %).

This term ties each node instead to its *extrapolated* position,

    f = −c d (d·(x − x̂)),   x̂ = x_n + (x_n − x_{n−1}) (t − t_n) / (t_n − t_{n−1}),   K = c d⊗d,

(x̂ = x_n in the first step) along one direction ``d`` per node out of the sheet's plane
(the nearest tool's normal, evaluated at x̂ once per step). It adds stiffness where the net
has none, but its force vanishes for motion at constant velocity and is of order c a Δt²
for accelerating nodes (a pseudo-inertia of mass c Δt²). Acting in all three directions it
still biased the in-plane shear, whose stiffness (a few N/mm per node) is of the order of c:
max shear 38° at c = 1.25 N/mm against 51° at c = 5. Out of the plane only, halving c from
1.25 to 0.625 N/mm moves the nodes by 0.006 mm on average (0.06 mm at most), the maximum
shear by 0.02° and the total wrinkling by 0.001 % (``demos/study_stabilisation.py``). It is
part of the model: a case's ``stabilisation_N_per_mm``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fenicsx_drape.errors import ParameterError


class ExtrapolationSpring:
    """Spring of stiffness ``c`` (N/mm) per node to its extrapolated position (a NodalTerm).

    Args:
        stiffness_N_per_mm: The spring stiffness ``c``.
        direction: Optional map ``(x̂, t) -> d`` of unit vectors (n, 3): the spring then acts
            along ``d`` only (f = −c d (d·(x − x̂))), e.g. out of the sheet's plane. It is
            evaluated at the extrapolated positions, so it is fixed within a step and the
            force stays linear in ``x``. Default: all three directions.
    """

    def __init__(self, stiffness_N_per_mm: float,
                 direction: Callable[[np.ndarray, float], np.ndarray] | None = None) -> None:
        if not (np.isfinite(stiffness_N_per_mm) and stiffness_N_per_mm >= 0.0):
            raise ParameterError(f"stabilisation stiffness {stiffness_N_per_mm} N/mm must be "
                                 ">= 0")
        self.c = float(stiffness_N_per_mm)
        self.direction = direction

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """Start from rest at the reference positions."""
        self._x = [np.array(X, dtype=float)] * 2  # x_{n-1}, x_n
        self._t = [None, 0.0]
        self._trial: tuple[np.ndarray, float] | None = None
        self._d: tuple[float, np.ndarray] | None = None

    def predicted(self, t: float) -> np.ndarray:
        """The extrapolated positions x̂ at time ``t``."""
        (x_m, x_n), (t_m, t_n) = self._x, self._t
        if t_m is None or t_n <= t_m:
            return x_n
        return x_n + (x_n - x_m) * ((t - t_n) / (t_n - t_m))

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Spring force (N) towards x̂ and its stiffness c I (N/mm)."""
        self._trial = (np.array(x, dtype=float), t)
        x̂ = self.predicted(t)
        if self.direction is None:
            return -self.c * (x - x̂), np.broadcast_to(self.c * np.eye(3), (len(x), 3, 3))
        if self._d is None or self._d[0] != t:  # the direction is fixed within a step
            self._d = (t, self.direction(x̂, t))
        d = self._d[1]
        f = -self.c * np.einsum("ni,ni->n", d, x - x̂)[:, None] * d
        return f, self.c * np.einsum("ni,nj->nij", d, d)

    def commit(self) -> None:
        """The converged step becomes the last one of the extrapolation."""
        if self._trial is not None:
            self._x = [self._x[1], self._trial[0]]
            self._t = [self._t[1], self._trial[1]]
            self._trial = None

    def revert(self) -> None:
        """Forget the trial of a step that is cut back."""
        self._trial = None
