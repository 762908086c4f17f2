"""Forming tests in ``compare`` and ``diagnose``: a simulated sheet against a measured grid.

A forming test (``kind = "forming"``, ``shared/spec/measurements.md``) gives the formed
positions of the nodes of a grid drawn on the flat sheet. It plugs into
:mod:`fenicsx_drape.diagnosis.compare` through the registry of test kinds
(:func:`~fenicsx_drape.diagnosis.kinds.register_kind`; compare never imports it):

- **simulation**: the hemisphere is formed (:func:`~fenicsx_drape.forming.hemisphere.
  run_hemisphere`) under the test's conditions (tool sizes, travel, duration, holding force)
  on a symmetric quarter, mirrored when the measured grid covers the whole sheet; the formed
  sheet is interpolated bilinearly in the reference coordinates at the measured grid's
  ``(x0_mm, y0_mm)``, so the measured grid may be coarser than the mesh (section 4.2);
- **values**: per row the three coordinates ``x, y, z`` (flattened), so a test's RMSE is the
  RMS position error per coordinate (mm) of the spec;
- **noise**: the RMS of ``position_sd_mm``, else a model-free estimate from fourth
  differences of the measured positions along the grid lines (:func:`grid_noise`);
- **regions** of the part (:func:`part_regions`): apex, bias diagonals, tow axes at the
  fillet, flange under the holder;
- the paper's measures beside them (:func:`metrics`): mean distance (mm and % of the mean
  node displacement, the paper's 1.57 mm and 4 %), and the shear-angle and wrinkling-strain
  errors when the grid has those columns.

**Fitting.** In a forming test only the forming parameters are fitted (:func:`fit_forming`):
the friction coefficients of the model's forming effects (``mu`` of ``holder_friction``,
``mu_tool`` of ``tool_friction``), the material parameters staying at their coupon-fitted (or
given) values. The fit is Gauss-Newton on the per-coordinate residuals in noise units, with
forward differences of :data:`FD_STEP`; every forming run is cached by its conditions and
parameters, and the runs of one iteration (the point and its perturbations) go to worker
processes at once (:mod:`~fenicsx_drape.diagnosis.forming_runs`).

**Cost.** A forming run costs seconds (4 s for the 10 mm quarter), and a diagnosis makes
a few dozen: only the friction coefficients are fitted (one or two parameters, Gauss-Newton
in at most :data:`MAX_ITERATIONS` iterations), every run is cached, the runs of an iteration
go to persistent worker processes, and the held-out folds (every third node of the grid
left out, three folds) start from the full fit, so a fold costs a run only when its step
moves the parameters by more than :data:`XTOL`. The runs use cells of
:data:`~fenicsx_drape.diagnosis.forming_runs.FULL_CELL_MM` (the paper's Δ), set with
:func:`~fenicsx_drape.diagnosis.forming_runs.resolution`. A coarser screening mesh
(:data:`~fenicsx_drape.diagnosis.forming_runs.SCREEN_CELL_MM`, 4× cheaper) is only sound
when its discretisation error is below the noise: against a grid formed on 10 mm cells, the
20 mm mesh misses by 2.9 × the 0.3 mm noise (at the tow axes over the fillet), which hides a
tool friction that the 10 mm mesh finds; :func:`confirm` refits the baseline and the winner
on another mesh to check a verdict.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.forming_runs import (
    FULL_CELL_MM,
    current_cell_mm,
    form_many,
    resolution,
    stopped_at,
)
from fenicsx_drape.diagnosis.kinds import Kind, Region, register_kind
from fenicsx_drape.errors import DrapeInputError

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.compare import Comparison
    from fenicsx_drape.forming.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

FORMING_PARAMETERS = ("mu", "mu_tool")  # what a forming test fits (friction coefficients)
FD_STEP = 0.02  # forward-difference step in a friction coefficient
XTOL = 0.002  # a Gauss-Newton step smaller than this (in μ) ends the fit
MAX_ITERATIONS = 4  # Gauss-Newton iterations of a forming fit at most
TOOL_KEYS = ("punch_radius_mm", "fillet_radius_mm", "holder_opening_mm", "sheet_mm",
             "travel_mm")


# --------------------------------------------------------------------------------------------
# Simulation


def case_of(test: Test, cell_mm: float | None = None):
    """The :class:`~fenicsx_drape.forming.hemisphere.HemisphereCase` of a forming test."""
    from fenicsx_drape.forming.hemisphere import HemisphereCase
    from fenicsx_drape.forming.tools import HemisphereTools

    if test.geometry != "hemisphere":
        raise DrapeInputError(f"test {test.id!r}: forming geometry {test.geometry!r} cannot be "
                              "simulated (known: hemisphere)")
    f = test.forming
    tools = HemisphereTools(**{k: float(f[k]) for k in TOOL_KEYS if k in f})
    return HemisphereCase(cell_mm=cell_mm or current_cell_mm(),
                          duration_s=float(f["duration_s"]),
                          holder_force_N=float(f["holder_force_N"]), quarter=True, tools=tools)


def is_quarter(test: Test) -> bool:
    """Whether the measured grid covers one symmetric quarter (x0, y0 ≥ 0)."""
    return bool((test.columns["x0_mm"] >= -1e-9).all() and (test.columns["y0_mm"] >= -1e-9).all())


def sheet_for(test: Test, quarter: FormedGrid) -> FormedGrid:
    """The simulated sheet matching the measured grid: the quarter, or mirrored to full."""
    return quarter if is_quarter(test) else quarter.full()


def reference_points(test: Test) -> np.ndarray:
    """The measured nodes on the flat sheet, (n, 2) in mm."""
    return np.column_stack([test.columns["x0_mm"], test.columns["y0_mm"]])


def measured_positions(test: Test) -> np.ndarray:
    """The measured formed positions, (n, 3) in mm."""
    return np.column_stack([test.columns[c] for c in ("x_mm", "y_mm", "z_mm")])


def simulated_sheets(test: Test, model: Model) -> list[FormedGrid]:
    """The simulated sheet(s) for a test: one per parameter set of a vectorised model."""
    sizes = {np.size(v) for v in model.parameters.values() if np.ndim(v) > 0}
    case = case_of(test)
    if not sizes:
        return [sheet_for(test, form_many([(case, model)])[0])]
    (k,) = sizes
    sets = [model.with_parameters(**{n: float(v[i]) for n, v in model.parameters.items()
                                     if np.ndim(v) > 0}) for i in range(k)]
    return [sheet_for(test, g) for g in form_many([(case, m) for m in sets])]


def simulate(test: Test, model: Model) -> np.ndarray:
    """Simulated ``x, y, z`` of every measured node, flattened (3n,), or (k, 3n) for k sets."""
    sheets = simulated_sheets(test, model)
    values = [s.sample(reference_points(test)).ravel() for s in sheets]
    vectorised = any(np.ndim(v) > 0 for v in model.parameters.values())
    return np.array(values) if vectorised else values[0]


def interpolate(sheet: FormedGrid, field: np.ndarray, points_mm: np.ndarray) -> np.ndarray:
    """A nodal scalar field of a sheet (n_i, n_j), bilinear at flat-sheet points (m, 2)."""
    from fenicsx_drape.forming.post import FormedGrid

    stacked = np.repeat(np.asarray(field, float)[..., None], 3, axis=-1)
    return FormedGrid(sheet.X, stacked, sheet.quarter).sample(points_mm)[:, 0]


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
    return float(np.median(np.abs(np.concatenate(d4))) / 0.6745 / math.sqrt(70.0))


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


def part_regions(test: Test) -> list[Region]:
    """The named regions of the part, each a mask over the flattened ``x, y, z`` values."""
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
        out |= field_errors(test, simulated_sheets(test, model)[0])
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


def _abscissa(test: Test) -> tuple[str, np.ndarray]:
    return "r0_mm", np.repeat(np.hypot(*reference_points(test).T), 3)


# --------------------------------------------------------------------------------------------
# Fitting the forming parameters


def forming_parameters(model: Model) -> tuple[str, ...]:
    """The forming parameters the model fits: those of :data:`FORMING_PARAMETERS` it uses."""
    active = model.active_parameters()
    return tuple(n for n in FORMING_PARAMETERS if n in active)


def _residuals(tests: Sequence[Test], model: Model, names: Sequence[str],
               sets: np.ndarray) -> np.ndarray:
    """Residuals in noise units, cost = Σ_tests (RMSE / noise)², one row per parameter set."""
    vectorised = model.with_parameters(**{n: sets[:, i] for i, n in enumerate(names)})
    out = []
    for test in tests:
        values = np.atleast_2d(simulate(test, vectorised))
        w = np.repeat(1.0 / row_noise(test), 3) / math.sqrt(3 * test.n_rows)
        r = (values - measured_positions(test).ravel()) * w
        out.append(np.where(np.isfinite(r), r, 0.0))
    return np.concatenate(out, axis=1)


def fit_forming(bundle: Bundle, model: Model, *, tests: Sequence[str] | None = None,
                max_iterations: int = MAX_ITERATIONS,
                progress: Callable[[str], None] | None = None) -> Model:
    """Fit the model's forming parameters to the forming tests of ``bundle`` (module doc).

    Args:
        bundle: The measurements (coupon tests are ignored here).
        model: The model, material parameters as fitted to the coupons (or given).
        tests: Only these test ids; all forming tests when None.
        max_iterations: Gauss-Newton iterations at most (capped at :data:`MAX_ITERATIONS`).
        progress: Called with a line of text per iteration.

    Returns:
        The model with its forming parameters fitted.
    """
    say = progress or (lambda line: None)
    chosen = [t for t in bundle.tests if t.kind == "forming" and (tests is None or t.id in tests)]
    names = forming_parameters(model)
    if not chosen or not names:
        return model
    p = np.array([float(model.parameters[n]) for n in names])
    h = FD_STEP * np.eye(len(names))

    def evaluate(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R = _residuals(chosen, model, names, np.vstack([p, p + h]))
        return R[0], (R[1:] - R[0]).T / FD_STEP

    r, J = evaluate(p)
    for iteration in range(min(max_iterations, MAX_ITERATIONS)):
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        trial = np.maximum(p + step, 0.0)
        if np.abs(trial - p).max() < XTOL:
            break
        r_new, J_new = evaluate(trial)
        say(f"  forming fit {iteration + 1}: "
            f"{ {n: round(float(v), 4) for n, v in zip(names, trial)} }, "
            f"cost {r_new @ r_new:.4g} (was {r @ r:.4g})")
        if r_new @ r_new >= r @ r:
            break
        p, r, J = trial, r_new, J_new
    return model.with_parameters(**{n: float(v) for n, v in zip(names, p)})


def _fit(bundle: Bundle, model: Model, *, tests: Sequence[str] | None = None,
         parameters: Sequence[str] | None = None, max_iterations: int = MAX_ITERATIONS,
         from_features: bool = True, progress: Callable[[str], None] | None = None) -> Model:
    """The forming kind's fit (:class:`~fenicsx_drape.diagnosis.kinds.FitHook`).

    The forming parameters only (:func:`fit_forming`), the material held as the coupons (or
    the model) left it: ``parameters`` and ``from_features`` concern the material.
    """
    return fit_forming(bundle, model, tests=tests, progress=progress,
                       max_iterations=max_iterations)


def synthetic_forming_test(model: Model, *, test_id: str = "hemisphere",
                           cell_mm: float = FULL_CELL_MM, grid_mm: float | None = None,
                           sd_mm: float = 0.3, seed: int = 0, quarter: bool = True,
                           duration_s: float = 40.0, holder_force_N: float = 133.0) -> Test:
    """A forming test "measured" by the project's simulator plus Gaussian position noise.

    The hemisphere formed by ``model`` on cells of ``cell_mm``, read at a drawn grid of
    ``grid_mm`` (default: the cell), with noise of ``sd_mm`` per coordinate written as the
    ``position_sd_mm`` column; the quarter grid, or the full sheet by symmetry.
    """
    from fenicsx_drape.forming.hemisphere import HemisphereCase
    from fenicsx_drape.measurements.bundle import Test

    case = HemisphereCase(cell_mm=cell_mm, duration_s=duration_s,
                          holder_force_N=holder_force_N)
    (sheet,) = form_many([(case, model)])
    table = (sheet if quarter else sheet.full()).drawn_grid(grid_mm or cell_mm)
    rng = np.random.default_rng(seed)
    columns = {k: np.asarray(v, float) for k, v in table.items()}
    for c in ("x_mm", "y_mm", "z_mm"):
        columns[c] = np.round(columns[c] + rng.normal(0.0, sd_mm, columns[c].size), 4)
    columns["position_sd_mm"] = np.full(columns["i"].size, sd_mm)
    t = case.tools
    setup = {"punch_radius_mm": t.punch_radius_mm, "fillet_radius_mm": t.fillet_radius_mm,
             "holder_opening_mm": t.holder_opening_mm, "sheet_mm": t.sheet_mm,
             "travel_mm": t.travel_mm, "duration_s": duration_s,
             "holder_force_N": holder_force_N, "grid_mm": grid_mm or cell_mm}
    return Test(id=test_id, kind="forming", file=f"{test_id}.csv", columns=columns,
                geometry="hemisphere", forming=setup)


def confirm(bundle: Bundle, report, cell_mm: float = FULL_CELL_MM,
            progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The screening's baseline and best candidate again on the full mesh (module doc, cost).

    Each model of a diagnosis :class:`~fenicsx_drape.diagnosis.diagnose.Report` keeps its material;
    its forming parameters are refitted on cells of ``cell_mm`` and it is compared with the
    forming tests there.

    Returns:
        ``{"cell_mm", label: {"error", "metrics", "forming_parameters"}}`` for the baseline
        and the first-ranked candidate.
    """
    from fenicsx_drape.diagnosis.compare import compare_tests, error_record

    tests = [t for t in bundle.tests if t.kind == "forming"]
    labels = ["baseline"] + [c["effect"] for c in report["candidates"][:1]]
    out: dict[str, Any] = {"cell_mm": cell_mm}
    with resolution(cell_mm):
        for label in labels:
            model = fit_forming(bundle, report.models[label], progress=progress)
            values = {t.id: simulate(t, model) for t in tests}
            out[label] = {"error": error_record(compare_tests(tests, values)),
                          "metrics": {t.id: metrics(t, values[t.id], model) for t in tests},
                          "forming_parameters": {n: float(model.parameters[n])
                                                 for n in forming_parameters(model)}}
    return out


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
    fig, axes = plt.subplots(1, n + 1, figsize=(4.2 * (n + 1), 4.2))
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


FORMING = Kind(unit="mm", measured=lambda test: measured_positions(test).ravel(), noise=noise,
               simulate=simulate, regions=part_regions, abscissa=_abscissa,
               sd_column="position_sd_mm", fit=_fit, metrics=metrics, plot=plot_error_map)
register_kind("forming", FORMING)
