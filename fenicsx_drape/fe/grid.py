"""The woven sheet as a structured truss: nodes, bars and tags (plain NumPy).

Section 2.1 and Fig. 1 of the paper: square unit cells of size Δ whose sides are tow bars
along the warp (x) and weft (y) directions and whose two diagonals are shear bars. The two
diagonals of a cell cross at its centre *without* a node (a node there would add a mechanism
and halve the shear bars), so every bar is one two-node element.

Frame (the measurement spec's): origin on the punch axis, x along warp, y along weft, the sheet
in the plane z = 0. A full sheet is centred on the origin; a quarter model covers x, y >= 0 and
its edges x = 0 and y = 0 are symmetry planes. A grid may be turned in its plane about the
origin by ``rotation_deg`` (e.g. 45° for a patch loaded in the bias direction along x); grid
indices and edges are those of the unturned grid.

A *ply at an angle* θ (:func:`sheet_grid` ``ply_angle_deg``) keeps the square sheet with its
edges along x and y and turns only the tow net: the lattice of cells Δ, turned by θ about a
node on the punch axis, is clipped to the square (``clip_half_mm``). The unit cells whose four
corners lie in the square are kept (a ply cut from a larger ply at θ: a ragged, cell-wise
edge), and of those only the cells joined side by side to the centre cell (a cell hanging by
a corner would turn freely about it). The grid stays structured in (i, j) along the tows:
:attr:`TrussGrid.cells` and :attr:`TrussGrid.present` mask the kept cells and nodes.

Node flags are bits, so a corner node can be on two edges at once:

- :data:`SYMMETRY_X` — on the symmetry plane x = 0 (u_x = 0 there),
- :data:`SYMMETRY_Y` — on the symmetry plane y = 0 (u_y = 0 there),
- :data:`BORDER` — on a free edge of the sheet (a node with a missing cell around it).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from fenicsx_drape.errors import DrapeInputError

# Bar kinds (cell tags): tows along warp and weft, and the two shear diagonals.
WARP, WEFT, DIAGONAL_PLUS, DIAGONAL_MINUS = 1, 2, 3, 4
BAR_KINDS = {WARP: "warp", WEFT: "weft", DIAGONAL_PLUS: "diagonal_plus",
             DIAGONAL_MINUS: "diagonal_minus"}

# Node flags (vertex tags), combined bitwise.
SYMMETRY_X, SYMMETRY_Y, BORDER = 1, 2, 4
NODE_FLAGS = {SYMMETRY_X: "symmetry_x", SYMMETRY_Y: "symmetry_y", BORDER: "border"}


def flag_name(value: int) -> str:
    """The name of a combination of node flags, e.g. ``"symmetry_x+border"``."""
    return "+".join(name for bit, name in NODE_FLAGS.items() if value & bit)


@dataclasses.dataclass(frozen=True)
class TrussGrid:
    """A structured truss sheet: ``(nx + 1) × (ny + 1)`` nodes, ``nx × ny`` unit cells.

    Node ``(i, j)`` sits at ``origin_mm + (i, j) · cell_mm`` (then turned by ``rotation_deg``)
    and has the lattice index ``j (nx + 1) + i``. Without clipping every lattice node is a
    node of the sheet and the lattice index is its index in :attr:`nodes`; a clipped net keeps
    the :attr:`present` nodes, numbered in lattice order.
    """

    nx: int  # unit cells along x (warp)
    ny: int  # unit cells along y (weft)
    cell_mm: float  # unit-cell size Δ (mm)
    origin_mm: tuple[float, float]  # position of node (0, 0) (mm)
    quarter: bool  # the edges x = 0 and y = 0 are symmetry planes
    rotation_deg: float = 0.0  # the grid is turned by this angle about the z axis
    clip_half_mm: float | None = None  # keep the cells inside |x|, |y| <= this (mm)

    def _rotation(self) -> np.ndarray:
        c, s = np.cos(np.radians(self.rotation_deg)), np.sin(np.radians(self.rotation_deg))
        return np.array([[c, -s], [s, c]])

    def grid_coordinates(self, xy: np.ndarray) -> np.ndarray:
        """Fractional grid indices of reference positions ``xy`` (n, 2) in mm."""
        return ((np.asarray(xy)[:, :2] @ self._rotation()) - np.asarray(self.origin_mm)) \
            / self.cell_mm

    def _lattice_xy(self) -> np.ndarray:
        """Positions (nx + 1, ny + 1, 2) of all lattice nodes (mm)."""
        i, j = np.meshgrid(np.arange(self.nx + 1), np.arange(self.ny + 1), indexing="ij")
        ij = np.stack([i, j], axis=-1)
        return (ij * self.cell_mm + np.asarray(self.origin_mm)) @ self._rotation().T

    @property
    def cells(self) -> np.ndarray:
        """Mask of the unit cells of the sheet, shaped (nx, ny) (all, unless clipped)."""
        if self.clip_half_mm is None:
            return np.ones((self.nx, self.ny), dtype=bool)
        a = self.clip_half_mm * (1.0 + 1e-12)
        inside = np.all(np.abs(self._lattice_xy()) <= a, axis=-1)
        keep = inside[:-1, :-1] & inside[1:, :-1] & inside[:-1, 1:] & inside[1:, 1:]
        from scipy import ndimage

        labels, _ = ndimage.label(keep)  # side-joined groups of cells
        centre = labels[self.nx // 2, self.ny // 2]
        return labels == centre if centre else np.zeros_like(keep)

    @property
    def present(self) -> np.ndarray:
        """Mask of the lattice nodes that are nodes of the sheet (corners of its cells)."""
        c = np.pad(self.cells, 1)
        return c[:-1, :-1] | c[1:, :-1] | c[:-1, 1:] | c[1:, 1:]

    def tow_bar_cells(self) -> tuple[np.ndarray, np.ndarray]:
        """Cells (0, 1 or 2) beside each warp bar (nx, ny + 1) and weft bar (nx + 1, ny).

        One on an edge of the sheet. Warp bar (i, j) joins nodes (i, j)-(i + 1, j), weft bar
        (i, j) nodes (i, j)-(i, j + 1).
        """
        cj = np.pad(self.cells, ((0, 0), (1, 1))).astype(int)
        ci = np.pad(self.cells, ((1, 1), (0, 0))).astype(int)
        return cj[:, :-1] + cj[:, 1:], ci[:-1] + ci[1:]

    def tow_bars(self) -> tuple[np.ndarray, np.ndarray]:
        """Masks of the warp bars (nx, ny + 1) and weft bars (nx + 1, ny): sides of cells."""
        warp, weft = self.tow_bar_cells()
        return warp > 0, weft > 0

    def _flat(self, mask: np.ndarray) -> np.ndarray:
        """A lattice mask (nx + 1, ny + 1) in the order of the lattice indices."""
        return mask.T.ravel()

    @property
    def ij(self) -> np.ndarray:
        """Grid indices ``(i, j)`` of every node, shaped (n_nodes, 2)."""
        j, i = np.divmod(np.arange((self.nx + 1) * (self.ny + 1)), self.nx + 1)
        ij = np.column_stack([i, j])
        return ij if self.clip_half_mm is None else ij[self._flat(self.present)]

    @property
    def nodes(self) -> np.ndarray:
        """Node positions (n_nodes, 3) in mm, z = 0."""
        xy = (self.ij * self.cell_mm + np.asarray(self.origin_mm)) @ self._rotation().T
        return np.column_stack([xy, np.zeros(len(xy))])

    def node(self, i: np.ndarray | int, j: np.ndarray | int) -> np.ndarray | int:
        """Lattice index of node ``(i, j)`` (its index in :attr:`nodes` unless clipped)."""
        return np.asarray(j) * (self.nx + 1) + np.asarray(i)

    @property
    def bars(self) -> tuple[np.ndarray, np.ndarray]:
        """Bars as node pairs (n_bars, 2) and their kinds (n_bars,)."""
        nx, ny = self.nx, self.ny
        ix, jx = np.meshgrid(np.arange(nx), np.arange(ny + 1), indexing="ij")
        iy, jy = np.meshgrid(np.arange(nx + 1), np.arange(ny), indexing="ij")
        ic, jc = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
        n = self.node
        warp, weft = self.tow_bars()
        cells = self.cells
        pairs = [
            (n(ix, jx), n(ix + 1, jx), WARP, warp),
            (n(iy, jy), n(iy, jy + 1), WEFT, weft),
            (n(ic, jc), n(ic + 1, jc + 1), DIAGONAL_PLUS, cells),
            (n(ic + 1, jc), n(ic, jc + 1), DIAGONAL_MINUS, cells),
        ]
        bars = np.concatenate([np.column_stack([a[m], b[m]]) for a, b, _, m in pairs])
        kinds = np.concatenate([np.full(m.sum(), k, dtype=np.int32) for *_, k, m in pairs])
        if self.clip_half_mm is not None:  # lattice indices → indices of the present nodes
            bars = (np.cumsum(self._flat(self.present)) - 1)[bars]
        return bars.astype(np.int64), kinds

    @property
    def node_flags(self) -> np.ndarray:
        """Bitwise node flags (n_nodes,): symmetry planes and free border."""
        c = np.pad(self.cells, 1)  # cell (i, j) at [i + 1, j + 1]; outside the lattice: none
        if self.quarter:  # the mirrored cells across the symmetry planes
            c[0, :] = c[1, :]
            c[:, 0] = c[:, 1]
        whole = c[:-1, :-1] & c[1:, :-1] & c[:-1, 1:] & c[1:, 1:]  # all four cells around
        i, j = np.meshgrid(np.arange(self.nx + 1), np.arange(self.ny + 1), indexing="ij")
        flags = np.where(whole, 0, BORDER).astype(np.int32)
        if self.quarter:
            flags |= np.where(i == 0, SYMMETRY_X, 0) | np.where(j == 0, SYMMETRY_Y, 0)
        flags = self._flat(flags)
        return flags if self.clip_half_mm is None else flags[self._flat(self.present)]


def sheet_grid(size_mm: float = 240.0, cell_mm: float = 10.0, quarter: bool = False,
               rotation_deg: float = 0.0, ply_angle_deg: float = 0.0) -> TrussGrid:
    """The square sheet of side ``size_mm``, or its quarter ``x, y >= 0``.

    The number of cells along a half side is ``round(size_mm / 2 / cell_mm)`` (at least 1),
    and Δ is adjusted so that they fit exactly; the full sheet has a node on the punch axis.

    Args:
        size_mm: Side of the square sheet (mm).
        cell_mm: Requested unit-cell size Δ (mm).
        quarter: Model one quarter with symmetry edges on x = 0 and y = 0.
        rotation_deg: Turn the sheet about the z axis by this angle (degrees).
        ply_angle_deg: Turn the tow net by θ inside the unturned square: warp at θ to the x
            edge (degrees); the net (same Δ, a node on the punch axis) is clipped to the
            square cell by cell. Full sheet only, not with ``rotation_deg``.
    """
    if not (math.isfinite(size_mm) and size_mm > 0):
        raise DrapeInputError(f"sheet size_mm = {size_mm} must be a positive number")
    if not (math.isfinite(cell_mm) and 0 < cell_mm <= size_mm / 2):
        raise DrapeInputError(f"cell_mm = {cell_mm} must be in (0, size_mm / 2 = {size_mm / 2}]")
    n_half = max(1, round(size_mm / 2 / cell_mm))
    Δ = size_mm / 2 / n_half
    for name, value in (("rotation_deg", rotation_deg), ("ply_angle_deg", ply_angle_deg)):
        if not math.isfinite(value):
            raise DrapeInputError(f"{name} = {value} is not a number")
    if ply_angle_deg:
        if quarter or rotation_deg:
            raise DrapeInputError(f"ply_angle_deg = {ply_angle_deg}: a ply at an angle needs "
                                  "the full sheet (no quarter symmetry) and rotation_deg = 0")
        θ = math.radians(ply_angle_deg)
        # Lattice cells along a half side: enough to cover the square turned by −θ.
        m = math.ceil(size_mm / 2 * (abs(math.cos(θ)) + abs(math.sin(θ))) / Δ - 1e-9)
        return TrussGrid(2 * m, 2 * m, Δ, (-m * Δ, -m * Δ), False, ply_angle_deg,
                         clip_half_mm=size_mm / 2)
    if quarter:
        return TrussGrid(n_half, n_half, Δ, (0.0, 0.0), True, rotation_deg)
    return TrussGrid(2 * n_half, 2 * n_half, Δ, (-size_mm / 2, -size_mm / 2), False,
                     rotation_deg)


def gmsh_model(nodes: np.ndarray, bars: np.ndarray, kinds: np.ndarray, flags: np.ndarray):
    """The current Gmsh model filled with a truss as discrete entities.

    No geometry is meshed: nodes and two-node line elements are added as they are, so the
    crossing diagonals are neither fragmented nor joined. Bars form one physical group per
    kind (tag = kind), flagged nodes one point group per flag value (tag = value). Gmsh must
    be initialised.
    """
    import gmsh

    model = gmsh.model
    model.add("truss")
    # All nodes on the first curve; the other curves use them (node tags start at 1).
    for kind in BAR_KINDS:
        model.addDiscreteEntity(1, kind)
    model.mesh.addNodes(1, 1, np.arange(1, len(nodes) + 1), nodes.ravel())
    first = 1
    for kind, name in BAR_KINDS.items():
        sel = bars[kinds == kind] + 1
        tags = np.arange(first, first + len(sel))
        first += len(sel)
        model.mesh.addElementsByType(kind, 1, tags, sel.ravel())  # type 1: 2-node line
        if len(sel):
            model.addPhysicalGroup(1, [kind], kind, name=name)
    # One point entity per flagged node, grouped by flag value.
    for value in np.unique(flags[flags > 0]):
        points = []
        for node in np.flatnonzero(flags == value):
            tag = model.addDiscreteEntity(0)
            model.mesh.addElementsByType(tag, 15, [first], [node + 1])  # type 15: point
            first += 1
            points.append(tag)
        model.addPhysicalGroup(0, points, int(value), name=flag_name(int(value)))
    return model


def write_grid(grid: TrussGrid, path: str | Path) -> Path:
    """Write the truss: ``.msh`` with Gmsh, other formats (``.xdmf``, ``.vtu``) with meshio.

    The ``.msh`` file (Gmsh 4.1) holds the bars in physical groups ``warp``, ``weft``,
    ``diagonal_plus``, ``diagonal_minus`` and the flagged nodes in point groups such as
    ``symmetry_x`` or ``border``; meshio formats get cell data ``kind`` and point data
    ``flags``. Both read back with :func:`read_grid` (meshio).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    bars, kinds = grid.bars
    if path.suffix == ".msh":
        import gmsh

        initialised = gmsh.isInitialized()
        if not initialised:
            gmsh.initialize(interruptible=False)
        gmsh.option.setNumber("General.Terminal", 0)
        try:
            gmsh_model(grid.nodes, bars, kinds, grid.node_flags)
            gmsh.write(str(path))
            gmsh.model.remove()
        finally:
            if not initialised:
                gmsh.finalize()
        return path
    import meshio

    mesh = meshio.Mesh(grid.nodes, [("line", bars)], point_data={"flags": grid.node_flags},
                       cell_data={"kind": [kinds]})
    if path.suffix == ".xdmf":
        mesh.write(path, data_format="XML")  # inline data: no HDF5 side file
    else:
        mesh.write(path)
    return path


