"""Forming measurements as labs take them (spec version 3): shear points, scans, outlines, force.

A forming test may carry, besides (or instead of) the tracked grid ``file``, any of

- ``shear_points``: a CSV of shear angles at points of the formed part (``x_mm, y_mm, z_mm,
  shear_deg``) or of the flat blank (``x0_mm, y0_mm, shear_deg``), optionally with
  ``shear_sd_deg``, ``label``, ``line`` (a named measuring line) and ``s_mm`` (the distance
  along it);
- ``surface``: the formed ply's scan, a triangulated surface (``.stl``, ``.ply``, ``.obj``,
  read with meshio) or a CSV point cloud (``x_mm, y_mm, z_mm``);
- ``outline``: a CSV of points of the blank's edge after forming (``x_mm, y_mm``, optional
  ``z_mm``, ``label``, ``draw_in_mm``, ``position_sd_mm``);
- ``punch_force``: a CSV of a tool's force against its travel (``travel_mm, force_N``,
  optional ``time_s``, ``force_sd_N``), the tool named by ``force_tool`` (default "punch").

:func:`split_test` turns such a test into one :class:`~fenicsx_drape.measurements.bundle.Test`
per measurement (ids ``"<test id>/<measurement>"``; a test holding only its grid keeps its
id), each carrying its :class:`LabData` (file lines of the rows, labels, the surface's
triangles, the frame). Positions are moved into the case's frame by ``[test.frame]`` when
loaded; ``register = true`` asks compare and diagnose to fit the rigid frame as well.

Every problem is reported as ``file:line: problem`` (exit status 2): a forming test without
any measurement file, a file of the wrong kind (missing columns, unknown extension, a table
where a surface was expected), NaN or infinite cells, a shear beyond ±90°, a position
farther from the tools than the blank's size, a non-positive standard deviation (the plain
checks are :mod:`~fenicsx_drape.measurements.plausible`'s, shared with the grid).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fenicsx_drape.errors import likely_typo
from fenicsx_drape.measurements import plausible
from fenicsx_drape.measurements.tables import ragged_hint, read_rows

MEASUREMENTS = ("shear_points", "surface", "outline", "punch_force")
# Keys of a forming [[test]] table that describe its lab measurements (not case overrides).
# Version 4: the ply of a stack each measurement was taken on (1 = the punch side).
PLY_KEYS = {f"{m}_ply": m for m in ("file", "shear_points", "surface", "outline")}
LAB_KEYS = (*MEASUREMENTS, "shear_sd_deg", "position_sd_mm", "force_sd_N", "shear_magnitude",
            "force_tool", "frame", *PLY_KEYS)
MESH_SUFFIXES = (".stl", ".ply", ".obj")
TEXT_COLUMNS = ("label", "line")

# Required and optional numeric columns of each CSV measurement (alternatives: any one set).
COLUMNS: dict[str, tuple[tuple[tuple[str, ...], ...], tuple[str, ...]]] = {
    "shear_points": ((("x_mm", "y_mm", "z_mm", "shear_deg"), ("x0_mm", "y0_mm", "shear_deg")),
                     ("shear_sd_deg", "s_mm")),
    "surface": ((("x_mm", "y_mm", "z_mm"),), ()),
    "outline": ((("x_mm", "y_mm"),), ("z_mm", "draw_in_mm", "position_sd_mm")),
    "punch_force": ((("travel_mm", "force_N"),), ("time_s", "force_sd_N")),
}
SD_COLUMN = {"shear_points": "shear_sd_deg", "surface": "position_sd_mm",
             "outline": "position_sd_mm", "punch_force": "force_sd_N"}
SD_KEY = {"shear_points": "shear_sd_deg", "surface": "position_sd_mm",
          "outline": "position_sd_mm", "punch_force": "force_sd_N"}


@dataclasses.dataclass(frozen=True)
class Frame:
    """Where the measuring frame sits in the case's frame: x_case = R x + t.

    R turns about x, then y, then z (R = R_z R_y R_x) by ``rotation_deg``.
    """

    translation_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    register: bool = False  # fit the rigid frame to the model (compare, diagnose)

    @property
    def matrix(self) -> np.ndarray:
        """The rotation R (3, 3)."""
        return rotation(self.rotation_deg)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Points (n, 3) of the measuring frame in the case's frame."""
        return np.asarray(x, float) @ self.matrix.T + np.asarray(self.translation_mm)

    @property
    def identity(self) -> bool:
        """Whether the frame moves nothing."""
        return not any(self.translation_mm) and not any(self.rotation_deg)


