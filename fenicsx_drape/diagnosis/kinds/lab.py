"""Forming measurements as labs take them, in ``compare`` and ``diagnose`` (spec version 3).

A forming test's lab measurements (:mod:`fenicsx_drape.measurements.lab`) are tests of their
own for the errors (ids ``"<test id>/<measurement>"``), of kind ``forming``: the forming
kind (:mod:`~fenicsx_drape.diagnosis.forming_fit`) hands them here. Each is compared with
the same forming run as the test's grid (cached: one run serves all of a test's
measurements), on the whole formed blank triangulated
(:mod:`fenicsx_drape.forming.running.measure`):

- **shear_points**: the model's shear angle at the same material point: by its flat position
  (``x0_mm, y0_mm``), or for a formed position at the closest point of the formed sheet,
  bilinear within the cell; its magnitude when the test says ``shear_magnitude = true``.
  Error in degrees;
- **surface**: the signed distance (mm, along the sheet's normal) from each scanned point to
  the formed sheet (the value of a point is the model's offset from it: measured 0); the
  share of the formed sheet the scan covers is reported (:func:`~fenicsx_drape.forming.
  measure.coverage`);
- **outline**: the signed in-plane (or 3D, with ``z_mm``) distance from each edge point to
  the model's blank edge after forming (positive outside it: less draw-in than modelled),
  and, with ``draw_in_mm``, the model's draw-in at that point (each row's two values
  interleaved);
- **punch_force**: the model's force on the named tool along its motion
  (:func:`~fenicsx_drape.diagnosis.forming_runs.tool_forces`), linear in the travel between
  the run's steps, at the measured travels (a run that stopped short holds its last force).
  Error in N.

A point farther than :data:`UNMATCHED_CELLS` cells from the formed sheet (or edge, or off
the blank) is **unmatched**: its residual is 0 and it is listed (file and line) in the
measures, never silently dropped.

**Noise** (contract: its column, else its key, else a model-free estimate that is named):
shear, second differences along each measuring line (``line``, ``s_mm``), else the
differences between nearest neighbours; scan, the residual of a local plane through each
point's :data:`PLANE_NEIGHBOURS` neighbours; outline, second differences along the edge
(ordered by angle about the tool axis); force, second differences along the travel.

**Registration** (``register = true``): a rigid frame (3 rotations about the points' centre,
3 translations) is fitted to the model's sheet by Gauss-Newton on the point-to-plane
distances of the test's scan (or of its own formed points when it has no scan), for each
model run, and given with its standard deviations (σ² (JᵀJ)⁻¹); a scan that no registration
brings within reach (more than half its points unmatched, or an RMS distance above
:data:`FAR_NOISE` × noise) is reported as far from any registration.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis import forming_kind as fk
from fenicsx_drape.diagnosis.kinds import Region
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.measurements.lab import SD_COLUMN, measurement_of

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds import Comparison
    from fenicsx_drape.forming.running.measure import SheetMesh
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model

UNMATCHED_CELLS = 2.0  # a point farther than this many cells from the formed sheet: unmatched
PLANE_NEIGHBOURS = 12  # neighbours of a scanned point in its local plane (noise estimate)
FAR_NOISE = 5.0  # a registered scan with an RMS distance above this × noise is "far"
REGISTER_ITERATIONS = 20
UNITS = {"shear_points": "deg", "surface": "mm", "outline": "mm", "punch_force": "N"}


def is_lab(test: Test) -> bool:
    """Whether a test holds a lab measurement (not a grid)."""
    m = measurement_of(test)
    return m is not None and m != "file"


def unit(test: Test) -> str:
    """The unit of the compared values of a forming test (mm for a grid)."""
    return UNITS.get(measurement_of(test) or "file", "mm")


def points(test: Test) -> np.ndarray:
    """The measured formed positions (n, 3) (an outline in plan: z = 0), case frame."""
    c = test.columns
    z = c.get("z_mm", np.zeros(test.n_rows))
    return np.column_stack([c["x_mm"], c["y_mm"], z])


def _draw_in(test: Test) -> bool:
    return measurement_of(test) == "outline" and "draw_in_mm" in test.columns


def measured(test: Test) -> np.ndarray:
    """The measured values, one per row (an outline with draw-in: two, interleaved)."""
    m, c = measurement_of(test), test.columns
    if m == "shear_points":
        return np.asarray(c["shear_deg"], float)
    if m == "punch_force":
        return np.asarray(c["force_N"], float)
    n = test.n_rows
    if _draw_in(test):
        return np.column_stack([np.zeros(n), c["draw_in_mm"]]).ravel()
    return np.zeros(n)


# --------------------------------------------------------------------------------------------
# Noise


def _local_plane_noise(P: np.ndarray) -> float:
    """σ of a point cloud from the residual of each point to its neighbours' plane."""
    from scipy.spatial import cKDTree

    k = min(PLANE_NEIGHBOURS, len(P))
    if k < 5:
        raise DrapeInputError("too few scanned points to estimate their noise (give "
                              "position_sd_mm)")
    _, idx = cKDTree(P).query(P, k=k)
    Q = P[idx]
    centred = Q - Q.mean(axis=1, keepdims=True)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))
    normal = vectors[:, :, 0]
    r = np.einsum("ni,ni->n", centred[:, 0], normal)
    # The plane through k points (the point among them) leaves it (k - 3)/k of its variance.
    return float(np.median(np.abs(r)) / 0.6745 * math.sqrt(k / (k - 3)))


