"""The blank holder as a nodal term: clamping in z and the friction bars of eq. 1.

Two plates at z = 0 with a circular opening of radius R_o clamp the sheet. Every node whose
distance from the axis exceeds R_o is *under the holder*:

- **Clamping:** the plates hold it at z = 0 with a penalty spring ``k_z`` (N/mm), the same
  stiffness as the tool contact (:mod:`fenicsx_drape.forming.contact`).
- **Friction (eq. 1):** a perfectly plastic bar fixed at the node's initial position acts on
  it in the sheet plane. The paper's bar has yield stress σ_y = F_tot μ / (A_f n_s), so it
  carries at most the force A_f σ_y = F_tot μ / n_s: the holding force times the friction
  coefficient, shared by the n_s nodes under the holder. As in the paper the bar lies along
  the node's *total* in-plane displacement u (not the slip velocity):

      N = k_f (|u| − e_p),  |N| ≤ f_y = w F μ / n_s,   f = −N u/|u|,

  with e_p the bar's plastic (sliding) elongation, a history variable committed with the
  step. Before sliding the bar is elastic with stiffness ``k_f = f_y / u_e``: it slides once
  the node has moved the *stick slip* ``u_e`` (default 0.05 mm, 0.5 % of a 10 mm cell).

``n_s`` follows the sheet as it draws in: the set of nodes under the holder, and n_s with it,
is re-evaluated from the converged positions after every step (so it lags by one step, which
keeps Newton's residual smooth within a step). A node that leaves the holder loses its bar.

**Symmetric models.** ``F_tot`` is the holding force carried by the modelled part of the
sheet: a quarter model carries F/4. Nodes on a symmetry plane stand for half a node of the
full sheet, so they count with weight w = 1/2 in n_s = Σ w and carry w times the force of an
interior node; a quarter model then reproduces the full sheet's force per node, F μ / n_s.
"""

from __future__ import annotations

import numpy as np

from fenicsx_drape.errors import ParameterError


class BlankHolder:
    """Clamping plates with a circular opening and eq. 1 friction bars (a :class:`NodalTerm`).

    Args:
        opening_radius_mm: radius of the plates' opening, R_o.
        force_N: holding force F_tot carried by the modelled part (F/4 for a quarter).
        friction: textile-tool friction coefficient μ.
        clamp_stiffness_N_per_mm: penalty stiffness ``k_z`` holding the nodes at z = 0.
        stick_slip_mm: elastic slip ``u_e`` of a friction bar before it slides.
        symmetry_axes: coordinate axes normal to the model's symmetry planes (0 for x = 0,
            1 for y = 0): nodes on them count with weight 1/2.
        holder_friction: the effect ``holder_friction``; without it the plates only clamp.
    """

    def __init__(self, *, opening_radius_mm: float, force_N: float, friction: float,
                 clamp_stiffness_N_per_mm: float, stick_slip_mm: float = 0.05,
                 symmetry_axes: tuple[int, ...] = (), holder_friction: bool = True) -> None:
        for name, value in (("opening_radius_mm", opening_radius_mm), ("force_N", force_N),
                            ("friction", friction), ("stick_slip_mm", stick_slip_mm),
                            ("clamp_stiffness_N_per_mm", clamp_stiffness_N_per_mm)):
            if not (np.isfinite(value) and value >= 0.0):
                raise ParameterError(f"BlankHolder: {name} = {value} must be finite and >= 0")
        if stick_slip_mm <= 0.0 or clamp_stiffness_N_per_mm <= 0.0:
            raise ParameterError("BlankHolder: stick_slip_mm and clamp_stiffness_N_per_mm "
                                 "must be positive")
        self.R_o = float(opening_radius_mm)
        self.F = float(force_N) if holder_friction else 0.0
        self.μ = float(friction)
        self.k_z = float(clamp_stiffness_N_per_mm)
        self.u_e = float(stick_slip_mm)
        self.symmetry_axes = tuple(symmetry_axes)

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """Reference positions, ownership and the communicator (for the global n_s)."""
        self.X = np.array(X, dtype=float)
        self.owned = np.asarray(owned, dtype=bool)
        self.comm = comm
        scale = max(np.abs(self.X[:, :2]).max(initial=0.0), 1.0)
        self.w = np.ones(len(self.X))
        for axis in self.symmetry_axes:
            self.w[np.abs(self.X[:, axis]) < 1e-9 * scale] *= 0.5
        self.e_p = np.zeros(len(self.X))  # plastic (sliding) elongation of the bars, mm
        self._trial: tuple[np.ndarray, np.ndarray] | None = None
        self._hold(self.X)

    def _hold(self, x: np.ndarray) -> None:
        """Re-evaluate which nodes are under the holder and n_s (collective under MPI)."""
        self.under = np.hypot(x[:, 0], x[:, 1]) > self.R_o
        local = float(self.w[self.under & self.owned].sum())
        self.n_s = self.comm.allreduce(local) if self.comm is not None else local
        self.f_y = self.w * self.F * self.μ / max(self.n_s, 1e-300)

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Clamping and friction forces (N) and stiffness −∂f/∂x (N/mm) at positions ``x``."""
        n = len(x)
        f = np.zeros((n, 3))
        K = np.zeros((n, 3, 3))
        on = self.under
        f[on, 2] = -self.k_z * x[on, 2]
        K[on, 2, 2] = self.k_z
        # Friction bars along the total in-plane displacement (eq. 1), return mapping on e_p.
        u = x[:, :2] - self.X[:, :2]
        e = np.hypot(u[:, 0], u[:, 1])
        k_f = self.f_y / self.u_e
        N = k_f * (e - self.e_p)
        sliding = np.abs(N) > self.f_y
        N = np.where(sliding, np.sign(N) * self.f_y, N)
        dN = np.where(sliding, 0.0, k_f)
        e_p = np.where(sliding, e - N / np.where(k_f > 0, k_f, 1.0), self.e_p)
        small = e < 1e-12 * self.u_e
        û = u / np.where(small, 1.0, e)[:, None]
        N_over_e = np.where(small, k_f, N / np.where(small, 1.0, e))
        uu = np.einsum("ni,nj->nij", û, û)
        K_bar = N_over_e[:, None, None] * (np.eye(2) - uu) + dN[:, None, None] * uu
        bar = on & (self.f_y > 0.0)
        f[bar, :2] = -N_over_e[bar, None] * u[bar]
        K[bar, :2, :2] = K_bar[bar]
        self._trial = (np.array(x, dtype=float), np.where(bar, e_p, self.e_p))
        return f, K

    def commit(self) -> None:
        """Keep the bars' sliding, then let the set under the holder follow the sheet."""
        if self._trial is None:
            return
        x, self.e_p = self._trial
        self._hold(x)
        self.e_p = np.where(self.under, self.e_p, 0.0)

    def revert(self) -> None:
        """Forget the trial sliding of a step that is cut back."""
        self._trial = None

    def draw_in(self, x: np.ndarray) -> np.ndarray:
        """Inward in-plane displacement (mm) of every node towards the axis."""
        r0 = np.hypot(self.X[:, 0], self.X[:, 1])
        return r0 - np.hypot(x[:, 0], x[:, 1])
