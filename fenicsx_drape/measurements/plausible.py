"""Is a measured number one a measurement could give? Checks shared by every measurement kind.

The spec (``docs/measurements.md``, version 3, "Bad and odd rows"): a value no
measurement could give -- a position farther from the tools than the blank's size, NaN or
infinite numbers -- is bad input (exit status 2, with the file and line), not an outlier.
Each check here returns the problems as ``(line, message)`` pairs for the caller to name its
file; they are plain NumPy, so any table reader (grids, shear points, scans, outlines, force
curves) can use them:

- :func:`finite_problems`: cells that are NaN or infinite;
- :class:`Reach` and :func:`far_problems`: positions farther than the blank's size from the
  region the tools sweep over the blank (:func:`reach_of_case`, :func:`reach_of_hemisphere`);
- :func:`grid_problems`: a drawn grid whose indices ``i, j`` do not match its flat positions
  ``x0_mm, y0_mm`` (a node off its grid, swapped columns, a grid from another part), or whose
  spacing disagrees with ``grid_mm``;
- :func:`grid_table_check`: all of these for a forming grid table (the bundle loader's).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

Problems = list[tuple[int | None, str]]

# A grid node may sit this share of the spacing off the place its indices give it.
GRID_NODE_TOLERANCE = 0.25
# The spacing along i and along j, and grid_mm, may differ by this share.
GRID_SPACING_TOLERANCE = 0.05


def _first(bad: np.ndarray, lines: Sequence[int], message: str) -> Problems:
    """One problem at the first bad row, counting the others."""
    rows = np.flatnonzero(bad)
    if not len(rows):
        return []
    more = f" ({len(rows)} such rows)" if len(rows) > 1 else ""
    return [(int(lines[rows[0]]), message.format(row=rows[0]) + more)]


def finite_problems(columns: Mapping[str, np.ndarray], lines: Sequence[int]) -> Problems:
    """Cells that are NaN or infinite: one problem per column, at its first such row."""
    out: Problems = []
    for name, values in columns.items():
        v = np.asarray(values, dtype=float)
        bad = ~np.isfinite(v)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            out += _first(bad, lines, f"column {name}: {v[k]:g} is not a finite number")
    return out


@dataclasses.dataclass(frozen=True)
class Reach:
    """Where a formed part can be: the box the tools sweep over the blank, and the blank's size.

    A position farther than ``size_mm`` from the box is one no measurement of this forming
    run could give.
    """

    lo_mm: tuple[float, float, float]  # the box's low corner (mm)
    hi_mm: tuple[float, float, float]  # the box's high corner (mm)
    size_mm: float  # the blank's size: the diagonal of its flat outline's box (mm)

    def distance(self, points_mm: np.ndarray) -> np.ndarray:
        """Distance (mm) of points (n, 3) from the box (0 inside)."""
        p = np.asarray(points_mm, dtype=float).reshape(-1, 3)
        lo, hi = np.asarray(self.lo_mm), np.asarray(self.hi_mm)
        with np.errstate(over="ignore"):  # 1e300 mm away is infinitely far
            return np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1)

    def far(self, points_mm: np.ndarray) -> np.ndarray:
        """Which points (n, 3) are farther than the blank's size from the box."""
        return ~(self.distance(points_mm) <= self.size_mm)


def far_problems(points_mm: np.ndarray, lines: Sequence[int], reach: Reach,
                 what: str = "position") -> Problems:
    """Positions (n, 3) farther from the tools than the blank's size (first row, and count)."""
    p = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    far = reach.far(p)
    if not far.any():
        return []
    k = int(np.flatnonzero(far)[0])
    return _first(far, lines, f"{what} ({p[k, 0]:g}, {p[k, 1]:g}, {p[k, 2]:g}) mm is "
                              f"{reach.distance(p[k:k + 1])[0]:.4g} mm from where the tools "
                              f"reach, farther than the blank's size {reach.size_mm:.4g} mm: no "
                              "measurement of this part gives it (units? columns swapped?)")


def reach_of_hemisphere(keys: Mapping[str, Any]) -> Reach | None:
    """The reach of the paper's hemisphere test from its keys (None without ``sheet_mm``)."""
    sheet = keys.get("sheet_mm")
    if sheet is None:
        return None
    travel = float(keys.get("travel_mm") or 0.0)
    half = float(sheet) / 2
    return Reach((-half, -half, min(0.0, travel)), (half, half, max(0.0, travel)),
                 float(np.hypot(sheet, sheet)))


def reach_of_case(case: Any) -> Reach:
    """The reach of a forming case: its flat blank's box, widened by every tool's motion.

    ``case`` is a :class:`~fenicsx_drape.forming.case.spec.FormingCase` (read through its
    attributes: ``blank.polygon()``, ``tools``, ``total_travel_mm``). A builtin (hemisphere)
    punch travels ``total_travel_mm`` along +z; a tool with a motion table moves the box by
    its translations.
    """
    P = np.asarray(case.blank.polygon(), dtype=float)
    lo = np.array([*P.min(axis=0), 0.0])
    hi = np.array([*P.max(axis=0), 0.0])
    size = float(np.linalg.norm(hi - lo))
    low, high = np.zeros(3), np.zeros(3)
    for tool in case.tools:
        motion = getattr(tool, "motion", None)
        if getattr(tool, "builtin", False):
            high[2] = max(high[2], float(case.total_travel_mm))
        elif motion is not None:
            T = np.column_stack([motion.x_mm, motion.y_mm, motion.z_mm])
            T = T - T[0]
            low, high = np.minimum(low, T.min(axis=0)), np.maximum(high, T.max(axis=0))
    return Reach(tuple(lo + low), tuple(hi + high), size)


