"""What the forming kinds' data checks share: is a measurement one of the case it names?

Each forming kind's ``check`` (:func:`~fenicsx_drape.diagnosis.data_check.data_check` runs
them before any fit) looks at its measurement against its case and says ``(suspect, why)``
(the first reason found), or None. Positions (a grid, shear points, a scan, an edge with z:
:func:`check_positions`):

- *units*: the formed positions span less than 1/100 of the blank (metres read as mm);
- *axes*: along an axis the formed positions span more than the tools reach (the case's
  reach, :func:`~fenicsx_drape.measurements.plausible.reach_of_case`, × 1.2 plus two cells);
  when another order of the axes fits, the swap is named (of those that fit, the one that
  moves the fewest axes, then whose spans are most like the tools');
- *another part*: more than :data:`OTHER_PART_SHARE` of the flat positions lie more than a
  quarter cell outside the case's blank, or of the formed positions farther than a cell from
  every tool at the end of the motion (a part formed on these tools lies on them); or at least
  :data:`INSIDE_COUNT` and :data:`INSIDE_SHARE` of the formed positions at a tool (within a
  cell of its surface, or inside it) lie inside it deeper than a cell at the end of the
  motion: a ply lies on the tools, not in them, and a net whose nodes lie on a convex tool
  cuts into it by less than a cell (the scenario benchmark's right bundles of seed 51, formed
  on 20 and 30 mm cells: by at most 9.4 mm); a shallower part's grid under a deeper part's
  punch is found so;
- *a shifted frame* (a grid: flat and formed positions of its nodes): on a symmetry plane of
  the case (x = 0 or y = 0) the tools hold the sheet's column of that plane: the grid's column
  nearest the plane in the formed positions has flat and formed coordinates that agree. When
  they differ by more than :data:`SHIFT_OF_GRID` of the grid's spacing (and 1 mm), the flat
  frame is shifted or the blank was placed off-centre by as much (a lab draws its grid on the
  blank where it meant the blank to lie): read as below.
- *a shifted frame without a symmetry plane*: the punch's top holds the sheet where it
  first touches it, so the grid's points formed farthest from the flat plane (|z| within
  half a cell of the largest) keep their flat x and y (median difference ≈ 0: below
  0.01 mm on the shipped parts formed whole on 20 mm cells). A median difference beyond the
  same tolerance is a shift of the flat frame, or a blank placed off-centre by as much; a
  grid drawn on the blank lies on it wherever the blank was placed, so the data are named
  when a flat position lies more than :data:`SHIFT_TOLERANCE_MM` outside the blank, and
  otherwise the blank offset, which the set-up stage sizes (``blank_offset_mm``), is
  chosen: not suspect, the ``why`` says so.

Shear points and a grid of one test and one ply (:func:`check_shear_against_grid`) are two
measurements of one ply: the shear of the grid's cells where the points lie (the angle between
the formed images of the ply's warp and weft, each cell's own; its noise 2 × the grid's
position noise / its spacing, in radians) and the points' shear must tell one pattern. The
points are named another part's when they differ from the grid's cells by more than
:data:`PATTERN_SDS` × the two noises combined (rms over the points within the grid's cells)
*and* by more than the points vary about their mean: the grid then explains none of their
pattern (on the scenario benchmark's right bundles of seed 51 it explains at least half of
their variance; of the cup's shear lines under the double dome's grid, none). A grid named
suspect by its own checks is no reference.

A *registered* measurement (``register = true``, its frame fitted by the comparison:
:func:`check_registered`) is checked only for what no rigid motion changes, its size: the
diameter of its points beyond 1.2 × the diagonal of the tools' reach plus two cells, or below
1/100 of the blank. An edge in plan and a force curve have checks of their own
(:mod:`~fenicsx_drape.diagnosis.kinds.outline`, :mod:`~fenicsx_drape.diagnosis.kinds.
punch_force`).
"""

from __future__ import annotations

import itertools

import numpy as np

#: A share of a measurement's points beyond the case that makes it another part's.
OTHER_PART_SHARE = 0.1
#: Positions inside a tool deeper than a cell: at least this many, and this share of those at
#: the tool (none on the scenario benchmark's right bundles of seed 51: at most 0.47 cell).
INSIDE_COUNT, INSIDE_SHARE = 3, 0.05
#: A flat-formed difference on a symmetry plane beyond this share of the grid spacing.
SHIFT_OF_GRID = 0.1
#: A shift of at least this (mm) is named; a flat position this far outside the blank is off it.
SHIFT_TOLERANCE_MM = 1.0
AXES = "xyz"
#: Shear points differ from their grid by more than this many times the combined noise.
PATTERN_SDS = 3.0