def rotation(angles_deg: Sequence[float]) -> np.ndarray:
    """R = R_z R_y R_x for angles (deg) about x, then y, then z."""
    a, b, c = np.radians(np.asarray(angles_deg, float))
    Rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    Ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    Rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


@dataclasses.dataclass(frozen=True)
class LabData:
    """What a lab measurement carries beyond its numeric columns."""

    measurement: str  # "file" (the grid) or one of MEASUREMENTS
    parent: str  # the id of the forming test it belongs to
    path: Path  # the file it was read from
    lines: np.ndarray  # file line of each row (a surface mesh: 0, the file has no rows)
    labels: tuple[str, ...] = ()  # the label column (empty strings where none)
    line_names: tuple[str, ...] = ()  # shear points: the measuring line of each row
    triangles: np.ndarray | None = None  # surface mesh: (m, 3) point indices
    frame: Frame = Frame()
    sd: float | None = None  # the noise key of the test (shear_sd_deg, position_sd_mm, ...)
    shear_magnitude: bool = False  # shear_points hold |shear| only
    force_tool: str = "punch"  # punch_force: the tool whose force was measured
    flat: bool = False  # shear_points given at flat-blank positions (x0_mm, y0_mm)
    anchor: np.ndarray | None = None  # register = true: the test's scan points (case frame)


# --------------------------------------------------------------------------------------------
# Checks (plain functions, shared with the grid's checks)


def reach_of(test) -> plausible.Reach | None:
    """Where a forming test's part can be (:mod:`~fenicsx_drape.measurements.plausible`)."""
    case = getattr(test, "forming_case", None)
    return plausible.reach_of_case(case) if case is not None else \
        plausible.reach_of_hemisphere(test.forming)


def _read_csv(path: Path, label: str, add) -> tuple[dict[str, np.ndarray],
                                                    dict[str, tuple[str, ...]], np.ndarray,
                                                    int] | None:
    """A CSV table: numeric columns, text columns (label, line), line of each row, header line.

    ``add(file, line, problem)`` collects problems; None when the table cannot be read.
    """
    fname = str(path)
    read = read_rows(path, label, add)
    if read is None:
        return None
    header, header_line, rows = read
    if len(set(header)) != len(header) or "" in header:
        add(fname, header_line, f"{label}: empty or duplicate column names in the header")
        return None
    if not rows:
        add(fname, header_line, f"{label}: the table has no data rows")
        return None
    numeric = [c for c in header if c not in TEXT_COLUMNS]
    values = np.zeros((len(rows), len(numeric)))
    texts: dict[str, list[str]] = {c: [] for c in header if c in TEXT_COLUMNS}
    bad = 0
    for r, (number, cells) in enumerate(rows):
        if len(cells) != len(header):
            add(fname, number, f"{label}: {len(cells)} cells, but the header has "
                               f"{len(header)} columns{ragged_hint(cells)}")
            bad += 1
            continue
        cell = dict(zip(header, cells))
        for name in texts:
            texts[name].append(cell[name])
        for c, name in enumerate(numeric):
            try:
                values[r, c] = float(cell[name])
            except ValueError:
                add(fname, number, f"{label}: column {name}: {cell[name]!r} is not a number")
                bad += 1
    if bad:
        return None
    lines = np.array([number for number, _ in rows])
    columns = {name: values[:, c] for c, name in enumerate(numeric)}
    return columns, {k: tuple(v) for k, v in texts.items()}, lines, header_line


