"""Quadrature-point state: strain, stress, tangent and the laws' internal variables.

Every quantity lives in a quadrature-space function with one point per bar. At each solver
iterate :meth:`MaterialState.evaluate` computes the strain of every owned bar from the UFL
expression of :mod:`~fenicsx_drape.fe.kinematics`, calls the law of its role (tows → the
``"tow"`` law, diagonals → the ``"shear"`` law: the same registered laws the unit-cell tests
use, user laws included) with the *committed* history, and writes the work-conjugate force
``S`` and its tangent ``dS/dε`` that the residual and Jacobian forms read. The new history is
kept aside: :meth:`commit` accepts it after a converged step, :meth:`revert` forgets it.

Buckled tows (eq. 4). With ``tow_buckling`` a compressed tow carries nothing, and a net of such
tows has zero-stiffness modes. The option ``buckled_tow_stiffness_N`` gives a buckled tow a small
residual compressive stiffness standing for the bending stiffness of the wrinkled tow: a tow of
3000 carbon fibres (7 µm, E = 230 GPa) bending as loose fibres has EI ≈ 0.08 N·mm², so it buckles
over a 10 mm cell at π²EI/Δ² ≈ 8e-3 N; reached at the paper's wrinkling strains (|ε| ≈ 0.2) this
is a secant stiffness of ≈ 0.04 N/tow (1.2e-5 E_o). It acts only where the tow law has the
``tow_buckling`` effect, only in compression, and it is part of the model (halve it and report
the change, see the FE benchmark).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import dolfinx
import numpy as np

from fenicsx_drape.fe.grid import DIAGONAL_MINUS, DIAGONAL_PLUS, WARP, WEFT
from fenicsx_drape.fe.kinematics import green_lagrange, quadrature_space
from fenicsx_drape.materials.base import MaterialLaw

ROLE_OF_KIND = {WARP: "tow", WEFT: "tow", DIAGONAL_PLUS: "shear", DIAGONAL_MINUS: "shear"}

# The smallest stretch a bar may reach before an iterate is rejected (a collapsed bar).
MIN_STRETCH = 1e-3


class StrainError(ValueError):
    """An iterate collapsed a bar (zero length) or produced a non-finite strain."""


class MaterialState:
    """The material state of the owned bars of a sheet, in quadrature functions.

    Args:
        u: Displacement (vector P1) the strain is evaluated from.
        kinds: Bar kind of every owned cell (WARP, WEFT, DIAGONAL_PLUS, DIAGONAL_MINUS).
        tows: Tows each owned bar stands for, ``n_t`` (section 4).
        laws: The law of each role, ``{"tow": ..., "shear": ...}``.
        buckled_tow_stiffness_N: Residual compressive stiffness of buckled tows (N/tow).
        own_laws: Bars with laws of their own (a ply of a stack with its own model): pairs
            of a boolean mask over the owned bars and the law of each role there. Their
            groups are named ``"<role>@<k>"`` (k from 1, in order), their internal variables
            ``"<role>@<k>.<name>"``.
    """

    def __init__(self, u: dolfinx.fem.Function, kinds: np.ndarray, tows: np.ndarray,
                 laws: Mapping[str, MaterialLaw], buckled_tow_stiffness_N: float = 0.0,
                 own_laws: Sequence[tuple[np.ndarray, Mapping[str, MaterialLaw]]] = ()):
        Q = quadrature_space(u.function_space.mesh)
        self.space = Q
        n = len(kinds)
        self.dofs = Q.dofmap.list[:n, 0]  # one point per cell, in cell order
        self.kinds = np.asarray(kinds)
        self.tows = np.asarray(tows, dtype=float)
        self.buckled_tow_stiffness_N = float(buckled_tow_stiffness_N)

        def function(name: str) -> dolfinx.fem.Function:
            return dolfinx.fem.Function(Q, name=name)

        self.strain = function("strain")  # ε, Green-Lagrange
        self.stress = function("stress_per_tow_N")  # σ, force per tow
        self.tangent = function("tangent_per_tow_N")  # dσ/dε per tow
        self.S = function("S_N")  # n_t σ / λ, work-conjugate of ε (N)
        self.dS = function("dS_N")  # dS/dε (N)
        # The force of the geometric stiffness: S, or S limited (limit_geometric_force).
        self.S_geometric = function("S_geometric_N")
        self._expression = dolfinx.fem.Expression(green_lagrange(u),
                                                  Q.element.interpolation_points)
        self._cells = np.arange(n, dtype=np.int32)
        roles = np.array([ROLE_OF_KIND[int(k)] for k in kinds]) if n else np.array([], str)
        # A group: the bars of one law (its role's, or a ply's own), by name.
        self.groups: dict[str, tuple[np.ndarray, MaterialLaw]] = {}
        self.history: dict[str, list[dolfinx.fem.Function]] = {}
        rest = np.ones(n, dtype=bool)
        for mask, _ in own_laws:
            rest &= ~np.asarray(mask, dtype=bool)
        sets = [("", rest, laws)] + [(f"@{k}", np.asarray(mask, dtype=bool), own)
                                     for k, (mask, own) in enumerate(own_laws, 1)]
        for suffix, mask, group_laws in sets:
            for role in ("tow", "shear"):
                if role not in group_laws:
                    raise KeyError(f"no {role!r} law given (laws for roles: "
                                   f"{', '.join(group_laws)})")
                law = group_laws[role]
                points = np.flatnonzero((roles == role) & mask)
                if suffix and not len(points):
                    continue
                self.groups[role + suffix] = (points, law)
                funcs = [function(f"{role}{suffix}.{name}") for name in law.state_names]
                initial = law.initial_state(len(points))
                for k, f in enumerate(funcs):
                    f.x.array[self.dofs[points]] = initial[:, k]
                self.history[role + suffix] = funcs
        self._trial: dict[str, np.ndarray] = {}
        self._committed = self._snapshot()

    def _snapshot(self) -> list[np.ndarray]:
        return [f.x.array.copy() for f in (self.strain, self.stress, self.tangent, self.S,
                                           self.dS)]

    def _history(self, group: str) -> np.ndarray:
        points, law = self.groups[group]
        dofs = self.dofs[points]
        return np.column_stack([f.x.array[dofs] for f in self.history[group]]) \
            if law.state_names else np.zeros((len(points), 0))

    def evaluate(self, dt: float) -> None:
        """Strain, stress and tangent of every owned bar at the current displacement.

        Uses the committed history and the step length ``dt`` (s); the new history is kept
        for :meth:`commit`.

        Raises:
            StrainError: when a bar collapses or the strain is not finite.
        """
        ε = self._expression.eval(self.space.mesh, self._cells).reshape(-1)
        if not np.isfinite(ε).all():
            raise StrainError("the strain is not finite")
        λ2 = 1.0 + 2.0 * ε
        if (λ2 < MIN_STRETCH**2).any():
            raise StrainError(f"a bar collapsed (stretch {np.sqrt(max(λ2.min(), 0)):.2g})")
        σ = np.zeros_like(ε)
        C = np.zeros_like(ε)
        for group, (points, law) in self.groups.items():
            stress, tangent, self._trial[group] = law.update(ε[points], dt,
                                                             self._history(group))
            if (group.startswith("tow") and self.buckled_tow_stiffness_N
                    and "tow_buckling" in law.effects):
                compressed = ε[points] < 0
                stress = stress + self.buckled_tow_stiffness_N * np.minimum(ε[points], 0.0)
                tangent = tangent + self.buckled_tow_stiffness_N * compressed
            σ[points], C[points] = stress, tangent
        self.strain.x.array[self.dofs] = ε
        self._write(np.arange(len(ε)), σ, C)

    def _write(self, points: np.ndarray, σ: np.ndarray, C: np.ndarray) -> None:
        """Store σ, dσ/dε of ``points`` and their work-conjugate S = n_t σ/λ and dS/dε."""
        dofs = self.dofs[points]
        λ = np.sqrt(1.0 + 2.0 * self.strain.x.array[dofs])
        n_t = self.tows[points]
        self.stress.x.array[dofs] = σ
        self.tangent.x.array[dofs] = C
        self.S.x.array[dofs] = n_t * σ / λ
        self.S_geometric.x.array[dofs] = self.S.x.array[dofs]
        self.dS.x.array[dofs] = n_t * (C / λ - σ / λ**3)

    def limit_geometric_force(self, limit_N: float = np.inf) -> None:
        """Set the force of the geometric stiffness: S limited to ±``limit_N`` (N)."""
        np.clip(self.S.x.array, -limit_N, limit_N, out=self.S_geometric.x.array)

    def largest_force(self) -> float:
        """The largest |S| (N) of the owned bars."""
        return float(np.abs(self.S.x.array[self.dofs]).max(initial=0.0))

    def scale_shear(self, factor: np.ndarray) -> None:
        """Multiply the stress and tangent of the shear diagonals by ``factor`` (per point).

        The cell-level ``shear_tension_coupling`` (see :mod:`fenicsx_drape.effects`): the
        shear law's own state is unchanged. The tangent is scaled at fixed factor (the
        factor's dependence on the tow strains is left out of the Jacobian).
        """
        points, _ = self.groups["shear"]
        dofs = self.dofs[points]
        self._write(points, factor * self.stress.x.array[dofs],
                    factor * self.tangent.x.array[dofs])

    def commit(self) -> None:
        """Accept the state of the last evaluation (a converged step)."""
        for role, new in self._trial.items():
            points, _ = self.groups[role]
            for k, f in enumerate(self.history[role]):
                f.x.array[self.dofs[points]] = new[:, k]
        self._committed = self._snapshot()

    def revert(self) -> None:
        """Forget the evaluations since the last commit (the step is cut back)."""
        self._trial = {}
        for f, saved in zip((self.strain, self.stress, self.tangent, self.S, self.dS),
                            self._committed):
            f.x.array[:] = saved
        self.S_geometric.x.array[:] = self.S.x.array

    def functions(self) -> list[dolfinx.fem.Function]:
        """All quadrature functions: strain, stress, tangent and every internal variable."""
        funcs = [self.strain, self.stress, self.tangent]
        for role in self.history:
            funcs += self.history[role]
        return funcs
