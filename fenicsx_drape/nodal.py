"""Nodal terms: forces that act node by node on the sheet (tool contact, blank holder).

A nodal term couples no two nodes, so its Jacobian is a 3×3 block per node. It knows nothing
of DOLFINx: the FE solver hands it the positions of its local nodes and adds the returned
forces and blocks to the residual and Jacobian (owned nodes only, so nothing is counted twice
under MPI). Terms with memory (friction) commit their state only after a converged step and
revert it when a step is cut back, like the material laws.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class NodalTerm(Protocol):
    """The interface of contact and holder terms.

    Positions are in mm, forces in N, time in s. ``x`` is shaped ``(n_nodes, 3)`` in the
    solver's local node order (the one given to :meth:`bind`).
    """

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """Set up once with the reference configuration.

        Args:
            X: reference positions (n, 3) of the local nodes in mm.
            owned: boolean mask of the nodes this rank owns.
            comm: the MPI communicator (for global counts such as n_s).
        """

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """External force on each node and its stiffness at the end of a step to time ``t``.

        Returns:
            ``f`` (n, 3) in N at the current positions ``x``, and ``K = -∂f/∂x`` (n, 3, 3)
            in N/mm.
        """

    def commit(self) -> None:
        """Accept the state of the last converged step."""

    def revert(self) -> None:
        """Forget the state computed since the last commit (the step is cut back)."""


def predict(terms, x: np.ndarray, t: float) -> np.ndarray:
    """Let terms that can (e.g. contact) move a predicted configuration to an admissible one.

    A term may define ``project(x, t) -> x``; the others are skipped.
    """
    for term in terms:
        project = getattr(term, "project", None)
        if project is not None:
            x = project(x, t)
    return x
