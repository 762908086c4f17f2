"""What the lab kinds share: a forming test's lab measurements (spec version 3).

A forming test's lab measurements (:mod:`fenicsx_drape.measurements.lab`) are tests of their
own for the errors (ids ``"<test id>/<measurement>"``), of bundle kind ``forming``, each of
its kind: :mod:`~fenicsx_drape.diagnosis.kinds.shear_points`,
:mod:`~fenicsx_drape.diagnosis.kinds.surface`, :mod:`~fenicsx_drape.diagnosis.kinds.outline`,
:mod:`~fenicsx_drape.diagnosis.kinds.punch_force`, a :class:`LabKind` each. Each is compared
with the same forming run as the test's grid (cached: one run serves all of a test's
measurements), on the whole formed blank triangulated
(:mod:`fenicsx_drape.forming.running.measure`): :func:`match` reads the model's values off
the sheet with the kind's own reading.

A point farther than :data:`UNMATCHED_CELLS` cells from the formed sheet (or edge, or off
the blank) is **unmatched**: its residual is 0 and it is listed (file and line) in the
measures, never silently dropped.

**Noise** (contract): its column, else its key, else the kind's model-free estimate, named
(:meth:`LabKind.noise`).

**Registration** (``register = true``): a rigid frame (3 rotations about the points' centre,
3 translations) is fitted to the model's sheet by Gauss-Newton on the point-to-plane
distances of the test's scan (or of its own formed points when it has no scan), for each
model run, and given with its standard deviations (σ² (JᵀJ)⁻¹); a scan that no registration
brings within reach (more than half its points unmatched, or an RMS distance above
:data:`FAR_NOISE` × noise) is reported as far from any registration.

Like every forming kind, they share the fit of the friction coefficients
(:func:`~fenicsx_drape.diagnosis.kinds.forming.fit_forming`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds.base import FitHook, Region
from fenicsx_drape.diagnosis.kinds.forming import (
    case_of,
    fit_friction,
    names_case,
    parameter_sets,
)
from fenicsx_drape.diagnosis.kinds.part import CASE_REGION_NAMES, region_of_points
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.measurements.lab import SD_COLUMN, measurement_of
from fenicsx_drape.runs import form_many, memo

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds.base import Comparison
    from fenicsx_drape.forming.case import FormingCase
    from fenicsx_drape.forming.running.measure import SheetMesh
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model

UNMATCHED_CELLS = 2.0  # a point farther than this many cells from the formed sheet: unmatched
FAR_NOISE = 5.0  # a registered scan with an RMS distance above this × noise is "far"
REGISTER_ITERATIONS = 20


def points(test: Test) -> np.ndarray:
    """The measured formed positions (n, 3) (an outline in plan: z = 0), case frame."""
    c = test.columns
    z = c.get("z_mm", np.zeros(test.n_rows))
    return np.column_stack([c["x_mm"], c["y_mm"], z])


def _along(t: np.ndarray, y: np.ndarray) -> float:
    from fenicsx_drape.measurements.noise import noise_from_second_differences

    order = np.argsort(t, kind="stable")
    t, y = t[order], y[order]
    keep = np.concatenate([[True], np.diff(t) > 0])
    return noise_from_second_differences(t[keep], y[keep])


def sheet_mesh(grid: FormedGrid) -> SheetMesh:
    """The whole blank's triangulation of a formed sheet (kept with the command's runs)."""
    from fenicsx_drape.forming.running.measure import SheetMesh

    meshes = memo("lab.sheet_mesh", 64)
    hit = meshes.get(id(grid))
    if hit is None or hit[0] is not grid:  # the sheet itself kept: its id is not reused
        hit = meshes.put(id(grid), (grid, SheetMesh.of(grid)))
    return hit[1]



def jobs(test: Test, model: Model) -> list[tuple[FormingCase, Model]]:
    """The (case, model) jobs of a test: one per parameter set of a vectorised model."""
    case = case_of(test)
    sets = parameter_sets(model)
    return [(case, model)] if sets is None else [(case, m) for m in sets]


def blank_centre(test: Test) -> np.ndarray:
    """The blank's origin in plan (mm): the tool axis the edge and directions are seen from."""
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



