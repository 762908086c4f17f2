"""Bending stiffness of the tows: a discrete curvature energy along every tow line.

The paper's truss is pin-jointed: a flat or slack net has no stiffness out of its plane
(section 2.1; ``shared/NUMERICS.md``). A real tow resists bending. For three consecutive nodes
``a, b, c`` of a tow line (spacing Δ) the bending energy ∫ ½ EI κ² ds is discretised with the
second difference x'' ≈ (x_a − 2x_b + x_c)/Δ²::

    W = ½ k |x_a − 2 x_b + x_c|²,   k = w n_t EI / Δ³,

with ``EI`` the bending stiffness of one tow (N·mm²), ``n_t = l_t Δ`` the tows of the strip
and ``w`` its share (½ for edge strips). W is quadratic in the positions and vanishes on any
straight, evenly stretched tow line and under rigid motion, so the term is a constant matrix:
its force is ``−K u`` (the flat reference has K X = 0) and its stiffness ``K``. It also
resists in-plane bending and uneven stretch along a line, by amounts of order EI/Δ³ that are
negligible against the axial stiffness n_t E_o/Δ. Lines are not continued across the
symmetry planes of a quarter model (their bending there is left out: a lower bound).

Magnitude: a 3k carbon tow bending as loose fibres (7 µm, E = 230 GPa) has EI ≈ 0.08 N·mm²,
as a solid 1.3 mm × 0.15 mm section ≈ 50 N·mm²; the uncured prepreg's tow lies in between.
The default, ``SolverOptions.tow_bending_EI_Nmm2 = 2`` N·mm², is the geometric mean of these
bounds (a bending rigidity of 1.4 N·mm per mm of width at 0.71 tows/mm, the order of room-
temperature woven prepregs). The paper's truss has none; set 0 to remove it. Only sheets
built as structured grids (:func:`~fenicsx_drape.fe.mesh.truss_sheet`) have tow lines; a free
truss (:func:`~fenicsx_drape.fe.mesh.truss_mesh`) gets no bending term.
"""

from __future__ import annotations

from petsc4py import PETSc

import numpy as np

from fenicsx_drape.fe.grid import TrussGrid
from fenicsx_drape.fe.plies import sheet_grids


