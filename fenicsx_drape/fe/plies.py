"""A stack of plies on one truss mesh, and the contact and friction between adjacent plies.

Every ply is its own pin-jointed net (its own bars, laws' internal variables and tags) laid
flat at the height of its mid-plane; :func:`stack_sheet` puts the nets of a stack in one
DOLFINx mesh, so one Newton solve forms them together. Ply 1 is the one on the punch side
(lowest z); ply k + 1 lies (t_k + t_{k+1})/2 above ply k.

:class:`PlyContact` couples each pair of adjacent plies, **node to the neighbouring ply's
surface**: every node a of ply k + 1 is paired, once, with the material point of ply k under
it in the flat stack (bilinear weights w_J over the four corners J of the unit cell that
holds it; for identical nets a node's partner is the node under it, w = 1). With
d = x_a − Σ w_J x_J and the unit normal n of the partner cell (the cross product of its
diagonals at the last converged step, so the normal is lagged by one step):

- **gap and pressure**: g = n·d − h (h the mid-plane distance); a penalty keeps the plies
  apart, f_n = k_n ⟨−g⟩ along n, and the pressure is p = f_n / A_a with A_a the node's share
  of its ply's area (a quarter of each unit cell around it, so Σ A_a is the ply's area);
- **friction**: the slip s = P (d − d₀) (P = I − n⊗n, d₀ the flat stack's d) goes through
  the inter-ply law (:class:`~fenicsx_drape.materials.interply.InterplyLaw`,
  τ = τ₀ + μ p + η_f v), whose plastic slip and last slip are the pair's state; the force on
  a is −A_a τ, and its reaction −w_J f_a goes to the partners.

The Jacobian is consistent in x for the lagged normal (∂τ/∂p couples the friction with the
gap, so it is not symmetric). A pair keeps its partner point: the pairing holds while the
plies slide by less than a cell (the pull-out test, the first millimetres of forming); with
``follow`` the pairs are re-made after every step with the point now under each node.
Bonded plies (the law without ``interply_friction``) are also held together across the gap
(a two-sided normal penalty).

**MPI.** :func:`stack_sheet` gives each rank columns of the stack (every ply), so most pairs
are local, but those along the cuts cross the partition. The pairs are made once over the
whole stack, by global node index, on every rank alike; a rank keeps the pairs that touch a
node it owns (a pair across two ranks is evaluated on both) and gathers every rank's owned
positions at each evaluation, so its owned nodes get whole forces and it fills its own rows
of the Jacobian (columns anywhere), with no force sent back. On one rank this is the plain
path (no gathering). Following the plies (``follow``) stays on one rank: the re-made pairs
would leave the ranks that hold their state.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.fe.grid import TrussGrid
from fenicsx_drape.materials.interply import InterplyLaw

__all__ = ["Ply", "PlyContact", "ply_of", "sheet_grids", "stack_nodes", "stack_plies",
           "stack_sheet"]


@dataclasses.dataclass(frozen=True)
class Ply:
    """One ply of a stack: its net and where it lies."""

    grid: TrussGrid  # the ply's net (its angle is the grid's)
    z_mm: float  # height of its mid-plane in the flat stack (mm)
    thickness_mm: float = 0.2  # its thickness (mm)


def stack_plies(grids: list[TrussGrid], thickness_mm: list[float], z0_mm: float = 0.0
                ) -> list[Ply]:
    """Plies laid on each other from ``z0_mm`` (ply 1's mid-plane) upwards."""
    if len(grids) != len(thickness_mm) or not grids:
        raise DrapeInputError("a stack needs one thickness per ply and at least one ply")
    for k, t in enumerate(thickness_mm, 1):
        if not (np.isfinite(t) and t > 0):
            raise DrapeInputError(f"ply {k}: thickness_mm = {t} must be > 0")
    z = z0_mm + np.concatenate([[0.0], np.cumsum(0.5 * (np.array(thickness_mm[:-1])
                                                         + np.array(thickness_mm[1:])))])
    return [Ply(g, float(zk), float(t)) for g, zk, t in zip(grids, z, thickness_mm)]


def stack_nodes(plies: list[Ply]):
    """Nodes (n, 3), bars (m, 2), bar kinds and node flags of all plies, ply after ply."""
    nodes, bars, kinds, flags, first = [], [], [], [], 0
    for ply in plies:
        xyz = ply.grid.nodes.copy()
        xyz[:, 2] = ply.z_mm
        b, k = ply.grid.bars
        nodes.append(xyz)
        bars.append(b + first)
        kinds.append(k)
        flags.append(ply.grid.node_flags)
        first += len(xyz)
    return (np.concatenate(nodes), np.concatenate(bars), np.concatenate(kinds),
            np.concatenate(flags))


def stack_sheet(plies: list[Ply], comm=None):
    """The plies' nets in one DOLFINx mesh (a :class:`~fenicsx_drape.fe.mesh.Sheet`).

    The sheet has no single structured grid (``grid`` is None); its ``plies`` hold the
    plies, and :func:`ply_of` tells a node's ply from its height. On several ranks the bars
    go to the ranks by their place in the plane (a column of the stack on one rank).
    """
    from mpi4py import MPI

    from fenicsx_drape.fe.mesh import Sheet, _distribute

    comm = comm or MPI.COMM_WORLD
    data = stack_nodes(plies) if comm.rank == 0 else None
    mesh, bar_tags, node_tags = _distribute(data, comm, columns=True)
    cell = plies[0].grid.cell_mm
    if any(abs(p.grid.cell_mm - cell) > 1e-9 * cell for p in plies):
        raise DrapeInputError("the plies of a stack need the same unit-cell size")
    return Sheet(mesh, bar_tags, node_tags, None, cell, plies=list(plies))


def ply_of(plies: list[Ply], X: np.ndarray) -> np.ndarray:
    """The index (0 = ply 1) of the ply of each node at reference positions ``X`` (n, 3)."""
    z = np.array([p.z_mm for p in plies])
    return np.argmin(np.abs(np.asarray(X)[:, 2:3] - z[None, :]), axis=1)


def sheet_grids(sheet, X: np.ndarray) -> list[tuple[TrussGrid, np.ndarray]]:
    """The structured grid of each ply of a sheet and the mask of the points ``X`` on it.

    One pair for a sheet of one grid, one per ply for a stack, none for a free truss.
    """
    if sheet.plies:
        which = ply_of(sheet.plies, X)
        return [(p.grid, which == k) for k, p in enumerate(sheet.plies)]
    if sheet.grid is None:
        return []
    return [(sheet.grid, np.ones(len(X), dtype=bool))]


def node_areas(grid: TrussGrid) -> np.ndarray:
    """Each node's share of its ply's area (mm²): a quarter of every unit cell around it."""
    c = np.pad(grid.cells, 1).astype(float)
    share = 0.25 * grid.cell_mm**2 * (c[:-1, :-1] + c[1:, :-1] + c[:-1, 1:] + c[1:, 1:])
    flat = share.T.ravel()
    return flat if not grid.clipped else flat[grid.present.T.ravel()]


def _corners(grid: TrussGrid, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Node indices (n, 4) of the corners of unit cells (i, j), in the bilinear order."""
    lattice = np.column_stack([grid.node(i, j), grid.node(i + 1, j), grid.node(i + 1, j + 1),
                               grid.node(i, j + 1)])
    return (np.cumsum(grid.present.T.ravel()) - 1)[lattice] if grid.clipped else lattice


def _bilinear(ξ: np.ndarray, η: np.ndarray) -> np.ndarray:
    """The bilinear weights (n, 4) of the corners at local coordinates (ξ, η) ∈ [0, 1]²."""
    return np.column_stack([(1 - ξ) * (1 - η), ξ * (1 - η), ξ * η, (1 - ξ) * η])


def _local_coordinates(xc: np.ndarray, xa: np.ndarray, iterations: int = 3) -> np.ndarray:
    """Local coordinates (ξ, η) (n, 2) of the points of bilinear cells nearest given points.

    The cells have corners ``xc`` (n, 4, 3), the points are ``xa`` (n, 3); Gauss-Newton from
    the cells' centres (the answer may leave [0, 1]²: the point is beyond the cell).
    """
    q = np.full((len(xa), 2), 0.5)
    for _ in range(iterations):
        w = _bilinear(*q.T)
        r = np.einsum("nk,nki->ni", w, xc) - xa
        ξ, η = q.T
        dξ = np.einsum("nk,nki->ni", np.column_stack([η - 1, 1 - η, η, -η]), xc)
        dη = np.einsum("nk,nki->ni", np.column_stack([ξ - 1, -ξ, ξ, 1 - ξ]), xc)
        Jm = np.stack([dξ, dη], axis=2)  # (n, 3, 2)
        q = q - np.linalg.solve(np.einsum("nia,nib->nab", Jm, Jm),
                                np.einsum("nia,ni->na", Jm, r)[..., None])[..., 0]
    return q


def _partners(lower: TrussGrid, xy: np.ndarray, tol: float = 1e-9):
    """Corners (n, 4) as node indices of ``lower``, bilinear weights and cells of points ``xy``.

    Rows of points over no unit cell of ``lower`` are −1.
    """
    ij = lower.grid_coordinates(xy)
    lo = np.clip(np.floor(ij + tol).astype(int), 0, [lower.nx - 1, lower.ny - 1])
    ξ, η = (ij - lo).T
    inside = ((ξ > -tol) & (ξ < 1 + tol) & (η > -tol) & (η < 1 + tol)
              & lower.cells[lo[:, 0], lo[:, 1]])
    corners = _corners(lower, *lo.T)
    corners[~inside] = -1
    return corners, _bilinear(np.clip(ξ, 0, 1), np.clip(η, 0, 1)), lo


class PlyContact:
    """Contact and inter-ply friction between the adjacent plies of a stack.

    A coupling term of :class:`~fenicsx_drape.fe.solver.TrussProblem` (module docstring): like
    a nodal term it gives forces, and its stiffness couples nodes of two plies, given as
    3 × 3 blocks (``values``) on the pattern ``pattern`` (CSR over the owned nodes, columns
    global node indices), which grows (``pattern_version``) when the pairs follow the plies.
    Under MPI its pair arrays (``a``, ``J``, ``state``, ...) hold the rank's pairs, in global
    node indices; :meth:`summary` gives every pair.

    Args:
        plies: The stack (:func:`stack_plies`), as meshed by :func:`stack_sheet`.
        law: The inter-ply law (one for every interface).
        normal_stiffness_N_per_mm: The penalty k_n on a node's gap (N/mm).
        follow: Re-pair the nodes after every step with the point now under them
            (:meth:`follow`); by default a pair keeps its partner point of the flat stack
            (following, on the hemisphere's 30 mm net, let two frictionless plies at 0° form
            unalike, 26° and 34° of shear where each forms as one ply, 31°: a node sliding
            on the coarse facets of the ply below).
            One rank only (a :class:`~fenicsx_drape.errors.DrapeInputError` on more).
    """

    def __init__(self, plies: list[Ply], law: InterplyLaw,
                 normal_stiffness_N_per_mm: float, follow: bool = False) -> None:
        if not (np.isfinite(normal_stiffness_N_per_mm) and normal_stiffness_N_per_mm > 0):
            raise DrapeInputError(f"PlyContact: normal_stiffness_N_per_mm = "
                                  f"{normal_stiffness_N_per_mm} must be > 0")
        self.plies = list(plies)
        self.law = law
        self.k_n = float(normal_stiffness_N_per_mm)
        self.follows = bool(follow)

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """Pair every node of ply k + 1 with its partner point on ply k (reference stack).

        Pairs are made over the whole stack, by global node index (the same on every rank);
        a rank keeps the pairs that touch a node it owns (module docstring, MPI).
        """
        from scipy.spatial import cKDTree

        self.comm = comm if comm is not None and comm.size > 1 else None
        X = np.asarray(X, dtype=float)
        if self.comm is None:
            self.n_owned, first, self._local_global = len(X), 0, None
        else:
            if self.follows:
                raise DrapeInputError("PlyContact(follow=True) runs on one rank (re-made "
                                      "pairs would cross the partition); run without "
                                      "mpirun or without follow")
            self.n_owned = int(np.count_nonzero(owned))
            first = self.comm.exscan(self.n_owned) or 0
            self._counts = np.array(self.comm.allgather(3 * self.n_owned))
        self.X = X if self.comm is None else self._gather(X)  # every node, global order
        n = len(self.X)
        self.owned_range = (first, first + self.n_owned)
        tree = cKDTree(self.X)
        if self.comm is not None:  # the global index of each local node (ghosts by place)
            dist, self._local_global = tree.query(X)
            if (dist > 1e-6 * self.plies[0].grid.cell_mm).any():
                raise DrapeInputError("PlyContact: the mesh is not the stack of these plies")
        local = []  # each ply's nodes (grid order) → global node index
        for ply in self.plies:
            xyz = ply.grid.nodes.copy()
            xyz[:, 2] = ply.z_mm
            dist, idx = tree.query(xyz)
            if (dist > 1e-6 * ply.grid.cell_mm).any():
                raise DrapeInputError("PlyContact: the mesh is not the stack of these plies")
            local.append(idx)
        self._local = local
        a, J, w, cell, area, h, face = [], [], [], [], [], [], []
        for k in range(1, len(self.plies)):
            upper, lower = self.plies[k], self.plies[k - 1]
            corners, weights, lo = _partners(lower.grid, upper.grid.nodes[:, :2])
            keep = corners[:, 0] >= 0
            a.append(local[k][keep])
            J.append(local[k - 1][corners[keep]])
            w.append(weights[keep])
            cell.append(lo[keep])
            area.append(node_areas(upper.grid)[keep])
            h.append(np.full(keep.sum(), upper.z_mm - lower.z_mm))
            face.append(np.full(keep.sum(), k - 1))
        self.a = np.concatenate(a) if a else np.zeros(0, int)
        self.J = np.concatenate(J) if J else np.zeros((0, 4), int)
        self.w = np.concatenate(w) if w else np.zeros((0, 4))
        self.cell = np.concatenate(cell) if cell else np.zeros((0, 2), int)  # partner's (i, j)
        self.area = np.concatenate(area) if area else np.zeros(0)
        self.h = np.concatenate(h) if h else np.zeros(0)
        # The interface of each pair: 0 between plies 1 and 2, ...
        self.interface = np.concatenate(face) if face else np.zeros(0, int)
        self.pair_id = np.arange(len(self.a))  # the pair's place in the whole stack's list
        if self.comm is not None:  # the pairs that touch an owned node, in the stack's order
            mine = ((self.J >= first) & (self.J < first + self.n_owned)).any(axis=1)
            mine |= (self.a >= first) & (self.a < first + self.n_owned)
            for name in ("a", "J", "w", "cell", "area", "h", "interface", "pair_id"):
                setattr(self, name, getattr(self, name)[mine])
        self.pairs_global = int(sum(len(i) for i in a))
        self.d0 = self.X[self.a] - np.einsum("pj,pji->pi", self.w, self.X[self.J])
        self.state = self.law.initial_state(len(self.a), 3)
        self._trial = None
        self._keys = np.zeros(0, dtype=np.int64)
        self._n = n
        self.pattern_version = 0  # grows by one when the pattern grows (pairs followed)
        self._build_pattern()
        self._normals(self.X)
        self.pressure_MPa = np.zeros(len(self.a))
        self.slip_mm = np.zeros((len(self.a), 3))
        if self.comm is not None:  # the last commit's pairs over all ranks (summary)
            self._x_committed = self.X
            self._gathered = self._gather_pairs()

    def _gather(self, x: np.ndarray) -> np.ndarray:
        """The owned rows of ``x`` (n, 3) of every rank, in global node order (collective)."""
        out = np.empty((int(self._counts.sum()) // 3, 3))
        self.comm.Allgatherv(np.ascontiguousarray(x[: self.n_owned]), [out, self._counts])
        return out

    def _build_pattern(self) -> None:
        """The blocks the pairs couple, added to the pattern (which only grows).

        A pair couples its node and the partner's corners of nonzero weight with each other
        (for identical nets, at first only the node under it: less fill).
        """
        n, (first, end) = self._n, self.owned_range
        nodes = np.column_stack([self.a, self.J])  # (p, 5)
        live = np.column_stack([np.ones(len(self.a), bool), self.w > 1e-12])
        rows_live = live & (nodes >= first) & (nodes < end)  # a rank fills its own rows
        self._live = rows_live[:, :, None] & live[:, None, :]  # (p, 5, 5)
        rows = np.broadcast_to(nodes[:, :, None] - first, self._live.shape)[self._live]
        cols = np.broadcast_to(nodes[:, None, :], self._live.shape)[self._live]
        keys = rows.astype(np.int64) * n + cols
        union = np.union1d(self._keys, keys)
        if len(union) != len(self._keys) or not self.pattern_version:
            self._keys = union
            r, c = np.divmod(union, n)
            self.pattern = (np.searchsorted(r, np.arange(end - first + 1)).astype(np.int32),
                            c.astype(np.int32))
            self.pattern_version += 1
        # Each live block (pair, node i, node j) and the slot of the pattern it adds to, as a
        # sparse sum: the blocks of all pairs go to their slots in one product.
        from scipy.sparse import csr_matrix

        self._live_at = np.nonzero(self._live)
        slot = np.searchsorted(self._keys, keys)
        self._to_slots = csr_matrix((np.ones(len(slot)), (slot, np.arange(len(slot)))),
                                    shape=(len(self._keys), len(slot)))
        self._c, self._G = np.zeros((len(self.a), 5)), np.zeros((len(self.a), 3, 3))

    def follow(self, x: np.ndarray) -> None:
        """Re-pair every node with the point of the ply below that lies under it now.

        The slip carries over (the new partner's reference gap is set so that s is
        unchanged); a node that slid more than half a cell off the ply below loses its pair.
        """
        keep = np.ones(len(self.a), bool)
        for k in range(1, len(self.plies)):
            on = np.flatnonzero(self.interface == k - 1)
            if not len(on):
                continue
            grid, local = self.plies[k - 1].grid, self._local[k - 1]
            cell = self.cell[on].copy()
            for _ in range(3):  # walk to the cell under the node
                corners = local[_corners(grid, cell[:, 0], cell[:, 1])]
                q = _local_coordinates(x[corners], x[self.a[on]])
                step = np.floor(q).astype(int)
                cell = np.clip(cell + step, 0, [grid.nx - 1, grid.ny - 1])
            corners = local[_corners(grid, cell[:, 0], cell[:, 1])]
            q = _local_coordinates(x[corners], x[self.a[on]])
            # Kept while the node's half cell still overlaps the ply below (at its edge the
            # partner point stays on the edge).
            inside = ((q > -0.5) & (q < 1.5)).all(axis=1) & grid.cells[cell[:, 0], cell[:, 1]]
            keep[on[~inside]] = False
            self.cell[on], self.J[on] = cell, corners
            self.w[on] = _bilinear(*np.clip(q, 0.0, 1.0).T)
        d = x[self.a] - np.einsum("pj,pji->pi", self.w, x[self.J])
        self.d0 = d - self.slip_mm
        if not keep.all():
            for name in ("a", "J", "w", "cell", "area", "h", "interface", "d0", "state",
                         "pressure_MPa", "slip_mm"):
                setattr(self, name, getattr(self, name)[keep])
        self._build_pattern()

    def _normals(self, x: np.ndarray) -> None:
        """Unit normals of the partner cells (cross product of their diagonals)."""
        xj = x[self.J]
        nrm = np.cross(xj[:, 2] - xj[:, 0], xj[:, 3] - xj[:, 1])
        self.n = nrm / np.linalg.norm(nrm, axis=1)[:, None]

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Forces (n, 3) in N; the stiffness goes to :attr:`values` (the diagonal is zero)."""
        local = len(x)
        x = x if self.comm is None else self._gather(x)
        nn = len(x)
        f = np.zeros((nn, 3))
        p_count = len(self.a)
        if not p_count:
            self.f = f if self.comm is None else f[self._local_global]
            return self.f, np.zeros((local, 3, 3))
        n = self.n
        d = x[self.a] - np.einsum("pj,pji->pi", self.w, x[self.J])
        g = np.einsum("pi,pi->p", n, d) - self.h
        bonded = not self.law.interply_friction
        # Touching plies (g ≤ 0, and within 1e-6 of h above: the flat stack starts so) keep
        # the penalty's stiffness, so a stack that only just touches is not singular.
        touch = np.ones(p_count, bool) if bonded else g < 1e-6 * self.h
        f_n = np.where(touch, -self.k_n * np.minimum(g, 0.0) if not bonded else -self.k_n * g, 0.0)
        p = np.maximum(f_n, 0.0) / self.area
        P = np.eye(3) - np.einsum("pi,pj->pij", n, n)
        s = np.einsum("pij,pj->pi", P, d - self.d0)
        state = self.state.copy()
        state[:, :3] = np.einsum("pij,pj->pi", P, state[:, :3])
        state[:, 3:] = np.einsum("pij,pj->pi", P, state[:, 3:])
        out = self.law.traction(s, p, dt, state)
        f_a = f_n[:, None] * n - self.area[:, None] * out.tau
        # G = −∂f_a/∂d: penalty, friction through s and through the pressure.
        k_touch = np.where(touch, self.k_n, 0.0)[:, None, None]
        nn_T = np.einsum("pi,pj->pij", n, n)
        pressed = (f_n > 0.0)[:, None, None]
        G = (k_touch * nn_T + self.area[:, None, None] * np.einsum("pik,pkj->pij", out.dtau_ds, P)
             - pressed * k_touch * np.einsum("pi,pj->pij", out.dtau_dp, n))
        c = np.column_stack([np.ones(p_count), -self.w])  # ∂d/∂x of the five nodes
        nodes = np.concatenate([self.a, self.J.ravel()])
        forces = np.concatenate([f_a, (-self.w[:, :, None] * f_a[:, None, :]).reshape(-1, 3)])
        for i in range(3):  # a scatter-add (bincount is much faster than ufunc.at)
            f[:, i] = np.bincount(nodes, forces[:, i], minlength=nn)
        self._c, self._G = c, G  # the blocks are made when the Jacobian asks (values)
        self._trial = (x.copy(), out.state, p, s)
        # The forces of the last evaluation (N), also on constrained nodes; on the local
        # nodes, whole on the owned ones (a ghost's may lack pairs other ranks hold).
        self.f = f if self.comm is None else f[self._local_global]
        return self.f, np.zeros((local, 3, 3))

    @property
    def values(self) -> np.ndarray:
        """The 3 × 3 blocks (N/mm) on :attr:`pattern` at the last :meth:`forces` call."""
        p, i, j = self._live_at
        if not len(p):
            return np.zeros((len(self._keys), 3, 3))
        blocks = (self._c[p, i] * self._c[p, j])[:, None] * self._G[p].reshape(-1, 9)
        return (self._to_slots @ blocks).reshape(-1, 3, 3)

    def commit(self) -> None:
        """Keep the pairs' slip; the normals follow the converged plies."""
        if self._trial is not None:
            x, self.state, self.pressure_MPa, self.slip_mm = self._trial
            self._trial = None
            if self.follows and len(self.a):
                self.follow(x)
            if len(self.a):
                self._normals(x)
            if self.comm is not None:
                self._x_committed = x
        if self.comm is not None:  # every rank commits (a rank may hold no pair)
            self._gathered = self._gather_pairs()

    def owned_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """The pairs whose node a this rank owns: a's local node index, and the pairs' mask.

        (Owned nodes come first in the local order, in the global order from the rank's
        first node; on one rank every pair, a itself.)
        """
        first, end = self.owned_range
        mine = (self.a >= first) & (self.a < end)
        return self.a[mine] - first, mine

    def _gather_pairs(self) -> tuple:
        """Interface, pressure, sliding and place (x, y) of every pair (collective).

        Each pair comes from the rank that owns its node a, in the stack's order.
        """
        _, mine = self.owned_pairs()
        parts = self.comm.allgather((self.pair_id[mine], self.interface[mine],
                                     self.pressure_MPa[mine], self.sliding_mm[mine],
                                     self._x_committed[self.a[mine], :2]))
        pid, *data = (np.concatenate(c) for c in zip(*parts))
        order = np.argsort(pid)
        return tuple(d[order] for d in data)

    def revert(self) -> None:
        """Forget the trial slip of a step that is cut back."""
        self._trial = None

    def summary(self, x: np.ndarray) -> list[dict]:
        """Per interface: pairs, pressed pairs, largest and mean pressure and sliding.

        ``x`` are the converged positions (for the pairs' places, ``xy``).
        """
        out = []
        if self.comm is None:
            face, pressure, sliding, xy = (self.interface, self.pressure_MPa, self.sliding_mm,
                                           x[self.a, :2])
        else:  # every pair once, at the last commit (x, local, lacks other ranks' nodes)
            face, pressure, sliding, xy = self._gathered
        sliding = np.linalg.norm(sliding, axis=1)
        for k in range(len(self.plies) - 1):
            on = face == k
            p, s = pressure[on], sliding[on]
            pressed = p > 0
            out.append({"interface": f"ply{k + 1}/ply{k + 2}", "pairs": int(on.sum()),
                        "pressed_pairs": int(pressed.sum()),
                        "max_pressure_MPa": float(p.max(initial=0.0)),
                        "mean_pressure_MPa": float(p[pressed].mean()) if pressed.any() else 0.0,
                        "max_sliding_mm": float(s.max(initial=0.0)),
                        "mean_sliding_mm": float(s.mean()) if len(s) else 0.0,
                        "sliding_fraction": float((s > 1e-9).mean()) if len(s) else 0.0,
                        "xy": xy[on], "sliding_mm": s, "pressure_MPa": p})
        return out

    @property
    def sliding_mm(self) -> np.ndarray:
        """Plastic (sliding) slip of every pair (p, 3) in mm, at the last converged step."""
        return self.state[:, :3]

