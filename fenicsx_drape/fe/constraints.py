"""Prescribed displacements on node sets, as DOLFINx Dirichlet conditions.

Each call of :meth:`Constraints.add` prescribes some displacement components (0 = x, 1 = y,
2 = z) of a set of nodes as a function of time. Components are independent: a node may have
u_x prescribed (a symmetry plane) and u_y, u_z free. A component prescribed twice takes the
value of the later call.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence

import dolfinx
import numpy as np

from fenicsx_drape.errors import DrapeInputError


def _as_function(value) -> Callable:
    """``value`` (a number, per-component numbers, ``f(t)`` or ``f(t, X)``) as ``f(t, X)``."""
    if callable(value):
        if len(inspect.signature(value).parameters) == 1:
            return lambda t, X: value(t)
        return value
    constant = np.asarray(value, dtype=float)
    if not np.isfinite(constant).all():
        raise DrapeInputError(f"prescribed displacement {value} is not finite")
    return lambda t, X: constant


class Constraints:
    """The prescribed displacement components of the local nodes of a vector P1 space.

    Args:
        V: The displacement space (vector P1, block size 3).
        X: Reference positions of its local nodes (n, 3) in mm.
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace, X: np.ndarray):
        self.V, self.X = V, X
        self._fixes: list[tuple[np.ndarray, tuple[int, ...], Callable]] = []
        self.bcs: list[dolfinx.fem.DirichletBC] = []  # one per component
        self.constrained = np.zeros((len(X), 3), dtype=bool)  # by node and component
        self._values: list[tuple[dolfinx.fem.Function, np.ndarray]] = []
        self._collapsed = []
        for c in range(3):
            Vc, parent = V.sub(c).collapse()
            parent = np.asarray(parent).ravel()
            to_collapsed = np.empty(len(X), dtype=np.int32)
            to_collapsed[(parent - c) // 3] = np.arange(len(parent))
            self._collapsed.append((Vc, to_collapsed))

    def add(self, mask: np.ndarray, components: Sequence[int], value) -> None:
        """Prescribe ``components`` of the nodes in ``mask`` (see the module docstring).

        ``value`` is in mm: a number or one per component, or a function of time ``value(t)``
        or of time and reference positions ``value(t, X)`` returning an array broadcastable
        to (n_selected, len(components)).
        """
        components = tuple(int(c) for c in components)
        if not components or any(c not in (0, 1, 2) for c in components):
            raise DrapeInputError(f"components {components} must be among 0, 1, 2 (x, y, z)")
        self._fixes.append((np.asarray(mask, dtype=bool), components, _as_function(value)))
        for c in components:
            self.constrained[mask, c] = True
        self.bcs, self._values = [], []
        for c, (Vc, to_collapsed) in enumerate(self._collapsed):
            nodes = np.flatnonzero(self.constrained[:, c]).astype(np.int32)
            g = dolfinx.fem.Function(Vc)
            self.bcs.append(dolfinx.fem.dirichletbc(g, [3 * nodes + c, to_collapsed[nodes]],
                                                    self.V.sub(c)))
            self._values.append((g, to_collapsed))

    def apply(self, t: float, u: np.ndarray) -> None:
        """Set the prescribed values at time ``t`` (s) in the conditions and in ``u``."""
        for c, (g, to_collapsed) in enumerate(self._values):
            for mask, components, f in self._fixes:
                if c in components:
                    nodes = np.flatnonzero(mask)
                    values = np.broadcast_to(f(t, self.X[nodes]), (len(nodes), len(components)))
                    g.x.array[to_collapsed[nodes]] = values[:, components.index(c)]
        for bc in self.bcs:
            bc.set(u)