def columns_of(test, names) -> np.ndarray | None:
    """The test's columns ``names`` side by side (n, k), None when one is missing."""
    cols = [test.columns.get(n) for n in names]
    if any(c is None for c in cols):
        return None
    return np.column_stack([np.asarray(c, dtype=float) for c in cols])


def outside_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Distance (n,) of points (n, 2) outside a polygon (m, 2); 0 inside."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("nmk,mk->nm", points[:, None, :] - a, ab)
                / np.maximum(np.einsum("mk,mk->m", ab, ab), 1e-300), 0.0, 1.0)
    d = np.linalg.norm(points[:, None, :] - (a + t[..., None] * ab), axis=2).min(axis=1)
    # Inside by the crossing rule.
    x, y = points[:, :1], points[:, 1:]
    crosses = ((a[:, 1] > y) != (b[:, 1] > y)) & (
        x < a[:, 0] + (y - a[:, 1]) * ab[:, 0] / np.where(ab[:, 1] == 0, 1e-300, ab[:, 1]))
    inside = crosses.sum(axis=1) % 2 == 1
    return np.where(inside, 0.0, d)


def _axes(formed: np.ndarray, reach, cell: float) -> str | None:
    """An axis whose span is beyond the tools' reach (and the order of axes that fits)."""
    span = np.ptp(formed, axis=0)
    reach_span = np.asarray(reach.hi_mm) - np.asarray(reach.lo_mm)
    allowed = 1.2 * reach_span + 2.0 * cell

    def excess(order) -> float:
        return float(np.maximum(span[list(order)] - allowed, 0.0).sum())

    if excess((0, 1, 2)) == 0.0:
        return None
    a = int(np.argmax(span - allowed))
    text = f"the measured {AXES[a]} spans {span[a]:.3g} mm, the tools {reach_span[a]:.3g} mm"

    def simplest(order) -> tuple[int, float]:  # fewest axes moved, spans most like the tools'
        moved = sum(k != o for k, o in enumerate(order))
        return moved, float(np.abs(np.log((span[list(order)] + cell)
                                          / (reach_span + cell))).sum())

    fits = sorted((o for o in itertools.permutations(range(3)) if excess(o) == 0.0),
                  key=simplest)
    if fits:
        swapped = [AXES[k] for k in range(3) if fits[0][k] != k]
        return f"{' and '.join(swapped)} look swapped: {text}"
    return f"{text}: positions of another part, or of another frame?"


def _on_tools(case, formed: np.ndarray) -> tuple[float, tuple | None]:
    """The formed positions against the tools at the end of the motion (module docstring).

    Returns:
        The share of positions farther than a cell from every tool, and the tool most cut
        into: ``(deep, at, depth, point, tool)`` — of the ``at`` positions within a cell of
        that tool or inside it, ``deep`` lie inside it deeper than a cell, the deepest
        ``depth`` mm at ``point`` — or None when no position lies deeper than a cell in a tool.
    """
    from fenicsx_drape.forming.running.geometry import _distance
    from fenicsx_drape.forming.tools.build import build_tools

    tools = build_tools(case)
    end = case.duration_s
    cell = case.blank.cell_mm
    near = np.full(len(formed), np.inf)
    cut = None
    for spec in case.tools:
        d = np.asarray(_distance(tools[spec.name], formed, end), dtype=float)
        near = np.minimum(near, np.abs(d))
        at, deep = d < cell, d < -cell
        if deep.any() and (cut is None or deep.sum() / at.sum() > cut[0] / cut[1]):
            k = int(np.argmin(d))
            cut = (int(deep.sum()), int(at.sum()), float(-d[k]), formed[k], spec)
    return float(np.mean(near > cell)), cut


def noun_of(test) -> str:
    """What a lab calls the measurement of ``test``: grid, shear points, scan or edge."""
    lab = getattr(test, "lab", None)
    name = lab.measurement if lab is not None else "file"
    return {"file": "grid", "shear_points": "shear points", "surface": "scan",
            "outline": "edge"}.get(name, name)