def grid_problems(i: np.ndarray, j: np.ndarray, x0_mm: np.ndarray, y0_mm: np.ndarray,
                  lines: Sequence[int], grid_mm: float | None = None) -> Problems:
    """Whether a drawn grid's indices match its flat positions, and its spacing ``grid_mm``.

    The flat positions of a drawn grid are ``c + g R (i, j)``: a spacing g along both indices
    and a rotation R (the tows' angle). The map is fitted by least squares (again without the
    rows off it): a row more than :data:`GRID_NODE_TOLERANCE` spacings from its place, a map
    that is not a rotation times g (i and j spaced differently, or a mirror: swapped columns),
    and a g that differs from ``grid_mm`` by more than :data:`GRID_SPACING_TOLERANCE` are
    problems. The problem with ``grid_mm`` has the line None: the caller names the key's.
    """
    ij = np.column_stack([i, j]).astype(float)
    xy = np.column_stack([x0_mm, y0_mm]).astype(float)
    M = np.column_stack([np.ones(len(ij)), ij])
    if len(ij) < 3 or np.linalg.matrix_rank(M) < 3:
        return []  # a line of nodes (or fewer): no grid to check
    keep = np.ones(len(ij), dtype=bool)
    for _ in range(2):  # fit, then refit without the rows off the fit
        coef = np.linalg.lstsq(M[keep], xy[keep], rcond=None)[0]
        A = coef[1:].T  # columns: the step of one index along x0, y0
        g = float(np.sqrt(abs(np.linalg.det(A))))
        off = np.linalg.norm(M @ coef - xy, axis=1) > GRID_NODE_TOLERANCE * g
        if off.sum() == (~keep).sum() or (~off).sum() < 3 \
                or np.linalg.matrix_rank(M[~off]) < 3:
            break
        keep = ~off
    out: Problems = []
    if off.any():
        k = int(np.flatnonzero(off)[0])
        at = M[k] @ coef
        out += _first(off, lines, f"grid node (i, j) = ({ij[k, 0]:g}, {ij[k, 1]:g}) is at "
                                  f"(x0, y0) = ({xy[k, 0]:g}, {xy[k, 1]:g}) mm, but the other "
                                  f"nodes put it at ({at[0]:.4g}, {at[1]:.4g}) mm (a grid of "
                                  f"{g:.4g} mm): its indices do not match its position")
    a_i, a_j = np.linalg.norm(A, axis=0)
    cos = float(A[:, 0] @ A[:, 1] / (a_i * a_j)) if a_i * a_j > 0 else 1.0
    if np.linalg.det(A) < 0:
        out.append((int(lines[0]), "the grid is mirrored: i must run along x0 and j along y0 "
                                   "(x along warp, y along weft); are columns swapped?"))
    elif abs(a_i / a_j - 1) > GRID_SPACING_TOLERANCE or abs(cos) > GRID_SPACING_TOLERANCE:
        out.append((int(lines[0]), f"the grid's steps are {a_i:.4g} mm along i and "
                                   f"{a_j:.4g} mm along j at {np.degrees(np.arccos(cos)):.3g}° "
                                   "to each other: a drawn grid is square; are columns "
                                   "swapped?"))
    elif grid_mm is not None and abs(g / grid_mm - 1) > GRID_SPACING_TOLERANCE:
        out.append((None, f"grid_mm = {grid_mm:g} disagrees with the flat positions "
                                  f"x0_mm, y0_mm: one index step is {g:.4g} mm"))
    return out


def grid_table_check(keys: Mapping[str, Any], case: Any, toml_file: str, grid_mm_line: int):
    """The check of a forming grid table, for a table reader: ``check(path, columns, lines)``.

    Indices against the flat positions and ``grid_mm`` (:func:`grid_problems`), flat and
    formed positions against the tools' reach (:func:`far_problems`: the case's, else the
    hemisphere test's ``keys``). The check returns ``(file, line, problem)``: the table's
    file, or ``toml_file`` at ``grid_mm_line`` for ``grid_mm``.
    """
    reach = reach_of_case(case) if case is not None else reach_of_hemisphere(keys)

    def check(path, columns: Mapping[str, np.ndarray], lines: Sequence[int]):
        c = columns
        found = []
        plies = c["ply"] if "ply" in c else np.zeros(len(lines))
        for k in np.unique(plies):  # a grid per ply of a stack (spec version 4)
            on = np.flatnonzero(plies == k)
            found += grid_problems(c["i"][on], c["j"][on], c["x0_mm"][on], c["y0_mm"][on],
                                   [lines[r] for r in on], keys.get("grid_mm"))
        if reach is not None:
            flat = np.column_stack([c["x0_mm"], c["y0_mm"], np.zeros(len(lines))])
            formed = np.column_stack([c["x_mm"], c["y_mm"], c["z_mm"]])
            found += far_problems(flat, lines, reach, "flat position (x0, y0, 0)")
            found += far_problems(formed, lines, reach, "formed position (x, y, z)")
        return [(str(path), line, text) if line is not None else (toml_file, grid_mm_line, text)
                for line, text in found]

    return check
