"""The truss sheet as a DOLFINx mesh: built with Gmsh, distributed over MPI ranks.

The bars are interval cells embedded in 3D. Up to eight bars meet at a node (four tows, four
diagonals), so the mesh is created with ``max_facet_to_cell_links=8``; with DOLFINx >= 0.10
this distributes the branching truss without duplicating any node (the global vertex count
is the same on any number of ranks).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from mpi4py import MPI

import dolfinx
import numpy as np
from dolfinx.io import gmsh as gmshio

from fenicsx_drape.fe.grid import TrussGrid, gmsh_model, read_grid, sheet_grid

MAX_BARS_AT_NODE = 8


@dataclasses.dataclass
class Sheet:
    """A truss sheet on DOLFINx: the mesh, its tags and the structured grid it came from."""

    mesh: dolfinx.mesh.Mesh  # interval cells in 3D, the reference (flat) configuration
    bar_tags: dolfinx.mesh.MeshTags  # cell tags: WARP, WEFT, DIAGONAL_PLUS, DIAGONAL_MINUS
    node_tags: dolfinx.mesh.MeshTags | None  # vertex tags: SYMMETRY_X | SYMMETRY_Y | BORDER
    grid: TrussGrid | None  # the structured grid (same on every rank); None for a free truss
    cell_mm: float  # unit-cell size Δ (mm): a bar stands for n_t = l_t Δ tows
    # A stack of plies (fe.plies.Ply, ply 1 first), each its own grid; then grid is None.
    plies: list | None = None

    @property
    def num_nodes_global(self) -> int:
        """Number of nodes of the whole sheet (all ranks)."""
        return self.mesh.topology.index_map(0).size_global


def _partitioner():
    return dolfinx.mesh.create_cell_partitioner(dolfinx.mesh.GhostMode.none, MAX_BARS_AT_NODE)


def grid_to_sheet(grid: TrussGrid, comm: MPI.Comm = MPI.COMM_WORLD) -> Sheet:
    """Build the Gmsh model of ``grid`` on rank 0 and distribute it as a DOLFINx mesh."""
    if comm.rank == 0:
        bars, kinds = grid.bars
        data = (grid.nodes, bars, kinds, grid.node_flags)
    else:
        data = None
    mesh, bar_tags, node_tags = _distribute(data, comm)
    return Sheet(mesh, bar_tags, node_tags, grid, grid.cell_mm)


def truss_mesh(nodes: np.ndarray, bars: np.ndarray, kinds: np.ndarray, cell_mm: float,
               comm: MPI.Comm = MPI.COMM_WORLD) -> Sheet:
    """Any truss (not a woven grid), e.g. for tests: bars are node pairs, kinds the bar kinds.

    Args:
        nodes: Node positions (n, 3) in mm (read on rank 0).
        bars: Node pairs (m, 2).
        kinds: Kind of each bar (WARP or WEFT: tow law; DIAGONAL_*: shear law).
        cell_mm: Unit-cell size Δ a bar stands for (n_t = l_t Δ tows).
        comm: MPI communicator.
    """
    data = None
    if comm.rank == 0:
        data = (np.asarray(nodes, float), np.asarray(bars, np.int64),
                np.asarray(kinds, np.int32), np.zeros(len(nodes), np.int32))
    mesh, bar_tags, _ = _distribute(data, comm)
    return Sheet(mesh, bar_tags, None, None, float(cell_mm))


def _bisect(points: np.ndarray, cells: np.ndarray, first: int, parts: int,
            dest: np.ndarray) -> None:
    """Ranks ``first`` … ``first + parts - 1`` to ``cells`` (into ``dest``), equal counts.

    Recursive bisection of the cells' ``points`` (n, 2) across the longer side.
    """
    if parts == 1 or not len(cells):
        dest[cells] = first
        return
    left = parts // 2
    axis = int(np.ptp(points[cells], axis=0).argmax())
    order = cells[np.argsort(points[cells, axis], kind="stable")]
    cut = len(order) * left // parts
    _bisect(points, order[:cut], first, left, dest)
    _bisect(points, order[cut:], first + left, parts - left, dest)


def _column_partitioner(xy: np.ndarray):
    """Bars to ranks by their place in the plane, whatever their height (a stack's plies).

    A graph partitioner splits the plies of a stack, which no bar joins, a ply to a rank;
    bisecting the bars' midpoints in (x, y) keeps each column of the stack on one rank, so
    the inter-ply pairs (fe/plies.py) are local but along the cuts.
    """

    def partition(comm, parts, cell_types, cells):
        bars = np.asarray(cells[0]).reshape(-1, 2)
        dest = np.zeros(len(bars), dtype=np.int32)
        _bisect(xy[bars].mean(axis=1), np.arange(len(bars)), 0, parts, dest)
        return dolfinx.graph.adjacencylist(dest[:, None])._cpp_object

    return partition


def _distribute(data, comm: MPI.Comm, columns: bool = False):
    """Gmsh model of ``data = (nodes, bars, kinds, flags)`` on rank 0 → DOLFINx mesh, tags.

    ``columns``: partition by place in the plane (:func:`_column_partitioner`, a stack).
    """
    import gmsh

    model = None
    if comm.rank == 0:
        initialised = gmsh.isInitialized()
        if not initialised:
            gmsh.initialize(interruptible=False)
        gmsh.option.setNumber("General.Terminal", 0)
        model = gmsh_model(*data)
    try:
        partitioner = _partitioner()
        if columns and comm.size > 1:
            xy = data[0][:, :2] if comm.rank == 0 else np.zeros((0, 2))
            partitioner = _column_partitioner(xy)
        data = gmshio.model_to_mesh(model, comm, 0, gdim=3, partitioner=partitioner,
                                    max_facet_to_cell_links=MAX_BARS_AT_NODE)
    finally:
        if comm.rank == 0:
            gmsh.model.remove()
            if not initialised:
                gmsh.finalize()
    data.mesh.topology.create_connectivity(0, 1)
    return data.mesh, data.cell_tags, data.facet_tags


def truss_sheet(size_mm: float = 240.0, cell_mm: float = 10.0, quarter: bool = False,
                comm: MPI.Comm = MPI.COMM_WORLD, rotation_deg: float = 0.0,
                ply_angle_deg: float = 0.0) -> Sheet:
    """The woven sheet (or its symmetric quarter) as a distributed truss mesh.

    Args:
        size_mm: Side of the square sheet (mm).
        cell_mm: Unit-cell size Δ (mm), adjusted so that a whole number of cells fits a half
            side (see :func:`~fenicsx_drape.fe.grid.sheet_grid`).
        quarter: Model the quarter x, y >= 0 with symmetry edges on x = 0 and y = 0.
        comm: MPI communicator.
        rotation_deg: Turn the sheet about the z axis (e.g. 45° for bias loading along x).
        ply_angle_deg: Turn only the tow net by θ inside the square, clipped to it cell by
            cell (full sheet only; see :func:`~fenicsx_drape.fe.grid.sheet_grid`).

    Example::

        sheet = truss_sheet(240, 10, quarter=True)
    """
    grid = None
    if comm.rank == 0:
        grid = sheet_grid(size_mm, cell_mm, quarter, rotation_deg, ply_angle_deg)
    return grid_to_sheet(comm.bcast(grid, root=0), comm)


def load_sheet(path: str | Path, comm: MPI.Comm = MPI.COMM_WORLD) -> Sheet:
    """Read a sheet written by :func:`~fenicsx_drape.fe.grid.write_grid` (``.msh``, ``.xdmf``)."""
    grid, error = None, None
    if comm.rank == 0:
        try:
            grid = read_grid(path)
        except Exception as err:  # raised again on every rank below
            error = err
    error = comm.bcast(error, root=0)
    if error is not None:
        raise error
    return grid_to_sheet(comm.bcast(grid, root=0), comm)
