"""Shear angles measured at points of the formed part or of the flat blank (``shear_points``).

A lab measures the shear angle with a protractor or a fibre-angle sensor, at points or along
measuring lines (``line``, ``s_mm``). The kind :data:`SHEAR_POINTS` (a
:class:`~fenicsx_drape.diagnosis.kinds.lab.LabKind`; what every lab kind shares, the noise
rule, runs, registration and measures, is in :mod:`~fenicsx_drape.diagnosis.kinds.lab`):

- **values**: the shear angle (deg), ``shear_deg``; its magnitude when the test says
  ``shear_magnitude = true``;
- **simulation** (:func:`read`): the model's shear angle at the same material point: by its
  flat position (``x0_mm, y0_mm``), or for a formed position at the closest point of the
  formed sheet, bilinear within the cell;
- **noise**: ``shear_sd_deg`` (column or key), else second differences along each measuring
  line, else the differences between nearest neighbours (:func:`model_free_noise`);
- **regions**: each measuring line in thirds of its ``s_mm``, and the regions of the part
  at formed points;
- **fit**: the friction coefficients (:func:`~fenicsx_drape.diagnosis.kinds.forming.
  fit_forming`, shared by every forming kind);
- **picture** (:func:`draw`): measured against model shear along each measuring line;
- **data check**: its positions against the case (:func:`~fenicsx_drape.diagnosis.kinds.
  checks.check_positions`), or only its size when registered.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds import checks
from fenicsx_drape.diagnosis.kinds.lab import (
    LabKind,
    Match,
    _along,
    add_region,
    formed_abscissa,
    part_or_all,
    points,
)

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds.base import Comparison, Region
    from fenicsx_drape.forming.running.measure import SheetMesh
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model


def measured(test: Test) -> np.ndarray:
    """The measured shear angles (deg), one per row."""
    return np.asarray(test.columns["shear_deg"], float)


def model_free_noise(test: Test) -> tuple[float, str]:
    """Second differences along each measuring line, else between nearest neighbours.

    A line counts with five points or more; neighbours are nearest in the flat or formed
    positions.
    """
    from scipy.spatial import cKDTree

    c = test.columns
    names = test.lab.line_names
    if "s_mm" in c and any(names):
        estimates, weights = [], []
        for name in sorted(set(names)):
            rows = np.asarray(names) == name
            if rows.sum() >= 5:
                estimates.append(_along(c["s_mm"][rows], c["shear_deg"][rows]))
                weights.append(rows.sum())
        if estimates:
            return (float(np.sqrt(np.average(np.square(estimates), weights=weights))),
                    "second_differences_along_lines")
    P = (np.column_stack([c["x0_mm"], c["y0_mm"]]) if test.lab.flat
         else points(test))
    _, k = cKDTree(P).query(P, k=2)
    diff = c["shear_deg"] - c["shear_deg"][k[:, 1]]
    return (float(np.median(np.abs(diff)) / 0.6745 / math.sqrt(2.0)),
            "nearest_neighbour_differences")


def read(test: Test, grid: FormedGrid, mesh: SheetMesh,
         moved: Callable[[np.ndarray], np.ndarray], reach: float,
         model: Model | None = None) -> Match:
    """The model's shear at the measured points (module doc).

    An unmatched row keeps its measured value (residual 0).
    """
    from fenicsx_drape.forming.running import measure

    c = test.columns
    if test.lab.flat:
        flat = np.column_stack([c["x0_mm"], c["y0_mm"]])
        values = measure.shear_at_flat(grid, flat)
        unmatched = ~np.isfinite(values)
    else:
        values, near = measure.shear_at_formed(grid, moved(points(test)), mesh)
        unmatched = (near.distance > reach) | ~np.isfinite(values)
    if test.lab.shear_magnitude:
        values = np.abs(values)
    values = np.where(unmatched, c["shear_deg"], values)
    return Match(values, unmatched)


def regions(test: Test) -> list[Region]:
    """Each measuring line in thirds of its ``s_mm``, then the regions of the part."""
    c, n = test.columns, test.n_rows
    out: list[Region] = []
    if "s_mm" in c:
        names = test.lab.line_names if any(test.lab.line_names) else ("",) * n
        s = c["s_mm"]
        for name in sorted(set(names)):
            on = np.asarray(names) == name
            lo, hi = float(s[on].min()), float(s[on].max())
            cuts = np.linspace(lo, hi, 4)
            for a, b, where in zip(cuts[:-1], cuts[1:], ("start", "middle", "end")):
                rows = on & (s >= a - 1e-9) & (s <= b + 1e-9)
                add_region(out, "s_mm", s, rows,
                           f"line {name or '(unnamed)'}, {where} (s {a:.0f}-{b:.0f} mm)")
    return part_or_all(test, out, lambda: 0.0)  # angles, not positions: no position noise


def abscissa(test: Test) -> tuple[str, np.ndarray]:
    """Along the measuring line (``s_mm``), else the formed height, else the row."""
    if "s_mm" in test.columns:
        return "s_mm", test.columns["s_mm"]
    return formed_abscissa(test)


def draw(comparisons: Mapping[str, Comparison], test: Test) -> Any:
    """Measured against model shear along each measuring line, one panel a line."""
    import matplotlib.pyplot as plt

    first = next(iter(comparisons.values()))
    names = test.lab.line_names if any(test.lab.line_names) else ("",) * test.n_rows
    lines = sorted(set(names))
    fig, axes = plt.subplots(len(lines), 1, figsize=(7, 2.6 * len(lines) + 0.6),
                             squeeze=False)
    s = (test.columns["s_mm"] if "s_mm" in test.columns
         else np.arange(test.n_rows, dtype=float))
    for ax, name in zip(axes[:, 0], lines):
        on = np.asarray(names) == name
        order = np.flatnonzero(on)[np.argsort(s[on])]
        ax.errorbar(s[order], first.measured[order], yerr=first.noise, fmt=".", ms=4,
                    color="0.3", label="measured")
        for i, (label, c) in enumerate(comparisons.items()):
            ax.plot(s[order], c.simulated[order], "-", color=f"C{i}", label=label)
        ax.set_ylabel("shear (deg)")
        ax.set_title(f"line {name or '(unnamed)'}", fontsize=8)
        ax.legend(fontsize=7)
    axes[-1, 0].set_xlabel("s (mm) along the line" if "s_mm" in test.columns else "row")
    return fig


SHEAR_POINTS = LabKind("shear_points", "deg", measured, model_free_noise, read, regions,
                       abscissa, draw, checks.check_registered_or_positions)
