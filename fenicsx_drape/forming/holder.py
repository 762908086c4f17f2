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

      N = N(|u|) from the friction law,  f = −N u/|u|,

  with the law (``"paper_friction"``, :class:`~fenicsx_drape.materials.FrictionLaw`, or a
  user law of role ``"friction"``) elastic up to the slip ``holder_slip_mm`` and then
  perfectly plastic at N = F_tot μ / n_s; its sliding slip is committed with the step.

``n_s`` follows the sheet as it draws in: the set of nodes under the holder, and n_s with it,
is re-evaluated from the converged positions after every step (so it lags by one step, which
keeps Newton's residual smooth within a step). A node that leaves the holder loses its bar.

**Symmetric models.** ``F_tot`` is the holding force carried by the modelled part of the
sheet: a quarter model carries F/4. Nodes on a symmetry plane stand for half a node of the
full sheet, so they count with weight w = 1/2 in n_s = Σ w and carry w times the force of an
interior node; a quarter model then reproduces the full sheet's force per node, F μ / n_s.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.materials.base import MaterialLaw


class BlankHolder:
    """Clamping plates with a circular opening and eq. 1 friction bars (a :class:`NodalTerm`).

    Args:
        law: the friction bar's law (role ``"friction"``; force in N against slip in mm),
            e.g. ``model.laws()["friction"]``; its conditions ``holder_force_N`` and
            ``holder_nodes`` are set here, node by node and step by step.
        opening_radius_mm: radius of the plates' opening, R_o.
        force_N: holding force F_tot carried by the modelled part (F/4 for a quarter).
        clamp_stiffness_N_per_mm: penalty stiffness ``k_z`` holding the nodes at z = 0.
        symmetry_axes: coordinate axes normal to the model's symmetry planes (0 for x = 0,
            1 for y = 0): nodes on them count with weight 1/2.
    """

    def __init__(self, law: MaterialLaw, *, opening_radius_mm: float, force_N: float,
                 clamp_stiffness_N_per_mm: float, symmetry_axes: tuple[int, ...] = ()) -> None:
        if law.role != "friction":
            raise ParameterError(f"BlankHolder: the law {type(law).__name__} has role "
                                 f"{law.role!r}, expected 'friction'")
        for name, value in (("opening_radius_mm", opening_radius_mm), ("force_N", force_N),
                            ("clamp_stiffness_N_per_mm", clamp_stiffness_N_per_mm)):
            if not (np.isfinite(value) and value >= 0.0):
                raise ParameterError(f"BlankHolder: {name} = {value} must be finite and >= 0")
        if clamp_stiffness_N_per_mm <= 0.0:
            raise ParameterError("BlankHolder: clamp_stiffness_N_per_mm must be positive")
        self.law = law
        self.R_o = float(opening_radius_mm)
        self.F = float(force_N)
        self.k_z = float(clamp_stiffness_N_per_mm)
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
        self.state = self.law.initial_state(len(self.X))  # the bars' history (sliding slip)
        self._trial: tuple[np.ndarray, np.ndarray] | None = None
        self._hold(self.X)

    def _hold(self, x: np.ndarray) -> None:
        """Re-evaluate which nodes are under the holder and n_s (collective under MPI)."""
        self.under = np.hypot(x[:, 0], x[:, 1]) > self.R_o
        local = float(self.w[self.under & self.owned].sum())
        self.n_s = self.comm.allreduce(local) if self.comm is not None else local
        self.bars = np.flatnonzero(self.under)
        # Each bar's share of the force: a node on a symmetry plane is half a node.
        self._law = dataclasses.replace(self.law, holder_force_N=self.F * self.w[self.bars],
                                        holder_nodes=max(self.n_s, 1e-300))

    @property
    def yield_force_N(self) -> np.ndarray:
        """The force (N) at which each node under the holder slides (0 elsewhere)."""
        f_y = np.zeros(len(self.X))
        f_y[self.bars] = np.broadcast_to(self._law.yield_force_N, self.bars.shape)
        return f_y

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Clamping and friction forces (N) and stiffness −∂f/∂x (N/mm) at positions ``x``."""
        n, b = len(x), self.bars
        f = np.zeros((n, 3))
        K = np.zeros((n, 3, 3))
        f[b, 2] = -self.k_z * x[b, 2]
        K[b, 2, 2] = self.k_z
        # Friction bars along the total in-plane displacement (eq. 1).
        u = x[b, :2] - self.X[b, :2]
        e = np.hypot(u[:, 0], u[:, 1])
        N, dN, state = self._law.update(e, dt, self.state[b])
        # N/e and the direction; at e → 0 the elastic bar is isotropic: N/e → dN/de.
        small = e < 1e-9 * getattr(self.law, "holder_slip_mm", 1.0)
        û = u / np.where(small, 1.0, e)[:, None]
        N_e = np.where(small, dN, N / np.where(small, 1.0, e))
        uu = np.einsum("ni,nj->nij", û, û)
        f[b, :2] = -N_e[:, None] * u
        K[b, :2, :2] = N_e[:, None, None] * (np.eye(2) - uu) + dN[:, None, None] * uu
        new = self.state.copy()
        new[b] = state
        self._trial = (np.array(x, dtype=float), new)
        return f, K

    def commit(self) -> None:
        """Keep the bars' sliding, then let the set under the holder follow the sheet."""
        if self._trial is None:
            return
        x, self.state = self._trial
        self._trial = None
        self._hold(x)
        self.state[~self.under] = 0.0  # a node that left the holder has lost its bar

    def revert(self) -> None:
        """Forget the trial sliding of a step that is cut back."""
        self._trial = None
