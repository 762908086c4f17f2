"""``shear_tension_coupling`` on the unit cells of the sheet (see :mod:`fenicsx_drape.effects`).

The diagonal forces of a unit cell are multiplied by 1 + k_st max(σ̄_t, 0), σ̄_t the mean
stress of the cell's four tow bars (:func:`~fenicsx_drape.effects.shear_tension_factor`, as in
the unit-cell solutions). The factor is applied staggered in time: a step uses the factor
extrapolated linearly from the last two converged steps (second order in dt), so every Newton
solve keeps its exact Jacobian. (An implicit coupling would need Jacobian terms between each
diagonal and the four tows of its cell, which are stiff: a tow's E_o is 10⁵ times the shear
stiffness, and a Newton iteration without them does not converge.)
"""

from __future__ import annotations

import numpy as np

from fenicsx_drape.effects import shear_tension_factor
from fenicsx_drape.fe.grid import WARP


class ShearTensionCoupling:
    """The coupling factor of every owned diagonal of a problem, step by step.

    Args:
        problem: The :class:`~fenicsx_drape.fe.solver.TrussProblem` (a structured sheet).
        k_st: Coupling coefficient (tow/N).
    """

    def __init__(self, problem, k_st: float):
        self.problem, self.k_st = problem, float(k_st)
        grid, state, mesh = problem.sheet.grid, problem.state, problem.sheet.mesh
        n = len(state.dofs)
        g = grid.grid_coordinates(mesh.geometry.x[mesh.geometry.dofmaps[0][:n]].mean(axis=1))
        tow, shear = state.groups["tow"][0], state.groups["shear"][0]
        warp = state.kinds[tow] == WARP
        # Warp bar (i, j) spans nodes (i, j)-(i+1, j); weft bar (i, j): (i, j)-(i, j+1).
        i = np.where(warp, np.floor(g[tow, 0]), np.rint(g[tow, 0])).astype(int)
        j = np.where(warp, np.rint(g[tow, 1]), np.floor(g[tow, 1])).astype(int)
        self._bars = (warp, i, j)
        self._cells = np.floor(g[shear]).astype(int)
        self._factors = [np.ones(len(shear))] * 2  # at the last two converged steps

    def current(self) -> np.ndarray:
        """The factor of every owned diagonal at the converged state (collective)."""
        grid, state = self.problem.sheet.grid, self.problem.state
        σ = state.stress.x.array[state.dofs[state.groups["tow"][0]]]
        σ_warp = np.zeros((grid.nx, grid.ny + 1))
        σ_weft = np.zeros((grid.nx + 1, grid.ny))
        for w, i, j, s in self.problem.comm.allgather((*self._bars, σ)):
            σ_warp[i[w], j[w]] = s[w]
            σ_weft[i[~w], j[~w]] = s[~w]
        mean = (σ_warp[:, :-1] + σ_warp[:, 1:] + σ_weft[:-1, :] + σ_weft[1:, :]) / 4
        return shear_tension_factor(mean[self._cells[:, 0], self._cells[:, 1]], self.k_st)[0]

    def predict(self, ratio: float) -> np.ndarray:
        """The factor for a step of ``ratio`` times the last step's length."""
        f_m, f_n = self._factors
        return np.maximum(f_n + (f_n - f_m) * ratio, 1.0)

    def commit(self) -> None:
        """After a converged step: its factor becomes the latest (collective)."""
        self._factors = [self._factors[1], self.current()]