def _along(t: np.ndarray, y: np.ndarray) -> float:
    from fenicsx_drape.measurements.noise import noise_from_second_differences

    order = np.argsort(t, kind="stable")
    t, y = t[order], y[order]
    keep = np.concatenate([[True], np.diff(t) > 0])
    return noise_from_second_differences(t[keep], y[keep])


def model_free_noise(test: Test) -> tuple[float, str]:
    """The named model-free estimate of a lab measurement's noise (module doc)."""
    from scipy.spatial import cKDTree

    m, c = measurement_of(test), test.columns
    try:
        if m == "shear_points":
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
        if m == "surface":
            return _local_plane_noise(points(test)), "local_plane_fit"
        if m == "outline":
            P = points(test)
            angle = np.arctan2(P[:, 1], P[:, 0])
            return _along(angle, np.hypot(P[:, 0], P[:, 1])), "second_differences_along_edge"
        return _along(c["travel_mm"], c["force_N"]), "second_differences"
    except ValueError as err:
        raise DrapeInputError(f"test {test.id!r}: cannot estimate the noise of its {m} from "
                              f"the data ({err}); give {SD_COLUMN[m]} as a column or key") \
            from None


def noise(test: Test) -> tuple[float, str]:
    """The noise of a lab measurement and its source: its column, else its key, else estimate."""
    m = measurement_of(test)
    sd = test.column(SD_COLUMN[m])
    if sd is not None:
        return float(np.sqrt(np.mean(np.asarray(sd) ** 2))), SD_COLUMN[m]
    if test.lab.sd is not None:
        return float(test.lab.sd), f"{SD_COLUMN[m]} key"
    level, source = model_free_noise(test)
    if not level > 0:
        raise DrapeInputError(f"test {test.id!r}: the model-free noise estimate of its {m} is "
                              f"zero ({source}); give {SD_COLUMN[m]} as a column or key")
    return level, source


def row_sd(test: Test) -> np.ndarray:
    """Per compared value, the noise a fit weighs it with (``inf``: not fitted)."""
    sd = test.column(SD_COLUMN[measurement_of(test)])
    sd = np.full(test.n_rows, noise(test)[0]) if sd is None else np.asarray(sd, float)
    return np.repeat(sd, 2) if _draw_in(test) else sd


# --------------------------------------------------------------------------------------------
# Simulation


_meshes: dict[int, tuple[Any, Any]] = {}


def sheet_mesh(grid: FormedGrid) -> SheetMesh:
    """The whole blank's triangulation of a formed sheet (cached with the sheet)."""
    from fenicsx_drape.forming.running.measure import SheetMesh

    hit = _meshes.get(id(grid))
    if hit is None or hit[0] is not grid:
        if len(_meshes) > 64:
            _meshes.pop(next(iter(_meshes)))
        hit = _meshes[id(grid)] = (grid, SheetMesh.of(grid))
    return hit[1]


def _runs(test: Test, model: Model) -> list[tuple[Any, Model]]:
    """The (case, model) jobs of a test: one per parameter set of a vectorised model."""
    case = fk.case_of(test)
    sizes = {np.size(v) for v in model.parameters.values() if np.ndim(v) > 0}
    if not sizes:
        return [(case, model)]
    (k,) = sizes
    return [(case, model.with_parameters(**{n: float(v[i]) for n, v in model.parameters.items()
                                            if np.ndim(v) > 0})) for i in range(k)]


