"""The blank's edge after forming (``outline``): points of it, in plan or in 3D.

The kind :data:`OUTLINE` (a :class:`~fenicsx_drape.diagnosis.kinds.lab.LabKind`; what every
lab kind shares, the noise rule, runs, registration and measures, is in
:mod:`~fenicsx_drape.diagnosis.kinds.lab`):

- **values**: the signed in-plane (or 3D, with ``z_mm``) distance from each edge point to
  the model's blank edge after forming (positive outside it: less draw-in than modelled),
  and, with ``draw_in_mm``, the model's draw-in at that point (each row's two values
  interleaved) (:func:`read`);
- **noise**: ``position_sd_mm`` (column or key), else second differences along the edge,
  ordered by angle about the tool axis (:func:`model_free_noise`);
- **regions**: the edge along the tow axes and at the bias corners;
- **fit**: the friction coefficients (:func:`~fenicsx_drape.diagnosis.kinds.forming.
  fit_forming`, shared by every forming kind);
- **picture** (:func:`draw`): the measured edge over each model's;
- **data check** (:func:`check`): an edge in plan must lie on the flat blank: more than
  :data:`~fenicsx_drape.diagnosis.kinds.checks.OTHER_PART_SHARE` of its points farther than
  a cell outside it (a formed edge is drawn in, never out), or a span below 1/100 of the
  blank (metres), make it suspect; an edge in 3D is checked as positions, a registered one
  only for its size (:mod:`~fenicsx_drape.diagnosis.kinds.checks`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds import checks
from fenicsx_drape.diagnosis.kinds.checks import OTHER_PART_SHARE, columns_of, outside_polygon
from fenicsx_drape.diagnosis.kinds.lab import (
    LabKind,
    Match,
    _along,
    add_region,
    blank_centre,
    matched,
    points,
    sheet_mesh,
)

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds.base import Comparison, Region
    from fenicsx_drape.forming.case import FormingCase
    from fenicsx_drape.forming.running.measure import SheetMesh
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model


def draw_in(test: Test) -> bool:
    """Whether the edge comes with the draw-in at each point (two values a row)."""
    return "draw_in_mm" in test.columns


def per_row(test: Test) -> int:
    """Compared values per row: the distance, and the draw-in when given."""
    return 2 if draw_in(test) else 1


def measured(test: Test) -> np.ndarray:
    """Zero per point (the model's distance from it), with the draw-in interleaved."""
    n = test.n_rows
    if draw_in(test):
        return np.column_stack([np.zeros(n), test.columns["draw_in_mm"]]).ravel()
    return np.zeros(n)


def model_free_noise(test: Test) -> tuple[float, str]:
    """Second differences of the radius along the edge, ordered by angle about the axis."""
    P = points(test)
    angle = np.arctan2(P[:, 1], P[:, 0])
    return _along(angle, np.hypot(P[:, 0], P[:, 1])), "second_differences_along_edge"


def read(test: Test, grid: FormedGrid, mesh: SheetMesh,
         moved: Callable[[np.ndarray], np.ndarray], reach: float,
         model: Model | None = None) -> Match:
    """The signed distance from each edge point to the model's edge, and its draw-in."""
    from fenicsx_drape.forming.running import measure

    c = test.columns
    P = points(test)
    if "z_mm" in c:
        P = moved(P)
    else:
        P = P[:, :2]
    edge = measure.closest_on_edge(mesh, P, blank_centre(test))
    unmatched = edge["distance"] > reach
    values = np.where(unmatched, 0.0, -edge["signed"])
    if draw_in(test):
        drawn = np.where(unmatched, c["draw_in_mm"], edge["draw_in"])
        values = np.column_stack([values, drawn]).ravel()
    return Match(values, unmatched)


def regions(test: Test) -> list[Region]:
    """The edge along the tow axes, and at the bias corners."""
    out: list[Region] = []
    per = per_row(test)
    P = points(test)[:, :2] - blank_centre(test)
    angle = np.degrees(np.arctan2(np.abs(P[:, 1]), np.abs(P[:, 0])))
    off_axis = np.minimum(angle, 90.0 - angle)
    add_region(out, "direction_deg", off_axis, off_axis < 22.5, "edge along the tow axes", per)
    add_region(out, "direction_deg", off_axis, off_axis >= 22.5, "edge at the bias corners",
               per)
    return out


def abscissa(test: Test) -> tuple[str, np.ndarray]:
    """The angle of each point about the tool axis (deg)."""
    P = points(test)[:, :2] - blank_centre(test)
    return "angle_deg", np.repeat(np.degrees(np.arctan2(P[:, 1], P[:, 0])), per_row(test))


def draw(comparisons: Mapping[str, Comparison], test: Test) -> Any:
    """The measured edge over each model's edge, in plan."""
    import matplotlib.pyplot as plt

    from fenicsx_drape.forming.running.measure import edge_segments

    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    P = points(test)
    ax.plot(P[:, 0], P[:, 1], ".", ms=4, color="0.2", label="measured edge")
    for i, (label, comparison) in enumerate(comparisons.items()):
        hit = matched(test, comparison)
        if hit is None:
            continue
        mesh = sheet_mesh(hit.grid)
        e, _ = edge_segments(mesh)
        seg = mesh.x[e][:, :, :2]
        for k, s in enumerate(seg):
            ax.plot(s[:, 0], s[:, 1], "-", color=f"C{i}", lw=1,
                    label=f"model ({label})" if k == 0 else None)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.legend(fontsize=7)
    return fig


def in_plan(test: Test, case: FormingCase) -> tuple[bool, str] | None:
    """An outline in plan: on the flat blank (a formed edge is drawn in, never out)."""
    xy = columns_of(test, ("x_mm", "y_mm"))
    if xy is None or len(xy) < 3:
        return None
    polygon = np.asarray(case.blank.polygon(), dtype=float)
    size = float(np.ptp(polygon, axis=0).max())
    span = float(np.ptp(xy, axis=0).max())
    if span < 0.01 * size:
        return True, (f"the outline spans {span:.3g} mm, the blank {size:.3g} mm: metres read "
                      "as millimetres?")
    cell = case.blank.cell_mm
    out = outside_polygon(xy, polygon)
    if np.mean(out > cell) > OTHER_PART_SHARE:
        k = int(np.argmax(out))
        return True, (f"{100 * np.mean(out > cell):.0f} % of the outline lies farther than a "
                      f"cell ({cell:g} mm) outside the flat blank (up to {out[k]:.3g} mm, at "
                      f"({xy[k, 0]:.4g}, {xy[k, 1]:.4g}) mm), where a formed edge, drawn in, "
                      "cannot be: another part's outline, or another frame?")
    return None


def check(test: Test, case: FormingCase) -> tuple[bool, str] | None:
    """A registered edge's size; an edge in plan on the flat blank; else its positions."""
    if test.lab.frame.register:
        return checks.check_registered(test, case)
    if columns_of(test, ("x_mm", "y_mm", "z_mm")) is None:
        return in_plan(test, case)
    return checks.check_positions(test, case)


OUTLINE = LabKind("outline", "mm", measured, model_free_noise, read, regions, abscissa, draw,
                  check, per_row=per_row)
