"""The measured grid: a simulated sheet against the formed positions of nodes drawn on it.

A forming test (``kind = "forming"``, ``docs/measurements.md``) gives the formed
positions of the nodes of a grid drawn on the flat sheet (its ``file``). The kind
:data:`GRID`:

- **simulation**: the part the test was formed on, under its conditions. A test with
  ``geometry = "hemisphere"`` forms the paper's hemisphere (``meshes/hemisphere/case.toml``,
  a symmetric quarter, with the tool sizes, travel, duration and holding force of the test:
  :func:`~fenicsx_drape.diagnosis.kinds.forming.forming_case_of`) as any case; a test that
  names its case file
  (``case = "part.toml"``) forms that case
  (:func:`~fenicsx_drape.forming.running.run.run_case`) with the test's keys as overrides
  (the bundle loader applied them, :func:`~fenicsx_drape.forming.case.case_for_test`),
  in the case's frame. The modelled part (quarter, half or whole blank, by the case's
  symmetry planes) is compared as it is when the measured grid lies in it, else mirrored
  through the planes to the whole sheet (:func:`sheet_for`); it is interpolated bilinearly
  in the reference coordinates at the measured grid's ``(x0_mm, y0_mm)``, so the measured
  grid may be coarser than the mesh (section 4.2). A measured node in a cell the model's net
  does not keep (the ragged edge of a polygon blank, coarser cells than the data's) takes the
  bilinear map of the nearest kept
  cell, extended (:func:`sample`), up to :data:`EXTRAPOLATE_CELLS` cells away;
- **values**: per row the three coordinates ``x, y, z`` (flattened), so a test's RMSE is the
  RMS position error per coordinate (mm) of the spec;
- **noise**: the RMS of ``position_sd_mm``, else a model-free estimate from fourth
  differences of the measured positions along the grid lines (:func:`grid_noise`);
- **regions** of the part (:func:`part_regions`): for the hemisphere, apex, bias diagonals,
  tow axes at the fillet and flange under the holder; for a case, named from the case
  itself (:func:`case_regions`): by what each measured node touches at the end of forming
  (punch top, walls, flat base, flange under the holder, free sheet), the walls split by
  the direction from the tool axis in the tow frame (along the tow axes, bias diagonals);
- the paper's measures beside them (:func:`metrics`): mean distance (mm and % of the mean
  node displacement, the paper's 1.57 mm and 4 %), and the shear-angle and wrinkling-strain
  errors when the grid has those columns;
- **fit**: the friction coefficients (:func:`~fenicsx_drape.diagnosis.kinds.forming.
  fit_forming`, shared by every forming kind);
- **picture** (:func:`plot_error_map`): the position error over the part, model by model;
- **data check**: the positions against the case, and a shifted flat frame
  (:func:`~fenicsx_drape.diagnosis.kinds.checks.check_positions`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds import checks
from fenicsx_drape.diagnosis.kinds.base import FitHook, Region
from fenicsx_drape.diagnosis.kinds.forming import (
    case_of,
    fit_friction,
    forming_case_of,
    names_case,
    parameter_sets,
)
from fenicsx_drape.diagnosis.kinds.part import CASE_REGION_NAMES, region_of_points, travel_axis
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.runs import form_many, stopped_at

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds.base import Comparison
    from fenicsx_drape.forming.case import FormingCase
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model

# A measured node outside the cells of the model's net (a ragged edge) takes the nearest kept
# cell's bilinear map up to this many cells away; farther, the grid does not fit the blank.
EXTRAPOLATE_CELLS = 1.5


# --------------------------------------------------------------------------------------------
# Simulation


def in_part(test: Test, planes: Sequence[str]) -> bool:
    """Whether the measured grid lies in the modelled part (x0 ≥ 0 for "x", y0 ≥ 0 for "y")."""
    P = reference_points(test)
    return all(bool((P[:, {"x": 0, "y": 1}[p]] >= -1e-9).all()) for p in planes)


def is_quarter(test: Test) -> bool:
    """Whether the measured grid covers one symmetric quarter (x0, y0 ≥ 0)."""
    return in_part(test, ("x", "y"))


def sheet_for(test: Test, part: FormedGrid) -> FormedGrid:
    """The simulated sheet matching the measured grid: the modelled part, or mirrored.

    A grid in the modelled part (a quarter grid against a quarter model) is compared with it
    as it is; any other (the whole sheet, or a half against a quarter) with the part mirrored
    through its symmetry planes to the whole blank.
    """
    return part if in_part(test, part.planes) else part.full()


def reference_points(test: Test) -> np.ndarray:
    """The measured nodes on the flat sheet, (n, 2) in mm."""
    return np.column_stack([test.columns["x0_mm"], test.columns["y0_mm"]])


def measured_positions(test: Test) -> np.ndarray:
    """The measured formed positions, (n, 3) in mm."""
    return np.column_stack([test.columns[c] for c in ("x_mm", "y_mm", "z_mm")])


def sample(sheet: FormedGrid, points_mm: np.ndarray, test_id: str = "") -> np.ndarray:
    """Formed positions (m, 3) of flat-sheet points (m, 2): bilinear in the cells of the net.

    A point in a cell the net does not keep (beyond a ragged edge) takes the bilinear map of
    the nearest kept cell, extended, up to :data:`EXTRAPOLATE_CELLS` cells away
    (:meth:`~fenicsx_drape.forming.running.post.FormedGrid.sample` gives NaN there).

    Raises:
        DrapeInputError: a point farther from the net: the grid does not fit the blank.
    """
    P = np.asarray(points_mm, float)
    origin, Δ, R = sheet.tow_frame()
    s = ((P - origin) @ R) / Δ
    n = np.array(sheet.X.shape[:2]) - 1
    out = np.full((len(P), 3), np.nan)
    inside = np.all((s >= -1e-9) & (s <= n + 1e-9), axis=1)
    if inside.any():
        out[inside] = sheet.sample(P[inside])
    missing = np.flatnonzero(np.isnan(out[:, 0]))
    if not len(missing):
        return out
    ok = sheet.present
    cells = np.argwhere(ok[:-1, :-1] & ok[1:, :-1] & ok[:-1, 1:] & ok[1:, 1:])  # lower corners
    d = np.linalg.norm(np.maximum(np.maximum(cells[None] - s[missing, None],
                                             s[missing, None] - cells[None] - 1), 0.0), axis=2)
    near = np.argmin(d, axis=1)
    far = d[np.arange(len(missing)), near] > EXTRAPOLATE_CELLS
    if far.any():
        p = P[missing[np.argmax(far)]]
        raise DrapeInputError(
            f"test {test_id!r}: the measured node at (x0, y0) = ({p[0]:g}, {p[1]:g}) mm lies "
            f"more than {EXTRAPOLATE_CELLS:g} cells from the model's blank ({far.sum()} such "
            "node(s)): does the grid belong to this case (frame, blank, symmetry)?")
    k = cells[near]
    a, b = (s[missing] - k)[:, :1], (s[missing] - k)[:, 1:]
    x = sheet.x
    out[missing] = ((1 - a) * (1 - b) * x[k[:, 0], k[:, 1]] + a * (1 - b) * x[k[:, 0] + 1, k[:, 1]]
                    + (1 - a) * b * x[k[:, 0], k[:, 1] + 1] + a * b * x[k[:, 0] + 1, k[:, 1] + 1])
    return out


def extrapolated_nodes(test: Test, sheet: FormedGrid) -> int:
    """How many measured nodes lie outside the cells of the simulated sheet's net."""
    sheet = sheet_for(test, sheet)
    P = reference_points(test)
    origin, Δ, R = sheet.tow_frame()
    s = ((P - origin) @ R) / Δ
    n = np.array(sheet.X.shape[:2]) - 1
    inside = np.all((s >= -1e-9) & (s <= n + 1e-9), axis=1)
    values = np.full(len(P), np.nan)
    if inside.any():
        values[inside] = sheet.sample(P[inside])[:, 0]
    return int(np.isnan(values).sum())


