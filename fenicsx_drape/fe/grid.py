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

A blank of any outline (:func:`outline_grid`: a polygon in the sheet plane, e.g. sampled from
a Gmsh curve) is clipped the same way (``outline_mm``): the cells with four corners in the
polygon, of those the largest group joined side by side (a cell hanging by a corner, or an
island cut off by a narrow neck, would move freely), on a lattice trimmed to the kept cells.
Symmetry planes (``symmetry``: ``"x"`` the plane x = 0, ``"y"`` the plane y = 0) are the
lattice's edges i = 0 and j = 0: the model keeps the half (or quarter) x ≥ 0, y ≥ 0.

Node flags are bits, so a corner node can be on two edges at once:

- :data:`SYMMETRY_X` — on the symmetry plane x = 0 (u_x = 0 there),
- :data:`SYMMETRY_Y` — on the symmetry plane y = 0 (u_y = 0 there),
- :data:`BORDER` — on a free edge of the sheet (a node with a missing cell around it).
"""

from __future__ import annotations

import dataclasses
import functools
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
    # Keep the cells inside this polygon ((x, y) vertices in mm, either orientation).
    outline_mm: tuple[tuple[float, float], ...] | None = None
    # Symmetry planes on the edges i = 0 ("x": the plane x = 0) and j = 0 ("y": y = 0);
    # None: both if ``quarter``, else none.
    symmetry: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        # Sizes before memory: a net beyond the machine is refused before any array exists.
        from fenicsx_drape.limits import check_nodes

        check_nodes((self.nx + 1) * (self.ny + 1), f"cell_mm = {self.cell_mm:g}")

    @property
    def planes(self) -> tuple[str, ...]:
        """The symmetry planes of the model: ``"x"`` (x = 0, edge i = 0), ``"y"`` (y = 0)."""
        if self.symmetry is not None:
            return tuple(self.symmetry)
        return ("x", "y") if self.quarter else ()

    @property
    def clipped(self) -> bool:
        """Whether the lattice is clipped (a square or an outline): some cells may be absent."""
        return self.clip_half_mm is not None or self.outline_mm is not None

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

    @functools.cached_property
    def cells(self) -> np.ndarray:
        """Mask of the unit cells of the sheet, shaped (nx, ny) (all, unless clipped)."""
        if not self.clipped:
            return np.ones((self.nx, self.ny), dtype=bool)
        from scipy import ndimage

        if self.outline_mm is not None:
            inside = inside_polygon(self._lattice_xy().reshape(-1, 2), np.asarray(self.outline_mm))
            inside = inside.reshape(self.nx + 1, self.ny + 1)
        else:
            a = self.clip_half_mm * (1.0 + 1e-12)
            inside = np.all(np.abs(self._lattice_xy()) <= a, axis=-1)
        keep = inside[:-1, :-1] & inside[1:, :-1] & inside[:-1, 1:] & inside[1:, 1:]
        labels, n = ndimage.label(keep)  # side-joined groups of cells
        if self.outline_mm is None:
            centre = labels[self.nx // 2, self.ny // 2]
            return labels == centre if centre else np.zeros_like(keep)
        if n == 0:
            return keep
        # The largest group; of equal ones, the one nearest the frame's origin.
        sizes = np.bincount(labels.ravel(), minlength=n + 1)[1:]
        xy = self._lattice_xy()
        centres = 0.25 * (xy[:-1, :-1] + xy[1:, :-1] + xy[:-1, 1:] + xy[1:, 1:])
        r = np.hypot(centres[..., 0], centres[..., 1])
        near = ndimage.minimum(r, labels, index=np.arange(1, n + 1))
        best = min(range(n), key=lambda k: (-sizes[k], near[k]))
        return labels == best + 1

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
        return ij if not self.clipped else ij[self._flat(self.present)]

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
        if self.clipped:  # lattice indices → indices of the present nodes
            bars = (np.cumsum(self._flat(self.present)) - 1)[bars]
        return bars.astype(np.int64), kinds

    @property
    def node_flags(self) -> np.ndarray:
        """Bitwise node flags (n_nodes,): symmetry planes and free border."""
        c = np.pad(self.cells, 1)  # cell (i, j) at [i + 1, j + 1]; outside the lattice: none
        planes = self.planes
        if "x" in planes:  # the mirrored cells across the symmetry planes
            c[0, :] = c[1, :]
        if "y" in planes:
            c[:, 0] = c[:, 1]
        whole = c[:-1, :-1] & c[1:, :-1] & c[:-1, 1:] & c[1:, 1:]  # all four cells around
        i, j = np.meshgrid(np.arange(self.nx + 1), np.arange(self.ny + 1), indexing="ij")
        flags = np.where(whole, 0, BORDER).astype(np.int32)
        if "x" in planes:
            flags |= np.where(i == 0, SYMMETRY_X, 0)
        if "y" in planes:
            flags |= np.where(j == 0, SYMMETRY_Y, 0)
        flags = self._flat(flags)
        return flags if not self.clipped else flags[self._flat(self.present)]


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


def inside_polygon(points: np.ndarray, polygon: np.ndarray, tol_mm: float | None = None
                   ) -> np.ndarray:
    """Which ``points`` (n, 2) lie in the closed ``polygon`` (m, 2) or on its boundary.

    Even-odd ray casting, plus the points within ``tol_mm`` of an edge (default 1e-9 of the
    polygon's size), so that nodes on the outline count as inside.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    a = np.asarray(polygon, dtype=float)
    b = np.roll(a, -1, axis=0)
    if tol_mm is None:
        tol_mm = 1e-9 * max(np.ptp(a, axis=0).max(), 1.0)
    x, y = p[:, :1], p[:, 1:]
    # Edges that straddle the horizontal line through the point, crossed to its right.
    straddle = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        cross_x = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    inside = np.count_nonzero(straddle & (x < cross_x), axis=1) % 2 == 1
    return inside | (polygon_distance(p, a) <= tol_mm)


def polygon_distance(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Distance (mm) of ``points`` (n, 2) from the boundary of the closed ``polygon`` (m, 2)."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)[:, None, :]
    a = np.asarray(polygon, dtype=float)
    e = np.roll(a, -1, axis=0) - a
    s = np.clip(np.einsum("nmk,mk->nm", p - a, e) / np.maximum(np.sum(e * e, 1), 1e-300), 0, 1)
    d = p - a - s[..., None] * e
    return np.sqrt(np.min(np.sum(d * d, axis=-1), axis=1))


def polygon_area(polygon: np.ndarray) -> float:
    """Area (mm², ≥ 0) of a simple polygon (m, 2), either orientation."""
    a = np.asarray(polygon, dtype=float)
    b = np.roll(a, -1, axis=0)
    return 0.5 * abs(float(np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])))


