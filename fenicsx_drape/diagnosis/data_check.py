"""Data before physics (spec version 4): is each measurement one of the case it names?

A bundle may hold measurements that cannot belong to its case: axes swapped, another part's
grid, a flat frame shifted, a scan in metres. No effect or set-up explains them, and blaming
the model sends a user the wrong way. :func:`data_check` looks at every measurement of a
forming test against its case, before any fit, and returns the report's ``data_check``
entries (``suspect`` with ``why``, the first reason found):

- *units*: the formed positions span less than 1/100 of the blank (metres read as mm);
- *axes*: along an axis the formed positions span more than the tools reach (the case's
  reach, :func:`~fenicsx_drape.measurements.plausible.reach_of_case`, × 1.2 plus two cells);
  when another order of the axes fits, the swap is named (of those that fit, the one that
  moves the fewest axes, then whose spans are most like the tools');
- *another part*: more than :data:`OTHER_PART_SHARE` of the flat positions lie more than a
  quarter cell outside the case's blank, or of the formed positions farther than a cell from
  every tool at the end of the motion (a part formed on these tools lies on them);
- *a shifted frame*: on a symmetry plane of the case (x = 0 or y = 0) the tools hold the
  sheet's column of that plane: the grid's column nearest the plane in the formed positions
  has flat and formed coordinates that agree. When they differ by more than
  :data:`SHIFT_OF_GRID` of the grid's spacing (and 1 mm), the flat (or formed) frame is
  shifted. A blank placed off-centre (a set-up error the set-up stage sizes) breaks the
  plane, and its test has no plane to check: the ``why`` says which was chosen.
- *a shifted frame without a symmetry plane*: the punch's top holds the sheet where it
  first touches it, so the grid's points formed farthest from the flat plane (|z| within
  half a cell of the largest) keep their flat x and y (median difference ≈ 0: below
  0.01 mm on the shipped parts formed whole on 20 mm cells). A median difference beyond the
  same tolerance is a shift of the flat frame, or a blank placed off-centre by as much; a
  grid drawn on the blank lies on it wherever the blank was placed, so the data are named
  when a flat position lies more than :data:`SHIFT_TOLERANCE_MM` outside the blank, and
  otherwise the blank offset, which the set-up stage sizes (``blank_offset_mm``), is
  chosen: not suspect, the ``why`` says so.

Measurements without a grid, each against what the case allows:

- an *outline* in plan (no z): more than :data:`OTHER_PART_SHARE` of its points farther
  than a cell outside the flat blank (the edge of a formed sheet is drawn in, never out),
  or a span < 1/100 of the blank (metres);
- a *force curve* (``punch_force``): a travel that exceeds the case's by more than
  :data:`TRAVEL_MARGIN` (and a load step), or is mostly ≤ 0 (a travel of the wrong sign:
  the lab's sign convention?);
- a *registered scan* (``register = true``, its frame fitted by the comparison): only what
  no rigid motion changes, its size: the diameter of its points beyond 1.2 × the diagonal
  of the tools' reach plus two cells, or below 1/100 of the blank.

A travel against the tool's motion (``travel_mm`` ≤ 0) is impossible input: the function
raises :class:`~fenicsx_drape.errors.DrapeInputError` (exit 2; the case's overrides refuse
it first, when the bundle is read).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError

#: A share of a measurement's points beyond the case that makes it another part's.
OTHER_PART_SHARE = 0.1
#: A flat-formed difference on a symmetry plane beyond this share of the grid spacing.
SHIFT_OF_GRID = 0.1
#: A shift of at least this (mm) is named; a flat position this far outside the blank is off it.
SHIFT_TOLERANCE_MM = 1.0
#: A force curve's travel may pass the case's by this share (and a load step).
TRAVEL_MARGIN = 0.05
AXES = "xyz"


def _columns(test, names) -> np.ndarray | None:
    cols = [test.columns.get(n) for n in names]
    if any(c is None for c in cols):
        return None
    return np.column_stack([np.asarray(c, dtype=float) for c in cols])


def _outside_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
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


def _off_tools(case, formed: np.ndarray) -> float:
    """The share of formed positions farther than a cell from every tool at the end."""
    from fenicsx_drape.forming.case.format import build_tools
    from fenicsx_drape.forming.running.geometry import _distance

    tools = build_tools(case)
    end = case.duration_s
    near = np.full(len(formed), np.inf)
    for tool in tools.values():
        near = np.minimum(near, np.abs(_distance(tool, formed, end)))
    return float(np.mean(near > case.blank.cell_mm))


def _spacing(test, grid: np.ndarray) -> float:
    return float(test.forming.get("grid_mm") or 0.0) or (
        float(np.median(np.abs(np.diff(np.unique(grid[:, 2]))))) if len(grid) > 1 else 0.0)


def _shift(test, case) -> tuple[bool, str] | None:
    """A flat frame shifted off the case's symmetry planes, or off the punch's top."""
    grid = _columns(test, ("i", "j", "x0_mm", "y0_mm", "x_mm", "y_mm"))
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
            return True, (f"every flat {plane} looks shifted by {s:.3g} mm: the grid's column "
                          f"the tools hold on their plane {plane} = 0 has {plane}0 = {s:+.3g} "
                          "mm (a blank placed off-centre, a set-up error, would keep flat and "
                          f"formed {plane} equal there: not a set-up the fit can size)")
    return None


def _top_shift(test, case, spacing: float) -> tuple[bool, str] | None:
    """Flat and formed x, y at the punch's top (module docstring): a frame or a blank offset."""
    p = _columns(test, ("x0_mm", "y0_mm", "x_mm", "y_mm", "z_mm"))
    if p is None or len(p) < 3:
        return None
    z = np.abs(p[:, 4])
    top = z >= z.max() - 0.5 * case.blank.cell_mm
    d = np.round(np.median(p[top, :2] - p[top, 2:4], axis=0), 2) + 0.0  # flat - formed
    b = -d + 0.0  # the blank offset that explains it
    tol = max(SHIFT_OF_GRID * spacing, SHIFT_TOLERANCE_MM)
    if not np.abs(d).max() > tol:
        return None
    out = _outside_polygon(p[:, :2], np.asarray(case.blank.polygon(), dtype=float))
    what = " and ".join(f"{a} by {v:+.3g} mm" for a, v in zip("xy", d) if abs(v) > tol)
    seen = (f"the {int(top.sum())} grid point(s) at the punch's top (formed within half a "
            f"cell of the farthest) moved {b[0]:+.3g}, {b[1]:+.3g} mm in plane, where the "
            f"top holds the sheet (tolerance {tol:.3g} mm)")
    if out.max() > SHIFT_TOLERANCE_MM:
        k = int(np.argmax(out))
        return True, (f"every flat position looks shifted ({what}): {seen}, and the flat "
                      f"position ({p[k, 0]:.4g}, {p[k, 1]:.4g}) mm lies {out[k]:.3g} mm "
                      "outside the blank (a grid drawn on the blank lies on it wherever the "
                      "blank was placed: the data's frame, not a set-up)")
    return False, (f"chosen: a blank placed off-centre by about ({b[0]:.3g}, {b[1]:.3g}) "
                   f"mm, a set-up error the set-up stage sizes (blank_offset_mm), not a "
                   f"shifted frame: {seen}, and every flat position lies on the blank")


