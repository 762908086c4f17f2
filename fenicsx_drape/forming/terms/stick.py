"""The punch's first point of contact sticks: a sheet without symmetry planes stays well-posed.

On the paper's frictionless tools a sheet that no symmetry plane holds has a mode that costs
almost nothing: it slides over the punch as a whole (on a hemisphere, a turn about the
sphere's centre), while the holder's eq. 1 bars, sliding at their yield force, resist the
draw-in on every side alike. Once they yield, the side that loses a node from under the holder
pulls less, the sheet moves away from it, and that side draws in more: a symmetric part formed
whole slides by millimetres one way or the other, decided by round-off (measured on
``meshes/octagon``, a half model free in y, at 300 N: a lab's STL copy of the tools, within
0.04 mm of them, moved the sheet's centre 9.5 mm over the punch). Any tool friction removes
the mode (μ_t = 0.01 brings the copy within 0.3 mm of the closed form); a lab's prepreg
sticks where the punch first presses it.

This term is that stick, and only that: the sheet's node at the punch's first contact (the
node nearest the centre of the contact at the end of the first step with any, the
penetrating nodes weighted by their depth; one node for the whole sheet) is held to
the punch's material point under it, in the punch's tangent plane at that moment, by a
linear spring of the contact stiffness k,

    f = −k P_c (x − x_c − Δx_punch),   K = k P_c,   P_c = I − n_c⊗n_c.

It acts on a single ply that is not held otherwise: a quarter's planes, or the centre held
by ``hold_origin`` (a part symmetric in both planes formed whole), fix the mode already. On a
half model whose apex lies on its plane the node does not slide anyway, so the forming of a
symmetric part is unchanged; the stick removes the sliding mode only, and no draw-in (the
rest of the sheet slides on the punch as before). A stack's plies are held to each other by
the inter-ply law and keep their own sliding.

With tool friction (``tool_friction``) the point sticks anyway; the term
stays, so that results move smoothly as μ_t goes to 0.
"""

from __future__ import annotations

from mpi4py import MPI

import numpy as np


class ApexStick:
    """The punch's first point of contact held to the punch in its tangent plane (NodalTerm).

    Args:
        tool: the punch (``gap(x, t)`` and ``displacement(x, t0, t1)``).
        stiffness_N_per_mm: the spring's stiffness ``k`` (the contact penalty's).
    """

    def __init__(self, tool, stiffness_N_per_mm: float) -> None:
        self.tool = tool
        self.k = float(stiffness_N_per_mm)
        self.node: int | None = None  # local index, on the rank that owns it

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """Ownership and the communicator (the node is chosen across ranks)."""
        self.owned = np.asarray(owned, dtype=bool)
        self.comm = comm
        self.chosen = False
        self._trial: tuple[np.ndarray, float] | None = None

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The spring's force (N) and stiffness (N/mm) at positions ``x`` (zero before contact)."""
        n = len(x)
        f, K = np.zeros((n, 3)), np.zeros((n, 3, 3))
        self._trial = (np.array(x, dtype=float), t)
        if self.node is not None:
            i = self.node
            d = x[i] - self.x_c - self.tool.displacement(x[i:i + 1], self.t_c, t)[0]
            f[i] = -self.k * self.P @ d
            K[i] = self.k * self.P
        return f, K

    def commit(self) -> None:
        """After the first step with contact: choose the node and fix its anchor.

        The node nearest the centre of the first contact (the penetrating nodes weighted by
        their depth): the apex a dome touches first, the part's centre between a double
        dome's two tops, so that a symmetric part keeps its symmetry.
        """
        if self.chosen or self._trial is None:
            return
        x, t = self._trial
        mine = np.flatnonzero(self.owned)
        phi = self.tool.gap(x[mine], t).phi if len(mine) else np.zeros(0)
        w = np.maximum(-phi, 0.0)
        sums = np.append(w @ x[mine], w.sum()) if len(mine) else np.zeros(4)
        total = self.comm.allreduce(sums, op=MPI.SUM) if self.comm is not None else sums
        if not total[3] > 0.0:
            return  # no contact yet
        self.chosen = True
        centre = total[:3] / total[3]
        rank = self.comm.rank if self.comm is not None else 0
        d = np.linalg.norm(x[mine] - centre, axis=1)
        near = (float(d.min()), rank) if len(mine) else (np.inf, rank)
        best = self.comm.allreduce(near, op=MPI.MIN) if self.comm is not None else near
        if best[1] != rank:
            return
        i = int(mine[np.argmin(d)])
        g = self.tool.gap(x[i:i + 1], t)
        size = np.linalg.norm(g.normal[0])
        # Beyond a meshed tool's distance band (the node between a double dome's two tops)
        # the gap has no normal: the contact's own then.
        n_c = g.normal[0] / size if size > 0.5 else self._contact_normal(x[mine], t, local=True)
        self.node, self.x_c, self.t_c = i, x[i].copy(), t
        self.P = np.eye(3) - np.outer(n_c, n_c)

    def revert(self) -> None:
        """Forget the trial positions of a step that is cut back."""
        self._trial = None

    def _contact_normal(self, x: np.ndarray, t: float, local: bool = False) -> np.ndarray:
        """The punch's normal over the first contact: its penetrating nodes', by depth.

        Collective unless ``local`` (the nodes ``x`` of this rank only).
        """
        g = self.tool.gap(x, t) if len(x) else None
        w = np.maximum(-g.phi, 0.0) if g is not None else np.zeros(0)
        n = w @ g.normal if g is not None else np.zeros(3)
        if self.comm is not None and not local:
            n = self.comm.allreduce(n, op=MPI.SUM)
        return n / np.linalg.norm(n)