def simulated_sheets(test: Test, model: Model) -> list[FormedGrid]:
    """The simulated sheet(s) for a test: one per parameter set of a vectorised model.

    On a stack, the sheet of the ply the test was measured on (``test.ply``; None: the
    outermost ply away from the punch).
    """
    sets = parameter_sets(model)
    case = case_of(test)
    if sets is None:
        return [sheet_for(test, form_many([(case, model)])[0].ply(test.ply))]
    return [sheet_for(test, g.ply(test.ply)) for g in form_many([(case, m) for m in sets])]


def simulate(test: Test, model: Model) -> np.ndarray:
    """Simulated ``x, y, z`` of every measured node, flattened (3n,), or (k, 3n) for k sets."""
    sheets = simulated_sheets(test, model)
    values = [sample(s, reference_points(test), test.id).ravel() for s in sheets]
    vectorised = any(np.ndim(v) > 0 for v in model.parameters.values())
    return np.array(values) if vectorised else values[0]


def interpolate(sheet: FormedGrid, field: np.ndarray, points_mm: np.ndarray) -> np.ndarray:
    """A nodal scalar field of a sheet (n_i, n_j), bilinear at flat-sheet points (m, 2)."""
    from fenicsx_drape.forming.running.post import FormedGrid

    stacked = np.repeat(np.asarray(field, float)[..., None], 3, axis=-1)
    return sample(FormedGrid(sheet.X, stacked, sheet.quarter, sheet.symmetry), points_mm)[:, 0]