@dataclasses.dataclass(frozen=True)
class Match:
    """A lab measurement against one formed sheet: the model's values and how they matched."""

    values: np.ndarray  # the model's values, as the kind's ``measured``
    unmatched: np.ndarray  # mask of the rows farther than UNMATCHED_CELLS cells (residual 0)
    registration: dict[str, Any] | None = None  # the fitted frame (``register``), else None
    grid: FormedGrid | None = None  # the sheet matched (its ply's)
    coverage: float | None = None  # a scan: the share of the formed sheet it covers
    model_curve: dict[str, np.ndarray] | None = None  # a force curve: the run's whole curve


def match(kind: LabKind, test: Test, grid: FormedGrid, model: Model | None = None) -> Match:
    """A lab measurement against one formed sheet, with the kind's own reading (module doc).

    A measurement of one ply of a stack (``test.ply``) is matched with that ply's sheet; a
    registered one (``register = true``, kinds that take a frame) after fitting its frame.
    Kept by the test's content and the sheet.
    """
    grid = grid.ply(test.ply)
    matches = memo("lab.match", 256)
    key = (test.id, _digest(test), id(grid))
    hit = matches.get(key)
    if hit is not None and hit.grid is grid:
        return hit
    mesh = sheet_mesh(grid)
    registration = None
    if test.lab.frame.register and kind.registers and (A := _anchor(test)) is not None:
        registration = register(mesh, A, kind.registration_noise(test))

    def moved(P: np.ndarray) -> np.ndarray:
        if registration is None:
            return P
        return (P - registration["centre"]) @ registration["R"].T + registration["centre"] \
            + registration["t"]

    read = kind.read(test, grid, mesh, moved, UNMATCHED_CELLS * mesh.cell_mm, model)
    out = dataclasses.replace(
        read, values=np.asarray(read.values, float), unmatched=np.asarray(read.unmatched, bool),
        grid=grid, registration=None if registration is None else {
            k: v for k, v in registration.items() if k not in ("R", "centre", "t")})
    return matches.put(key, out)


def matched(test: Test, comparison: Comparison) -> Match | None:
    """The match whose model values a comparison holds, if still kept (:func:`match`)."""
    for (test_id, _, _), hit in memo("lab.match", 256).newest_first():
        if test_id == test.id and np.array_equal(hit.values, comparison.simulated):
            return hit
    return None


# --------------------------------------------------------------------------------------------
# Regions


def part_region_of_points(test: Test, x: np.ndarray, noise_mm: float
                          ) -> tuple[np.ndarray, Sequence[str]]:
    """The case's named region of formed points (n, 3), as for the grid's nodes.

    Indices into :data:`~fenicsx_drape.diagnosis.kinds.part.CASE_REGION_NAMES`;
    ``noise_mm``: the points' position noise (0 for values that are not positions).
    """
    rel = x[:, :2] - blank_centre(test)
    θ = math.radians(test.forming_case.blank.ply_angle_deg)
    u = rel[:, 0] * math.cos(θ) + rel[:, 1] * math.sin(θ)
    v = -rel[:, 0] * math.sin(θ) + rel[:, 1] * math.cos(θ)
    angle = np.degrees(np.arctan2(np.abs(v), np.abs(u)))
    direction = np.minimum(angle, 90.0 - angle)
    return region_of_points(test, x, direction, noise_mm), CASE_REGION_NAMES


def add_region(out: list[Region], variable: str, values: np.ndarray, rows: np.ndarray,
               says: str, per: int = 1) -> None:
    """Append a region of the rows ``rows`` (a mask) when it has any (``per`` values a row)."""
    if rows.any():
        out.append(Region(variable, (float(values[rows].min()), float(values[rows].max())),
                          says, np.repeat(rows, per)))