def _read_mesh(path: Path, label: str, add) -> tuple[np.ndarray, np.ndarray | None] | None:
    """A scanned surface: points (n, 3) and triangles (m, 3) (None for a bare point cloud)."""
    import meshio

    from fenicsx_drape.limits import BYTES_PER_ROW, max_table_rows

    size, limit = path.stat().st_size, BYTES_PER_ROW * max_table_rows()
    if size > limit:  # a scan's points are rows: the tables' limit, before meshio reads it
        add(str(path), 0, f"{label}: the surface is {size / 1e6:.3g} MB, more than "
                          f"{limit / 1e6:.3g} MB (DRAPE_MAX_TABLE_ROWS × {BYTES_PER_ROW} "
                          "bytes): not read")
        return None
    try:
        mesh = meshio.read(path)
    except Exception as err:  # meshio raises many kinds: all mean "not a mesh of this type"
        add(str(path), 0, f"{label}: cannot read the surface as {path.suffix}: {err}")
        return None
    points = np.asarray(mesh.points, float)
    if points.ndim != 2 or len(points) == 0:
        add(str(path), 0, f"{label}: the surface has no points")
        return None
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    triangles = [np.asarray(c.data) for c in mesh.cells if c.type == "triangle"]
    return points, (np.vstack(triangles) if triangles else None)


def _kind_hint(header: Sequence[str]) -> str:
    """Which measurement a table's columns look like (for a file of the wrong kind)."""
    for name, (alternatives, _) in COLUMNS.items():
        if any(set(cols) <= set(header) for cols in alternatives) and name != "surface":
            return f"; its columns are those of {_a(name)} table: the wrong file?"
    if {"i", "j", "x0_mm", "y0_mm"} <= set(header):
        return "; its columns are those of a grid table: give it as file = ..."
    return ""


def _a(name: str) -> str:
    """``a shear_points``, ``an outline``."""
    return f"{'an' if name[0] in 'aeiou' else 'a'} {name}"


def missing_columns(name: str, header: Sequence[str]) -> str:
    """What a table of measurement ``name`` lacks: the missing columns of its nearest set.

    ``needs the columns x_mm, y_mm, z_mm, shear_deg (or x0_mm, y0_mm, shear_deg): missing
    shear_deg; 'shear_angle' is not a column of it: did you mean `shear_deg`?``
    """
    alternatives, optional = COLUMNS[name]
    nearest = min(alternatives, key=lambda cols: len(set(cols) - set(header)))
    missing = [c for c in nearest if c not in header]
    text = (f"{_a(name)} table needs the columns "
            + " or ".join(", ".join(cols) for cols in alternatives)
            + f": missing {', '.join(missing)} (its header: {', '.join(header)})")
    known = {c for cols in alternatives for c in cols} | set(optional) | set(TEXT_COLUMNS)
    for column in header:
        if column not in known and (guess := likely_typo(column, missing)):
            text += f"; {column!r}: did you mean `{guess}`?"
    return text + _kind_hint(header)


def _frame(raw: Any, fname: str, at: int, label: str, add) -> Frame:
    if raw is None:
        return Frame()
    if not isinstance(raw, dict):
        add(fname, at, f"{label}: [test.frame] must be a table")
        return Frame()
    known = {"translation_mm", "rotation_deg", "register"}
    for key in set(raw) - known:
        add(fname, at, f"{label}: unknown [test.frame] key {key!r} (known: "
                       f"{', '.join(sorted(known))})")
    vectors = {}
    for key in ("translation_mm", "rotation_deg"):
        v = raw.get(key, [0.0, 0.0, 0.0])
        ok = (isinstance(v, list) and len(v) == 3
              and all(isinstance(a, (int, float)) and not isinstance(a, bool)
                      and math.isfinite(a) for a in v))
        if not ok:
            add(fname, at, f"{label}: [test.frame] {key} = {v!r} must be three finite numbers")
            v = [0.0, 0.0, 0.0]
        vectors[key] = tuple(float(a) for a in v)
    register = raw.get("register", False)
    if not isinstance(register, bool):
        add(fname, at, f"{label}: [test.frame] register = {register!r} must be true or false")
        register = False
    return Frame(vectors["translation_mm"], vectors["rotation_deg"], register)


NO_FRAME = Frame()