def on_sheet(test: Test, sheet: FormedGrid, plane: str | None = None) -> np.ndarray:
    """The grid's ``x, y, z`` on one formed sheet (flattened), as :func:`simulate` reads it.

    ``plane``: the sheet is the run of the mirror image in that symmetry plane ("x" or "y"):
    the grid is read at its image and mirrored back.
    """
    sheet = sheet.ply(test.ply)  # a stack: the ply measured
    M = np.ones(3) if plane is None else np.where(np.arange(3) == "xy".index(plane), -1.0, 1.0)
    P = reference_points(test) * M[:2]
    part = sheet if all(bool((P[:, "xy".index(q)] >= -1e-9).all()) for q in sheet.planes) \
        else sheet.full()
    return (sample(part, P, test.id) * M).ravel()

# --------------------------------------------------------------------------------------------
# Noise, regions, the paper's measures


def grid_noise(test: Test) -> float:
    """A model-free estimate of the position noise (mm, one sd per coordinate).

    Along every line of the grid (constant i or j), fourth differences of the measured
    positions (weights 1, -4, 6, -4, 1: variance 70 σ² for white noise) remove the smooth
    formed shape up to cubic terms; σ is their median absolute value / 0.6745 / √70, robust
    to the few places (fillet edges) where the shape itself is not smooth on the grid.
    """
    ij = np.rint(np.column_stack([test.columns["i"], test.columns["j"]])).astype(int)
    p = measured_positions(test)
    index = {tuple(k): n for n, k in enumerate(ij)}
    d4 = []
    for axis in (0, 1):
        step = np.eye(2, dtype=int)[axis]
        for n, k in enumerate(ij):
            chain = [index.get(tuple(k + m * step)) for m in range(1, 5)]
            if None not in chain:
                a, b, c, d = (p[m] for m in chain)
                d4.append(p[n] - 4 * a + 6 * b - 4 * c + d)
    if not d4:
        raise DrapeInputError(f"test {test.id!r}: too few grid nodes to estimate the noise "
                              "(give position_sd_mm)")
    σ = float(np.median(np.abs(np.concatenate(d4))) / 0.6745 / math.sqrt(70.0))
    if not σ > 0:  # a noiseless grid (synthetic, rounded): no error can be normalised by it
        raise DrapeInputError(f"test {test.id!r}: the grid's positions show no noise (their "
                              "fourth differences along the grid lines are zero): give "
                              "position_sd_mm (mm, one standard deviation per coordinate)")
    return σ


def noise(test: Test) -> tuple[float, str]:
    """The test's position noise (mm) and its source (contract definition)."""
    sd = test.column("position_sd_mm")
    if sd is not None:
        return float(np.sqrt(np.mean(np.asarray(sd) ** 2))), "position_sd_mm"
    return grid_noise(test), "fourth_differences"


