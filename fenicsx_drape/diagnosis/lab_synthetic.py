"""Lab-style measurements "taken" on a simulated part: for demos, tests and benchmarks.

:func:`lab_tables` reads, from one forming run, what a lab would bring after a trial
(spec version 3): shear angles along measuring lines (``line``, ``s_mm``; formed positions),
a scan of the formed ply (a point cloud, optionally with holes, of part of the part, or in
another frame), points of the blank's edge after forming, and the punch's force against its
travel, each with noise as a lab would have it. :func:`write_lab_bundle` writes them with a
copy of the case as a bundle. The noise levels are declared as the test's keys.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fenicsx_drape.provenance import atomic_write_text, toml_text

SHEAR_SD_DEG = 1.0  # a protractor or fibre-angle sensor
SCAN_SD_MM = 0.15  # a structured-light scanner
EDGE_SD_MM = 0.3  # an edge read from a photograph
FORCE_SD_REL = 0.02  # of the peak force


def _table(columns: Mapping[str, Sequence], comment: str = "") -> str:
    names = list(columns)
    out = [f"# {line}" for line in comment.splitlines()]
    out.append(",".join(names))
    n = len(next(iter(columns.values())))
    for k in range(n):
        out.append(",".join(str(columns[c][k]) if isinstance(columns[c][k], str)
                            else f"{float(columns[c][k]):.6g}" for c in names))
    return "\n".join(out) + "\n"


def lab_tables(grid, curves: Mapping[str, np.ndarray], *, seed: int = 0,
               lines: Mapping[str, tuple[Sequence[float], Sequence[float]]] | None = None,
               points_per_line: int = 40, scan_points: int = 3000,
               holes: Sequence[tuple[float, float, float]] = (), scan_where=None,
               edge_points: int = 100, force_tool: str = "punch",
               frame: tuple[np.ndarray, np.ndarray] | None = None,
               magnitude: bool = False) -> dict[str, dict[str, Any]]:
    """Measurements of a formed sheet with lab-like noise (module doc).

    Args:
        grid: The formed sheet (:class:`~fenicsx_drape.forming.running.post.FormedGrid`, any part).
        curves: The run's tool forces (``travel_mm`` and ``force_tool``).
        seed: Of the noise.
        lines: Measuring lines by name: (start, end) on the flat blank (mm); default two,
            along the warp axis and along a bias diagonal.
        points_per_line: Shear points per line.
        scan_points: Points of the scan (before holes and clipping).
        holes: Circles (x, y, radius in mm, formed plan) left out of the scan.
        scan_where: A mask function of the formed points (n, 3) -> bool: the scanned part.
        edge_points: Points of the outline.
        force_tool: The tool whose force is measured.
        frame: (R, t) of the measuring frame: the scan's points are written as R⁻¹ (x − t),
            so that the frame [test.frame] R, t brings them back.
        magnitude: Shear points as magnitudes.

    Returns:
        The columns of each measurement, by name: ``shear_points``, ``surface``,
        ``outline`` and ``punch_force``.
    """
    from fenicsx_drape.forming.running import measure

    rng = np.random.default_rng(seed)
    g = grid.full()
    mesh = measure.SheetMesh.of(g)
    hi = np.nanmax(g.X[..., :2], axis=(0, 1))
    if lines is None:
        lines = {"A": ((0.0, 0.0), (0.9 * hi[0], 0.0)),
                 "B": ((0.0, 0.0), (0.9 * hi[1], 0.9 * hi[1]))}
    shear: dict[str, list] = {k: [] for k in ("x_mm", "y_mm", "z_mm", "shear_deg", "line",
                                              "s_mm")}
    for name, (a, b) in lines.items():
        s = np.linspace(0.0, 1.0, points_per_line)
        flat = np.asarray(a) + s[:, None] * (np.asarray(b) - np.asarray(a))
        x = g.sample(flat, outside="nan")  # a turned net's lattice may end before the line
        γ = measure.shear_at_flat(g, flat)
        ok = np.isfinite(γ) & np.isfinite(x[:, 0])
        γ = γ[ok] + rng.normal(0.0, SHEAR_SD_DEG, ok.sum())
        shear["x_mm"] += list(x[ok, 0] + rng.normal(0, 0.2, ok.sum()))
        shear["y_mm"] += list(x[ok, 1] + rng.normal(0, 0.2, ok.sum()))
        shear["z_mm"] += list(x[ok, 2] + rng.normal(0, 0.2, ok.sum()))
        shear["shear_deg"] += list(np.abs(γ) if magnitude else γ)
        shear["line"] += [name] * int(ok.sum())
        shear["s_mm"] += list(s[ok] * np.linalg.norm(np.asarray(b) - np.asarray(a)))
    # The scan: random points of the formed sheet (area-weighted on its triangles), plus
    # noise along its normal.
    areas = mesh.areas
    pick = rng.choice(len(areas), size=scan_points, p=areas / areas.sum())
    a, b = rng.uniform(0.0, 1.0, (2, scan_points))
    flip = a + b > 1.0
    a, b = np.where(flip, 1.0 - a, a), np.where(flip, 1.0 - b, b)
    corners = mesh.x[mesh.triangles[pick]]
    x = corners[:, 0] + a[:, None] * (corners[:, 1] - corners[:, 0]) \
        + b[:, None] * (corners[:, 2] - corners[:, 0])
    keep = np.ones(len(x), bool)
    for cx, cy, r in holes:
        keep &= np.hypot(x[:, 0] - cx, x[:, 1] - cy) > r
    if scan_where is not None:
        keep &= np.where(keep, scan_where(np.nan_to_num(x)), False)
    x = x[keep]
    near = measure.closest_points(mesh, x)
    x = x + rng.normal(0.0, SCAN_SD_MM, len(x))[:, None] * mesh.normals[near.triangle]
    if frame is not None:
        R, t = frame
        x = (x - t) @ R  # R⁻¹ (x − t), as rows
    scan = {"x_mm": x[:, 0], "y_mm": x[:, 1], "z_mm": x[:, 2]}
    # The outline: points along the formed edge, with in-plane noise.
    e, _ = measure.edge_segments(mesh)
    seg = mesh.x[e]
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    pick = rng.choice(len(e), size=edge_points, p=length / length.sum())
    u = rng.uniform(0.0, 1.0, edge_points)[:, None]
    p = seg[pick, 0] + u * (seg[pick, 1] - seg[pick, 0])
    p[:, :2] += rng.normal(0.0, EDGE_SD_MM, (edge_points, 2))
    order = np.argsort(np.arctan2(p[:, 1], p[:, 0]))
    outline = {"x_mm": p[order, 0], "y_mm": p[order, 1],
               "position_sd_mm": np.full(edge_points, EDGE_SD_MM)}
    # The force curve: the model's, at every step, with noise of 2 % of the peak.
    f = np.asarray(curves[force_tool], float)
    travel = np.asarray(curves["travel_mm"], float)
    sd = FORCE_SD_REL * float(np.abs(f).max())
    force = {"travel_mm": travel, "force_N": f + rng.normal(0.0, sd, f.size)}
    return {"shear_points": shear, "surface": scan, "outline": outline, "punch_force": force,
            "_noise": {"shear_sd_deg": SHEAR_SD_DEG, "position_sd_mm": SCAN_SD_MM,
                       "force_sd_N": sd, "edge_sd_mm": EDGE_SD_MM}}


def write_lab_bundle(folder: str | Path, case, tables: Mapping[str, Mapping[str, Any]], *,
                     name: str = "lab", test_id: str = "part", keys: Mapping[str, Any] = (),
                     frame: Mapping[str, Any] | None = None, comment: str = "",
                     measurements: Sequence[str] | None = None) -> Path:
    """Write lab tables as a bundle with a copy of the case (``case/case.toml``).

    ``measurements`` picks some of the tables (default all); ``keys`` are added to the test
    (process overrides, ``shear_magnitude``, noise keys); ``frame`` is its [test.frame].
    """
    from fenicsx_drape.forming.case import write_case

    folder = Path(folder)
    write_case(case, folder / "case", comment=comment)
    chosen = [m for m in (measurements or ("shear_points", "surface", "outline",
                                           "punch_force")) if m in tables]
    test: dict[str, Any] = {"id": test_id, "kind": "forming", "case": "case/case.toml"}
    files = {"shear_points": "shear.csv", "surface": "scan.csv", "outline": "edge.csv",
             "punch_force": "force.csv"}
    for m in chosen:
        atomic_write_text(folder / files[m], _table(tables[m], comment))
        test[m] = files[m]
    noise = tables.get("_noise", {})
    if "shear_points" in chosen:
        test["shear_sd_deg"] = noise.get("shear_sd_deg", SHEAR_SD_DEG)
    if "surface" in chosen:
        test["position_sd_mm"] = noise.get("position_sd_mm", SCAN_SD_MM)
    if "punch_force" in chosen:
        test["force_sd_N"] = float(noise.get("force_sd_N", 1.0))
    test.update(keys)
    if frame:
        test["frame"] = {k: v if isinstance(v, bool) else [float(a) for a in v]
                         for k, v in frame.items()}
    atomic_write_text(folder / "bundle.toml",
                      toml_text({"bundle": {"name": name}, "test": [test]}, comment=comment))
    return folder