def file_problem(name: str, path: Path) -> str | None:
    """What is wrong with the file a measurement names (none, a wrong kind), or None."""
    if not path.is_file():
        return (f"{name} = {path.name!r}: no such file {str(path)!r} (the path is relative to "
                "the bundle folder)")
    suffix = path.suffix.lower()
    if suffix == ".csv" or (name == "surface" and suffix in (*MESH_SUFFIXES, ".txt", ".xyz")):
        return None
    allowed = ".csv, " + ", ".join(MESH_SUFFIXES) if name == "surface" else ".csv"
    return f"{name} = {path.name!r} must be a {allowed} file, not {suffix or 'no suffix'!r}"


def read_measurement(name: str, path: Path, label: str, add, *, frame: Frame = NO_FRAME,
                     reach: tuple[np.ndarray, float] | None = None
                     ) -> tuple[dict[str, np.ndarray], dict[str, Any]] | None:
    """Read and check one lab measurement: its numeric columns (in the case's frame) and extras.

    Returns ``(columns, extras)`` with extras ``lines``, ``labels``, ``line_names``,
    ``triangles``, ``flat``; None when it has problems (each given to ``add``).
    """
    fname = str(path)
    if problem := file_problem(name, path):
        add(fname, 0, f"{label}: {problem}")
        return None
    suffix = path.suffix.lower()
    extras: dict[str, Any] = {"labels": (), "line_names": (), "triangles": None, "flat": False}
    if name == "surface" and suffix in MESH_SUFFIXES:
        mesh = _read_mesh(path, label, add)
        if mesh is None:
            return None
        points, extras["triangles"] = mesh
        columns = {"x_mm": points[:, 0], "y_mm": points[:, 1], "z_mm": points[:, 2]}
        extras["lines"] = np.zeros(len(points), int)
    else:
        table = _read_csv(path, label, add)
        if table is None:
            return None
        columns, texts, lines, header_line = table
        alternatives, _ = COLUMNS[name]
        present = [cols for cols in alternatives if set(cols) <= set(columns)]
        if not present:
            add(fname, header_line, f"{label}: {missing_columns(name, [*columns, *texts])}")
            return None
        extras["flat"] = name == "shear_points" and "x_mm" not in columns
        extras["lines"] = lines
        n = len(lines)
        extras["labels"] = texts.get("label", ("",) * n)
        extras["line_names"] = texts.get("line", ("",) * n)
    lines = extras["lines"]
    def failed(problems: plausible.Problems) -> bool:
        for line, problem in problems:
            add(fname, line, f"{label}: {problem}")
        return bool(problems)

    if failed(plausible.finite_problems(columns, lines)):
        return None
    if "shear_deg" in columns and (bad := np.flatnonzero(np.abs(columns["shear_deg"]) > 90.0)
                                   ).size:
        k = bad[0]
        add(fname, int(lines[k]), f"{label}: shear_deg = {columns['shear_deg'][k]:g} lies "
                                  f"beyond ±90° (a shear angle cannot; {bad.size} such row(s))")
        return None
    for sd in ("shear_sd_deg", "position_sd_mm", "force_sd_N"):
        if sd in columns and (bad := np.flatnonzero(columns[sd] <= 0)).size:
            add(fname, int(lines[bad[0]]), f"{label}: {sd} must be positive (one standard "
                                           f"deviation), got {columns[sd][bad[0]]:g}")
            return None
    if "z_mm" in columns or name in ("shear_points", "surface"):
        if "x_mm" in columns:
            P = np.column_stack([columns["x_mm"], columns["y_mm"],
                                 columns.get("z_mm", np.zeros(len(lines)))])
            P = frame.apply(P)
            columns["x_mm"], columns["y_mm"] = P[:, 0], P[:, 1]
            if "z_mm" in columns:
                columns["z_mm"] = P[:, 2]
    elif "x_mm" in columns and not frame.identity:  # an outline in plan: z = 0 of the frame
        P = frame.apply(np.column_stack([columns["x_mm"], columns["y_mm"],
                                         np.zeros(len(lines))]))
        columns["x_mm"], columns["y_mm"] = P[:, 0], P[:, 1]
    if reach is not None:
        zero = np.zeros(len(lines))
        positions = [("the position", columns.get("x_mm"), columns.get("y_mm"),
                      columns.get("z_mm", zero)),
                     ("the flat position", columns.get("x0_mm"), columns.get("y0_mm"), zero),
                     ("the travel (0, 0, travel_mm)", zero, zero, columns.get("travel_mm"))]
        for what, *xyz in positions:
            if all(c is not None for c in xyz) and failed(
                    plausible.far_problems(np.column_stack(xyz), lines, reach, what)):
                return None
    if name == "punch_force" and len(lines) < 2:
        add(fname, int(lines[0]), f"{label}: a force curve needs at least two rows")
        return None
    for array in columns.values():
        array.setflags(write=False)
    return columns, extras