def _centre(test: Test) -> np.ndarray:
    case = test.forming_case
    return np.asarray(case.blank.origin_mm, float)[:2] if case is not None else np.zeros(2)


def register(mesh: SheetMesh, P: np.ndarray, noise_mm: float) -> dict[str, Any]:
    """A rigid frame bringing points (n, 3) onto the sheet: point-to-plane Gauss-Newton.

    Fitted as rotations about the points' centre and a translation there: x ↦ R (x − centre)
    + centre + t. Returns ``R``, ``centre``, ``t``, and as [test.frame] states a frame
    (x ↦ R x + translation) ``rotation_deg`` (about x, then y, then z) and
    ``translation_mm``, with the standard deviations ``sd_rotation_deg`` and
    ``sd_translation_mm`` (of the translation at the points' centre), ``rms_mm``,
    ``matched`` (share of the points within :data:`UNMATCHED_CELLS` cells after the fit),
    ``far`` and ``points``. The registration is relative to a given frame, if any.
    """
    from fenicsx_drape.forming.running.measure import closest_points
    from fenicsx_drape.measurements.lab import rotation

    centre = P.mean(axis=0)
    angles, t = np.zeros(3), np.zeros(3)
    reach = UNMATCHED_CELLS * mesh.cell_mm
    J = None
    for _ in range(REGISTER_ITERATIONS):
        R = rotation(angles)
        Q = (P - centre) @ R.T + centre + t
        near = closest_points(mesh, Q)
        use = near.distance <= max(reach, 3.0 * float(np.median(near.distance)))
        n = mesh.normals[near.triangle][use]
        r = near.signed[use]
        # d(signed)/d(small rotation ω about centre) = ((Q − centre) × n)·ω; d/dt = n.
        J = np.column_stack([np.cross(Q[use] - centre, n), n])
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        dR = rotation(np.degrees(step[:3]))
        angles = _angles(dR @ R)
        t = t + step[3:]
        if np.abs(step[:3]).max() < 1e-7 and np.abs(step[3:]).max() < 1e-5:
            break
    R = rotation(angles)
    Q = (P - centre) @ R.T + centre + t
    near = closest_points(mesh, Q)
    matched = near.distance <= reach
    use = matched if matched.sum() > 6 else np.ones(len(P), bool)
    n = mesh.normals[near.triangle][use]
    J = np.column_stack([np.cross(Q[use] - centre, n), n])
    dof = max(int(use.sum()) - 6, 1)
    s2 = float(np.sum(near.signed[use] ** 2) / dof)
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        sd = np.full(6, np.inf)
    rms = float(np.sqrt(np.mean(near.signed[matched] ** 2))) if matched.any() else math.inf
    far = bool(matched.mean() < 0.5 or rms > FAR_NOISE * noise_mm)
    # As [test.frame] states a frame: x ↦ R x + translation.
    translation = centre + t - R @ centre
    return {"R": R, "centre": centre, "t": t, "rotation_deg": angles.tolist(),
            "translation_mm": translation.tolist(),
            "sd_rotation_deg": np.degrees(sd[:3]).tolist(),
            "sd_translation_mm": sd[3:].tolist(), "rms_mm": rms,
            "matched": float(matched.mean()), "far": far, "points": len(P)}


def _angles(R: np.ndarray) -> np.ndarray:
    """Angles (deg) about x, then y, then z of R = R_z R_y R_x."""
    b = -math.asin(float(np.clip(R[2, 0], -1.0, 1.0)))
    a = math.atan2(R[2, 1], R[2, 2])
    c = math.atan2(R[1, 0], R[0, 0])
    return np.degrees([a, b, c])


def _anchor(test: Test) -> np.ndarray | None:
    """The points a test's frame is registered on: its scan, else its own formed points."""
    anchor = getattr(test.lab, "anchor", None)
    if anchor is not None:
        return anchor
    if "x_mm" in test.columns and ("z_mm" in test.columns):
        return points(test)
    return None


_matches: dict[tuple, dict[str, Any]] = {}


def _digest(test: Test) -> str:
    """What a lab test's match depends on besides the run: its rows, frame and flags."""
    import hashlib

    h = hashlib.sha1(repr((test.lab.frame, test.lab.shear_magnitude, test.lab.force_tool,
                           test.lab.flat, sorted(test.columns))).encode())
    for name in sorted(test.columns):
        h.update(np.ascontiguousarray(test.columns[name], float).tobytes())
    if test.lab.anchor is not None:
        h.update(np.ascontiguousarray(test.lab.anchor, float).tobytes())
    return h.hexdigest()