def _spacing(test, grid: np.ndarray) -> float:
    return float(test.forming.get("grid_mm") or 0.0) or (
        float(np.median(np.abs(np.diff(np.unique(grid[:, 2]))))) if len(grid) > 1 else 0.0)


def _shift(test, case) -> tuple[bool, str] | None:
    """A flat frame shifted off the case's symmetry planes, or off the punch's top."""
    grid = columns_of(test, ("i", "j", "x0_mm", "y0_mm", "x_mm", "y_mm"))
    if grid is None:
        return None
    spacing = _spacing(test, grid)
    if not case.planes:
        return _top_shift(test, case, spacing)
    for plane in case.planes:
        k = {"x": 0, "y": 1}[plane]
        index, flat, formed = grid[:, k], grid[:, 2 + k], grid[:, 4 + k]
        columns = [c for c in np.unique(index) if (index == c).sum() >= 2]
        if not columns:
            continue
        best = min(columns, key=lambda c: float(np.median(np.abs(formed[index == c]))))
        rows = index == best
        if np.median(np.abs(formed[rows])) > 0.5 * spacing:
            continue  # the grid has no column on the plane
        s = float(np.median(flat[rows] - formed[rows]))
        if abs(s) > max(SHIFT_OF_GRID * spacing, SHIFT_TOLERANCE_MM):
            seen = (f"the grid's column the tools hold on their plane {plane} = 0 has "
                    f"{plane}0 = {s:+.3g} mm")
            return _frame_or_offset(grid[:, 2:4], case, f"every flat {plane} looks shifted "
                                    f"by {s:.3g} mm", seen, np.where(np.arange(2) == k, -s, 0.0))
    return None


def _frame_or_offset(flat, case, what: str, seen: str, b) -> tuple[bool, str]:
    """A flat shift: the data's frame if a flat position lies off the blank, else an offset.

    A grid drawn on the blank lies on it wherever the blank was placed, so a flat position
    more than :data:`SHIFT_TOLERANCE_MM` outside the blank names the data; otherwise the blank
    placed off-centre by ``b`` (which the set-up stage sizes) is chosen and said.
    """
    out = outside_polygon(flat, np.asarray(case.blank.polygon(), dtype=float))
    if out.max() > SHIFT_TOLERANCE_MM:
        k = int(np.argmax(out))
        return True, (f"{what}: {seen}, and the flat position ({flat[k, 0]:.4g}, "
                      f"{flat[k, 1]:.4g}) mm lies {out[k]:.3g} mm outside the blank (a grid "
                      "drawn on the blank lies on it wherever the blank was placed: the data's "
                      "frame, not a set-up the fit can size)")
    return False, (f"chosen: a blank placed off-centre by about ({b[0]:.3g}, {b[1]:.3g}) "
                   f"mm, a set-up error the set-up stage sizes (blank_offset_mm), not a "
                   f"shifted frame: {seen}, and every flat position lies on the blank")


def _top_shift(test, case, spacing: float) -> tuple[bool, str] | None:
    """Flat and formed x, y at the punch's top (module docstring): a frame or a blank offset."""
    p = columns_of(test, ("x0_mm", "y0_mm", "x_mm", "y_mm", "z_mm"))
    if p is None or len(p) < 3:
        return None
    z = np.abs(p[:, 4])
    top = z >= z.max() - 0.5 * case.blank.cell_mm
    d = np.round(np.median(p[top, :2] - p[top, 2:4], axis=0), 2) + 0.0  # flat - formed
    b = -d + 0.0  # the blank offset that explains it
    tol = max(SHIFT_OF_GRID * spacing, SHIFT_TOLERANCE_MM)
    if not np.abs(d).max() > tol:
        return None
    what = " and ".join(f"{a} by {v:+.3g} mm" for a, v in zip("xy", d) if abs(v) > tol)
    seen = (f"the {int(top.sum())} grid point(s) at the punch's top (formed within half a "
            f"cell of the farthest) moved {b[0]:+.3g}, {b[1]:+.3g} mm in plane, where the "
            f"top holds the sheet (tolerance {tol:.3g} mm)")
    return _frame_or_offset(p[:, :2], case, f"every flat position looks shifted ({what})",
                            seen, b)


