"""Forming tests in ``compare`` and ``diagnose``: a simulated sheet against a measured grid.

A forming test (``kind = "forming"``, ``docs/measurements.md``) gives the formed
positions of the nodes of a grid drawn on the flat sheet. These are the grid's hooks of the
forming kind (:data:`~fenicsx_drape.diagnosis.forming_fit.FORMING`, which hands a lab
measurement to :mod:`~fenicsx_drape.diagnosis.lab_kind`):

- **simulation**: the part the test was formed on, under its conditions. A test with
  ``geometry = "hemisphere"`` forms the paper's hemisphere (``meshes/hemisphere/case.toml``,
  a symmetric quarter, with the tool sizes, travel, duration and holding force of the test:
  :func:`forming_case_of`) as any case; a test that names its case file
  (``case = "part.toml"``) forms that case
  (:func:`~fenicsx_drape.forming.running.run.run_case`) with the test's keys as overrides
  (the bundle loader applied them, :func:`~fenicsx_drape.forming.case.format.case_for_test`),
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
  errors when the grid has those columns.

**Fitting.** In a forming test only the forming parameters are fitted
(:func:`~fenicsx_drape.diagnosis.forming_fit.fit_forming`):
the friction coefficients of the model's forming effects (``mu`` of ``holder_friction``,
``mu_tool`` of ``tool_friction``), the material parameters staying at their coupon-fitted (or
given) values. The fit is Gauss-Newton on the per-coordinate residuals in noise units, with
forward differences of :data:`FD_STEP`, from the better of two starts (the model's values and
the parameters' defaults, judged in the first batch of runs: a warm start from a model
lacking the right physics can sit far off, e.g. a holder μ driven up by a model whose tows
carry compression), steps of at most :data:`MAX_STEP` within :data:`MU_BOUNDS` and halved
once when they do not lower the cost; every forming run is cached by its case and
parameters. The runs of one iteration (the point and its perturbations) go to the workers
at once (:mod:`~fenicsx_drape.diagnosis.forming_runs`) when the point fits in the
perturbations' last batch for no extra time (one parameter on two workers); else a point's
perturbations are formed only once the fit takes the point (a rejected step's are not
needed: on one worker, a fifth of the lab README diagnosis's runs). The fit is the same
either way.

The holder's μ is fitted only where a test's holder does not fix it (a case's
``[holder] mu``).

**Cost.** A forming run costs seconds (4 s for the 10 mm quarter), and a diagnosis makes
a few dozen: only the friction coefficients are fitted (one or two parameters, Gauss-Newton
in at most :data:`MAX_ITERATIONS` iterations), every run is cached, the runs of an iteration
go to persistent worker processes, and the held-out folds (every third node of the grid
left out, three folds) start from the full fit, so a fold costs a run only when its step
moves the parameters by more than :data:`XTOL`. The hemisphere runs use cells of
:data:`~fenicsx_drape.diagnosis.forming_runs.FULL_CELL_MM` (the paper's Δ) and a case its
blank's ``cell_mm``; :func:`~fenicsx_drape.diagnosis.forming_runs.resolution` sets another
for both. A coarser screening mesh
(:data:`~fenicsx_drape.diagnosis.forming_runs.SCREEN_CELL_MM`, 4× cheaper) is only sound
when its discretisation error is below the noise: against a grid formed on 10 mm cells, the
20 mm mesh misses by 2.9 × the 0.3 mm noise (at the tow axes over the fillet), which hides a
tool friction that the 10 mm mesh finds; :func:`~fenicsx_drape.diagnosis.diagnose.confirm`
refits the baseline and the winner on another mesh to check a verdict.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.forming_runs import (
    FULL_CELL_MM,
    case_key,
    cell_override,
    form_many,
    stopped_at,
)
from fenicsx_drape.diagnosis.kinds import Region
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case.format import FormingCase, case_file, case_for_test, with_overrides

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds import Comparison
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model

FORMING_PARAMETERS = ("mu", "mu_tool")  # what a forming test fits (friction coefficients)
FD_STEP = 0.02  # forward-difference step in a friction coefficient
XTOL = 0.002  # a Gauss-Newton step smaller than this (in μ) ends the fit
MAX_ITERATIONS = 4  # Gauss-Newton iterations of a forming fit at most
MAX_STEP = 0.3  # largest change of a friction coefficient in one iteration
MU_BOUNDS = (0.0, 2.0)  # friction coefficients fitted within (prepreg on steel: 0.1-0.5)
# A measured node outside the cells of the model's net (a ragged edge) takes the nearest kept
# cell's bilinear map up to this many cells away; farther, the grid does not fit the blank.
EXTRAPOLATE_CELLS = 1.5


# --------------------------------------------------------------------------------------------
# Simulation


def names_case(test: Test) -> bool:
    """Whether a forming test names its case file (else it is the paper's hemisphere)."""
    return test.case is not None or test.forming_case is not None


_read_cases: dict[tuple, FormingCase] = {}


def forming_case_of(test: Test) -> FormingCase:
    """The case a test forms, with the test's keys applied.

    A test that names its case file: that case (as the bundle loader read it, else read here);
    a test with ``geometry = "hemisphere"``: the paper's, ``meshes/hemisphere/case.toml`` (a
    symmetric quarter), with the test's tool sizes, travel, duration and holding force. Read
    once per file and keys.
    """
    if test.forming_case is not None:
        return test.forming_case
    if test.case_path is not None:
        path, keys = test.case_path, test.case_keys
    elif test.geometry == "hemisphere":
        path, keys = case_file("hemisphere"), test.forming
    else:
        raise DrapeInputError(f"test {test.id!r}: forming geometry {test.geometry!r} cannot be "
                              "simulated (known: hemisphere; or name the forming case with "
                              "case = \"case.toml\")")
    key = (str(path), tuple(sorted((k, str(v)) for k, v in keys.items())))
    if key not in _read_cases:
        _read_cases[key] = case_for_test(path, keys)[0]
    return _read_cases[key]


@functools.lru_cache(maxsize=64)
def _with_cell(case: FormingCase, cell_mm: float) -> FormingCase:
    return case if case.blank.cell_mm == cell_mm else with_overrides(case, cell_mm=cell_mm)


def case_of(test: Test, cell_mm: float | None = None) -> FormingCase:
    """The case a forming test is simulated with (:func:`forming_case_of`), on its cells.

    The cells are ``cell_mm``, else the :func:`~fenicsx_drape.diagnosis.forming_runs.
    resolution`'s, else the case's own (the hemisphere's: the paper's 10 mm).
    """
    case = forming_case_of(test)
    cell = cell_mm or cell_override()
    return _with_cell(case, float(cell)) if cell else case


def model_planes(test: Test) -> tuple[str, ...]:
    """The symmetry planes of the part the test's runs model (the hemisphere: a quarter)."""
    return forming_case_of(test).planes


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
    sizes = {np.size(v) for v in model.parameters.values() if np.ndim(v) > 0}
    case = case_of(test)
    if not sizes:
        return [sheet_for(test, form_many([(case, model)])[0].ply(test.ply))]
    (k,) = sizes
    sets = [model.with_parameters(**{n: float(v[i]) for n, v in model.parameters.items()
                                     if np.ndim(v) > 0}) for i in range(k)]
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


# Regions of the part a case forms (:func:`case_regions`): by what a node touches at the end
# and, on the walls, by its direction from the tool axis in the tow frame.
CASE_REGION_NAMES = ("punch top", "walls along the tow axes", "walls on the bias diagonals",
                     "flat base", "flange under the holder", "free sheet (no tool contact)")
CONTACT_MM = 1.0  # a node within this (plus three times the noise) of a surface touches it
WALL_DEG = 30.0  # a surface steeper than this to the plane normal to the travel is a wall
CONTACT_ROLES = ("punch", "die", "surface")
_built_tools: dict[str, dict[str, Any]] = {}


def _tools_of(case: FormingCase) -> dict[str, Any]:
    """The built tools of a case (cached by the case's content: meshing costs seconds)."""
    from fenicsx_drape.forming.case.format import build_tools

    key = case_key(case)
    if key not in _built_tools:
        _built_tools[key] = build_tools(case)
    return _built_tools[key]


def travel_axis(case: FormingCase) -> np.ndarray:
    """The unit direction the case's fastest tool travels (the frame's z for the hemisphere)."""
    speeds = [case.speed_mm_per_s(t) for t in case.tools]
    spec = case.tools[int(np.argmax(speeds))]
    if spec.motion is not None:
        d = spec.motion.translation(spec.motion.time_s[-1]) - spec.motion.translation(0.0)
        if np.linalg.norm(d) > 0:
            return d / np.linalg.norm(d)
    return np.array([0.0, 0.0, 1.0])


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


def region_of_points(test: Test, x: np.ndarray, direction_deg: np.ndarray,
                     noise_mm: float) -> np.ndarray:
    """:func:`case_region_of_nodes` of any formed points (n, 3).

    With their directions (deg, 0-45) from the nearest tow axis and the positions' noise (mm).
    """
    case = forming_case_of(test)
    tools = _tools_of(case)
    t = case.duration_s
    x = np.array(x, float)
    for plane in case.planes:
        axis = {"x": 0, "y": 1}[plane]
        x[:, axis] = np.abs(x[:, axis])
    tol = CONTACT_MM + 3.0 * noise_mm
    n = len(x)
    best = np.full(n, np.inf)
    normal = np.zeros((n, 3))
    for spec in case.tools:
        if spec.role in CONTACT_ROLES:
            g = tools[spec.name].gap(x, t)
            closer = (np.abs(g.phi) < tol) & (np.abs(g.phi) < best)
            best = np.where(closer, np.abs(g.phi), best)
            normal[closer] = g.normal[closer]
    touching = np.isfinite(best)
    e = travel_axis(case)
    cos = np.abs(normal @ e) / np.maximum(np.linalg.norm(normal, axis=1), 1e-300)
    wall = touching & (cos < math.cos(math.radians(WALL_DEG)))
    height = x @ e
    top = touching & ~wall & (height >= 0.5 * max(float(height.max()), 0.0))
    bias = np.asarray(direction_deg) >= 22.5
    which = np.select([wall & ~bias, wall & bias, top, touching], [1, 2, 0, 3], default=5)
    if case.holder is not None:
        holder = tools[case.holder.tool]
        under = np.asarray(holder.covers(x, t), bool) & (np.abs(holder.gap(x, t).phi) < tol)
        which = np.where(under, 4, which)
    return which


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
# Fitting the forming parameters


def holder_mu_free(test: Test) -> bool:
    """Whether the model's holder μ acts in a test (a case may fix it, or have no holder)."""
    if not names_case(test):
        return True
    holder = forming_case_of(test).holder
    return holder is not None and holder.mu is None


def synthetic_forming_test(model: Model, *, test_id: str = "hemisphere",
                           cell_mm: float = FULL_CELL_MM, grid_mm: float | None = None,
                           sd_mm: float = 0.3, seed: int = 0, quarter: bool = True,
                           duration_s: float = 40.0, holder_force_N: float = 133.0) -> Test:
    """A forming test "measured" by the project's simulator plus Gaussian position noise.

    The hemisphere formed by ``model`` on cells of ``cell_mm``, read at a drawn grid of
    ``grid_mm`` (default: the cell), with noise of ``sd_mm`` per coordinate written as the
    ``position_sd_mm`` column; the quarter grid, or the full sheet by symmetry.
    """
    from fenicsx_drape.forming.case.format import load_case
    from fenicsx_drape.forming.tools.shapes import HemisphereTools
    from fenicsx_drape.measurements.bundle import Test

    case = load_case("hemisphere", cell_mm=cell_mm, duration_s=duration_s,
                     holder_force_N=holder_force_N)
    (sheet,) = form_many([(case, model)])
    table = (sheet if quarter else sheet.full()).drawn_grid(grid_mm or cell_mm)
    rng = np.random.default_rng(seed)
    columns = {k: np.asarray(v, float) for k, v in table.items()}
    for c in ("x_mm", "y_mm", "z_mm"):
        columns[c] = np.round(columns[c] + rng.normal(0.0, sd_mm, columns[c].size), 4)
    columns["position_sd_mm"] = np.full(columns["i"].size, sd_mm)
    t = HemisphereTools(**case.tool("punch").params)
    setup = {"punch_radius_mm": t.punch_radius_mm, "fillet_radius_mm": t.fillet_radius_mm,
             "holder_opening_mm": t.holder_opening_mm, "sheet_mm": t.sheet_mm,
             "travel_mm": t.travel_mm, "duration_s": duration_s,
             "holder_force_N": holder_force_N, "grid_mm": grid_mm or cell_mm}
    return Test(id=test_id, kind="forming", file=f"{test_id}.csv", columns=columns,
                geometry="hemisphere", forming=setup)


def synthetic_case_test(model: Model, case: FormingCase, *, test_id: str | None = None,
                        grid_mm: float | None = None, sd_mm: float = 0.3, seed: int = 0,
                        full: bool = False, case_file: str = "case/case.toml",
                        ply: int | None = None) -> Test:
    """A forming test of any case "measured" by the project's simulator plus Gaussian noise.

    The case formed by ``model`` (on its own cells), read at a drawn grid of ``grid_mm``
    (default: the cell) on the modelled part, or on the whole blank by symmetry (``full``),
    with noise of ``sd_mm`` per coordinate written as the ``position_sd_mm`` column (none when
    0). The test names ``case_file`` and carries the case; its keys repeat the case's
    duration, travel and holding force. Write it with :func:`write_case_bundle`. On a stack,
    ``ply`` names the ply measured (its ``file_ply`` key); None: the outermost one.
    """
    from fenicsx_drape.measurements.bundle import Test

    (sheet,) = form_many([(case, model)])
    sheet = sheet.ply(ply)
    grid_mm = grid_mm or case.blank.cell_mm
    table = (sheet.full() if full else sheet).drawn_grid(grid_mm)
    rng = np.random.default_rng(seed)
    columns = {k: np.asarray(v, float) for k, v in table.items()}
    if sd_mm:
        for c in ("x_mm", "y_mm", "z_mm"):
            columns[c] = np.round(columns[c] + rng.normal(0.0, sd_mm, columns[c].size), 4)
        columns["position_sd_mm"] = np.full(columns["i"].size, sd_mm)
    keys = {"duration_s": case.duration_s, "travel_mm": case.total_travel_mm}
    if case.holder is not None:
        keys["holder_force_N"] = case.holder.force_N
    test_id = test_id or case.name
    return Test(id=test_id, kind="forming", file=f"{test_id}.csv", columns=columns,
                forming={**keys, "grid_mm": grid_mm}, case=case_file, case_keys=keys,
                forming_case=case, ply=ply)


def write_case_bundle(name: str, tests: Sequence[Test], folder: str | Path, *,
                      comment: str = "") -> Path:
    """Write forming tests that carry their case as a bundle folder, with copies of the cases.

    Each test's case is written (with its geometry files) at its ``case`` path inside the
    folder; the tests that name no case are written as they are.
    """
    from fenicsx_drape.forming.case.format import write_case
    from fenicsx_drape.measurements.bundle import Bundle, write_bundle

    folder = Path(folder)
    for test in tests:
        if test.forming_case is not None and test.case is not None:
            where = folder / test.case
            write_case(test.forming_case, where.parent, name=where.name, comment=comment)
    return write_bundle(Bundle(name=name, tests=tuple(tests)), folder, comment=comment)


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
