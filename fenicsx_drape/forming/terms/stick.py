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
        n_c = g.normal[0] / size if size > 0.5 else self._contact_normal(x[mine], t)
        self.node, self.x_c, self.t_c = i, x[i].copy(), t
        self.P = np.eye(3) - np.outer(n_c, n_c)

    def revert(self) -> None:
        """Forget the trial positions of a step that is cut back."""
        self._trial = None

    def _contact_normal(self, x: np.ndarray, t: float) -> np.ndarray:
        """The punch's normal over the contact of the nodes ``x``: theirs, by depth."""
        g = self.tool.gap(x, t)
        n = np.maximum(-g.phi, 0.0) @ g.normal
        return n / np.linalg.norm(n)


TOP_CAP_MM = 1.0
"""The punch's top, where a stack is held: the region within this of its highest point."""


class PlyStick(ApexStick):
    """Each ply of a stack held at the punch's first point of contact (a NodalTerm).

    A stack on frictionless tools has the single ply's sliding mode (the module docstring)
    once per ply: the whole stack slides over the punch, and a ply slides over its
    neighbours where their friction is small. When the punch first touches the stack, the
    centroid of its top is found (:meth:`commit`); then, in each ply, the material point over
    it (in the flat stack) is held to the punch's material point under it, in the punch's
    tangent plane there. The point is held through the four corners
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
        """After the first step with contact: each ply's point over the punch's top, anchors.

        The place held is the centroid of the punch's top: the region within
        :data:`TOP_CAP_MM` of its highest point, sampled on a 1 mm grid over the sheet's
        plane (so it is the tool's, not the net's: it does not move as the blank is moved,
        turned or held harder; two equal tops, as a double dome's, give the point between).
        """
        from fenicsx_drape.fe.plies import _bilinear, _corners

        if self.chosen or self._trial is None:
            return
        x, t = self._trial
        mine = np.flatnonzero(self.owned)
        phi = self.tool.gap(x[mine], t).phi if len(mine) else np.zeros(0)
        w = np.maximum(-phi, 0.0)
        sums = np.array([w.sum(), w @ x[mine, 2]]) if len(mine) else np.zeros(2)
        box = (np.concatenate([-self.X[mine, :2].min(axis=0), self.X[mine, :2].max(axis=0)])
               if len(mine) else np.full(4, -np.inf))
        if self.comm is not None:
            sums = self.comm.allreduce(sums, op=MPI.SUM)
            box = self.comm.allreduce(box, op=MPI.MAX)
        if not sums[0] > 0.0:
            return  # no contact yet
        self.chosen = True
        lo, hi = -box[:2], box[2:]
        n = np.minimum(np.ceil((hi - lo) / 1.0).astype(int) + 1, 600)
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n[0]), np.linspace(lo[1], hi[1], n[1]))
        points = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, sums[1] / sums[0])])
        g = self.tool.gap(points, t)
        depth = -g.phi
        w = np.maximum(depth - (depth.max() - TOP_CAP_MM), 0.0)
        centre = w @ points / w.sum()
        n_c = w @ g.normal
        n_c /= np.linalg.norm(n_c)
        self.P = np.eye(3) - np.outer(n_c, n_c)
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