def read_grid(path: str | Path) -> TrussGrid:
    """Read a truss sheet written by :func:`write_grid` (or any structured truss like it).

    The grid (not turned, not clipped) is recovered from the node positions and checked
    against the file's bars.
    """
    import meshio

    path = Path(path)
    if not path.exists():
        raise DrapeInputError(f"{path}: no such mesh file")
    try:
        mesh = meshio.read(path, file_format="gmsh" if path.suffix == ".msh" else None)
    except Exception as err:  # meshio raises many kinds of errors on bad files
        raise DrapeInputError(f"{path}: cannot read the mesh ({err})") from err
    x = np.asarray(mesh.points, dtype=float)
    lines = [c.data for c in mesh.cells if c.type == "line"]
    if not lines or len(x) < 4:
        raise DrapeInputError(f"{path}: no line cells; not a truss sheet")
    bars = np.concatenate(lines)
    lo, hi = x[:, :2].min(axis=0), x[:, :2].max(axis=0)
    Δ = float(np.min(np.linalg.norm(x[bars[:, 1], :2] - x[bars[:, 0], :2], axis=1)))
    nx, ny = (round(float(v)) for v in (hi - lo) / Δ)
    quarter = bool(np.allclose(lo, 0.0))
    grid = TrussGrid(nx, ny, Δ, (float(lo[0]), float(lo[1])), quarter)
    expected_bars, _ = grid.bars
    off_grid = np.abs((x[:, :2] - lo) / Δ - np.round((x[:, :2] - lo) / Δ)).max()
    if (len(x) != (nx + 1) * (ny + 1) or len(bars) != len(expected_bars) or off_grid > 1e-6
            or np.abs(x[:, 2]).max() > 1e-9 * Δ):
        raise DrapeInputError(f"{path}: {len(x)} nodes and {len(bars)} bars do not form a "
                              f"{nx} × {ny} woven truss with Δ = {Δ:g} mm")
    return grid