class PlyStick(ApexStick):
    """Each ply of a stack held at the punch's first point of contact (a NodalTerm).

    A stack on frictionless tools has the single ply's sliding mode (the module docstring)
    once per ply: the whole stack slides over the punch, and a ply slides over its
    neighbours where their friction is small. The centre of the first contact is found as
    for one ply (from every ply's penetrating nodes: ply 1's); then, in each ply, the
    material point over that centre (in the flat stack) is held to the punch's material point
    under it, in the punch's tangent plane there. The point is held through the four corners
    of its unit cell, each by a spring k w_J with its bilinear weight w_J,

        f_J = −k w_J P_c (x_J − x_J,c − Δx_punch),   K_J = k w_J P_c,

    so that what is held moves smoothly as the blank or a ply is moved or turned (a point on
    a node of the net is held by that node alone, as one ply's stick). It removes the sliding
    of the stack as a whole and of each ply at one point; the plies slide on each other
    everywhere else (on a part that a half turn about the punch's axis maps onto itself, as a
    double dome or a hemisphere with a [0/90, ±45] stack, the centre does not slide anyway).

    Args:
        tool: the punch (``gap(x, t)`` and ``displacement(x, t0, t1)``).
        stiffness_N_per_mm: the springs' total stiffness ``k`` (the contact penalty's).
        plies: the stack (:class:`~fenicsx_drape.fe.plies.Ply`, ply 1 first).
    """

    def __init__(self, tool, stiffness_N_per_mm: float, plies) -> None:
        super().__init__(tool, stiffness_N_per_mm)
        self.plies = list(plies)
        self.held: tuple[np.ndarray, np.ndarray] | None = None  # local nodes, weights

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """The reference positions (each ply's nodes are found by place), then as ApexStick."""
        super().bind(X, owned, comm)
        self.X = np.asarray(X, dtype=float)

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The springs' forces (N) and stiffness (N/mm) at positions ``x`` (zero before contact)."""
        n = len(x)
        f, K = np.zeros((n, 3)), np.zeros((n, 3, 3))
        self._trial = (np.array(x, dtype=float), t)
        if self.held is not None:
            nodes, w = self.held
            d = x[nodes] - self.x_c - self.tool.displacement(x[nodes], self.t_c, t)
            np.add.at(f, nodes, -self.k * w[:, None] * (d @ self.P))
            np.add.at(K, nodes, self.k * w[:, None, None] * self.P)
        return f, K

    def commit(self) -> None:
        """After the first step with contact: each ply's point over its centre, and anchors."""
        from fenicsx_drape.fe.plies import _bilinear, _corners

        if self.chosen or self._trial is None:
            return
        x, t = self._trial
        mine = np.flatnonzero(self.owned)
        phi = self.tool.gap(x[mine], t).phi if len(mine) else np.zeros(0)
        w = np.maximum(-phi, 0.0)
        sums = np.append(w @ x[mine], w.sum()) if len(mine) else np.zeros(4)
        total = self.comm.allreduce(sums, op=MPI.SUM) if self.comm is not None else sums
        if not total[3] > 0.0:
            return  # no contact yet
        self.chosen = True
        centre = total[:3] / total[3]
        self.P = np.eye(3) - np.outer(*[self._contact_normal(x[mine], t)] * 2)
        nodes, weights = [], []
        for ply in self.plies:  # the point of each ply over the centre, in the flat stack
            grid = ply.grid
            ij = grid.grid_coordinates(centre[None, :2])[0]
            lo = np.clip(np.floor(ij).astype(int), 0, [grid.nx - 1, grid.ny - 1])
            if not grid.cells[lo[0], lo[1]]:
                continue  # the centre is off this ply
            q = np.clip(ij - lo, 0.0, 1.0)
            corners = _corners(grid, lo[:1], lo[1:])[0]
            at = grid.nodes[corners]
            at[:, 2] = ply.z_mm
            for X_J, w_J in zip(at, _bilinear(q[:1], q[1:])[0]):
                i = np.flatnonzero(np.linalg.norm(self.X[mine] - X_J, axis=1)
                                   <= 1e-6 * grid.cell_mm)
                if len(i) and w_J > 1e-12:
                    nodes.append(int(mine[i[0]]))
                    weights.append(float(w_J))
        if nodes:  # a rank holds the corners it owns
            self.held = (np.array(nodes), np.array(weights))
            self.x_c, self.t_c = x[self.held[0]].copy(), t