def match(test: Test, grid: FormedGrid, model: Model | None = None) -> dict[str, Any]:
    """A lab measurement against one formed sheet: the model's values and how they matched.

    Returns ``values`` (the model's values, as :func:`measured`), ``unmatched`` (mask of the
    rows), ``registration`` (or None) and, for a scan, ``coverage``. A measurement of one ply
    of a stack (``test.ply``) is matched with that ply's sheet.
    """
    grid = grid.ply(test.ply)
    key = (test.id, _digest(test), id(grid))
    hit = _matches.get(key)
    if hit is not None and hit["_grid"] is grid:
        return hit
    from fenicsx_drape.diagnosis.forming_runs import tool_forces
    from fenicsx_drape.forming.running import measure

    m, c = measurement_of(test), test.columns
    mesh = sheet_mesh(grid)
    reach = UNMATCHED_CELLS * mesh.cell_mm
    out: dict[str, Any] = {"registration": None, "_grid": grid}
    registration = None
    if test.lab.frame.register and m != "punch_force" and (A := _anchor(test)) is not None:
        registration = register(mesh, A, noise(test)[0] if m == "surface" else
                                float(test.lab.sd or 0.5))
        out["registration"] = {k: v for k, v in registration.items()
                               if k not in ("R", "centre", "t")}

    def moved(P: np.ndarray) -> np.ndarray:
        if registration is None:
            return P
        return (P - registration["centre"]) @ registration["R"].T + registration["centre"] \
            + registration["t"]

    if m == "shear_points":
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
    elif m == "surface":
        P = moved(points(test))
        near = measure.closest_points(mesh, P)
        unmatched = near.distance > reach
        values = np.where(unmatched, 0.0, -near.signed)
        out["coverage"] = measure.coverage(mesh, P[~unmatched]) if (~unmatched).any() else 0.0
    elif m == "outline":
        P = points(test)
        if "z_mm" in c:
            P = moved(P)
        else:
            P = P[:, :2]
        edge = measure.closest_on_edge(mesh, P, _centre(test))
        unmatched = edge["distance"] > reach
        values = np.where(unmatched, 0.0, -edge["signed"])
        if _draw_in(test):
            drawn = np.where(unmatched, c["draw_in_mm"], edge["draw_in"])
            values = np.column_stack([values, drawn]).ravel()
    else:
        if model is None:
            raise ValueError("a force curve is matched with the model's run")
        curves = tool_forces(*_job(test, model))
        tool = test.lab.force_tool
        if not curves:  # a run that stopped before its first step: the flat sheet, no force
            curves = {"travel_mm": np.zeros(1), tool: np.zeros(1)}
        if tool not in curves:
            known = ", ".join(k for k in curves if k not in ("time_s", "travel_mm"))
            raise DrapeInputError(f"test {test.id!r}: the model records no force of tool "
                                  f"{tool!r} (its tools: {known})")
        # A run that stopped short is compared as far as it got (its last force held), as
        # the grid compares the sheet where it stopped.
        values = np.interp(c["travel_mm"], curves["travel_mm"], curves[tool])
        unmatched = np.zeros(len(values), bool)
        out["model_curve"] = {"travel_mm": curves["travel_mm"], "force_N": curves[tool]}
    out["values"] = np.asarray(values, float)
    out["unmatched"] = np.asarray(unmatched, bool)
    if len(_matches) > 256:
        _matches.pop(next(iter(_matches)))
    _matches[key] = out
    return out


def _job(test: Test, model: Model) -> tuple[Any, Model]:
    return fk.case_of(test), model


def simulate(test: Test, model: Model) -> np.ndarray:
    """The model's values of a lab measurement, or (k, n) for a vectorised model."""
    from fenicsx_drape.diagnosis.forming_runs import form_many

    jobs = _runs(test, model)
    grids = form_many(jobs)
    values = [match(test, g, m)["values"] for g, (_, m) in zip(grids, jobs)]
    vectorised = any(np.ndim(v) > 0 for v in model.parameters.values())
    return np.array(values) if vectorised else values[0]


# --------------------------------------------------------------------------------------------
# Regions, abscissa, measures


_regions: dict[tuple, list[Region]] = {}