def split_test(test, raw: Mapping[str, Any], folder: Path, fname: str, where, index: int,
               add) -> list:
    """One :class:`~fenicsx_drape.measurements.bundle.Test` per measurement of a forming test.

    Args:
        test: The test as the bundle loader built it (its grid columns, or none).
        raw: Its [[test]] table.
        folder: The bundle folder.
        fname: The bundle.toml path (for messages).
        where: ``where(table, index, key)``: the line of a key of bundle.toml.
        index: The test's index among the [[test]] tables.
        add: ``add(file, line, problem)``.

    On a stack (spec version 4) each measurement's ply comes from its ``<measurement>_ply``
    key or its ``ply`` column (:func:`by_ply`).

    Returns:
        The tests (empty when the measurements have problems, each given to ``add``).
    """
    label = f"test {test.id!r}"
    case = getattr(test, "forming_case", None)
    plies = (len(case.plies) or 1) if case is not None else 1
    ply_keys = {}
    for key, name in PLY_KEYS.items():
        if key in raw:
            v = raw[key]
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= plies:
                add(fname, where("test", index, key), f"{label}: {key} = {v!r} must be a ply "
                    f"of the stack, 1 (the punch side) to {plies}")
            else:
                ply_keys[name] = v
    out = []
    for t in _measurements(test, raw, folder, fname, where, index, add):
        out += by_ply(t, ply_keys.get(measurement_of(t) or "file"), plies, folder, label, add)
    return out


def by_ply(test, ply: int | None, plies: int, folder: Path, label: str, add) -> list:
    """A measurement as one test per ply it names (spec version 4).

    The ``ply`` column splits a table holding rows of several plies into tests with ids
    ``"<test id>/<measurement>/ply<k>"`` (a table of one ply keeps its id); else the test's
    ``<measurement>_ply`` key, else None (the outermost ply away from the punch).
    """
    if "ply" not in test.columns:
        return [dataclasses.replace(test, ply=ply)]
    column = np.asarray(test.columns["ply"])
    where = test.lab.path if test.lab is not None else folder / test.file
    lines = test.lab.lines if test.lab is not None else row_lines(where)
    bad = np.flatnonzero((column != np.rint(column)) | (column < 1) | (column > plies))
    if bad.size:
        line = int(lines[bad[0]]) if len(lines) > bad[0] else 0
        add(str(where), line, f"{label}: ply = {column[bad[0]]:g} must be a ply of the stack, "
                              f"1 (the punch side) to {plies}")
        return []
    values = np.unique(column).astype(int)
    if values.size == 1:
        return [dataclasses.replace(test, ply=int(values[0]))]
    name = measurement_of(test) or "file"
    stem = test.id if test.id.endswith(f"/{name}") else f"{test.id}/{name}"
    return [dataclasses.replace(without_rows(test, np.flatnonzero(column != k)),
                                id=f"{stem}/ply{k}", ply=int(k)) for k in values]