def check_registered(test, case) -> tuple[bool, str] | None:
    """A scan whose frame the comparison fits: only its size, which no rigid motion changes."""
    from fenicsx_drape.measurements.plausible import reach_of_case

    xyz = columns_of(test, ("x_mm", "y_mm", "z_mm"))
    if xyz is None or len(xyz) < 3:
        return None
    centred = xyz - xyz.mean(axis=0)
    axes = np.linalg.svd(centred, full_matrices=False)[2]
    diameter = float(np.linalg.norm(np.ptp(centred @ axes.T, axis=0)))
    reach = reach_of_case(case)
    diagonal = float(np.linalg.norm(np.subtract(reach.hi_mm, reach.lo_mm)))
    size = float(np.ptp(np.asarray(case.blank.polygon(), dtype=float), axis=0).max())
    allowed = 1.2 * diagonal + 2.0 * case.blank.cell_mm
    if diameter > allowed:
        return True, (f"the registered scan is {diameter:.4g} mm across, more than the "
                      f"tools' reach allows ({allowed:.4g} mm: 1.2 × its diagonal "
                      f"{diagonal:.4g} mm and two cells), whatever its frame: another part's "
                      "scan, or millimetres read as something larger?")
    if diameter < 0.01 * size:
        return True, (f"the registered scan is {diameter:.3g} mm across, the blank "
                      f"{size:.3g} mm: metres read as millimetres?")
    return None



def check_positions(test, case) -> tuple[bool, str] | None:
    """A measurement's flat and formed positions against ``case`` (module doc)."""
    from fenicsx_drape.measurements.plausible import reach_of_case

    formed = columns_of(test, ("x_mm", "y_mm", "z_mm"))
    flat = columns_of(test, ("x0_mm", "y0_mm"))
    polygon = np.asarray(case.blank.polygon(), dtype=float)
    size = float(np.ptp(polygon, axis=0).max())
    cell = case.blank.cell_mm
    if formed is not None and len(formed) >= 3:
        span = float(np.ptp(formed, axis=0).max())
        if span < 0.01 * size:
            return True, (f"the positions span {span:.3g} mm, the blank {size:.3g} mm: metres "
                          "read as millimetres?")
        axes = _axes(formed, reach_of_case(case), cell)
        if axes:
            return True, axes
    if flat is not None and len(flat):
        out = outside_polygon(flat, polygon) > 0.25 * cell
        if out.mean() > OTHER_PART_SHARE:
            k = int(np.argmax(outside_polygon(flat, polygon)))
            return True, (f"{100 * out.mean():.0f} % of the flat positions lie outside the "
                          f"case's blank (up to ({flat[k, 0]:.4g}, {flat[k, 1]:.4g}) mm): "
                          "another part's grid?")
    if formed is not None and len(formed):
        share, cut = _on_tools(case, formed)
        if share > OTHER_PART_SHARE:
            return True, (f"{100 * share:.0f} % of the formed positions lie farther than a "
                          f"cell ({cell:g} mm) from every tool at the end of the motion: "
                          "another part's shape?")
        if cut is not None and cut[0] >= max(INSIDE_COUNT, INSIDE_SHARE * cut[1]):
            deep, at, depth, p, spec = cut
            return True, (f"{deep} of the {at} formed positions at the {spec.role} "
                          f"{spec.name!r} (within a cell of it, or in it) lie inside it deeper "
                          f"than a cell ({cell:g} mm) at the end of its motion, up to "
                          f"{depth:.3g} mm at ({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) mm: a ply "
                          "formed on these tools lies on them, not in them (a net cuts into "
                          "a tool by less than a cell): another part's "
                          f"{noun_of(test)}?")
    return _shift(test, case)


def check_registered_or_positions(test, case) -> tuple[bool, str] | None:
    """A registered measurement's size (:func:`check_registered`), else its positions."""
    lab = getattr(test, "lab", None)
    if lab is not None and lab.frame.register:
        return check_registered(test, case)
    return check_positions(test, case)


