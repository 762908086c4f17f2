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
path (no gathering). Following the plies (``follow``), every rank re-makes every pair from
the same gathered positions; the pattern, its own rows only, grows on the ranks those rows
are on (``pattern_version`` counts it per rank), and the solver re-allocates the Jacobian
on every rank when it grew on any.
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


def _catmull_rom(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights (n, 4) of the Catmull-Rom curve through points −1, 0, 1, 2 at t ∈ [0, 1].

    The curve passes through points 0 and 1 with the tangents (p₁ − p₋₁)/2 and (p₂ − p₀)/2,
    so that the pieces of neighbouring intervals join with a continuous tangent (C¹). Also
    the weights' derivatives in t.
    """
    t2, t3 = t * t, t * t * t
    w = 0.5 * np.column_stack([-t3 + 2 * t2 - t, 3 * t3 - 5 * t2 + 2, -3 * t3 + 4 * t2 + t,
                               t3 - t2])
    dw = 0.5 * np.column_stack([-3 * t2 + 4 * t - 1, 9 * t2 - 10 * t, -9 * t2 + 8 * t + 1,
                                3 * t2 - 2 * t])
    return w, dw


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1)[:, None]


class _Surface:
    """The smooth surface of one ply at given node positions (C¹ across its cells).

    The tensor product of Catmull-Rom curves along the ply's warp and weft lines: it passes
    through every node, and its position and tangents are continuous from cell to cell, so
    the gap and the normal of a node sliding over it vary smoothly where the bilinear cells
    of the net would kink. Each cell uses the 4 × 4 nodes around it; beyond the ply's edge
    the lattice is extended linearly (mirrored on a symmetry plane), and a cell whose 4 × 4
    nodes cannot be completed (the ragged edge of a turned ply) is its bilinear cell.
    """

    def __init__(self, grid: TrussGrid, lattice: np.ndarray, x: np.ndarray) -> None:
        self.grid = grid
        nx, ny = grid.nx, grid.ny
        P = np.full((nx + 3, ny + 3, 3), np.nan)
        there = lattice >= 0
        P[1:-1, 1:-1][there] = x[lattice[there]]
        planes = grid.planes
        for _ in range(2):  # twice: the corners of the extension need both directions
            for axis, plane in ((0, "x"), (1, "y")):
                Q = np.moveaxis(P, axis, 0)  # a view: filling Q fills P
                miss = np.isnan(Q[..., 0])
                ahead = np.full_like(Q, np.nan)
                ahead[:-2] = 2 * Q[1:-1] - Q[2:]
                behind = np.full_like(Q, np.nan)
                behind[2:] = 2 * Q[1:-1] - Q[:-2]
                guess = np.where(np.isfinite(ahead), ahead, behind)
                if plane in planes:  # the lattice mirrored in the plane x = 0 (or y = 0)
                    mirror = Q[2].copy()
                    mirror[..., axis] *= -1.0
                    guess[0] = mirror
                Q[miss] = guess[miss]
        self.P = P

    def at(self, cell: np.ndarray, q: np.ndarray):
        """Point, tangents along ξ and η, and the bilinear cell's point at (cell, q).

        Returns S, S_ξ, S_η and S_bilinear, each (p, 3).
        """
        i, j = cell[:, 0], cell[:, 1]
        wi, dwi = _catmull_rom(q[:, 0])
        wj, dwj = _catmull_rom(q[:, 1])
        k = np.arange(4)
        st = self.P[(i[:, None] + k)[:, :, None], (j[:, None] + k)[:, None, :]]  # (p, 4, 4, 3)
        c00, c10, c11, c01 = st[:, 1, 1], st[:, 2, 1], st[:, 2, 2], st[:, 1, 2]
        ξ, η = q[:, :1], q[:, 1:]
        bil = (1 - ξ) * (1 - η) * c00 + ξ * (1 - η) * c10 + ξ * η * c11 + (1 - ξ) * η * c01
        smooth = np.isfinite(st).all(axis=(1, 2, 3))
        st = np.where(smooth[:, None, None, None], st, 0.0)
        S = np.einsum("pa,pb,pabk->pk", wi, wj, st)
        Su = np.einsum("pa,pb,pabk->pk", dwi, wj, st)
        Sv = np.einsum("pa,pb,pabk->pk", wi, dwj, st)
        rough = ~smooth[:, None]
        S = np.where(rough, bil, S)
        Su = np.where(rough, (1 - η) * (c10 - c00) + η * (c11 - c01), Su)
        Sv = np.where(rough, (1 - ξ) * (c01 - c00) + ξ * (c11 - c10), Sv)
        return S, Su, Sv, bil

    def project(self, xa: np.ndarray, cell: np.ndarray, q: np.ndarray, walks: int = 6):
        """The point of the surface nearest each point ``xa`` (p, 3), from cells and (ξ, η).

        Gauss-Newton in the cell, then a step to the neighbouring cell while (ξ, η) leaves
        [0, 1]² (up to ``walks`` cells). Returns the cells and (ξ, η), outside [0, 1]² where
        the point lies beyond the ply's edge (:func:`overlap`).
        """
        grid = self.grid
        cell, q = cell.copy(), q.copy()
        todo = np.ones(len(xa), bool)
        for _ in range(walks):
            idx = np.flatnonzero(todo)
            if not len(idx):
                break
            c, s = cell[idx], q[idx]
            for _ in range(3):
                S, Su, Sv, _ = self.at(c, s)
                r = S - xa[idx]
                a, b, d = (np.einsum("pi,pi->p", u, v) for u, v in ((Su, Su), (Su, Sv),
                                                                    (Sv, Sv)))
                ga, gb = np.einsum("pi,pi->p", Su, r), np.einsum("pi,pi->p", Sv, r)
                det = a * d - b * b
                det = np.where(np.abs(det) > 1e-300, det, 1.0)
                s = np.clip(s - np.column_stack([d * ga - b * gb, a * gb - b * ga]) / det[:, None],
                            -1.0, 2.0)
            step = np.where(s < 0.0, -1, np.where(s >= 1.0, 1, 0))
            new = np.clip(c + step, 0, [grid.nx - 1, grid.ny - 1])
            new = np.where(grid.cells[new[:, 0], new[:, 1]][:, None], new, c)
            moved = (new != c).any(axis=1)
            s[moved] -= (new - c)[moved]
            cell[idx], q[idx] = new, s
            todo[idx[~moved]] = False
        return cell, q


def overlap(grid: TrussGrid, cell: np.ndarray, q: np.ndarray,
            sides: np.ndarray | None = None) -> np.ndarray:
    """The share of each upper node's area that lies over the ply below (p,), in [0, 1].

    A node at (ξ, η) of a cell of the lower ply's net has its area from ξ − l to ξ + r (and
    alike in η; ``sides`` (p, 4) the node's (l_ξ, r_ξ, l_η, r_η) in cells: ½ where its own ply
    has cells on that side, else 0; default ½ each, a node inside its ply). Beyond the lower
    ply's edge (a side of the cell with no cell beyond it, other than a symmetry plane) that
    part is not over the ply. So a node fades out of the contact over a cell as it slides
    off the ply, and the shares of a sliding ply's nodes add up to the area over the ply
    below, as under a pull-out's plates.
    """
    i, j = cell[:, 0], cell[:, 1]
    c = np.pad(grid.cells, 1)  # cell (i, j) at [i + 1, j + 1]; none beyond the net
    planes = grid.planes
    if "x" in planes:
        c[0, :] = c[1, :]
    if "y" in planes:
        c[:, 0] = c[:, 1]
    sides = np.full((len(cell), 4), 0.5) if sides is None else sides
    ω = np.ones(len(cell))
    for k, before, after in ((0, c[i, j + 1], c[i + 2, j + 1]), (1, c[i + 1, j], c[i + 1, j + 2])):
        left, right = q[:, k] - sides[:, 2 * k], q[:, k] + sides[:, 2 * k + 1]
        width = right - left
        lo = np.where(before, left, np.maximum(left, 0.0))  # cut at the lower ply's edges
        hi = np.where(after, right, np.minimum(right, 1.0))
        ω = ω * np.clip(hi - lo, 0.0, None) / np.where(width > 0, width, 1.0)
    return ω * grid.cells[i, j]


def _sides(upper: TrussGrid, lower: TrussGrid) -> np.ndarray:
    """Each node of ``upper``: how far (cells) its area reaches along ``lower``'s ±ξ, ±η.

    ½ where the upper ply has cells on that side, else 0, when the two nets are parallel;
    ½ every way otherwise (the area of a turned net is not a box of the lower net's).
    """
    n = len(upper.nodes)
    if abs(upper.rotation_deg - lower.rotation_deg) > 1e-9:
        return np.full((n, 4), 0.5)
    c = np.pad(upper.cells, 1)
    planes = upper.planes
    if "x" in planes:
        c[0, :] = c[1, :]
    if "y" in planes:
        c[:, 0] = c[:, 1]
    i, j = upper.ij.T
    return 0.5 * np.column_stack([c[i, j] | c[i, j + 1], c[i + 1, j] | c[i + 1, j + 1],
                                  c[i, j] | c[i + 1, j], c[i, j + 1] | c[i + 1, j + 1]])


class PlyContact:
    """Contact and inter-ply friction between the adjacent plies of a stack.

    A coupling term of :class:`~fenicsx_drape.fe.solver.TrussProblem` (module docstring): like
    a nodal term it gives forces, and its stiffness couples nodes of two plies, given as
    3 × 3 blocks (``values``) on the pattern ``pattern`` (CSR over the owned nodes, columns
    global node indices), which grows (``pattern_version``) as the pairs follow the plies.
    Every rank holds every pair (arrays over the whole stack, in the stack's order: ply 2's
    nodes in grid order, then ply 3's, ...); ``active`` marks the pairs whose node lies over
    the ply below.

    Args:
        plies: The stack (:func:`stack_plies`), as meshed by :func:`stack_sheet`.
        law: The inter-ply law (one for every interface).
        normal_stiffness_N_per_mm: The penalty k_n on a node's gap (N/mm).
        follow: Re-pair the nodes after every step with the point of the ply below that is
            now nearest them (:meth:`follow`; bonded plies keep their partners, they do not
            slide). False: a pair keeps its partner point of the flat stack (right while the
            plies slide by less than a cell).
    """

    def __init__(self, plies: list[Ply], law: InterplyLaw,
                 normal_stiffness_N_per_mm: float, follow: bool = True) -> None:
        if not (np.isfinite(normal_stiffness_N_per_mm) and normal_stiffness_N_per_mm > 0):
            raise DrapeInputError(f"PlyContact: normal_stiffness_N_per_mm = "
                                  f"{normal_stiffness_N_per_mm} must be > 0")
        self.plies = list(plies)
        self.law = law
        self.k_n = float(normal_stiffness_N_per_mm)
        self.follows = bool(follow) and law.interply_friction

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """Pair every node of ply k + 1 with its partner point on ply k (reference stack).

        Pairs are made over the whole stack, by global node index, the same on every rank.
        """
        from scipy.spatial import cKDTree

        self.comm = comm if comm is not None and comm.size > 1 else None
        X = np.asarray(X, dtype=float)
        if self.comm is None:
            self.n_owned, first, self._local_global = len(X), 0, None
        else:
            self.n_owned = int(np.count_nonzero(owned))
            first = self.comm.exscan(self.n_owned) or 0
            self._counts = np.array(self.comm.allgather(3 * self.n_owned))
        self.X = X if self.comm is None else self._gather(X)  # every node, global order
        n = len(self.X)
        self.owned_range = (first, first + self.n_owned)
        tree = cKDTree(self.X)
        cell_mm = self.plies[0].grid.cell_mm
        if self.comm is not None:  # the global index of each local node (ghosts by place)
            dist, self._local_global = tree.query(X)
            if (dist > 1e-6 * cell_mm).any():
                raise DrapeInputError("PlyContact: the mesh is not the stack of these plies")
        self._lattice = []  # each ply's lattice (nx + 1, ny + 1) → global node index, or −1
        local = []
        for ply in self.plies:
            xyz = ply.grid.nodes.copy()
            xyz[:, 2] = ply.z_mm
            dist, idx = tree.query(xyz)
            if (dist > 1e-6 * ply.grid.cell_mm).any():
                raise DrapeInputError("PlyContact: the mesh is not the stack of these plies")
            local.append(idx)
            lattice = np.full((ply.grid.nx + 1, ply.grid.ny + 1), -1, dtype=np.int64)
            ij = ply.grid.ij
            lattice[ij[:, 0], ij[:, 1]] = idx
            self._lattice.append(lattice)
        a, cell, q, active, area, h, face, side = [], [], [], [], [], [], [], []
        for k in range(1, len(self.plies)):
            upper, lower = self.plies[k], self.plies[k - 1]
            _, _, lo = _partners(lower.grid, upper.grid.nodes[:, :2])
            ij = lower.grid.grid_coordinates(upper.grid.nodes[:, :2])
            a.append(local[k])
            cell.append(lo)
            q.append(ij - lo)
            side.append(_sides(upper.grid, lower.grid))
            active.append(overlap(lower.grid, lo, ij - lo, side[-1]))
            area.append(node_areas(upper.grid))
            h.append(np.full(len(local[k]), upper.z_mm - lower.z_mm))
            face.append(np.full(len(local[k]), k - 1))

        def joined(parts, empty):
            return np.concatenate(parts) if parts else empty

        self.a = joined(a, np.zeros(0, np.int64))
        self.cell = joined(cell, np.zeros((0, 2), int))  # partner's cell (i, j) on the ply below
        self.q = joined(q, np.zeros((0, 2)))  # and its local coordinates (ξ, η) there
        self.overlap = joined(active, np.zeros(0))  # the share of a's area over the ply below
        self.sides = joined(side, np.zeros((0, 4)))  # how far a's area reaches (overlap)
        self.active = self.overlap > 0.0
        self.area = joined(area, np.zeros(0))
        self.h = joined(h, np.zeros(0))
        self.interface = joined(face, np.zeros(0, int))  # 0 between plies 1 and 2, ...
        p = len(self.a)
        self.pairs_global = int(self.active.sum())
        self.state = self.law.initial_state(p, 3)
        self.pressure_MPa = np.zeros(p)
        self.slip_mm = np.zeros((p, 3))
        self._n = n
        self._keys = np.zeros(0, dtype=np.int64)
        self.pattern_version = 0  # +1 when this rank's rows of the pattern grow
        self._trial = None
        self._dt_last = 0.0
        self._partner(self.X)
        self.d0 = self._gap_vector(self.X)
        self._x_committed = self.X
        # The stack moving as one: each node of ply 2, 3, ... on ply 1 (stack_solver).
        self._first = local[0]
        self._upper = np.concatenate(local[1:]) if len(local) > 1 else np.zeros(0, np.int64)
        first = self.plies[0].grid
        upper_xy = np.concatenate([p.grid.nodes[:, :2] for p in self.plies[1:]]) \
            if len(local) > 1 else np.zeros((0, 2))
        _, _, lo = _partners(first, upper_xy)
        self._to_first_cell = lo
        self._to_first_q = first.grid_coordinates(upper_xy) - lo
        self._map_to_first(self.X)

    def _gather(self, x: np.ndarray) -> np.ndarray:
        """The owned rows of ``x`` (n, 3) of every rank, in global node order (collective)."""
        out = np.empty((int(self._counts.sum()) // 3, 3))
        self.comm.Allgatherv(np.ascontiguousarray(x[: self.n_owned]), [out, self._counts])
        return out

    def _partner(self, x: np.ndarray, before: np.ndarray | None = None) -> None:
        """Corners, weights, correction and normal of every pair's point at positions ``x``.

        The partner point is x_p = Σ w_J x_J + δ: the bilinear point of its cell plus the
        smooth surface's offset from it (δ, and the normal n, are those of the positions
        ``x``, the last converged step's; over the next step the normal turns on at the rate
        it turned from the positions ``before``, the step before), then :meth:`_build_pattern`.
        """
        p = len(self.a)
        self.J = np.zeros((p, 4), np.int64)
        self.w = np.zeros((p, 4))
        self.delta = np.zeros((p, 3))
        self.n = np.tile([0.0, 0.0, 1.0], (p, 1))  # the smooth surface's, last step
        self.n_rate = np.zeros((p, 3))  # and its change over that step
        for k in range(1, len(self.plies)):
            on = np.flatnonzero((self.interface == k - 1) & self.active)
            if not len(on):
                continue
            grid, lattice = self.plies[k - 1].grid, self._lattice[k - 1]
            i, j = self.cell[on].T
            self.J[on] = np.column_stack([lattice[i, j], lattice[i + 1, j],
                                          lattice[i + 1, j + 1], lattice[i, j + 1]])
            q = np.clip(self.q[on], 0.0, 1.0)  # beyond the edge: the edge's point
            self.w[on] = _bilinear(*q.T)
            S, Su, Sv, bil = _Surface(grid, lattice, x).at(self.cell[on], q)
            self.delta[on] = S - bil
            self.n[on] = _unit(np.cross(Su, Sv))
            if before is not None:  # the same points of the ply below a step earlier
                _, Su, Sv, _ = _Surface(grid, lattice, before).at(self.cell[on], q)
                self.n_rate[on] = self.n[on] - _unit(np.cross(Su, Sv))
        self._on = np.flatnonzero(self.active)
        self._build_pattern()
        self._weigh_slots()

    def _gap_vector(self, x: np.ndarray) -> np.ndarray:
        """The gap vectors d = x_a − x_p (p, 3) (zero for the pairs that are not active)."""
        return np.where(self.active[:, None], x[self.a] - np.einsum(
            "pj,pji->pi", self.w, x[self.J]) - self.delta, 0.0)

    def _build_pattern(self) -> None:
        """The blocks the active pairs couple, added to the pattern (which only grows).

        A pair couples its node and the partner's corners of nonzero weight with each other
        (for identical nets, at first only the node under it: less fill). Unchanged pairs
        keep the pattern as it is.
        """
        n, (first, end) = self._n, self.owned_range
        on = self._on
        nodes = np.column_stack([self.a[on], self.J[on]])  # (p, 5)
        live = np.column_stack([np.ones(len(on), bool), self.w[on] > 1e-12])
        key = (nodes.tobytes(), live.tobytes())
        if key == getattr(self, "_pattern_key", None):
            return
        self._pattern_key = key
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
        # Each live block (pair, node i, node j) and the slot of the pattern it adds to
        # (_weigh_slots makes the sparse sum).
        self._live_at = np.nonzero(self._live)
        self._slot = np.searchsorted(self._keys, keys)
        self._G = np.zeros((len(on), 3, 3))

    def _weigh_slots(self) -> None:
        """The sparse map of the pairs' −∂f/∂d blocks G (p, 9) to the pattern's slots.

        Block (node i, node j) of pair p is c_i c_j G_p, with c = (1, −w) the derivatives of
        d by the five nodes' positions; the weights are fixed within a step, so the Jacobian
        is one sparse product a Newton iteration.
        """
        from scipy.sparse import csr_matrix

        p, i, j = self._live_at
        c = np.column_stack([np.ones(len(self._on)), -self.w[self._on]])
        self._to_slots = csr_matrix((c[p, i] * c[p, j], (self._slot, p)),
                                    shape=(len(self._keys), len(self._on)))

    def follow(self, x: np.ndarray) -> None:
        """Re-pair every node with the point of the ply below nearest it now (positions ``x``).

        The slip carries over: the new partner's reference gap d₀ is set so that the slip
        s = P (d − d₀) is unchanged. A node beyond the edge of the ply below (more than half
        a cell) loses its pair; one that comes back over it is paired again, unslipped.
        """
        was = self.active.copy()
        for k in range(1, len(self.plies)):
            on = np.flatnonzero(self.interface == k - 1)
            if not len(on):
                continue
            grid = self.plies[k - 1].grid
            surface = _Surface(grid, self._lattice[k - 1], x)
            cell, q = surface.project(x[self.a[on]], self.cell[on], self.q[on])
            self.cell[on], self.q[on] = cell, q
            self.overlap[on] = overlap(grid, cell, q, self.sides[on])
        self.active = self.overlap > 0.0
        fresh = self.active & ~was
        self.state[fresh] = 0.0
        self.slip_mm[fresh] = 0.0
        self.pressure_MPa[~self.active] = 0.0

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Forces (n, 3) in N; the stiffness goes to :attr:`values` (the diagonal is zero)."""
        local = len(x)
        x = x if self.comm is None else self._gather(x)
        nn = len(x)
        f = np.zeros((nn, 3))
        on = self._on
        p_count = len(on)
        if not p_count:
            self._trial = (x.copy(), self.state[on], np.zeros(0), np.zeros((0, 3)), dt)
            self.f = f if self.comm is None else f[self._local_global]
            return self.f, np.zeros((local, 3, 3))
        a, J, w = self.a[on], self.J[on], self.w[on]
        ω, h = self.overlap[on], self.h[on]
        area = self.area[on] * ω  # the node's area over the ply below
        # The normal over the step: the last step's, turned on at the rate it turned then
        # (a normal lagged by a step pushed plies that wrap a tool along each other).
        n = self.n[on] + (dt / self._dt_last if self._dt_last else 0.0) * self.n_rate[on]
        n /= np.linalg.norm(n, axis=1)[:, None]
        d = x[a] - np.einsum("pj,pji->pi", w, x[J]) - self.delta[on]
        g = np.einsum("pi,pi->p", n, d) - h
        bonded = not self.law.interply_friction
        # Touching plies (g ≤ 0, and within 1e-6 of h above: the flat stack starts so) keep
        # the penalty's stiffness, so a stack that only just touches is not singular.
        touch = np.ones(p_count, bool) if bonded else g < 1e-6 * h
        k_n = self.k_n * ω  # a penalty per area: the pressure does not grow as ω fades
        f_n = np.where(touch, -k_n * np.minimum(g, 0.0) if not bonded else -k_n * g, 0.0)
        p = np.maximum(f_n, 0.0) / area
        P = np.eye(3) - np.einsum("pi,pj->pij", n, n)
        s = np.einsum("pij,pj->pi", P, d - self.d0[on])
        state = self.state[on].copy()
        state[:, :3] = np.einsum("pij,pj->pi", P, state[:, :3])
        state[:, 3:] = np.einsum("pij,pj->pi", P, state[:, 3:])
        out = self.law.traction(s, p, dt, state)
        f_a = f_n[:, None] * n - area[:, None] * out.tau
        # G = −∂f_a/∂d: penalty, friction through s and through the pressure.
        k_touch = np.where(touch, k_n, 0.0)[:, None, None]
        nn_T = np.einsum("pi,pj->pij", n, n)
        pressed = (f_n > 0.0)[:, None, None]
        G = (k_touch * nn_T + area[:, None, None] * np.einsum("pik,pkj->pij", out.dtau_ds, P)
             - pressed * k_touch * np.einsum("pi,pj->pij", out.dtau_dp, n))
        nodes = np.concatenate([a, J.ravel()])
        forces = np.concatenate([f_a, (-w[:, :, None] * f_a[:, None, :]).reshape(-1, 3)])
        for i in range(3):  # a scatter-add (bincount is much faster than ufunc.at)
            f[:, i] = np.bincount(nodes, forces[:, i], minlength=nn)
        self._G = G  # the blocks are made when the Jacobian asks (values)
        self._trial = (x.copy(), out.state, p, s, dt)
        # The forces of the last evaluation (N), also on constrained nodes; on the local
        # nodes (every pair is on every rank: whole on ghosts too).
        self.f = f if self.comm is None else f[self._local_global]
        return self.f, np.zeros((local, 3, 3))

    @property
    def values(self) -> np.ndarray:
        """The 3 × 3 blocks (N/mm) on :attr:`pattern` at the last :meth:`forces` call."""
        if not len(self._live_at[0]):
            return np.zeros((len(self._keys), 3, 3))
        return (self._to_slots @ self._G.reshape(-1, 9)).reshape(-1, 3, 3)

    def commit(self) -> None:
        """Keep the pairs' slip; the pairs follow the converged plies, and so do δ and n."""
        if self._trial is None:
            return
        x, state, pressure, slip, self._dt_last = self._trial
        self._trial = None
        on = self._on
        self.state[on], self.pressure_MPa[on], self.slip_mm[on] = state, pressure, slip
        if self.follows:
            self.follow(x)
        self._partner(x, self._x_committed)
        # The slip carries over the new partner point, normal and correction.
        self.d0 = self._gap_vector(x) - np.where(self.active[:, None], self.slip_mm, 0.0)
        self._x_committed = x
        self._map_to_first(x)

    def first_ply_nodes(self) -> np.ndarray:
        """The global node indices of ply 1, in its grid's order."""
        return self._first

    def first_ply_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every node of ply 2, 3, ...: its global index, and the point of ply 1 under it.

        Returns the nodes (m,), the corners of ply 1's cell under each (m, 4, global node
        indices) and their bilinear weights (m, 4), at the last converged step: the stack
        moving as one, for the solver (:mod:`~fenicsx_drape.fe.stack_solver`).
        """
        return self._upper, self._to_first_J, self._to_first_w

    def _map_to_first(self, x: np.ndarray) -> None:
        """Project the nodes of plies 2, 3, ... on ply 1's surface at positions ``x``."""
        grid, lattice = self.plies[0].grid, self._lattice[0]
        if not len(self._upper):
            return
        cell, q = _Surface(grid, lattice, x).project(x[self._upper], self._to_first_cell,
                                                     self._to_first_q)
        changed = not np.array_equal(cell, self._to_first_cell)
        self._to_first_cell, self._to_first_q = cell, q
        i, j = cell.T
        J = np.column_stack([lattice[i, j], lattice[i + 1, j], lattice[i + 1, j + 1],
                             lattice[i, j + 1]])
        self._to_first_J, self._to_first_w = J, _bilinear(*np.clip(q, 0.0, 1.0).T)
        if changed or not hasattr(self, "map_version"):
            self.map_version = getattr(self, "map_version", -1) + 1

    def owned_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """The active pairs whose node a this rank owns: a's local index, and the pairs' mask.

        (Owned nodes come first in the local order, in the global order from the rank's
        first node; on one rank every active pair, a itself.)
        """
        first, end = self.owned_range
        mine = (self.a >= first) & (self.a < end) & self.active
        return self.a[mine] - first, mine

    def revert(self) -> None:
        """Forget the trial slip of a step that is cut back."""
        self._trial = None

    def summary(self, x: np.ndarray | None = None) -> list[dict]:
        """Per interface: pairs, pressed pairs, largest and mean pressure and sliding.

        The pairs over the ply below at the last converged step, with their places (``xy``).
        ``x`` is not needed (every rank holds every pair); it is accepted for callers that
        give the converged positions.
        """
        out = []
        xy = self._x_committed[self.a, :2]
        sliding = np.linalg.norm(self.sliding_mm, axis=1)
        for k in range(len(self.plies) - 1):
            on = (self.interface == k) & self.active
            p, s = self.pressure_MPa[on], sliding[on]
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