def row_noise(test: Test) -> np.ndarray:
    """Per row, the noise (mm) a fit weighs the row with (``inf``: not fitted)."""
    sd = test.column("position_sd_mm")
    return np.asarray(sd, float) if sd is not None else np.full(test.n_rows, noise(test)[0])


REGION_NAMES = ("apex", "bias diagonals", "tow axes at the fillet", "flange under the holder")


def region_of_nodes(test: Test) -> np.ndarray:
    """Index into :data:`REGION_NAMES` of every measured node.

    On the part: the flange is what ends under the holder (formed radius beyond the holder
    opening); the apex is the cap within half the punch radius of the axis on the flat
    sheet; the rest (the punch's side and fillet) is split by the direction from the axis:
    within 22.5° of a tow axis (warp or weft), or of a bias diagonal.
    """
    f = test.forming
    opening = 0.5 * float(f.get("holder_opening_mm", 170.0))
    apex = 0.5 * float(f.get("punch_radius_mm", 60.0))
    P, x = reference_points(test), measured_positions(test)
    r0 = np.hypot(P[:, 0], P[:, 1])
    θ = np.degrees(np.arctan2(np.abs(P[:, 1]), np.abs(P[:, 0])))
    axes = (θ < 22.5) | (θ > 67.5)
    return np.where(np.hypot(x[:, 0], x[:, 1]) >= opening, 3,
                    np.where(r0 <= apex, 0, np.where(axes, 2, 1)))


def case_region_of_nodes(test: Test) -> np.ndarray:
    """Index into :data:`CASE_REGION_NAMES` of every measured node of a case's test.

    At the end of forming, from the measured position: under the holder when the clamping
    tool covers the node and it lies on its surface; else on a punch, die or surface tool when
    within :data:`CONTACT_MM` + 3 × noise of it: on a *wall* where that surface is steeper
    than :data:`WALL_DEG` to the plane normal to the travel (split by the node's direction
    from the tool axis on the flat sheet, :func:`direction_of_nodes`: within 22.5° of a tow
    axis, or nearer a bias diagonal), else the *punch top* when in the upper half of the
    part's depth and the *flat base* when lower; else free. Nodes of a whole grid are folded
    into the modelled part first (the tools need only be given there).
    """
    return region_of_points(test, measured_positions(test), direction_of_nodes(test),
                            noise(test)[0])


def direction_of_nodes(test: Test) -> np.ndarray:
    """Angle (deg, 0-45) of every measured node's direction from the nearest tow axis.

    On the flat sheet, from the net's origin (the tool axis) in the tow frame of the case's
    ply angle; 0 at the origin.
    """
    blank = forming_case_of(test).blank
    θ = math.radians(blank.ply_angle_deg)
    d = reference_points(test) - np.asarray(blank.origin_mm)
    u = d[:, 0] * math.cos(θ) + d[:, 1] * math.sin(θ)
    v = -d[:, 0] * math.sin(θ) + d[:, 1] * math.cos(θ)
    angle = np.degrees(np.arctan2(np.abs(v), np.abs(u)))
    return np.minimum(angle, 90.0 - angle)


def case_regions(test: Test) -> list[Region]:
    """The named regions of a case's part (:func:`case_region_of_nodes`), a partition.

    Each region's variable is the measured height along the travel (mm).
    """
    height = measured_positions(test) @ travel_axis(forming_case_of(test))
    which = case_region_of_nodes(test)
    out = []
    for k, name in enumerate(CASE_REGION_NAMES):
        nodes = which == k
        if nodes.any():
            out.append(Region("height_mm", (float(height[nodes].min()),
                                            float(height[nodes].max())), name,
                              np.repeat(nodes, 3)))
    return out


def part_regions(test: Test) -> list[Region]:
    """The named regions of the part, each a mask over the flattened ``x, y, z`` values.

    The hemisphere's (:data:`REGION_NAMES`) for a hemisphere test, a case's own
    (:func:`case_regions`) for a test that names its case.
    """
    if names_case(test):
        return case_regions(test)
    which = region_of_nodes(test)
    r0 = np.hypot(*reference_points(test).T)
    out = []
    for k, name in enumerate(REGION_NAMES):
        nodes = which == k
        if nodes.any():
            out.append(Region("r0_mm", (float(r0[nodes].min()), float(r0[nodes].max())),
                              name, np.repeat(nodes, 3)))
    return out