def outline_grid(polygon_mm, cell_mm: float, *, origin_mm=(0.0, 0.0), ply_angle_deg: float = 0.0,
                 symmetry=()) -> TrussGrid:
    """The net of unit cells Δ inside a blank outline, turned by the ply angle.

    The lattice has a node at ``origin_mm`` and its warp at ``ply_angle_deg`` to x (turned
    about ``origin_mm``); the cells with four corners in the polygon are kept, of those the
    largest side-joined group (:attr:`TrussGrid.cells`), and the lattice is trimmed to them.
    When every cell of the trimmed lattice is kept the grid is returned unclipped (a blank
    whose sides are tow lines: the same grid as :func:`sheet_grid`'s).

    Args:
        polygon_mm: Vertices (m, 2) of the whole blank's outline (mm), m >= 3.
        cell_mm: Unit-cell size Δ (mm), used as given.
        origin_mm: A node of the net (mm).
        ply_angle_deg: Warp direction, degrees from x.
        symmetry: Symmetry planes kept, ``"x"`` (x = 0) and/or ``"y"`` (y = 0): the model is
            the part x ≥ 0 and/or y ≥ 0 of the blank, which must be symmetric in them, and the
            net needs nodes on them (tows along x and y, ``origin_mm`` a whole number of
            cells from each plane).

    Raises:
        DrapeInputError: a bad outline, cell size, angle or symmetry, or no whole cell fits.
    """
    P = np.asarray(polygon_mm, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or len(P) < 3 or not np.isfinite(P).all():
        raise DrapeInputError(f"outline: {P.shape} points; a polygon needs at least three "
                              "finite (x, y) vertices in mm")
    if not polygon_area(P) > 0.0:
        raise DrapeInputError("outline: the polygon encloses no area")
    if not (math.isfinite(cell_mm) and cell_mm > 0):
        raise DrapeInputError(f"cell_mm = {cell_mm} must be a positive number")
    o = np.asarray(origin_mm, dtype=float).reshape(2)
    θ = float(ply_angle_deg)
    if not (np.isfinite(o).all() and math.isfinite(θ)):
        raise DrapeInputError(f"origin_mm = {tuple(o)}, ply_angle_deg = {θ}: not numbers")
    planes = tuple(symmetry)
    if not set(planes) <= {"x", "y"} or len(set(planes)) != len(planes):
        raise DrapeInputError(f"symmetry = {list(planes)}: planes are \"x\" (x = 0) and/or "
                              "\"y\" (y = 0), each once")
    planes = tuple(p for p in ("x", "y") if p in planes)
    Δ = float(cell_mm)
    size = float(np.ptp(P, axis=0).max())
    for axis, plane in enumerate(("x", "y")):
        if plane not in planes:
            continue
        if θ:
            raise DrapeInputError(f"ply_angle_deg = {θ:g} breaks the symmetry in the plane "
                                  f"{plane} = 0; model the full blank (symmetry = [])")
        if abs(o[axis] / Δ - round(o[axis] / Δ)) > 1e-9:
            raise DrapeInputError(f"symmetry {plane!r}: the net has no nodes on the plane "
                                  f"{plane} = 0 (origin_mm {plane} = {o[axis]:g} is not a whole "
                                  f"number of cells Δ = {Δ:g} mm from it)")
        mirrored = P.copy()
        mirrored[:, axis] *= -1.0
        if polygon_distance(mirrored, P).max() > 1e-6 * size:
            raise DrapeInputError(f"symmetry {plane!r}: the outline is not symmetric in the "
                                  f"plane {plane} = 0")
        if not (P[:, axis].min() < 0.0 < P[:, axis].max()):
            raise DrapeInputError(f"symmetry {plane!r}: the outline does not cross the plane "
                                  f"{plane} = 0")
    c, s = math.cos(math.radians(θ)), math.sin(math.radians(θ))
    R = np.array([[c, -s], [s, c]])
    a = o @ R  # the net's origin in the lattice frame (Rᵀ o)
    Q = P @ R
    tol = 1e-9
    lo = np.ceil((Q.min(axis=0) - a) / Δ - tol).astype(int)
    hi = np.floor((Q.max(axis=0) - a) / Δ + tol).astype(int)
    corner = a + lo * Δ
    for axis, plane in enumerate(("x", "y")):
        if plane in planes:  # the lattice starts on the plane
            lo[axis] = round(-o[axis] / Δ)
            corner[axis] = 0.0
    n = hi - lo
    if (n < 1).any():
        raise DrapeInputError(f"outline: no unit cell of Δ = {Δ:g} mm fits in the blank")
    both = planes == ("x", "y")
    grid = TrussGrid(int(n[0]), int(n[1]), Δ, (float(corner[0]), float(corner[1])), both, θ,
                     outline_mm=tuple((float(x), float(y)) for x, y in P),
                     symmetry=None if both or not planes else planes)
    cells = grid.cells
    if not cells.any():
        raise DrapeInputError(f"outline: no unit cell of Δ = {Δ:g} mm fits in the blank")
    (i0, j0), (i1, j1) = np.argwhere(cells).min(axis=0), np.argwhere(cells).max(axis=0) + 1
    for plane, first in (("x", i0), ("y", j0)):
        if plane in planes and first != 0:
            raise DrapeInputError(f"symmetry {plane!r}: the net kept in the outline does not "
                                  f"reach the plane {plane} = 0")
    kept = cells[i0:i1, j0:j1]
    origin = (float(grid.origin_mm[0] + i0 * Δ), float(grid.origin_mm[1] + j0 * Δ))
    trimmed = dataclasses.replace(grid, nx=int(i1 - i0), ny=int(j1 - j0), origin_mm=origin,
                                  outline_mm=None if kept.all() else grid.outline_mm)
    if not kept.all() and not np.array_equal(trimmed.cells, kept):
        raise AssertionError("outline_grid: trimming the lattice changed its cells")
    return trimmed


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