def _outline(test, case) -> tuple[bool, str] | None:
    """An outline in plan: on the flat blank (a formed edge is drawn in, never out)."""
    xy = _columns(test, ("x_mm", "y_mm"))
    if xy is None or len(xy) < 3:
        return None
    polygon = np.asarray(case.blank.polygon(), dtype=float)
    size = float(np.ptp(polygon, axis=0).max())
    span = float(np.ptp(xy, axis=0).max())
    if span < 0.01 * size:
        return True, (f"the outline spans {span:.3g} mm, the blank {size:.3g} mm: metres read "
                      "as millimetres?")
    cell = case.blank.cell_mm
    out = _outside_polygon(xy, polygon)
    if np.mean(out > cell) > OTHER_PART_SHARE:
        k = int(np.argmax(out))
        return True, (f"{100 * np.mean(out > cell):.0f} % of the outline lies farther than a "
                      f"cell ({cell:g} mm) outside the flat blank (up to {out[k]:.3g} mm, at "
                      f"({xy[k, 0]:.4g}, {xy[k, 1]:.4g}) mm), where a formed edge, drawn in, "
                      "cannot be: another part's outline, or another frame?")
    return None


def _force(test, case) -> tuple[bool, str] | None:
    """A force curve's travel against the case's: not beyond it, not of the wrong sign."""
    travel = test.columns.get("travel_mm")
    if travel is None or not len(travel):
        return None
    travel = np.asarray(travel, dtype=float)
    full = float(case.total_travel_mm)
    if np.mean(travel <= 0.0) > 0.5:
        return True, (f"the force curve's travel runs from {travel.min():.4g} to "
                      f"{travel.max():.4g} mm, mostly ≤ 0: a travel of the wrong sign (the "
                      f"case's tools travel {full:.4g} mm forward; the lab's sign convention?)")
    allowed = (1.0 + TRAVEL_MARGIN) * full + case.step_mm
    if travel.max() > allowed:
        return True, (f"the force curve's travel reaches {travel.max():.4g} mm, the case's "
                      f"tools travel {full:.4g} mm (allowed {allowed:.4g} mm): a curve of "
                      "another test, or travel in other units?")
    return None


def _registered(test, case) -> tuple[bool, str] | None:
    """A scan whose frame the comparison fits: only its size, which no rigid motion changes."""
    from fenicsx_drape.measurements.plausible import reach_of_case

    xyz = _columns(test, ("x_mm", "y_mm", "z_mm"))
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