def stencils(grid: TrussGrid, edge_factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Node triplets (n, 3) of every tow line (lattice node indices) and their strip shares.

    A triplet needs both its bars in the sheet; its strip is an edge strip when a cell
    around its centre node is missing (the sheet's or a symmetry plane's edge, or the ragged
    edge of a clipped net).
    """
    triplets, shares = [], []
    bars = grid.tow_bars()
    c = np.pad(grid.cells, 1)
    whole = c[:-1, :-1] & c[1:, :-1] & c[:-1, 1:] & c[1:, 1:]  # the four cells around a node
    for axis, (n_along, n_across) in enumerate(((grid.nx, grid.ny), (grid.ny, grid.nx))):
        centre, line = np.meshgrid(np.arange(1, n_along), np.arange(n_across + 1),
                                   indexing="ij")
        ij = [centre, line] if axis == 0 else [line, centre]
        step = (1, 0) if axis == 0 else (0, 1)
        triplet = [grid.node(ij[0] + s * step[0], ij[1] + s * step[1]) for s in (-1, 0, 1)]
        keep = (bars[axis][ij[0] - step[0], ij[1] - step[1]] & bars[axis][ij[0], ij[1]]).ravel()
        triplets.append(np.stack([t.ravel() for t in triplet], axis=1)[keep])
        edge = ~whole[ij[0], ij[1]]
        shares.append(np.where(edge, edge_factor, 1.0).ravel()[keep])
    return np.concatenate(triplets), np.concatenate(shares)


class TowBending:
    """The bending matrix of a problem's tow lines, in the layout of its PETSc matrices.

    Args:
        problem: The :class:`~fenicsx_drape.fe.solver.TrussProblem` (a structured sheet, or a
            stack of them: each ply's tow lines).
        EI_Nmm2: Bending stiffness of one tow (N·mm²).
    """

    def __init__(self, problem, EI_Nmm2: float):
        comm = problem.comm
        n = problem.num_owned
        grids = sheet_grids(problem.sheet, problem.X[:n])
        if not grids:
            raise ValueError("tow bending needs a structured sheet (truss_sheet)")
        first = problem.V.dofmap.index_map.local_range[0]
        # The lattices of the plies one after the other (one lattice for one ply).
        flat = np.zeros(n, dtype=np.int64)
        offset, triplets, shares = 0, [], []
        for grid, on in grids:
            ij = np.rint(grid.grid_coordinates(problem.X[:n][on])).astype(np.int64)
            flat[on] = offset + grid.node(ij[:, 0], ij[:, 1])
            t, s = stencils(grid, problem.options.edge_tow_factor)
            triplets.append(t + offset)
            shares.append(s)
            offset += (grid.nx + 1) * (grid.ny + 1)
        triplets, shares = np.concatenate(triplets), np.concatenate(shares)
        # PETSc block index of every node of the sheet, on every rank.
        self.global_index = np.full(offset, -1, dtype=np.int64)
        for f, g in comm.allgather((flat, first + np.arange(n))):
            self.global_index[f] = g
        owned_rows = np.full(len(self.global_index), -1, dtype=np.int64)
        owned_rows[flat] = np.arange(n)
        self.flat = flat

        Δ = problem.sheet.cell_mm
        k = shares * problem.options.tows_per_mm * Δ * EI_Nmm2 / Δ**3
        w = np.array([1.0, -2.0, 1.0])
        rows = np.repeat(triplets, 3, axis=1).ravel()  # (a a a b b b c c c)
        cols = np.tile(triplets, (1, 3)).ravel()  # (a b c a b c a b c)
        vals = (k[:, None] * np.outer(w, w).ravel()).ravel()
        local = owned_rows[rows]
        keep = local >= 0
        rows, cols, vals = local[keep], self.global_index[cols[keep]], vals[keep]
        # Sum duplicates: one scalar per (row, column) block, rows sorted (CSR).
        order = np.lexsort((cols, rows))
        rows, cols, vals = rows[order], cols[order], vals[order]
        first_of = np.ones(len(rows), dtype=bool)
        first_of[1:] = (rows[1:] != rows[:-1]) | (cols[1:] != cols[:-1])
        starts = np.flatnonzero(first_of)
        self.rows, self.cols = rows[starts], cols[starts]
        self.scalars = np.add.reduceat(vals, starts) if len(vals) else vals
        self.indptr = np.searchsorted(self.rows, np.arange(n + 1)).astype(PETSc.IntType)
        free = np.ones((len(self.global_index), 3), dtype=bool)
        self.matrix = self._matrix(problem, free)  # K, for the force K u
        self.constrained_matrix = self._matrix(problem, free)  # K, constraints zeroed

    def matrix_values(self, free: np.ndarray) -> np.ndarray:
        """Block values (3×3 per block, flattened) with constrained rows and columns zeroed.

        ``free`` is shaped (n_nodes_of_the_sheet, 3), by flat node index.
        """
        row_free = free[self.flat][self.rows]  # (n_blocks, 3)
        col_flat = np.empty(len(self.global_index), dtype=np.int64)
        present = self.global_index >= 0  # lattice nodes of a clipped net may be absent
        col_flat[self.global_index[present]] = np.flatnonzero(present)
        col_free = free[col_flat[self.cols]]
        diag = self.scalars[:, None] * row_free * col_free
        blocks = np.zeros((len(self.scalars), 3, 3))
        blocks[:, [0, 1, 2], [0, 1, 2]] = diag
        return blocks.ravel()

    def _matrix(self, problem, free: np.ndarray) -> PETSc.Mat:
        n = problem.num_owned
        N = problem.V.dofmap.index_map.size_global
        A = PETSc.Mat().createAIJ(((3 * n, 3 * N), (3 * n, 3 * N)), bsize=3,
                                  comm=problem.comm)
        nnz = np.diff(self.indptr).max(initial=0)
        A.setPreallocationNNZ((3 * max(nnz, 1), 3 * max(nnz, 1)))
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        A.setValuesBlockedCSR(self.indptr, self.cols.astype(PETSc.IntType),
                              self.matrix_values(free), PETSc.InsertMode.ADD_VALUES)
        A.assemble()
        return A

    def constrain(self, problem) -> None:
        """Zero the rows and columns of the problem's constrained dofs in :meth:`add_to`."""
        n = problem.num_owned
        free = np.ones((len(self.global_index), 3), dtype=bool)
        for f, fr in problem.comm.allgather((self.flat, ~problem.constrained[:n])):
            free[f] = fr
        self.constrained_matrix.destroy()
        self.constrained_matrix = self._matrix(problem, free)

    def add_to(self, A: PETSc.Mat) -> None:
        """Add K (constrained rows and columns zeroed) to the assembled Jacobian ``A``.

        ``A``'s pattern must hold K's (see :class:`~fenicsx_drape.fe.solver.TrussProblem`).
        """
        A.axpy(1.0, self.constrained_matrix, PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)

    def force(self, u: PETSc.Vec) -> np.ndarray:
        """The internal bending force ``K u`` at the owned dofs (flat array)."""
        y = self.matrix.createVecLeft()
        self.matrix.mult(u, y)
        values = y.array_r.copy()
        y.destroy()
        return values

    def energy(self, u: PETSc.Vec) -> float:
        """The bending energy ½ uᵀ K u (N mm) of the displacement ``u``, over all ranks."""
        y = self.matrix.createVecLeft()
        self.matrix.mult(u, y)
        value = 0.5 * y.dot(u)
        y.destroy()
        return value