def regions(test: Test) -> list[Region]:
    """Named regions of a lab measurement's rows (a mask over its values).

    Shear points: each measuring line in thirds of its ``s_mm`` (positions along it), and
    the regions of the part at the formed points; scan: the regions of the part; outline:
    the edge along the tow axes and at the bias corners; force: thirds of the travel. They
    depend on the measurement alone: kept by its content.
    """
    key = (test.id, _digest(test))
    if key not in _regions:
        if len(_regions) > 64:
            _regions.pop(next(iter(_regions)))
        _regions[key] = _regions_of(test)
    return _regions[key]


def _regions_of(test: Test) -> list[Region]:
    m, c = measurement_of(test), test.columns
    n = test.n_rows
    per = 2 if _draw_in(test) else 1
    out: list[Region] = []

    def add(variable: str, values: np.ndarray, rows: np.ndarray, says: str) -> None:
        if rows.any():
            out.append(Region(variable, (float(values[rows].min()), float(values[rows].max())),
                              says, np.repeat(rows, per)))

    if m == "shear_points" and "s_mm" in c:
        names = test.lab.line_names if any(test.lab.line_names) else ("",) * n
        s = c["s_mm"]
        for name in sorted(set(names)):
            on = np.asarray(names) == name
            lo, hi = float(s[on].min()), float(s[on].max())
            cuts = np.linspace(lo, hi, 4)
            for a, b, where in zip(cuts[:-1], cuts[1:], ("start", "middle", "end")):
                rows = on & (s >= a - 1e-9) & (s <= b + 1e-9)
                add("s_mm", s, rows, f"line {name or '(unnamed)'}, {where} (s {a:.0f}-{b:.0f} mm)")
    if m == "punch_force":
        travel = c["travel_mm"]
        cuts = np.linspace(travel.min(), travel.max(), 4)
        for a, b, where in zip(cuts[:-1], cuts[1:], ("start", "middle", "end")):
            add("travel_mm", travel, (travel >= a - 1e-9) & (travel <= b + 1e-9),
                f"{where} of the travel")
        return out
    if m == "outline":
        P = points(test)[:, :2] - _centre(test)
        angle = np.degrees(np.arctan2(np.abs(P[:, 1]), np.abs(P[:, 0])))
        off_axis = np.minimum(angle, 90.0 - angle)
        add("direction_deg", off_axis, off_axis < 22.5, "edge along the tow axes")
        add("direction_deg", off_axis, off_axis >= 22.5, "edge at the bias corners")
        return out
    formed = "x_mm" in c and "z_mm" in c
    if formed and fk.names_case(test):
        which, names = part_region_of_points(test, points(test))
        height = points(test)[:, 2]
        for k, name in enumerate(names):
            add("height_mm", height, which == k, name)
    elif not out:
        add("row", np.arange(n, dtype=float), np.ones(n, bool), "all points")
    return out


def part_region_of_points(test: Test, x: np.ndarray) -> tuple[np.ndarray, Sequence[str]]:
    """The case's named region of formed points (n, 3), as for the grid's nodes.

    Indices into :data:`~fenicsx_drape.diagnosis.forming_kind.CASE_REGION_NAMES`.
    """
    rel = x[:, :2] - _centre(test)
    θ = math.radians(test.forming_case.blank.ply_angle_deg)
    u = rel[:, 0] * math.cos(θ) + rel[:, 1] * math.sin(θ)
    v = -rel[:, 0] * math.sin(θ) + rel[:, 1] * math.cos(θ)
    angle = np.degrees(np.arctan2(np.abs(v), np.abs(u)))
    direction = np.minimum(angle, 90.0 - angle)
    return fk.region_of_points(test, x, direction, noise(test)[0] if unit(test) == "mm"
                               else 0.0), fk.CASE_REGION_NAMES


def abscissa(test: Test) -> tuple[str, np.ndarray]:
    """What a lab measurement's rows are plotted against."""
    m, c = measurement_of(test), test.columns
    per = 2 if _draw_in(test) else 1
    if m == "punch_force":
        return "travel_mm", c["travel_mm"]
    if m == "shear_points" and "s_mm" in c:
        return "s_mm", c["s_mm"]
    if m == "outline":
        P = points(test)[:, :2] - _centre(test)
        return "angle_deg", np.repeat(np.degrees(np.arctan2(P[:, 1], P[:, 0])), per)
    if "z_mm" in c:
        return "z_mm", c["z_mm"]
    return "row", np.arange(test.n_rows, dtype=float)