def grid_cells(grid: np.ndarray, angle_deg: float) -> tuple[np.ndarray, np.ndarray,
                                                              np.ndarray, float]:
    """Each cell of a grid (columns i, j, x0, y0, x, y, z): its own shear and centres.

    A cell's deformation is the least-squares map of its four corners' flat positions to their
    formed ones; the ply's warp and weft (at ``angle_deg`` to x) turn with it, and its shear is
    90° minus the angle between their images (the measurement spec's sign).

    Returns:
        Flat centres (m, 2), formed centres (m, 3), shear (m,) in degrees, and the grid's
        spacing (median cell side, mm).
    """
    index = {(int(r[0]), int(r[1])): k for k, r in enumerate(grid)}
    flat, formed = grid[:, 2:4], grid[:, 4:7]
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    fibres = np.array([[c, -s], [s, c]])  # columns: warp, weft on the flat blank
    centres0, centres, shear, sides = [], [], [], []
    for (i, j), a in index.items():
        corners = [a, index.get((i + 1, j)), index.get((i, j + 1)), index.get((i + 1, j + 1))]
        if None in corners:
            continue
        dX = flat[corners] - flat[corners].mean(axis=0)
        dx = formed[corners] - formed[corners].mean(axis=0)
        F = np.linalg.lstsq(dX, dx, rcond=None)[0].T  # (3, 2): flat to formed
        warp, weft = (F @ fibres).T
        cos = warp @ weft / max(np.linalg.norm(warp) * np.linalg.norm(weft), 1e-300)
        shear.append(90.0 - np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
        centres0.append(flat[corners].mean(axis=0))
        centres.append(formed[corners].mean(axis=0))
        sides.append(np.ptp(flat[corners], axis=0).mean())
    spacing = float(np.median(sides)) if sides else 0.0
    return np.array(centres0), np.array(centres), np.array(shear), spacing


def ply_angle_of(test, case) -> float:
    """The warp's angle (deg) of the ply a measurement is of (the outermost when not named)."""
    angle = float(case.blank.ply_angle_deg)
    if case.plies:
        ply = getattr(test, "ply", None) or len(case.plies)
        angle += float(case.plies[ply - 1].angle_deg)
    return angle


def check_shear_against_grid(points, grid, case, sd_points: float, sd_grid_mm: float
                             ) -> tuple[bool, str] | None:
    """Shear points against the shear of their test's grid on the same ply (module docstring).

    Args:
        points: The shear points' test (``shear_deg`` at flat ``x0_mm, y0_mm`` or formed
            ``x_mm, y_mm, z_mm`` positions).
        grid: The same forming test's grid of the same ply.
        case: Their forming case.
        sd_points: The points' shear noise (degrees).
        sd_grid_mm: The grid's position noise (mm).

    Returns:
        ``(True, why)`` when the points cannot be of the ply the grid measured, else None
        (also when the two cannot be set side by side: magnitudes only, formed positions in
        a registered frame, too few points within the grid's cells).
    """
    lab = points.lab
    table = columns_of(grid, ("i", "j", "x0_mm", "y0_mm", "x_mm", "y_mm", "z_mm"))
    shear = points.columns.get("shear_deg")
    if table is None or shear is None or lab.shear_magnitude:
        return None
    if not lab.flat and any(getattr(t.lab, "frame", None) is not None and t.lab.frame.register
                            for t in (points, grid) if t.lab is not None):
        return None  # formed positions in a frame the comparison fits: not set side by side
    where = columns_of(points, ("x0_mm", "y0_mm") if lab.flat else ("x_mm", "y_mm", "z_mm"))
    if where is None:
        return None
    centres0, centres, cell_shear, spacing = grid_cells(table, ply_angle_of(points, case))
    if len(cell_shear) < 2 or not spacing > 0:
        return None
    centre = centres0 if lab.flat else centres
    distance = np.linalg.norm(where[:, None, :] - centre[None, :, :], axis=2)
    inside = distance.min(axis=1) <= 0.75 * spacing  # within the grid's cells
    if inside.sum() < 5:
        return None
    measured = np.asarray(shear, dtype=float)[inside]
    of_grid = cell_shear[distance[inside].argmin(axis=1)]
    sd_grid = np.degrees(2.0 * sd_grid_mm / spacing)
    apart = float(np.sqrt(np.mean((measured - of_grid) ** 2)))
    spread = float(np.std(measured))
    allowed = PATTERN_SDS * float(np.hypot(sd_points, sd_grid))
    if apart > allowed and apart > spread:
        return True, (f"the shear points differ from the shear of the test's own grid "
                      f"(each grid cell's angle between the ply's warp and weft, at "
                      f"{int(inside.sum())} points within its cells) by {apart:.3g}° rms, "
                      f"more than {PATTERN_SDS:g} × their combined noise ({allowed:.3g}°) "
                      f"and more than the points vary ({spread:.3g}° rms about their mean): "
                      "the grid explains none of their pattern, and one ply has one shear: "
                      "another part's shear points?")
    return None