def check_measurement(test, case) -> tuple[bool, str] | None:
    """A measurement of a forming test against ``case``: ``(suspect, why)``, None when fine.

    Not suspect with a ``why``: the reading of the data that was chosen (a blank offset
    rather than a shifted frame, the module docstring).
    """
    from fenicsx_drape.measurements.plausible import reach_of_case

    lab = getattr(test, "lab", None)
    if lab is not None and lab.measurement == "punch_force":
        return _force(test, case)
    if lab is not None and lab.frame.register:
        return _registered(test, case)
    formed = _columns(test, ("x_mm", "y_mm", "z_mm"))
    if formed is None and lab is not None and lab.measurement == "outline":
        return _outline(test, case)
    flat = _columns(test, ("x0_mm", "y0_mm"))
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
        out = _outside_polygon(flat, polygon) > 0.25 * cell
        if out.mean() > OTHER_PART_SHARE:
            k = int(np.argmax(_outside_polygon(flat, polygon)))
            return True, (f"{100 * out.mean():.0f} % of the flat positions lie outside the "
                          f"case's blank (up to ({flat[k, 0]:.4g}, {flat[k, 1]:.4g}) mm): "
                          "another part's grid?")
    if formed is not None and len(formed):
        share = _off_tools(case, formed)
        if share > OTHER_PART_SHARE:
            return True, (f"{100 * share:.0f} % of the formed positions lie farther than a "
                          f"cell ({cell:g} mm) from every tool at the end of the motion: "
                          "another part's shape?")
    return _shift(test, case)


def data_check(bundle) -> list[dict[str, Any]]:
    """The report's ``data_check``: every forming measurement checked against its case.

    Returns:
        One entry per measurement: ``test`` (the forming test's id), ``measurement``
        (``"file"`` for the grid, or the lab measurement's name), ``suspect`` and ``why``
        (not suspect, a ``why`` starting "chosen:" is the reading of the data chosen).

    Raises:
        DrapeInputError: a travel against the tool's motion (``travel_mm`` ≤ 0).
    """
    from fenicsx_drape.diagnosis.forming_kind import forming_case_of

    out = []
    for test in bundle.tests:
        if test.kind != "forming":
            continue
        travel = test.forming.get("travel_mm", test.case_keys.get("travel_mm"))
        if travel is not None and not float(travel) > 0:
            raise DrapeInputError(f"test {test.id!r}: travel_mm = {travel:g}: a travel against "
                                  "the tool's motion (travel is the distance it moves, > 0)")
        lab = getattr(test, "lab", None)
        found = check_measurement(test, forming_case_of(test))
        suspect, why = found or (False, "consistent with the case (extent, blank, tools, "
                                        "frame)")
        out.append({"test": lab.parent if lab is not None else test.id,
                    "measurement": lab.measurement if lab is not None else "file",
                    "suspect": suspect, "why": why})
    return out


def suspect_tests(bundle, entries: list[dict[str, Any]]) -> set[str]:
    """The ids of the tests whose measurement the ``entries`` (:func:`data_check`) suspect."""
    bad = {(e["test"], e["measurement"]) for e in entries if e["suspect"]}
    out = set()
    for test in bundle.tests:
        lab = getattr(test, "lab", None)
        if ((lab.parent, lab.measurement) if lab is not None else (test.id, "file")) in bad:
            out.add(test.id)
    return out


def say_suspects(entries: list[dict[str, Any]], say) -> None:
    """A progress line for each suspect measurement, as soon as it is found."""
    for e in entries:
        if e["suspect"]:
            say(f"check the data: {e['test']}/{e['measurement']}: {e['why']}")


def apply_data_check(report: dict[str, Any], entries: list[dict[str, Any]]) -> None:
    """Put ``data_check`` into a diagnosis report; suspect data first in its conclusion.

    With a suspect measurement no effect is named (``missing_effect`` null, ``add_effects``
    empty): the conclusion starts "Check the data: ..." with each suspect's ``why``; what the
    fit found stays in the report's other fields (candidates, set-up). A reading chosen for
    data that are not suspect (a blank offset rather than a shifted frame) goes to ``notes``.
    """
    report["data_check"] = entries
    report.setdefault("notes", []).extend(
        f"{e['test']}/{e['measurement']}: {e['why']}" for e in entries
        if not e["suspect"] and e["why"].startswith("chosen:"))
    bad = [e for e in entries if e["suspect"]]
    if not bad:
        return
    report["missing_effect"] = None
    report["add_effects"] = []
    report["conclusion"] = (
        "Check the data: " + "; ".join(f"{e['test']}/{e['measurement']}: {e['why']}"
                                       for e in bad)
        + ". No effect is named on the evidence of data that cannot be of the case; set them "
        "right (or leave them out) and diagnose again.")