def _measurements(test, raw: Mapping[str, Any], folder: Path, fname: str, where, index: int,
                  add) -> list:
    """The tests of each measurement of a forming test (:func:`split_test`), plies aside."""
    label = f"test {test.id!r}"
    names = [m for m in MEASUREMENTS if m in raw]
    grid = bool(test.file)
    keys: dict[str, Any] = {}
    for key in ("shear_sd_deg", "position_sd_mm", "force_sd_N"):
        if key in raw:
            v = raw[key]
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v < math.inf):
                add(fname, where("test", index, key), f"{label}: {key} = {v!r} must be a "
                                                      "positive number")
            else:
                keys[key] = float(v)
    magnitude = raw.get("shear_magnitude", False)
    if not isinstance(magnitude, bool):
        add(fname, where("test", index, "shear_magnitude"),
            f"{label}: shear_magnitude = {magnitude!r} must be true or false")
    tool = raw.get("force_tool", "punch")
    if not isinstance(tool, str) or not tool:
        add(fname, where("test", index, "force_tool"), f"{label}: force_tool must name a tool")
        tool = "punch"
    case = getattr(test, "forming_case", None)
    if case is not None and "punch_force" in raw and tool not in {t.name for t in case.tools}:
        add(fname, where("test", index, "force_tool"),
            f"{label}: force_tool = {tool!r} is not a tool of the case (its tools: "
            f"{', '.join(t.name for t in case.tools)})")
    frame = _frame(raw.get("frame"), fname, where("test", index, "frame"), label, add)
    reach = reach_of(test)
    out = []
    if grid:
        columns = dict(test.columns)
        if "position_sd_mm" in keys and "position_sd_mm" not in columns:
            columns["position_sd_mm"] = np.full(test.n_rows, keys["position_sd_mm"])
        if not frame.identity:  # the grid's formed positions into the case's frame
            x = frame.apply(np.column_stack([columns[c] for c in ("x_mm", "y_mm", "z_mm")]))
            columns.update({c: x[:, k] for k, c in enumerate(("x_mm", "y_mm", "z_mm"))})
        if not names:  # a grid alone keeps its id (version 2)
            return [dataclasses.replace(test, columns=columns)]
        out.append(dataclasses.replace(
            test, id=f"{test.id}/file", columns=columns,
            lab=LabData("file", test.id, folder / test.file, row_lines(folder / test.file),
                        frame=frame)))
    for name in names:
        file = raw[name]
        at = where("test", index, name)
        if not isinstance(file, str) or not file:
            add(fname, at, f"{label}: {name} must name a file (relative to the bundle folder)")
            continue
        if problem := file_problem(name, folder / file):  # at its key in bundle.toml
            add(fname, at, f"{label}: {problem}")
            continue
        read = read_measurement(name, folder / file, label, add, frame=frame, reach=reach)
        if read is None:
            continue
        columns, extras = read
        data = LabData(name, test.id, folder / file, extras["lines"], extras["labels"],
                       extras["line_names"], extras["triangles"], frame,
                       keys.get(SD_KEY[name]), bool(magnitude), tool, extras["flat"])
        out.append(dataclasses.replace(test, id=f"{test.id}/{name}", file=file,
                                       columns=columns, lab=data))
    scans = [t for t in out if t.lab.measurement == "surface"]
    if frame.register and scans:  # the whole test's frame is registered on its scan
        anchor = np.column_stack([scans[0].columns[c] for c in ("x_mm", "y_mm", "z_mm")])
        out = [dataclasses.replace(t, lab=dataclasses.replace(t.lab, anchor=anchor))
               if t.lab.measurement != "file" else t for t in out]
    return out


def row_lines(path: Path) -> np.ndarray:
    """The file line of each data row of a CSV table (after ``#`` comments and the header)."""
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except OSError:
        return np.zeros(0, int)
    numbers = [n for n, raw in enumerate(text.splitlines(), start=1)
               if raw.strip() and not raw.strip().startswith("#")]
    return np.array(numbers[1:], int)


def measurement_of(test) -> str | None:
    """The lab measurement a test holds (``"file"`` for a grid split off), None for v2 tests."""
    lab = getattr(test, "lab", None)
    return None if lab is None else lab.measurement


def without_rows(test, rows: Sequence[int]):
    """A test with the given rows (indices) left out: its columns and row data (outliers)."""
    keep = np.ones(test.n_rows, bool)
    keep[list(rows)] = False
    columns = {k: np.asarray(v)[keep] for k, v in test.columns.items()}
    lab = test.lab
    if lab is not None:
        def pick(seq):
            return tuple(x for x, k in zip(seq, keep) if k) if seq else seq

        lab = dataclasses.replace(
            lab, lines=np.asarray(lab.lines)[keep] if lab.lines.size == keep.size
            else lab.lines, labels=pick(lab.labels), line_names=pick(lab.line_names),
            triangles=None)
    return dataclasses.replace(test, columns=columns, lab=lab)