def part_or_all(test: Test, out: list[Region], noise_mm: Callable[[], float]) -> list[Region]:
    """The regions of the part at formed points (a case's test), else "all points".

    "All points" only when ``out`` has no region yet; ``noise_mm`` gives the points'
    position noise (0 when the values are not positions).
    """
    c, n = test.columns, test.n_rows
    formed = "x_mm" in c and "z_mm" in c
    if formed and names_case(test):
        which, names = part_region_of_points(test, points(test), noise_mm())
        height = points(test)[:, 2]
        for k, name in enumerate(names):
            add_region(out, "height_mm", height, which == k, name)
    elif not out:
        add_region(out, "row", np.arange(n, dtype=float), np.ones(n, bool), "all points")
    return out


def formed_abscissa(test: Test) -> tuple[str, np.ndarray]:
    """Formed points plotted against their height, else their row."""
    if "z_mm" in test.columns:
        return "z_mm", test.columns["z_mm"]
    return "row", np.arange(test.n_rows, dtype=float)


# --------------------------------------------------------------------------------------------
# The kinds


def one(test: Test) -> int:
    """One compared value per row."""
    return 1


def declared_sd(test: Test) -> float:
    """A registration's point noise (mm): the test's noise key, else 0.5 mm."""
    return float(test.lab.sd or 0.5)