def metrics(test: Test, simulated: np.ndarray, model: Model | None = None) -> dict[str, Any]:
    """The paper's measures of a forming comparison (section 4.2).

    ``mean_distance_mm`` (mean of the node distances), ``mean_displacement_mm`` (mean
    measured displacement of the nodes from the flat sheet), ``percent_of_displacement``
    (the paper's 1.57 mm, about 4 %), ``max_distance_mm``, and, when the grid has the columns,
    ``shear_rmse_deg`` and ``wrinkle_rmse`` (the simulated fields interpolated at the nodes).
    The fields need the ``model`` (its sheet comes from the cache of forming runs); with it,
    ``stopped_at_travel_mm`` tells when the model could not form the part to full travel.
    """
    x = measured_positions(test)
    d = np.linalg.norm(x - simulated.reshape(-1, 3), axis=1)
    P = reference_points(test)
    displacement = np.linalg.norm(x - np.column_stack([P, np.zeros(len(P))]), axis=1)
    out = {"mean_distance_mm": float(d.mean()), "max_distance_mm": float(d.max()),
           "mean_displacement_mm": float(displacement.mean()),
           "percent_of_displacement": float(100 * d.mean() / displacement.mean())}
    if model is not None:
        sheet = simulated_sheets(test, model)[0]
        out |= field_errors(test, sheet)
        if extrapolated := extrapolated_nodes(test, sheet):
            out["extrapolated_nodes"] = extrapolated
        stopped = stopped_at(case_of(test), model)
        if stopped is not None:
            out["stopped_at_travel_mm"] = stopped
    return out


def field_errors(test: Test, sheet: FormedGrid) -> dict[str, float]:
    """RMS errors of the shear angle (deg) and wrinkling strain at the measured nodes."""
    out = {}
    P = reference_points(test)
    for column, field, name in (("shear_deg", sheet.shear_nodes, "shear_rmse_deg"),
                                ("wrinkle_strain", sheet.wrinkle_strain_nodes, "wrinkle_rmse")):
        measured = test.column(column)
        if measured is not None:
            diff = np.asarray(measured) - interpolate(sheet, field(), P)
            ok = np.isfinite(diff)
            out[name] = float(np.sqrt(np.mean(diff[ok] ** 2))) if ok.any() else math.nan
    return out


def abscissa(test: Test) -> tuple[str, np.ndarray]:
    """What a grid's residuals are plotted against: each node's flat distance from the axis."""
    return "r0_mm", np.repeat(np.hypot(*reference_points(test).T), 3)


# --------------------------------------------------------------------------------------------
# Pictures


def plot_error_map(comparisons: Mapping[str, Comparison], test: Test, path: Path,
                   shares: Sequence[Mapping[str, Any]] = ()) -> Path:
    """Maps of the position error over the part, one panel per model, and its regions.

    Each panel shows the measured nodes in plan view (formed x, y) coloured by the distance
    (mm) to the model's node; the last panel gives each region's share of the first model's
    squared normalised error.
    """
    import matplotlib.pyplot as plt

    from fenicsx_drape.provenance import save_figure

    x = measured_positions(test)
    dist = {label: np.linalg.norm(c.residual.reshape(-1, 3), axis=1)
            for label, c in comparisons.items()}
    top = max(max(float(d.max()) for d in dist.values()), 1e-9)
    n = len(comparisons)
    fig, axes = plt.subplots(1, n + 1, figsize=(4.2 * n + 5.5, 4.4), layout="constrained",
                             gridspec_kw={"width_ratios": [1.0] * n + [1.1]})
    for ax, (label, c) in zip(axes, comparisons.items()):
        m = metrics(test, c.simulated)
        art = ax.scatter(x[:, 0], x[:, 1], c=dist[label], s=18, cmap="inferno_r", vmin=0,
                         vmax=top)
        ax.set_aspect("equal")
        ax.set_title(f"{label}\nmean distance {m['mean_distance_mm']:.2f} mm "
                     f"({m['percent_of_displacement']:.1f} %), {c.normalised:.2f} × noise",
                     fontsize=8)
        ax.set_xlabel("x (mm)")
    axes[0].set_ylabel("y (mm)")
    fig.colorbar(art, ax=list(axes[:n]), label="position error (mm)", shrink=0.8)
    first = next(iter(comparisons.values()))
    parts = first.residual**2
    total = float(parts.sum()) or 1.0
    names = [r.says for r in first.regions]
    axes[n].barh(range(len(names)), [100 * parts[r.rows].sum() / total for r in first.regions],
                 color="C3")
    axes[n].set_yticks(range(len(names)), names, fontsize=8)
    axes[n].invert_yaxis()
    axes[n].set_xlabel(f"share of the {next(iter(comparisons))} error (%)")
    fig.suptitle(f"{test.id}: where the formed part misses", fontsize=10)
    return save_figure(fig, path)


