"""Parameter studies of the hemisphere (the paper's Figs. 9 and 12): run, tabulate, plot.

A study is a list of :class:`Variant` s (a labelled case, model and solver options) run with
:func:`run_variants`, which returns one row of :func:`metrics` per variant and the formed
grids. Rows go to CSV with :func:`write_rows`; :func:`plot_trend` draws the maximum shear and
the total wrinkling against the varied quantity beside the paper's (Figs. 12a and 12b share
it); :func:`paper_numbers` reduces the sweeps of one reading of the model to the numbers the
paper states (section 4). Rank 0 writes.

Runs are cached on disk when ``cache`` is given: per run the formed grid (``.npz``) and the
run's statistics (``.json``), keyed by a hash of the case, the model, the options and a tag
(:func:`source_tag`: a hash of the sources that decide a forming result, so any change of the
solver, the laws or the forming terms reruns everything). Metrics are recomputed from the
grids, so changing them needs no rerun.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from fenicsx_drape.forming.case import FormingCase, case_dict, load_case
from fenicsx_drape.forming.case.spec import builtin_tools
from fenicsx_drape.forming.running.post import FormedGrid, mean_distance
from fenicsx_drape.forming.running.run import draw_in, run_case
from fenicsx_drape.provenance import atomic_write_bytes, atomic_write_text, write_json

# The two readings of eq. 1 on a symmetric part model: "symmetric_part" gives the
# quarter F/4 (the whole sheet's force per node), "model" the whole F over the quarter's own
# n_s nodes (four times the force per node), as a model built of the quarter alone would.
READINGS = ("symmetric_part", "model")
# μ of prepreg on (release-agent-coated) steel: the literature range (docs/paper.md).
MU_LITERATURE = (0.1, 0.2, 0.3, 0.4)
# The paper's sweeps (section 4): Fig. 12a durations at 133 N, Fig. 12b forces at 40 s, and
# Fig. 9 quarter models of 9 to 225 nodes (cells of 120 mm / 2 ... 120 mm / 14).
DURATIONS_S = (8.0, 12.0, 20.0, 40.0, 60.0, 100.0, 160.0, 240.0)
FORCES_N = (70.0, 100.0, 133.0, 200.0, 300.0, 400.0, 500.0, 650.0, 800.0)
MESH_CELLS_MM = tuple(120.0 / n for n in range(2, 15))

STATS = ("steps", "cutbacks", "snes_iterations", "wall_time_s", "max_penetration_mm",
         "travel_reached_mm")
# The columns of :func:`metrics`, in the order the CSV files list them.
METRICS = ("max_shear_deg", "diagonal_max_shear_deg", "total_wrinkling_strain",
           "total_wrinkling_engineering", "total_wrinkling_gl_bars", "min_wrinkling_strain",
           "max_tow_strain",
           "mean_tow_strain_in_part", "wrinkle_r_mm", "wrinkle_z_mm", "wrinkle_flat_mm",
           "wrinkle_on_edge", "wrinkle_centroid_r_mm", "max_shear_flat_mm", "max_shear_r_mm",
           "mid_side_r_mm", "corner_r_mm", "base_radius_mm", "draw_in_mid_side_mm",
           "draw_in_corner_mm", "nodes", *STATS)


@dataclasses.dataclass(frozen=True)
class Variant:
    """One run of a study: a label, the case, and optionally the model and solver options.

    ``model=None`` is the paper's model; ``options=None`` the case's default solver options
    (:func:`~fenicsx_drape.forming.running.run.run_case`).
    """

    label: str
    case: FormingCase
    model: object = None
    options: object = None


def paper_case(reading: str, **overrides) -> FormingCase:
    """The paper's hemisphere under one reading of eq. 1's force share (see :data:`READINGS`).

    ``meshes/hemisphere/case.toml`` with ``overrides`` (:func:`~fenicsx_drape.forming.case.reading.
    load_case`'s: ``cell_mm``, ``duration_s``, ``holder_force_N``, a tool parameter, ...).
    """
    if reading not in READINGS:
        raise ValueError(f"paper_case: reading {reading!r} is not one of {READINGS}")
    return load_case("hemisphere", holder_force_share=reading, **overrides)


def default_options(model=None, **changes):
    """The hemisphere's default solver options with ``changes`` (e.g. ``tow_bending_EI_Nmm2``).

    As :func:`~fenicsx_drape.forming.running.run.run_case` builds them when given none:
    :func:`~fenicsx_drape.forming.running.run.forming_options` for the hemisphere's flat holder.
    """
    from fenicsx_drape.forming.running.run import forming_options
    from fenicsx_drape.model import default_model

    return forming_options(model or default_model(), **changes)


def _bars(q: FormedGrid, strains):
    """Per tow family: the bars' formed and flat mid-points and whether on the free edge."""
    n_i, n_j = q.X.shape[:2]
    out = []
    for axis, e in enumerate(strains):
        def mid(P, axis=axis):
            return 0.5 * (np.take(P, range(P.shape[axis] - 1), axis=axis)
                          + np.take(P, range(1, P.shape[axis]), axis=axis))

        i, j = np.meshgrid(np.arange(e.shape[0]), np.arange(e.shape[1]), indexing="ij")
        # On the free edge: the weft bars of the last column, the warp bars of the last row.
        edge = (i == n_i - 1) if axis == 1 else (j == n_j - 1)
        out.append((mid(q.x), mid(q.X), edge))
    return out


def metrics(grid: FormedGrid, case: FormingCase, stats: Mapping | None = None
            ) -> dict[str, float]:
    """The numbers of a formed sheet that the studies compare with the paper (a CSV row).

    - ``max_shear_deg``, ``total_wrinkling_strain`` (Green-Lagrange, edge bars weighted as
      half strips: the summary's), ``min_wrinkling_strain`` as in ``summary.json``;
      ``diagonal_max_shear_deg``: the largest shear on the bias line from the corner to the
      apex (Fig. 11a's path; a wrinkled cell at the sheet's edge cannot set it);
    - ``total_wrinkling_engineering``: the length change of the compressed tow bars over the
      length of all tow bars (the paper's literal definition), ``total_wrinkling_gl_bars``:
      Green-Lagrange with every bar counted once
      (:meth:`~fenicsx_drape.forming.running.post.FormedGrid.total_wrinkling_strain`);
    - ``max_tow_strain``: the largest Green-Lagrange tow strain (Fig. 12b's ~0.5 % at 800 N),
      ``mean_tow_strain_in_part``: the mean tensile strain (compressed bars count 0) of the
      bars lying on the punch (inside the base radius, above the holder plane);
    - where the deepest wrinkle sits: formed radius and height of its bar's middle
      (``wrinkle_r_mm``, ``wrinkle_z_mm``), distance from the apex on the flat sheet
      (``wrinkle_flat_mm``), whether the bar lies on the sheet's free edge
      (``wrinkle_on_edge``); ``wrinkle_centroid_r_mm``: the wrinkling-weighted mean radius;
    - where the most sheared cell lies (its centre's distance from the apex on the flat sheet,
      its formed radius);
    - the formed radius of the middle of a side and of a corner of the sheet (the holder's
      opening is at the builtin tools' ``opening_radius_mm``), the part's base radius, the
      draw-in;
    - ``stats``: steps, cut-backs, Newton iterations, wall time, penetration, travel reached.
    """
    q = grid.quadrant
    tools = builtin_tools(case)
    strains = q.tow_strains()
    row: dict[str, float] = {
        "max_shear_deg": float(np.nanmax(np.abs(grid.shear_deg()))),
        "diagonal_max_shear_deg": float(np.nanmax(np.abs(grid.diagonal_path()[1]))),
        "total_wrinkling_strain": grid.total_wrinkling_strain(),
        "total_wrinkling_engineering": grid.total_wrinkling_strain("engineering", "bars"),
        "total_wrinkling_gl_bars": grid.total_wrinkling_strain("green_lagrange", "bars"),
        "min_wrinkling_strain": float(min(min(np.nanmin(e) for e in strains), 0.0)),
        "max_tow_strain": float(max(np.nanmax(e) for e in strains)),
    }
    bars = _bars(q, strains)
    r = [np.hypot(m[..., 0], m[..., 1]) for m, _, _ in bars]
    on_punch = [(rr < tools.base_radius_mm) & (m[..., 2] > 1.0) for rr, (m, _, _) in zip(r, bars)]
    tension = np.concatenate([np.maximum(e[o], 0.0) for e, o in zip(strains, on_punch)])
    row["mean_tow_strain_in_part"] = float(np.mean(tension)) if tension.size else np.nan
    k = int(np.argmin([np.nanmin(e) for e in strains]))
    at = np.unravel_index(np.nanargmin(strains[k]), strains[k].shape)
    formed, flat, edge = bars[k]
    row["wrinkle_r_mm"] = float(r[k][at])
    row["wrinkle_z_mm"] = float(formed[at][2])
    row["wrinkle_flat_mm"] = float(np.hypot(*flat[at][:2]))
    row["wrinkle_on_edge"] = float(edge[at])
    depth = np.concatenate([np.minimum(e, 0.0).ravel() for e in strains])
    radii = np.concatenate([rr.ravel() for rr in r])
    ok = np.isfinite(depth) & (depth < 0)
    row["wrinkle_centroid_r_mm"] = (float(np.sum(depth[ok] * radii[ok]) / np.sum(depth[ok]))
                                    if ok.any() else np.nan)
    γ = np.abs(q.shear_deg())
    c = np.unravel_index(np.nanargmax(γ), γ.shape)
    centre = [0.25 * (P[c[0], c[1]] + P[c[0] + 1, c[1]] + P[c[0], c[1] + 1]
                      + P[c[0] + 1, c[1] + 1]) for P in (q.X, q.x)]
    row["max_shear_flat_mm"] = float(np.hypot(*centre[0][:2]))
    row["max_shear_r_mm"] = float(np.hypot(*centre[1][:2]))
    row["mid_side_r_mm"] = float(np.hypot(*q.x[-1, 0, :2]))
    row["corner_r_mm"] = float(np.hypot(*q.x[-1, -1, :2]))
    row["base_radius_mm"] = tools.base_radius_mm
    d = draw_in(grid)
    row["draw_in_mid_side_mm"], row["draw_in_corner_mm"] = d["mid_side_mm"], d["corner_mm"]
    row["nodes"] = float(q.present.sum())
    for name in STATS:
        row[name] = float((stats or {}).get(name, np.nan))
    return row


def _plain(value):
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in sorted(value.items())}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


