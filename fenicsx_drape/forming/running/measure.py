"""What a lab measures on a formed sheet, taken from the model: points, edge, shear, distance.

The formed sheet (:class:`~fenicsx_drape.forming.running.post.FormedGrid`, mirrored to the whole
blank) is triangulated (:class:`SheetMesh`: each unit cell split along its 00-11 diagonal),
so that

- the **closest point** of the formed sheet to any point (a scanned point, a point where a
  shear angle was read) is found with a k-d tree on the triangles' centres and a vectorised
  point-to-triangle projection (:func:`closest_points`), with its material (flat) position
  by the barycentric coordinates;
- the **shear angle at a material point** (flat x0, y0; :func:`shear_at_flat`) is the local
  angle between the tows there, as a lab reads it: at a cell's centre, that cell's own angle
  (90° minus the angle between its mean warp and weft tow vectors, from its own four nodes:
  :meth:`~fenicsx_drape.forming.running.post.FormedGrid.shear_deg`, positive when the angle
  between the tows' +x and +y directions closes, the spec's sign); between centres, bilinear
  in the cells' own angles on the lattice of cell centres; within half a cell of the blank's
  edge (beyond the outermost centres), the edge cells' angles carried to the edge (constant
  across). At a point of a clipped net's ragged edge, the centres of absent cells drop out
  and the others' weights are rescaled. On a symmetric part the mirrored cells count (the
  signed angle changes sign across a symmetry plane: 0 on it). At a node this is the mean of
  the cells around it (:meth:`~fenicsx_drape.forming.running.post.FormedGrid.shear_nodes`,
  the grid table's ``shear_deg``), so grids and shear points share one definition; on a
  homogeneously sheared sheet every point has the exact angle. At a formed point, it is that
  of the closest point's material position (:func:`shear_at_formed`);
- the **blank's edge after forming** is the chain of the triangulation's boundary edges
  (:func:`edge_segments`), with the distance of a point to it and the model's **draw-in**
  there (inward in-plane displacement of the edge's material point, as
  :func:`~fenicsx_drape.forming.running.run.draw_in`) from :func:`closest_on_edge`.

No Python loop over points: everything is NumPy over (points × candidates) arrays.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.running.post import FormedGrid

CANDIDATES = 8  # triangles (or edges) tried per point, nearest centres first
# A point farther than this many cells from the formed sheet (or its edge) is unmatched
# (spec version 3: "farther than 2 cells"), as compare has it.
UNMATCHED_CELLS = 2.0
SHEET_FILE = "formed_sheet.csv"  # the formed sheet drape form writes (write_sheet)
SHEET_COLUMNS = ("ply", "i", "j", "x0_mm", "y0_mm", "z0_mm", "x_mm", "y_mm", "z_mm")


@dataclasses.dataclass(frozen=True)
class SheetMesh:
    """A formed sheet as triangles: flat and formed node positions (n, 3), triangles (m, 3)."""

    X: np.ndarray  # flat positions of the nodes
    x: np.ndarray  # formed positions
    triangles: np.ndarray  # node indices, counter-clockwise on the flat sheet
    cell_mm: float

    @classmethod
    def of(cls, grid: FormedGrid) -> SheetMesh:
        """The whole blank's triangulation (a symmetric part is mirrored first)."""
        g = grid.full()
        ok = g.present
        index = -np.ones(ok.shape, int)
        index[ok] = np.arange(int(ok.sum()))
        cells = ok[:-1, :-1] & ok[1:, :-1] & ok[:-1, 1:] & ok[1:, 1:]
        i, j = np.nonzero(cells)
        a, b = index[i, j], index[i + 1, j]
        c, d = index[i + 1, j + 1], index[i, j + 1]
        tri = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
        return cls(g.X[ok], g.x[ok], tri, g.cell_mm)

    @property
    def areas(self) -> np.ndarray:
        """Area (mm²) of every formed triangle."""
        p = self.x[self.triangles]
        return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)

    @property
    def normals(self) -> np.ndarray:
        """Unit normal of every formed triangle (+z on the flat sheet)."""
        p = self.x[self.triangles]
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def _closest_on_triangles(P: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points of triangles ABC to points P (all (..., 3)): point and barycentrics v, w.

    The point is A + v (B − A) + w (C − A); the regions of the triangle (vertices, edges,
    face) are told apart by the signs of the projections (Ericson, Real-Time Collision
    Detection, 5.1.5), here for whole arrays at once.
    """
    ab, ac, ap = B - A, C - A, P - A
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = P - B
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = P - C
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    tiny = 1e-300
    # Face (default), then overwrite by the edge and vertex regions in turn.
    denom = np.where(np.abs(va + vb + vc) > tiny, va + vb + vc, tiny)
    v, w = vb / denom, vc / denom
    on_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
    t = (d4 - d3) / np.where((d4 - d3) + (d5 - d6) > tiny, (d4 - d3) + (d5 - d6), tiny)
    v, w = np.where(on_bc, 1 - t, v), np.where(on_bc, t, w)
    on_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    t = d2 / np.where(d2 - d6 > tiny, d2 - d6, tiny)
    v, w = np.where(on_ac, 0.0, v), np.where(on_ac, t, w)
    on_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    t = d1 / np.where(d1 - d3 > tiny, d1 - d3, tiny)
    v, w = np.where(on_ab, t, v), np.where(on_ab, 0.0, w)
    at_c = (d6 >= 0) & (d5 <= d6)
    v, w = np.where(at_c, 0.0, v), np.where(at_c, 1.0, w)
    at_b = (d3 >= 0) & (d4 <= d3)
    v, w = np.where(at_b, 1.0, v), np.where(at_b, 0.0, w)
    at_a = (d1 <= 0) & (d2 <= 0)
    v, w = np.where(at_a, 0.0, v), np.where(at_a, 0.0, w)
    Q = A + v[..., None] * ab + w[..., None] * ac
    return Q, v, w


@dataclasses.dataclass(frozen=True)
class Closest:
    """The closest points of a sheet to query points."""

    distance: np.ndarray  # (n,) mm, ≥ 0
    signed: np.ndarray  # (n,) mm, along the triangle's normal (+ on the +z side when flat)
    point: np.ndarray  # (n, 3) the closest formed point
    flat: np.ndarray  # (n, 3) its material position on the flat blank
    triangle: np.ndarray  # (n,) index of its triangle


def closest_points(mesh: SheetMesh, points: np.ndarray, k: int = CANDIDATES) -> Closest:
    """The closest point of the formed sheet to each point (n, 3).

    The ``k`` triangles with the nearest centres (a k-d tree) are projected on; on the
    structured cells of a formed ply (aspect near 1) the closest point's triangle is among
    them.
    """
    from scipy.spatial import cKDTree

    P = np.asarray(points, float)
    tri = mesh.triangles
    corners = mesh.x[tri]
    centres = corners.mean(axis=1)
    k = min(k, len(tri))
    _, cand = cKDTree(centres).query(P, k=k)
    cand = cand.reshape(len(P), k)
    A, B, C = (corners[cand, m] for m in range(3))
    Q, v, w = _closest_on_triangles(P[:, None, :], A, B, C)
    d = np.linalg.norm(P[:, None, :] - Q, axis=-1)
    best = np.argmin(d, axis=1)
    rows = np.arange(len(P))
    t = cand[rows, best]
    v, w, Q = v[rows, best], w[rows, best], Q[rows, best]
    F = mesh.X[tri[t]]
    flat = F[:, 0] + v[:, None] * (F[:, 1] - F[:, 0]) + w[:, None] * (F[:, 2] - F[:, 0])
    signed = np.einsum("ni,ni->n", P - Q, mesh.normals[t])
    return Closest(d[rows, best], signed, Q, flat, t)


def coverage(mesh: SheetMesh, points: np.ndarray, reach_mm: float | None = None) -> float:
    """The share of the formed sheet's area within ``reach_mm`` (default ¾ cell) of a point."""
    from scipy.spatial import cKDTree

    reach = 0.75 * mesh.cell_mm if reach_mm is None else reach_mm
    centres = mesh.x[mesh.triangles].mean(axis=1)
    d, _ = cKDTree(np.asarray(points, float)).query(centres, k=1)
    areas = mesh.areas
    return float(areas[d <= reach].sum() / areas.sum())


def shear_at_flat(grid: FormedGrid, flat_mm: np.ndarray) -> np.ndarray:
    """The model's shear angle (deg) at material points (m, 2), as a lab reads it.

    Each cell's own angle at its centre, bilinear between the centres (the module doc); NaN
    for a point off the blank (outside the net or in an absent cell of a clipped net).
    """
    g = grid.full()
    γ = g.shear_deg()  # (n_i − 1, n_j − 1): each cell's own angle, NaN for absent cells
    p = np.asarray(flat_mm, float)[:, :2]
    origin, Δ, R = g.tow_frame()
    s = ((p - origin) @ R) / Δ  # lattice coordinates of the nodes: cell k spans [k, k + 1]
    n = np.array(γ.shape)
    present = np.isfinite(γ)
    # On the blank: a present cell holds the point (one on a cell's side may have its
    # present cell on either side of it).
    on = np.zeros(len(p), bool)
    for shift in (-1e-9, 1e-9):
        for other in (-1e-9, 1e-9):
            k = np.floor(s + np.array([shift, other])).astype(int)
            inside = np.all((k >= 0) & (k < n), axis=1)
            kc = np.clip(k, 0, n - 1)
            on |= inside & present[kc[:, 0], kc[:, 1]]
    # Bilinear on the lattice of centres (centre k at k + ½), clamped to the outermost ones.
    c = np.clip(s - 0.5, 0.0, n - 1.0)
    k0 = np.clip(np.floor(c).astype(int), 0, np.maximum(n - 2, 0))
    t = c - k0
    value, weight = np.zeros(len(p)), np.zeros(len(p))
    for di in (0, 1):
        for dj in (0, 1):
            i = np.minimum(k0[:, 0] + di, n[0] - 1)
            j = np.minimum(k0[:, 1] + dj, n[1] - 1)
            w = (t[:, 0] if di else 1.0 - t[:, 0]) * (t[:, 1] if dj else 1.0 - t[:, 1])
            ok = present[i, j]
            value += np.where(ok, w * np.where(ok, γ[i, j], 0.0), 0.0)
            weight += np.where(ok, w, 0.0)
    out = np.divide(value, weight, out=np.full(len(p), np.nan), where=weight > 0)
    return np.where(on, out, np.nan)


def shear_at_formed(grid: FormedGrid, points: np.ndarray,
                    mesh: SheetMesh | None = None) -> tuple[np.ndarray, Closest]:
    """The model's shear angle (deg) at the closest point of the formed sheet to each point."""
    mesh = mesh or SheetMesh.of(grid)
    near = closest_points(mesh, points)
    return shear_at_flat(grid, near.flat), near


def edge_segments(mesh: SheetMesh) -> tuple[np.ndarray, np.ndarray]:
    """The blank's edge: the triangulation's boundary edges.

    Returns the edges' node pairs (e, 2) and the outward in-plane direction (e, 2) of each on
    the flat blank.
    """
    tri = mesh.triangles
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    opposite = np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
    key = np.sort(edges, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = counts[inverse.ravel()] == 1
    e, o = edges[once], opposite[once]
    mid = mesh.X[e, :2].mean(axis=1)
    t = mesh.X[e[:, 1], :2] - mesh.X[e[:, 0], :2]
    n = np.column_stack([t[:, 1], -t[:, 0]])
    n *= np.sign(np.einsum("ni,ni->n", n, mid - mesh.X[o, :2]))[:, None]
    return e, n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def closest_on_edge(mesh: SheetMesh, points: np.ndarray, centre_mm=(0.0, 0.0),
                    k: int = CANDIDATES) -> dict[str, np.ndarray]:
    """The closest point of the formed blank's edge to each point (n, 2 or 3).

    Points given in plan (two coordinates) are matched in plan. Returns ``signed`` (mm,
    positive when the point lies outside the model's edge: less draw-in than modelled),
    ``distance``, ``point`` (the edge's closest formed point, in the points' dimension),
    ``formed`` (that point in 3D), ``flat`` (its material position on the flat blank, (n,
    2)) and ``draw_in`` (the model's draw-in there: inward in-plane displacement of the
    edge's material point from ``centre_mm``).
    """
    from scipy.spatial import cKDTree

    P = np.asarray(points, float)
    dim = P.shape[1]
    e, outward = edge_segments(mesh)
    a, b = mesh.x[e[:, 0], :dim], mesh.x[e[:, 1], :dim]
    k = min(k, len(e))
    _, cand = cKDTree(0.5 * (a + b)).query(P, k=k)
    cand = cand.reshape(len(P), k)
    A, B = a[cand], b[cand]
    AB = B - A
    s = np.clip(((P[:, None] - A) * AB).sum(-1) / np.maximum((AB * AB).sum(-1), 1e-300), 0, 1)
    Q = A + s[..., None] * AB
    d = np.linalg.norm(P[:, None] - Q, axis=-1)
    best = np.argmin(d, axis=1)
    rows = np.arange(len(P))
    edge, s, Q = cand[rows, best], s[rows, best], Q[rows, best]
    # Outward on the formed edge: the flat outward turned with the edge's in-plane direction.
    t_flat = mesh.X[e[edge, 1], :2] - mesh.X[e[edge, 0], :2]
    t_form = mesh.x[e[edge, 1], :2] - mesh.x[e[edge, 0], :2]
    ang = np.arctan2(t_form[:, 1], t_form[:, 0]) - np.arctan2(t_flat[:, 1], t_flat[:, 0])
    o = outward[edge]
    o = np.column_stack([np.cos(ang) * o[:, 0] - np.sin(ang) * o[:, 1],
                         np.sin(ang) * o[:, 0] + np.cos(ang) * o[:, 1]])
    sign = np.sign(np.einsum("ni,ni->n", (P - Q)[:, :2], o))
    F = mesh.X[e[edge, 0], :2] + s[:, None] * (mesh.X[e[edge, 1], :2] - mesh.X[e[edge, 0], :2])
    x3 = mesh.x[e[edge, 0]] + s[:, None] * (mesh.x[e[edge, 1]] - mesh.x[e[edge, 0]])
    x = x3[:, :2]
    c = np.asarray(centre_mm, float)[:2]
    draw_in = np.linalg.norm(F - c, axis=1) - np.linalg.norm(x - c, axis=1)
    return {"signed": np.where(sign == 0, 1.0, sign) * d[rows, best],
            "distance": d[rows, best], "point": Q, "formed": x3, "flat": F,
            "draw_in": draw_in}


# --------------------------------------------------------------------------------------------
# The formed sheet of a run, on disk, and the model's values at a lab's points


def draw_in_at(flat: np.ndarray, formed: np.ndarray, centre_mm=(0.0, 0.0)) -> np.ndarray:
    """The draw-in (mm) of material points: inward in-plane displacement from ``centre_mm``.

    |X − c| − |x − c| in plan, X the flat and x the formed position (as the edge's draw-in
    of :func:`closest_on_edge`): positive when the point moved towards the centre.
    """
    c = np.asarray(centre_mm, float)[:2]
    return (np.linalg.norm(np.asarray(flat, float)[:, :2] - c, axis=1)
            - np.linalg.norm(np.asarray(formed, float)[:, :2] - c, axis=1))


def write_sheet(grid: FormedGrid, path: str | os.PathLike, comment: str = "") -> Path:
    """Write a formed sheet (every ply of a stack) as a CSV table, node by node.

    Columns :data:`SHEET_COLUMNS`: the ply (1 = the punch side), the node's indices on the
    grid of the modelled part, its flat and formed positions (mm), full precision; absent
    nodes of a clipped net are left out. The symmetry planes are the run's (``summary.json``,
    ``symmetry``).
    """
    from fenicsx_drape.provenance import atomic_write_text

    rows = []
    for k, g in enumerate(grid.plies or (grid,), start=1):
        i, j = np.nonzero(g.present)
        block = np.column_stack([np.full(len(i), k), i, j, g.X[i, j], g.x[i, j]])
        rows.append(block)
    data = np.concatenate(rows)
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append(",".join(SHEET_COLUMNS))
    lines += [",".join([str(int(r[0])), str(int(r[1])), str(int(r[2]))]
                       + [repr(float(v)) for v in r[3:]]) for r in data]
    return atomic_write_text(path, "\n".join(lines) + "\n")


def read_sheet(path: str | os.PathLike, planes: tuple[str, ...] = ()) -> FormedGrid:
    """Read a formed sheet written by :func:`write_sheet` (the last ply, carrying every ply).

    Raises:
        DrapeInputError: a missing or malformed file (named with its line).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise DrapeInputError(f"{path}: cannot read the formed sheet ({err})") from err
    body = [(n, line) for n, line in enumerate(text.splitlines(), start=1)
            if line.strip() and not line.lstrip().startswith("#")]
    if not body or tuple(c.strip() for c in body[0][1].split(",")) != SHEET_COLUMNS:
        raise DrapeInputError(f"{path}:{body[0][0] if body else 1}: not a formed sheet (its "
                              f"header must be {','.join(SHEET_COLUMNS)})")
    try:
        data = np.array([[float(v) for v in line.split(",")] for _, line in body[1:]])
    except ValueError as err:
        raise DrapeInputError(f"{path}: a row of the formed sheet is not numbers ({err})") from err
    if data.ndim != 2 or data.shape[1] != len(SHEET_COLUMNS) or not np.isfinite(data).all():
        raise DrapeInputError(f"{path}: the formed sheet needs {len(SHEET_COLUMNS)} finite "
                              "numbers in every row")
    both = tuple(planes) == ("x", "y")
    symmetry = None if both or not planes else tuple(planes)
    grids = []
    for k in np.unique(data[:, 0]).astype(int):
        rows = data[data[:, 0] == k]
        i, j = rows[:, 1].astype(int), rows[:, 2].astype(int)
        X = np.full((i.max() + 1, j.max() + 1, 3), np.nan)
        x = X.copy()
        X[i, j], x[i, j] = rows[:, 3:6], rows[:, 6:9]
        grids.append(FormedGrid(X, x, both, symmetry))
    if len(grids) == 1:
        return grids[0]
    return dataclasses.replace(grids[-1], plies=tuple(grids))


@dataclasses.dataclass(frozen=True)
class Formed:
    """A formed run read from the output folder of ``drape form``."""

    grid: FormedGrid  # the ply away from the punch (every ply in ``grid.plies`` of a stack)
    centre_mm: tuple[float, float]  # the net's origin: the centre of draw-in
    case_name: str
    folder: Path


def read_formed(folder: str | os.PathLike) -> Formed:
    """The formed sheet of a ``drape form`` output folder (``formed_sheet.csv``, ``summary.json``).

    Raises:
        DrapeInputError: not such a folder, or one written before the sheet was.
    """
    import json

    folder = Path(folder)
    summary_path, sheet_path = folder / "summary.json", folder / SHEET_FILE
    if not summary_path.is_file():
        raise DrapeInputError(f"{folder}: not the output folder of 'drape form' (no "
                              "summary.json)")
    if not sheet_path.is_file():
        raise DrapeInputError(f"{folder}: no {SHEET_FILE} (written by 'drape form' from this "
                              "version on): form the case again")
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise DrapeInputError(f"{summary_path}: cannot read it ({err})") from err
    planes = tuple(summary.get("symmetry", ()))
    blank = (summary.get("case") or {}).get("blank", {})
    centre = tuple(float(v) for v in blank.get("origin_mm", (0.0, 0.0)))[:2]
    return Formed(read_sheet(sheet_path, planes), centre, str(summary.get("case_name", "")),
                  folder)


def _read_points(path: Path) -> tuple[dict[str, np.ndarray], dict[str, tuple[str, ...]],
                                      np.ndarray, list[str]]:
    """A CSV of points: its columns, text columns, file lines and header order.

    Numeric columns, the text columns ``label`` and ``line``, the file line of each row and
    the header's order.
    """
    import csv

    from fenicsx_drape.measurements.lab import _read_csv

    problems: list[str] = []
    table = _read_csv(path, "points", lambda f, line, text: problems.append(f"{f}:{line}: {text}"))
    if table is None:
        raise DrapeInputError("\n".join(problems))
    columns, texts, lines, header_line = table
    header = path.read_text(encoding="utf-8-sig").splitlines()[header_line - 1]
    order = [c.strip() for c in next(csv.reader([header]))]
    for name, values in columns.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise DrapeInputError(f"{path}:{lines[bad[0]]}: column {name} is not a finite "
                                  "number")
    return columns, texts, lines, order


def probe(formed: str | os.PathLike | Formed | FormedGrid,
          points: str | os.PathLike | Mapping[str, Any], *, edge: bool = False,
          ply: int | None = None, centre_mm=None) -> dict[str, Any]:
    """The model's values at a lab's points, by the definitions ``compare`` uses.

    Args:
        formed: The output folder of ``drape form`` (:func:`read_formed`), or a formed sheet.
        points: A CSV file or columns. Points of the formed part (``x_mm, y_mm, z_mm``) or of
            the flat blank (``x0_mm, y0_mm``; the formed position wins when both are given,
            as in a bundle); with ``edge``, points of the blank's edge after forming
            (``x_mm, y_mm``, matched in plan, or with ``z_mm`` in 3D). Optional ``ply`` (of a
            stack, 1 = the punch side), ``label``, ``line``, ``s_mm`` and any other column,
            all passed through.
        edge: The points are of the edge (an outline) rather than points of the part.
        ply: The ply of a stack for rows without a ``ply`` column (default: the ply away
            from the punch, the one a camera sees).
        centre_mm: The centre of draw-in (default: the run's net origin).

    Returns:
        The columns of the input, then the model's: for points, ``x0_mm, y0_mm`` (the
        material point: given, or that of the closest point of the formed sheet),
        ``x_mm, y_mm, z_mm`` (its formed position: given, or bilinear in its cell),
        ``distance_mm`` (formed points: signed distance to the sheet along its normal),
        ``shear_deg`` (:func:`shear_at_flat`: each cell's own angle at its centre, bilinear
        between centres), ``draw_in_mm`` (:func:`draw_in_at`); for an edge, ``distance_mm``
        (signed, positive outside the model's edge: less draw-in than modelled),
        ``edge_x_mm, edge_y_mm, edge_z_mm`` and ``x0_mm, y0_mm`` (the edge's closest point,
        formed and flat) and ``draw_in_mm`` there. ``unmatched`` is 1 for a point off the
        blank or farther than :data:`UNMATCHED_CELLS` cells from the sheet (its values
        NaN), else 0. An input column the model's values replace is kept as
        ``measured_<name>``.

    Raises:
        DrapeInputError: a points table without the columns it needs, NaN cells, a ply the
            sheet does not have.
    """
    if isinstance(formed, FormedGrid):
        grid, centre = formed, (0.0, 0.0)
    else:
        run = formed if isinstance(formed, Formed) else read_formed(formed)
        grid, centre = run.grid, run.centre_mm
    centre = centre if centre_mm is None else tuple(centre_mm)
    where = "points"
    if isinstance(points, Mapping):
        texts = {k: tuple(str(v) for v in points[k]) for k in ("label", "line") if k in points}
        columns = {k: np.asarray(v, float) for k, v in points.items() if k not in texts}
        n = len(next(iter(points.values()))) if points else 0
        lines, order = np.arange(1, n + 1), list(points)
    else:
        where = str(points)
        columns, texts, lines, order = _read_points(Path(points))
    n = len(lines)
    formed_xyz = {"x_mm", "y_mm", "z_mm"} <= set(columns)
    if edge:
        if not {"x_mm", "y_mm"} <= set(columns):
            raise DrapeInputError(f"{where}: edge points need the columns x_mm, y_mm (z_mm "
                                  f"optional); it has {', '.join([*columns, *texts])}")
    elif not formed_xyz and not {"x0_mm", "y0_mm"} <= set(columns):
        raise DrapeInputError(f"{where}: points need the columns x_mm, y_mm, z_mm (formed) or "
                              f"x0_mm, y0_mm (flat); it has {', '.join([*columns, *texts])}")
    plies = columns.get("ply")
    if plies is not None and np.any(plies != np.round(plies)):
        k = np.flatnonzero(plies != np.round(plies))[0]
        raise DrapeInputError(f"{where}:{lines[k]}: ply {plies[k]:g} is not a whole number")
    ply_of = np.full(n, -1 if ply is None else ply) if plies is None else plies.astype(int)
    out: dict[str, np.ndarray] = {}
    for k in np.unique(ply_of):
        rows = np.flatnonzero(ply_of == k)
        try:
            sheet = grid.ply(None if k == -1 else int(k))
        except DrapeInputError as err:
            raise DrapeInputError(f"{where}:{lines[rows[0]]}: {err}") from None
        part = {c: v[rows] for c, v in columns.items()}
        values = (_edge_values if edge else _point_values)(sheet, part, centre)
        for name, v in values.items():
            out.setdefault(name, np.full(n, np.nan))[rows] = v
    given = ("x_mm", "y_mm", "z_mm") if edge or formed_xyz else ("x0_mm", "y0_mm")
    inputs = {**columns, **texts}
    result: dict[str, Any] = {}
    for name in order or inputs:  # the input's columns first, in its order
        kept = name in given or name not in out
        result[name if kept else f"measured_{name}"] = inputs[name]
    result.update({k: v for k, v in out.items() if k not in given})
    return result


def _point_values(grid: FormedGrid, c: Mapping[str, np.ndarray], centre) -> dict:
    full = grid.full()
    reach = UNMATCHED_CELLS * full.cell_mm
    if {"x_mm", "y_mm", "z_mm"} <= set(c):
        P = np.column_stack([c["x_mm"], c["y_mm"], c["z_mm"]])
        γ, near = shear_at_formed(full, P)
        flat, x = near.flat[:, :2], near.point
        unmatched = (near.distance > reach) | ~np.isfinite(γ)
        values = {"x0_mm": flat[:, 0], "y0_mm": flat[:, 1], "distance_mm": near.signed}
    else:
        flat = np.column_stack([c["x0_mm"], c["y0_mm"]])
        γ = shear_at_flat(full, flat)
        x = full.sample(flat, outside="nan")
        unmatched = ~np.isfinite(γ) | ~np.isfinite(x[:, 0])
        values = {"x_mm": x[:, 0], "y_mm": x[:, 1], "z_mm": x[:, 2]}
    values.update(shear_deg=γ, draw_in_mm=draw_in_at(flat, x, centre))
    values = {k: np.where(unmatched, np.nan, v) for k, v in values.items()}
    values["unmatched"] = unmatched.astype(float)
    return values


def _edge_values(grid: FormedGrid, c: Mapping[str, np.ndarray], centre) -> dict:
    mesh = SheetMesh.of(grid)
    P = np.column_stack([c["x_mm"], c["y_mm"], c["z_mm"]]) if "z_mm" in c else \
        np.column_stack([c["x_mm"], c["y_mm"]])
    e = closest_on_edge(mesh, P, centre)
    unmatched = e["distance"] > UNMATCHED_CELLS * mesh.cell_mm
    values = {"distance_mm": e["signed"], "edge_x_mm": e["formed"][:, 0],
              "edge_y_mm": e["formed"][:, 1], "edge_z_mm": e["formed"][:, 2],
              "x0_mm": e["flat"][:, 0], "y0_mm": e["flat"][:, 1], "draw_in_mm": e["draw_in"]}
    values = {k: np.where(unmatched, np.nan, v) for k, v in values.items()}
    values["unmatched"] = unmatched.astype(float)
    return values


def write_values(columns: Mapping[str, Any], path: str | os.PathLike | None = None,
                 comment: str = "") -> str:
    """The columns of :func:`probe` as CSV text (written to ``path`` when given).

    Numbers in full precision (``nan`` where unmatched), ``unmatched`` and ``ply`` as whole
    numbers, text columns quoted where needed.
    """
    import csv
    import io

    from fenicsx_drape.provenance import atomic_write_text

    names = list(columns)
    buffer = io.StringIO()
    for line in comment.splitlines():
        buffer.write(f"# {line}\n")
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(names)
    n = len(next(iter(columns.values()))) if names else 0

    def cell(name: str, v: Any) -> str:
        if isinstance(v, str):
            return v
        if name in ("unmatched", "ply") and np.isfinite(v):
            return str(int(v))
        return repr(float(v))

    for r in range(n):
        writer.writerow([cell(name, columns[name][r]) for name in names])
    text = buffer.getvalue()
    if path is not None:
        atomic_write_text(path, text)
    return text