# --------------------------------------------------------------------------------------------
# The kind


@dataclasses.dataclass(frozen=True)
class GridKind:
    """The measured grid (:class:`~fenicsx_drape.diagnosis.kinds.base.FormedKind`).

    The formed ``x, y, z`` of nodes drawn on the flat sheet (module doc).
    """

    name: str = "grid"
    test_kind: str = "forming"  # the bundle's kind of its tests
    formed: bool = True
    mirrorable: bool = True  # a grid is read at its image in a symmetry plane
    fit: FitHook = fit_friction  # the friction coefficients, shared by the forming kinds

    def holds(self, test: Test) -> bool:
        """Whether ``test`` is a forming test's grid (no lab measurement, or its ``file``)."""
        lab = getattr(test, "lab", None)
        return test.kind == "forming" and (lab is None or lab.measurement == "file")

    def unit(self, test: Test) -> str:
        """Millimetres."""
        return "mm"

    def measured(self, test: Test) -> np.ndarray:
        """The measured ``x, y, z`` of every node (flattened)."""
        return measured_positions(test).ravel()

    def noise(self, test: Test) -> tuple[float, str]:
        """The position noise (mm) and its source (:func:`noise`)."""
        return noise(test)

    def value_sd(self, test: Test) -> np.ndarray:
        """Per compared value, the noise a fit weighs it with (:func:`row_noise`).

        A node's x, y, z share its ``position_sd_mm``.
        """
        return np.repeat(row_noise(test), 3)

    def sd_column(self, test: Test) -> str:
        """``position_sd_mm``."""
        return "position_sd_mm"

    def simulate(self, test: Test, model: Model) -> np.ndarray:
        """The model's ``x, y, z`` of every node (:func:`simulate`)."""
        return simulate(test, model)

    def on_sheet(self, test: Test, sheet: FormedGrid, model: Model,
                 plane: str | None = None) -> np.ndarray:
        """The grid read on one formed sheet (:func:`on_sheet`)."""
        return on_sheet(test, sheet, plane)

    def regions(self, test: Test) -> list[Region]:
        """The regions of the part (:func:`part_regions`)."""
        return part_regions(test)

    def abscissa(self, test: Test) -> tuple[str, np.ndarray]:
        """Each node's flat distance from the axis (:func:`abscissa`)."""
        return abscissa(test)

    def metrics(self, test: Test, simulated: np.ndarray, model: Model | None = None
                ) -> dict[str, Any]:
        """The paper's measures (:func:`metrics`)."""
        return metrics(test, simulated, model)

    def plot(self, comparisons: Mapping[str, Comparison], test: Test, path: Path,
             shares: Sequence[Mapping[str, Any]] = ()) -> Path:
        """The error map over the part (:func:`plot_error_map`)."""
        return plot_error_map(comparisons, test, path, shares)

    def check(self, test: Test, case: FormingCase) -> tuple[bool, str] | None:
        """The positions against the case and a shifted frame (module doc)."""
        return checks.check_registered_or_positions(test, case)


GRID = GridKind()