# The sources that decide a forming result (their hash is the default cache tag).
_RESULT_SOURCES = ("fe", "materials", "forming/running/run.py", "forming/case", "forming/terms",
                   "forming/tools/shapes.py", "forming/tools/motion.py", "nodal.py", "model.py",
                   "effects.py", "data")


def source_tag() -> str:
    """A hash of the package sources that decide a forming result (the default cache tag)."""
    root = Path(__file__).resolve().parents[2]
    digest = hashlib.sha256()
    for name in _RESULT_SOURCES:
        path = root / name
        files = sorted(path.rglob("*")) if path.is_dir() else [path]
        for f in files:
            if f.is_file() and f.suffix in (".py", ".toml"):
                digest.update(str(f.relative_to(root)).encode())
                digest.update(f.read_bytes())
    return digest.hexdigest()[:16]


def run_key(variant: Variant, tag: str) -> str:
    """A hash of everything that decides a run's result (case, model, options, ``tag``).

    No model is the paper's model: the same key as ``default_model()`` given explicitly.
    """
    from fenicsx_drape.model import default_model

    model = variant.model if variant.model is not None else default_model()
    described = {"case": case_dict(variant.case, variant.case.folder), "tag": tag,
                 "options": _plain(variant.options) if variant.options is not None else None,
                 "model": {"effects": sorted(model.effects),
                           "parameters": _plain(model.parameters)}}
    text = json.dumps(described, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def run_variants(variants: Iterable[Variant], *, cache: str | os.PathLike | None = None,
                 tag: str | None = None, allow_incomplete: bool = True,
                 progress: Callable[[str], None] | None = print
                 ) -> tuple[list[dict], list[FormedGrid | None]]:
    """Run every variant (or read it from ``cache``); one row of :func:`metrics` each.

    Rows carry the variant's ``label``. A run that stops short of full travel gives its row
    as far as it got, with ``failed`` set to the reason (and ``travel_reached_mm``); a run
    that fails outright gives a row with ``failed`` only and no grid. ``tag`` defaults to
    :func:`source_tag`.
    """
    from mpi4py import MPI

    from fenicsx_drape.errors import SolverError

    rank0 = MPI.COMM_WORLD.rank == 0
    folder = Path(cache) if cache is not None else None
    tag = source_tag() if tag is None else tag
    rows, grids = [], []
    for variant in variants:
        key = run_key(variant, tag)
        stored = folder / f"{key}.json" if folder is not None else None
        if stored is not None and stored.exists():
            stats = json.loads(stored.read_text())
            npz = stored.with_suffix(".npz")
            grid = None
            if npz.exists():
                with np.load(npz) as data:
                    grid = FormedGrid(data["X"], data["x"], bool(data["quarter"]))
        else:
            try:
                run = run_case(variant.case, variant.model, variant.options,
                               allow_incomplete=allow_incomplete)
                grid = run.grid
                stats = {"steps": run.steps, "cutbacks": run.cutbacks,
                         "snes_iterations": run.iterations, "wall_time_s": run.wall_time_s,
                         "max_penetration_mm": run.max_penetration_mm,
                         "travel_reached_mm": run.travel_mm}
                if run.stopped:
                    stats["failed"] = run.stopped
            except SolverError as err:
                grid, stats = None, {"failed": str(err)}
            if stored is not None and rank0:
                folder.mkdir(parents=True, exist_ok=True)
                if grid is not None:
                    buf = io.BytesIO()
                    np.savez(buf, X=grid.X, x=grid.x, quarter=grid.quarter)
                    atomic_write_bytes(stored.with_suffix(".npz"), buf.getvalue())
                write_json(stored, stats)
        row = {"label": variant.label}
        if grid is not None:
            row.update(metrics(grid, variant.case, stats))
        if "failed" in stats:
            row["failed"] = stats["failed"]
        rows.append(row)
        grids.append(grid)
        if progress is not None and rank0:
            shown = {k: row[k] for k in ("max_shear_deg", "total_wrinkling_strain",
                                         "min_wrinkling_strain", "max_tow_strain") if k in row}
            progress(f"{variant.label}: " + ", ".join(f"{k} {v:.4g}" for k, v in shown.items())
                     + (f"  [failed: {row['failed']}]" if "failed" in row else ""))
    return rows, grids


def sweep(cases: Iterable[FormingCase], model=None, options=None,
          progress: Callable[[str], None] | None = print) -> tuple[list[dict], list[FormedGrid]]:
    """Run every case with the same model and options (see :func:`run_variants`)."""
    variants = [Variant(f"case {k}", c, model, options) for k, c in enumerate(cases)]
    return run_variants(variants, allow_incomplete=False, progress=progress)


def write_rows(path: str | os.PathLike, rows: Sequence[Mapping],
               first: Mapping[str, Iterable] | None = None, comment: str = "") -> Path:
    """Write a study's table as CSV: the varied columns ``first``, the label, the metrics.

    Text columns (``label``, ``failed``) are quoted; missing numbers are written as nan.
    """
    first = dict(first or {})
    varied = [list(v) for v in first.values()]
    extra = sorted({k for r in rows for k in r} - set(METRICS) - {"label", "failed"})
    names = [*first, "label", *METRICS, *extra, "failed"]
    buf = io.StringIO()
    buf.writelines(f"# {line}\n" for line in comment.splitlines())
    buf.write(",".join(names) + "\n")
    for k, row in enumerate(rows):
        values = [v[k] for v in varied] + [row.get(n, np.nan) for n in names[len(first):]]
        buf.write(",".join(_cell(v) for v in values) + "\n")
    return atomic_write_text(path, buf.getvalue())


def _cell(value) -> str:
    if isinstance(value, str):
        return '"' + value.replace('"', "'").replace("\n", " ") + '"'
    return f"{float(value):.6g}"


def _column(rows: Sequence[Mapping], key: str) -> np.ndarray:
    return np.array([float(r.get(key, np.nan)) for r in rows])


def paper_numbers(default: Mapping, durations: Mapping[float, Mapping],
                  forces: Mapping[float, Mapping], meshes: Sequence[Mapping],
                  mesh_distance_mm: Sequence[float], cells_mm: Sequence[float]) -> dict:
    """Reduce one reading's runs to the numbers the paper states (section 4).

    Args:
        default: The row of the default case (10 mm cells, 133 N, 40 s).
        durations: Rows by forming duration (s) at 133 N (Fig. 12a; :data:`DURATIONS_S`).
        forces: Rows by total holding force (N) at 40 s (Fig. 12b; :data:`FORCES_N`).
        meshes: Rows of the mesh sweep, coarse to fine (Fig. 9; :data:`MESH_CELLS_MM`).
        mesh_distance_mm: Each mesh's mean node distance from the finest (Fig. 9).
        cells_mm: The mesh sweep's cell sizes.

    Returns:
        ``max_shear_deg``, ``total_wrinkling_strain`` (and ``_engineering``),
        ``min_wrinkling_strain``, ``wrinkle_r_mm``, ``wrinkle_on_edge``, ``mid_side_r_mm``
        of the default case; Fig. 9: ``shear_plateau_nodes`` (fewest nodes from which the
        maximum shear stays within 1° of the finest model's), ``wrinkling_stable_nodes``
        (within 10 % of the finest's), ``distance_10mm_mm``; Fig. 12a: ``wrinkling_8s``,
        ``wrinkling_240s``, ``shear_span_duration_deg`` (max − min over the durations),
        ``shear_100_240s_deg`` and ``wrinkling_100_240s`` (changes from 100 to 240 s: the
        plateau); Fig. 12b: ``wrinkling_70N``, ``wrinkling_800N``, ``wrinkling_500_800N``,
        ``shear_peak_force_N`` (force of the largest maximum shear), ``shear_fall_deg``
        (peak minus the value at the largest force), ``tow_strain_800N``. A point missing
        from a sweep gives NaN.
    """
    def get(rows: Mapping[float, Mapping], x: float, key: str) -> float:
        return float(rows.get(x, {}).get(key, np.nan))

    out = {k: float(default.get(k, np.nan)) for k in
           ("max_shear_deg", "total_wrinkling_strain", "total_wrinkling_engineering",
            "min_wrinkling_strain", "wrinkle_r_mm", "wrinkle_on_edge", "mid_side_r_mm")}
    nodes = _column(meshes, "nodes")
    for key, name, tol in (("max_shear_deg", "shear_plateau_nodes", 1.0),
                           ("total_wrinkling_strain", "wrinkling_stable_nodes", None)):
        v = _column(meshes, key)
        ref = v[-1] if len(v) else np.nan
        within = np.abs(v - ref) <= (tol if tol is not None else 0.1 * abs(ref))
        # The fewest nodes from which every finer model is within the tolerance.
        first = len(v) - 1
        while first > 0 and within[first - 1]:
            first -= 1
        out[name] = float(nodes[first]) if np.isfinite(ref) else np.nan
    at10 = np.flatnonzero(np.isclose(np.asarray(cells_mm, float), 10.0))
    out["distance_10mm_mm"] = float(mesh_distance_mm[at10[0]]) if at10.size else np.nan
    shear_d = np.array([get(durations, x, "max_shear_deg") for x in sorted(durations)])
    out["wrinkling_8s"] = get(durations, 8.0, "total_wrinkling_strain")
    out["wrinkling_240s"] = get(durations, 240.0, "total_wrinkling_strain")
    out["shear_span_duration_deg"] = float(np.nanmax(shear_d) - np.nanmin(shear_d))
    out["shear_100_240s_deg"] = (get(durations, 240.0, "max_shear_deg")
                                 - get(durations, 100.0, "max_shear_deg"))
    out["wrinkling_100_240s"] = (get(durations, 240.0, "total_wrinkling_strain")
                                 - get(durations, 100.0, "total_wrinkling_strain"))
    xs = sorted(forces)
    shear_f = np.array([get(forces, x, "max_shear_deg") for x in xs])
    out["wrinkling_70N"] = get(forces, 70.0, "total_wrinkling_strain")
    out["wrinkling_800N"] = get(forces, 800.0, "total_wrinkling_strain")
    out["wrinkling_500_800N"] = (get(forces, 800.0, "total_wrinkling_strain")
                                 - get(forces, 500.0, "total_wrinkling_strain"))
    peak = int(np.nanargmax(shear_f))
    out["shear_peak_force_N"] = float(xs[peak])
    out["shear_fall_deg"] = float(shear_f[peak] - shear_f[-1])
    out["tow_strain_800N"] = get(forces, 800.0, "max_tow_strain")
    return out


def mesh_distances(grids: Sequence[FormedGrid | None]) -> list[float]:
    """Mean node distance (mm) of every formed sheet from the last (finest) one (Fig. 9)."""
    finest = grids[-1]
    return [mean_distance(g, finest) if g is not None and finest is not None else np.nan
            for g in grids]


def plot_trend(path: str | os.PathLike, x: Sequence[float],
               series: Mapping[str, Sequence[Mapping]], *, xlabel: str, title: str,
               log_x: bool = False, paper_x: Sequence[float] | None = None,
               paper_wrinkling: Sequence[float] | None = None,
               paper_shear: Sequence[float] | None = None,
               tow_strain: bool = False) -> Path:
    """Maximum shear and total wrinkling against ``x``, one line per series (Fig. 12).

    Panels: (a) the maximum shear angle, (b) the total wrinkling magnitude (%), Green-Lagrange
    (solid) and as the literal length change (dotted); with ``tow_strain`` (c) the largest tow
    strain (%). The paper's points (``paper_x``, ``paper_wrinkling`` as strains ≤ 0,
    ``paper_shear``) are black stars joined by a dotted line.
    """
    import matplotlib.pyplot as plt

    from fenicsx_drape.provenance import save_figure

    n = 3 if tow_strain else 2
    fig, ax = plt.subplots(1, n, figsize=(5.6 * n, 4.2))
    for k, (name, rows) in enumerate(series.items()):
        colour = f"C{k}"
        ax[0].plot(x, _column(rows, "max_shear_deg"), "o-", color=colour, label=name)
        ax[1].plot(x, -100 * _column(rows, "total_wrinkling_strain"), "s-", color=colour,
                   label=f"{name}, Green-Lagrange")
        ax[1].plot(x, -100 * _column(rows, "total_wrinkling_engineering"), ":",
                   color=colour, label=f"{name}, length change")
        if tow_strain:
            ax[2].plot(x, 100 * _column(rows, "max_tow_strain"), "^-", color=colour,
                       label=name)
    if paper_x is not None and paper_shear is not None:
        ax[0].plot(paper_x, paper_shear, "k*:", ms=10, label="paper's model")
    if paper_x is not None and paper_wrinkling is not None:
        ax[1].plot(paper_x, [-100 * w for w in paper_wrinkling], "k*:", ms=10,
                   label="paper's model")
    ax[0].set(ylabel="maximum shear angle (deg)")
    ax[1].set(ylabel="total wrinkling strain, magnitude (%)")
    if tow_strain:
        ax[2].set(ylabel="largest tow strain, Green-Lagrange (%)")
    for a in ax:
        a.set(xlabel=xlabel)
        if log_x:
            a.set_xscale("log")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle(title)
    return save_figure(fig, path)