@dataclasses.dataclass(frozen=True)
class LabKind:
    """A lab measurement kind (:class:`~fenicsx_drape.diagnosis.kinds.base.FormedKind`).

    The fields are the kind's own functions (its module's); what every lab kind does alike
    (the noise rule, the runs, the cache of matches and regions, the measures) is here.
    """

    name: str  # the measurement: "shear_points", "surface", "outline", "punch_force"
    units: str  # of the compared values
    values: Callable[[Test], np.ndarray]  # the measured values (``measured``)
    # the model-free noise estimate and its source (raises ValueError when it cannot)
    model_free_noise: Callable[[Test], tuple[float, str]]
    # the model's values on one formed sheet: (test, grid, its mesh, the registration's
    # motion of points, the reach of a match in mm, the model) -> Match (values, unmatched)
    read: Callable[..., Match]
    named_regions: Callable[[Test], list[Region]]  # the kind's regions of the rows
    abscissa: Callable[[Test], tuple[str, np.ndarray]]
    # the picture's panels: (comparisons, test) -> the figure (the title is added here)
    draw: Callable[[Mapping[str, Comparison], Test], Any]
    check: Callable[[Test, FormingCase], tuple[bool, str] | None]  # the data check
    per_row: Callable[[Test], int] = one  # compared values per row (an edge with draw-in: 2)
    registers: bool = True  # its frame can be registered (``register = true``)
    # the noise (mm) of the points a registration fits
    registration_noise: Callable[[Test], float] = declared_sd
    lists_points: bool = False  # unmatched rows named by index when the file has no lines
    test_kind: str = "forming"  # the bundle's kind of its tests
    formed: bool = True
    mirrorable: bool = False  # a lab measurement is not read from a mirrored run
    fit: FitHook = fit_friction  # the friction coefficients, shared by the forming kinds

    def holds(self, test: Test) -> bool:
        """Whether ``test`` holds this lab measurement."""
        return test.kind == "forming" and measurement_of(test) == self.name

    def unit(self, test: Test) -> str:
        """The unit of the compared values."""
        return self.units

    def measured(self, test: Test) -> np.ndarray:
        """The measured values (the kind's ``values``)."""
        return self.values(test)

    def sd_column(self, test: Test) -> str:
        """The column of each row's sd (:data:`~fenicsx_drape.measurements.lab.SD_COLUMN`)."""
        return SD_COLUMN[self.name]

    def noise(self, test: Test) -> tuple[float, str]:
        """The noise and its source: its column, else its key, else the model-free estimate."""
        column = self.sd_column(test)
        sd = test.column(column)
        if sd is not None:
            return float(np.sqrt(np.mean(np.asarray(sd) ** 2))), column
        if test.lab.sd is not None:
            return float(test.lab.sd), f"{column} key"
        try:
            level, source = self.model_free_noise(test)
        except ValueError as err:
            raise DrapeInputError(f"test {test.id!r}: cannot estimate the noise of its "
                                  f"{self.name} from the data ({err}); give {column} as a "
                                  "column or key") from None
        if not level > 0:
            raise DrapeInputError(f"test {test.id!r}: the model-free noise estimate of its "
                                  f"{self.name} is zero ({source}); give {column} as a column "
                                  "or key")
        return level, source

    def value_sd(self, test: Test) -> np.ndarray:
        """Per compared value, the noise a fit weighs it with (``inf``: not fitted)."""
        sd = test.column(self.sd_column(test))
        sd = np.full(test.n_rows, self.noise(test)[0]) if sd is None else np.asarray(sd, float)
        per = self.per_row(test)
        return np.repeat(sd, per) if per > 1 else sd

    def simulate(self, test: Test, model: Model) -> np.ndarray:
        """The model's values, or (k, n) for a vectorised model."""
        runs = jobs(test, model)
        grids = form_many(runs)
        values = [match(self, test, g, m).values for g, (_, m) in zip(grids, runs)]
        vectorised = any(np.ndim(v) > 0 for v in model.parameters.values())
        return np.array(values) if vectorised else values[0]

    def on_sheet(self, test: Test, sheet: FormedGrid, model: Model,
                 plane: str | None = None) -> np.ndarray:
        """The model's values on one formed sheet (a lab measurement is not read mirrored)."""
        if plane is not None:
            raise ValueError(f"test {test.id!r}: a lab measurement is not read mirrored")
        return np.asarray(match(self, test, sheet, model).values, float)

    def regions(self, test: Test) -> list[Region]:
        """The kind's named regions of the rows (a mask over its values), kept by content."""
        regions, key = memo("lab.regions", 64), (test.id, _digest(test))
        hit = regions.get(key)
        return hit if hit is not None else regions.put(key, self.named_regions(test))

    def metrics(self, test: Test, simulated: np.ndarray, model: Model | None = None
                ) -> dict[str, Any]:
        """The measures: unmatched rows (file lines), coverage, registration."""
        out: dict[str, Any] = {"measurement": self.name, "file": test.file}
        if model is None:
            return out
        job = jobs(test, model)[0]
        result = match(self, test, form_many([job])[0], job[1])
        rows = np.flatnonzero(result.unmatched)
        out["unmatched"] = int(rows.size)
        out["unmatched_lines"] = [int(test.lab.lines[k]) for k in rows[:20]]
        if self.lists_points and not test.lab.lines.any():
            out["unmatched_points"] = [int(k) for k in rows[:20]]
        if result.coverage is not None:
            out["coverage"] = result.coverage
        if result.registration is not None:
            reg = result.registration
            out["registration"] = reg
            if reg["far"]:
                out["says"] = (f"the {self.name} lies far from any registration: "
                               f"{100 * reg['matched']:.0f} % of its points within "
                               f"{UNMATCHED_CELLS:g} cells, RMS {reg['rms_mm']:.3g} mm after "
                               "the fit (another part, or a frame too far off to start from?)")
        return out

    def plot(self, comparisons: Mapping[str, Comparison], test: Test, path: Path,
             shares: Sequence[Mapping[str, Any]] = ()) -> Path:
        """The kind's picture (its ``draw``), titled with each model's error."""
        from fenicsx_drape.provenance import save_figure

        title = (f"{test.id}: " + ", ".join(f"{label} {c.rmse:.3g} {c.unit} = "
                                            f"{c.normalised:.2f} × noise"
                                            for label, c in comparisons.items()))
        fig = self.draw(comparisons, test)
        fig.suptitle(title, fontsize=8)
        return save_figure(fig, path)