def metrics(test: Test, simulated: np.ndarray, model: Model | None = None) -> dict[str, Any]:
    """A lab measurement's own measures: unmatched rows (file lines), coverage, registration."""
    from fenicsx_drape.diagnosis.forming_runs import form_many

    out: dict[str, Any] = {"measurement": measurement_of(test), "file": test.file}
    if model is None:
        return out
    job = _runs(test, model)[0]
    result = match(test, form_many([job])[0], job[1])
    rows = np.flatnonzero(result["unmatched"])
    out["unmatched"] = int(rows.size)
    out["unmatched_lines"] = [int(test.lab.lines[k]) for k in rows[:20]]
    if measurement_of(test) == "surface" and not test.lab.lines.any():
        out["unmatched_points"] = [int(k) for k in rows[:20]]
    if "coverage" in result:
        out["coverage"] = result["coverage"]
    if result["registration"] is not None:
        reg = result["registration"]
        out["registration"] = reg
        if reg["far"]:
            out["says"] = (f"the {measurement_of(test)} lies far from any registration: "
                           f"{100 * reg['matched']:.0f} % of its points within "
                           f"{UNMATCHED_CELLS:g} cells, RMS {reg['rms_mm']:.3g} mm after the "
                           "fit (another part, or a frame too far off to start from?)")
    return out


# --------------------------------------------------------------------------------------------
# Pictures


def plot(comparisons: Mapping[str, Comparison], test: Test, path: Path,
         shares: Sequence[Mapping[str, Any]] = ()) -> Path:
    """The picture of a lab measurement, by measurement (module doc).

    Shear points: measured against model shear along each measuring line; scan: its
    deviation map on the part (plan view); outline: the measured edge over the model's;
    force: the two force curves.
    """
    import matplotlib.pyplot as plt

    from fenicsx_drape.provenance import save_figure

    m = measurement_of(test)
    first = next(iter(comparisons.values()))
    title = (f"{test.id}: " + ", ".join(f"{label} {c.rmse:.3g} {c.unit} = "
                                        f"{c.normalised:.2f} × noise"
                                        for label, c in comparisons.items()))
    if m == "shear_points":
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
    elif m == "surface":
        P = points(test)
        n = len(comparisons)
        fig, axes = plt.subplots(1, n, figsize=(5.2 * n, 4.4), squeeze=False)
        top = max(float(np.abs(c.residual).max()) for c in comparisons.values()) or 1.0
        for ax, (label, c) in zip(axes[0], comparisons.items()):
            art = ax.scatter(P[:, 0], P[:, 1], c=c.residual, s=2, cmap="coolwarm", vmin=-top,
                             vmax=top)
            ax.set_aspect("equal")
            ax.set_title(f"{label}: scan − model sheet (mm)", fontsize=8)
            ax.set_xlabel("x (mm)")
            fig.colorbar(art, ax=ax, shrink=0.8)
        axes[0, 0].set_ylabel("y (mm)")
    elif m == "outline":
        from fenicsx_drape.forming.running.measure import edge_segments

        fig, ax = plt.subplots(figsize=(6.5, 5.5))
        P = points(test)
        ax.plot(P[:, 0], P[:, 1], ".", ms=4, color="0.2", label="measured edge")
        for i, (label, comparison) in enumerate(comparisons.items()):
            hit = _matched(test, comparison)
            if hit is None:
                continue
            mesh = sheet_mesh(hit["_grid"])
            e, _ = edge_segments(mesh)
            seg = mesh.x[e][:, :, :2]
            for k, s in enumerate(seg):
                ax.plot(s[:, 0], s[:, 1], "-", color=f"C{i}", lw=1,
                        label=f"model ({label})" if k == 0 else None)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.legend(fontsize=7)
    else:
        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        c = test.columns
        ax.plot(c["travel_mm"], c["force_N"], ".", ms=3, color="0.3", label="measured")
        for i, (label, comparison) in enumerate(comparisons.items()):
            hit = _matched(test, comparison)
            curve = hit["model_curve"] if hit is not None else {
                "travel_mm": c["travel_mm"], "force_N": comparison.simulated}
            ax.plot(curve["travel_mm"], curve["force_N"], "-", color=f"C{i}",
                    label=f"model ({label})")
        ax.set_xlabel("travel (mm)")
        ax.set_ylabel(f"force of the {test.lab.force_tool} (N)")
        ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=8)
    return save_figure(fig, path)


def _matched(test: Test, comparison: Comparison) -> dict[str, Any] | None:
    """The match (:func:`match`) whose model values a comparison holds, if still cached."""
    for (test_id, _, _), hit in reversed(list(_matches.items())):
        if test_id == test.id and np.array_equal(hit["values"], comparison.simulated):
            return hit
    return None


