"""Measurement bundles: ``bundle.toml`` plus one CSV table per test (spec: docs/measurements.md).

:func:`load_bundle` reads a bundle into typed, validated objects. Every problem is reported
as ``file:line: problem``; all problems of a bundle are collected and raised together in one
:class:`BundleError`, so a bundle is either loaded whole or not at all. Keys the loader does
not know are kept (as test conditions, or as notes when not numeric) and listed in
:attr:`Bundle.unknown_keys`.

A forming test names either the paper's tool set (``geometry = "hemisphere"`` and its keys)
or the forming case it was made with (``case = "part.toml"``, relative to the bundle folder;
spec version 2, "forming tests on any part"). This layer does not know forming cases: given a
reader (``load_bundle(path, read_case=case_for_test)``, as every command does), it reads and
checks the case file with the test's keys as overrides, so that a malformed case is reported
here as a problem of the bundle, with the case file and its key; without one the case is read
when the test is simulated.

:func:`write_bundle` writes a bundle back (each file atomically, ``bundle.toml`` last).
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError, InputFileError, likely_typo, old_name
from fenicsx_drape.limits import check_file_size
from fenicsx_drape.measurements import lab
from fenicsx_drape.measurements.tables import ragged_hint, read_rows
from fenicsx_drape.provenance import atomic_write_text, toml_text

KINDS = ("tensile", "bias_extension", "picture_frame", "forming", "interply_friction")

# Required and optional CSV columns per test kind.
COLUMNS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "tensile": (("time_s", "displacement_mm", "force_N"), ("force_sd_N",)),
    "bias_extension": (("time_s", "displacement_mm", "force_N"), ("force_sd_N", "shear_deg")),
    "picture_frame": (("time_s", "displacement_mm", "force_N"), ("force_sd_N", "shear_deg")),
    "forming": (
        ("i", "j", "x0_mm", "y0_mm", "x_mm", "y_mm", "z_mm"),
        ("position_sd_mm", "shear_deg", "wrinkle_strain", "ply"),
    ),
    # Spec version 4: one ply pulled between two (or over one) under a normal pressure.
    "interply_friction": (("time_s", "displacement_mm", "force_N"), ("force_sd_N", "pressure_kPa")),
}

# A declared noise for coupon tables without a force_sd_N column (an addition to the spec,
# which may accept more): one standard deviation per row in N, or as a fraction of the test's
# peak |force|. Given in a [[test]] table, or in [bundle] for every coupon test without its own.
NOISE_KEYS = ("force_sd_N", "force_sd_rel")

# Numeric keys of a [[test]] table that describe the test (not conditions), per kind.
# Keys in REQUIRED_KEYS must be present; ``tows`` may instead be derived from tows_per_mm.
SETUP_KEYS: dict[str, tuple[str, ...]] = {
    "tensile": ("gauge_length_mm", "width_mm", "tows", "speed_mm_per_min", *NOISE_KEYS),
    "bias_extension": ("length_mm", "width_mm", "tows", "speed_mm_per_min", *NOISE_KEYS),
    "picture_frame": ("frame_side_mm", "fabric_side_mm", "tows", "speed_mm_per_min",
                      *NOISE_KEYS),
    "forming": (
        "punch_radius_mm", "fillet_radius_mm", "holder_opening_mm", "sheet_mm", "travel_mm",
        "duration_s", "holder_force_N", "grid_mm",
    ),
    "interply_friction": ("contact_length_mm", "contact_width_mm", "interfaces", "pressure_kPa",
                          "speed_mm_per_min", *NOISE_KEYS),
}
REQUIRED_KEYS: dict[str, tuple[str, ...]] = {
    "tensile": ("gauge_length_mm",),
    "bias_extension": ("length_mm", "width_mm"),
    "picture_frame": ("frame_side_mm", "fabric_side_mm"),
    "forming": ("geometry", "sheet_mm", "travel_mm", "duration_s", "holder_force_N"),
    "interply_friction": ("contact_length_mm", "contact_width_mm", "interfaces", "pressure_kPa"),
}
# A forming test that names its case file needs nothing else: the case says the rest, and the
# test's own keys override it. ``grid_mm`` describes the drawn grid (not a case value).
CASE_DESCRIPTIVE_KEYS = ("grid_mm",)
# The set-up keys a forming test naming its case gives as [x, y] in mm (spec version 3: the
# blank's or the punch's displacement from where the case puts it).
PAIR_KEYS = ("blank_offset_mm", "tool_offset_mm")
# The set-up a forming test may state, on a hemisphere test as on a test naming its case (the
# case format's set-up overrides: a turned ply, a blank or punch placed off-centre).
SETUP_OVERRIDE_KEYS = ("ply_angle_deg", *PAIR_KEYS)

# Earlier names of a forming test's conditions, read as today's with a note (one release):
# the holder's friction coefficient is ``mu`` everywhere (the spec's set-up candidate).
OLD_CONDITIONS = {"friction_coefficient": "mu"}

# A reader of forming cases (the forming layer's ``case_for_test``, passed to
# :func:`load_bundle`): ``read_case(case_path, keys) -> (case, used)`` reads and checks the
# case file, applies those of the test's ``keys`` that name a value of the case as overrides
# and returns the case with the keys it used; it raises a DrapeInputError (with ``problems``,
# each naming the case file and key) for a malformed case or a key the case cannot take.
CaseReader = Callable[[Path, Mapping[str, Any]], tuple[Any, Mapping[str, Any]]]


# The unit each physical quantity must carry in a key or column name. A name made of one of
# these quantities and another unit (``force_kN``, ``length_m``, ``temperature_K``) is an
# inconsistent unit and rejected rather than silently misread.
UNITS: dict[str, str] = {
    "time": "s", "duration": "s", "displacement": "mm", "force": "N", "force_sd": "N",
    "length": "mm", "width": "mm", "gauge_length": "mm", "sheet": "mm", "travel": "mm",
    "grid": "mm", "punch_radius": "mm", "fillet_radius": "mm", "holder_opening": "mm",
    "holder_force": "N", "position_sd": "mm", "x": "mm", "y": "mm", "z": "mm", "x0": "mm",
    "y0": "mm", "shear": "deg", "temperature": "C", "speed": "mm_per_min",
    "frame_side": "mm", "fabric_side": "mm", "contact_length": "mm", "contact_width": "mm",
    "pressure": "kPa",
}
_FOREIGN_UNITS = (
    "m", "cm", "um", "in", "inch", "ft", "kN", "mN", "lbf", "N", "mm", "s", "ms", "min", "h",
    "K", "F", "C", "deg", "rad", "mm_per_s", "m_per_s", "mm_per_min", "in_per_min", "Pa",
    "kPa", "MPa", "bar", "psi",
)
_UNIT_NAME = re.compile(
    "^({})_({})$".format(*("|".join(sorted(names, key=len, reverse=True))
                           for names in (UNITS, _FOREIGN_UNITS)))
)

# A crosshead speed key and the table's own speed may differ (holds, a ramp, ...), but not by
# the factor of a unit mix-up (60 for min/s, 10 or 1000 for cm/m against mm).
_SPEED_TOLERANCE = 3.0
# Given and derived tow counts may differ by the specimen's edge tows, not by a factor 10
# (tows/cm against tows/mm).
_TOWS_TOLERANCE = 1.5


# A bundle that cannot be loaded: the package's one error for bad input files, whose
# ``problems`` list every ``file:line: problem`` (``BundleError`` is its earlier name).
BundleError = InputFileError


@dataclasses.dataclass(frozen=True)
class Test:
    """One test of a bundle: its setup, conditions and measured table.

    Geometry in mm, speeds in mm/min, forces in N. Keys absent from ``bundle.toml`` are None.
    """

    __test__ = False  # not a pytest test class

    id: str  # unique in the bundle
    kind: str  # "tensile" | "bias_extension" | "picture_frame" | "forming" | "interply_friction"
    file: str  # CSV table, relative to the bundle folder
    columns: Mapping[str, np.ndarray]  # the table by column name (all read-only float arrays)
    line: int = 0  # line of the [[test]] header in bundle.toml (for messages)
    gauge_length_mm: float | None = None  # tensile: gauge length
    length_mm: float | None = None  # bias extension: specimen length L0
    width_mm: float | None = None  # specimen width W0
    frame_side_mm: float | None = None  # picture frame: side hinge to hinge, L_frame
    fabric_side_mm: float | None = None  # picture frame: side of the sheared fabric, L_fabric
    tows: float | None = None  # tows sharing the force (per-tow force = force_N / tows)
    tows_derived: bool = False  # tows computed from tows_per_mm and the width
    speed_mm_per_min: float | None = None  # nominal crosshead speed (descriptive)
    noise_sd_N: float | None = None  # declared noise, one standard deviation per row (N)
    noise_rel: float | None = None  # declared noise as a fraction of the peak |force|
    noise_declared_by: str | None = None  # where the declaration came from (for the report)
    geometry: str | None = None  # forming: tool set ("hemisphere")
    forming: Mapping[str, Any] = dataclasses.field(default_factory=dict)  # forming keys
    case: str | None = None  # forming: the case file as written (relative to the bundle)
    case_path: Path | None = None  # forming: the case file (absolute)
    # forming: the test's keys offered to its case as overrides (all its scalar keys but the
    # descriptive ones), and the case with those it names applied (read by the forming
    # layer's reader when the bundle is loaded; None when no reader was registered then)
    case_keys: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    forming_case: Any = None
    conditions: Mapping[str, float] = dataclasses.field(default_factory=dict)  # e.g. temperature_C
    notes: Mapping[str, str] = dataclasses.field(default_factory=dict)  # non-numeric extra keys
    # forming (version 3): the lab measurement this test holds, a
    # :class:`~fenicsx_drape.measurements.lab.LabData` (None: a test as in version 2)
    lab: Any = None
    # interply_friction (version 4): contact_length_mm, contact_width_mm, interfaces,
    # pressure_kPa and, when given, ply_angles_deg
    interply: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    # forming on a stack (version 4): the ply it was measured on (1 = the punch side), from
    # its <measurement>_ply key or its table's ply column; None: the outermost ply on the
    # side away from the punch (the one a camera sees)
    ply: int | None = None

    def column(self, name: str) -> np.ndarray | None:
        """A column of the table, or None when the table does not have it."""
        return self.columns.get(name)

    @property
    def time_s(self) -> np.ndarray:
        """Time of each row (s)."""
        return self.columns["time_s"]

    @property
    def displacement_mm(self) -> np.ndarray:
        """Crosshead displacement of each row (mm)."""
        return self.columns["displacement_mm"]

    @property
    def force_N(self) -> np.ndarray:
        """Measured force of each row (N)."""
        return self.columns["force_N"]

    @property
    def force_sd_N(self) -> np.ndarray | None:
        """Measurement noise of each row, one standard deviation (N), if given."""
        return self.columns.get("force_sd_N")

    @property
    def shear_deg(self) -> np.ndarray | None:
        """Measured shear angle (deg), if given."""
        return self.columns.get("shear_deg")

    @property
    def n_rows(self) -> int:
        """Number of rows of the table."""
        return len(next(iter(self.columns.values())))


@dataclasses.dataclass(frozen=True)
class Bundle:
    """A loaded measurement bundle."""

    name: str
    tests: tuple[Test, ...]
    material: str = ""
    tows_per_mm: float | None = None  # linear tow density (warp = weft), tows/mm
    path: Path | None = None  # the bundle folder
    unknown_keys: tuple[str, ...] = ()  # report of keys kept as conditions or notes
    notes: tuple[str, ...] = ()  # what the loader derived (e.g. tow counts)
    extra: Mapping[str, Any] = dataclasses.field(default_factory=dict)  # unknown [bundle] keys

    def test(self, test_id: str) -> Test:
        """The test named ``test_id``."""
        for t in self.tests:
            if t.id == test_id:
                return t
        raise KeyError(f"bundle {self.name!r} has no test {test_id!r} "
                       f"(tests: {', '.join(t.id for t in self.tests)})")

    def of_kind(self, *kinds: str) -> tuple[Test, ...]:
        """The tests of the given kinds, in bundle order."""
        return tuple(t for t in self.tests if t.kind in kinds)

    def report(self) -> str:
        """What the loader kept or derived beyond the spec's keys, one line each."""
        return "\n".join([*self.unknown_keys, *self.notes])


def derived_tows(kind: str, tows_per_mm: float, width_mm: float) -> float:
    """Tows sharing the force in a specimen of width W (section 3.2).

    A tensile specimen cut along the warp holds l_t·W tows; a bias specimen's tows cross its
    width at 45°, so l_t·W/√2 of each family reach a clamp (0.71 × 70/√2 = 35.1, the paper's
    35.3). A picture frame's fabric square of side W (``fabric_side_mm``) holds l_t·W tows
    of each family.
    """
    tows = tows_per_mm * width_mm
    return tows / math.sqrt(2.0) if kind == "bias_extension" else tows


# --------------------------------------------------------------------------------------------
# Loading


class _Problems:
    """Collects ``file:line: problem`` messages."""

    def __init__(self) -> None:
        self.items: list[str] = []

    def add(self, file: str, line: int | None, problem: str) -> None:
        self.items.append(f"{file}:{line}: {problem}" if line else f"{file}: {problem}")


def _key_lines(text: str) -> dict[tuple[str, int, str], int]:
    """Line numbers of the keys of ``bundle.toml``.

    Returns a map ``(table, test index, key) -> line`` where table is "bundle", "test",
    "conditions" or "" (top level), and the headers themselves under key "". A plain line scan
    is enough for the flat tables of the spec; keys it cannot place fall back to their table's
    header line.
    """
    lines: dict[tuple[str, int, str], int] = {}
    table, index = "", -1
    header = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\"' -]+?)\s*\]\]?\s*(#.*)?$")
    keyline = re.compile(r"^\s*([A-Za-z0-9_-]+|\"[^\"]*\"|'[^']*')\s*=")
    for number, raw in enumerate(text.splitlines(), start=1):
        if m := header.match(raw):
            name = m.group(2).replace('"', "").replace("'", "").replace(" ", "")
            if m.group(1) == "[[" and name == "test":
                table, index = "test", index + 1
            elif name == "test.conditions":
                table = "conditions"
            else:
                table = name
            lines.setdefault((table, index, ""), number)
        elif m := keyline.match(raw):
            lines.setdefault((table, index, m.group(1).strip("\"'")), number)
    return lines


# The keys of [bundle].
BUNDLE_KEYS = ("name", "material", "tows_per_mm", *NOISE_KEYS)


def _typo_note(key: str, known) -> str:
    """A note naming the known key that ``key`` is likely a typo of (else empty)."""
    guess = likely_typo(key, known)
    return (f" -- did you mean `{guess}`? (a likely typo: the key is not read as "
            f"{guess})" if guess else "")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_pair(value: Any) -> bool:
    """Whether ``value`` is [x, y]: two finite numbers."""
    return (isinstance(value, list) and len(value) == 2
            and all(_is_number(v) and math.isfinite(v) for v in value))


def _unit_problem(name: str) -> str | None:
    """A message when ``name`` carries a unit other than the spec's for its quantity."""
    m = _UNIT_NAME.match(name)
    if m is None:
        return None
    quantity, unit = m.groups()
    expected = UNITS[quantity]
    if unit == expected:
        return None
    return (f"{name!r} is in {unit.replace('_per_', '/')}, but {quantity} must be given in "
            f"{expected.replace('_per_', '/')} (as {quantity}_{expected})")


def _missing(required: tuple[str, ...], present) -> list[str]:
    """Required names absent from ``present``.

    A name given in another unit is not reported as missing: :func:`_unit_problem` says so.
    """
    misunited = {m.group(1) for name in present if (m := _UNIT_NAME.match(name))}
    return [name for name in required
            if name not in present and not ((m := _UNIT_NAME.match(name))
                                            and m.group(1) in misunited)]


def load_bundle(path: str | Path, read_case: CaseReader | None = None) -> Bundle:
    """Read and validate a measurement bundle (a folder with ``bundle.toml``, or the file).

    Args:
        path: The bundle folder, or its ``bundle.toml``.
        read_case: Reads and checks the case file a forming test names, with the test's keys
            (:data:`CaseReader`, e.g. ``fenicsx_drape.forming.case_for_test``); None: the
            case is read when the test is simulated.

    Raises:
        BundleError: listing every problem found as ``file:line: problem``: a missing or
            unreadable file, a TOML syntax error, a missing or mistyped key, an unknown test
            kind, a duplicate test id, a unit other than the spec's, a missing or duplicate
            column, a non-numeric, NaN or infinite cell, a ragged row, non-increasing time,
            a non-positive standard deviation, a crosshead speed or tow count that contradicts
            the table or the tow density.
    """
    path = Path(path)
    folder = path.parent if path.name == "bundle.toml" or path.is_file() else path
    toml_path = path if path.is_file() else folder / "bundle.toml"
    fname = str(toml_path)
    if not toml_path.is_file():
        raise BundleError([f"{fname}: no bundle.toml here (a bundle is a folder holding "
                           "bundle.toml and one CSV table per test)"])
    try:
        check_file_size(toml_path, "bundle.toml")
    except DrapeInputError as err:
        raise BundleError([str(err)]) from None
    text = toml_path.read_text(encoding="utf-8-sig", errors="replace")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        line = re.search(r"line (\d+)", str(err))
        at = f":{line.group(1)}" if line else ""
        raise BundleError([f"{fname}{at}: not valid TOML: {err}"]) from None
    lines = _key_lines(text)
    problems = _Problems()
    unknown: list[str] = []
    notes: list[str] = []

    def where(table: str, index: int, key: str = "") -> int:
        return lines.get((table, index, key), lines.get((table, index, ""), 0))

    for key in data:
        if key not in ("bundle", "test"):
            unknown.append(f"{fname}:{where(key, -1)}: unknown top-level entry {key!r} kept "
                           "in Bundle.extra")
    head = data.get("bundle")
    if not isinstance(head, dict):
        problems.add(fname, 0, "missing [bundle] table (with at least name = \"...\")")
        head = {}
    name = head.get("name")
    if not isinstance(name, str) or not name.strip():
        problems.add(fname, where("bundle", -1, "name"),
                     "[bundle] needs name = \"...\" (a non-empty string)")
    material = head.get("material", "")
    if not isinstance(material, str):
        problems.add(fname, where("bundle", -1, "material"), "material must be a string")
    tows_per_mm = head.get("tows_per_mm")
    if tows_per_mm is not None and not (_is_number(tows_per_mm) and 0 < tows_per_mm < math.inf):
        problems.add(fname, where("bundle", -1, "tows_per_mm"),
                     f"tows_per_mm = {tows_per_mm!r} must be a positive number (tows/mm)")
        tows_per_mm = None
    extra = {k: v for k, v in data.items() if k not in ("bundle", "test")}
    bundle_noise: dict[str, float] = {}
    for key in NOISE_KEYS:
        if key in head:
            value = head[key]
            if _is_number(value) and 0 < value < math.inf:
                bundle_noise[key] = float(value)
            else:
                problems.add(fname, where("bundle", -1, key),
                             f"[bundle] {key} = {value!r} must be a positive number")
    for key, value in head.items():
        if key in BUNDLE_KEYS:
            continue
        if msg := _unit_problem(key):
            problems.add(fname, where("bundle", -1, key), msg)
            continue
        extra[key] = value
        unknown.append(f"{fname}:{where('bundle', -1, key)}: unknown [bundle] key {key!r} "
                       f"kept in Bundle.extra{_typo_note(key, BUNDLE_KEYS)}")

    raw_tests = data.get("test", [])
    if not isinstance(raw_tests, list) or not raw_tests:
        problems.add(fname, 0, "no [[test]] tables: a bundle needs at least one test")
        raw_tests = []
    tests: list[Test] = []
    seen: dict[str, int] = {}
    for index, raw in enumerate(raw_tests):
        test = _load_test(folder, fname, raw, index, where, tows_per_mm, problems, unknown,
                          read_case, notes)
        if test is None:
            continue
        if test.kind == "forming" and (any(k in raw for k in lab.LAB_KEYS)
                                       or "ply" in test.columns
                                       or len(getattr(test.forming_case, "plies", ())) > 1):
            parts = lab.split_test(test, raw, folder, fname, where, index, problems.add)
            tests.extend(parts)
            stack = getattr(test.forming_case, "plies", ())
            for part in parts:
                if part.ply is None and len(stack) > 1:
                    notes.append(f"test {part.id!r}: no ply named; taken as measured on the "
                                 f"outermost ply away from the punch (ply {len(stack)})")
            seen.update({p.id: where("test", index, "id") for p in parts})
            continue
        if bundle_noise and test.kind in ("tensile", "bias_extension", "picture_frame"):
            test = declared_noise(test, bundle_noise, f"{fname} [bundle]")
        at = where("test", index, "id")
        if test.id in seen:
            problems.add(fname, at, f"test id {test.id!r} is used twice (first on line "
                                    f"{seen[test.id]}); ids must be unique")
            continue
        seen[test.id] = at
        tests.append(test)
    if problems.items:
        raise BundleError(problems.items)
    return Bundle(name=name, material=material, tows_per_mm=tows_per_mm, tests=tuple(tests),
                  path=folder, unknown_keys=tuple(unknown), notes=tuple(notes), extra=extra)


def _load_test(folder, fname, raw, index, where, tows_per_mm, problems, unknown, read_case,
               notes):
    """One [[test]] table and its CSV; None (with problems added) when it cannot be built."""
    line = where("test", index)
    if not isinstance(raw, dict):
        problems.add(fname, line, "a [[test]] entry must be a table")
        return None
    before = len(problems.items)
    test_id = raw.get("id")
    label = f"test {test_id!r}" if isinstance(test_id, str) else f"test #{index + 1}"
    if not isinstance(test_id, str) or not test_id.strip():
        problems.add(fname, line, f"{label}: needs id = \"...\" (a non-empty string)")
    kind = raw.get("kind")
    if kind not in KINDS:
        problems.add(fname, where("test", index, "kind"),
                     f"{label}: unknown test kind {kind!r} (expected one of: "
                     f"{', '.join(KINDS)})")
        return None
    file = raw.get("file")
    measured = kind == "forming" and any(m in raw for m in lab.MEASUREMENTS)
    if measured and file is None:
        file = ""  # version 3: a forming test may hold lab measurements without a grid
    elif not isinstance(file, str) or not file:
        problems.add(fname, where("test", index, "file"),
                     f"{label}: needs file = \"table.csv\" (relative to the bundle folder)"
                     + (f" or one of {', '.join(lab.MEASUREMENTS)}" if kind == "forming"
                        else ""))
    names_case = kind == "forming" and "case" in raw
    if names_case and "geometry" in raw:
        problems.add(fname, where("test", index, "case"),
                     f"{label}: give either geometry = \"hemisphere\" (with its keys) or "
                     "case = \"case.toml\", not both")
    elif kind == "forming" and not names_case and "geometry" not in raw:
        problems.add(fname, line, f"{label}: a forming test needs geometry = \"hemisphere\" "
                                  "(with its keys) or case = \"case.toml\" (the forming case "
                                  "it was made with, relative to the bundle folder)")
    elif not names_case:
        for key in _missing(REQUIRED_KEYS[kind], raw):
            problems.add(fname, line, f"{label}: a {kind} test needs {key}")

    setup: dict[str, Any] = {}
    conditions: dict[str, float] = {}
    text_notes: dict[str, str] = {}
    geometry = raw.get("geometry")
    if kind == "forming" and "geometry" in raw and not isinstance(geometry, str):
        problems.add(fname, where("test", index, "geometry"),
                     f"{label}: geometry must be a string (e.g. \"hemisphere\")")
    known = {"id", "kind", "file", "conditions"} | ({"geometry", "case", *lab.LAB_KEYS}
                                                    if kind == "forming" else set())
    angles = raw.get("ply_angles_deg")
    if kind == "interply_friction":
        known.add("ply_angles_deg")
        if angles is not None and not (isinstance(angles, list) and angles and all(
                _is_number(a) and math.isfinite(a) for a in angles)):
            problems.add(fname, where("test", index, "ply_angles_deg"),
                         f"{label}: ply_angles_deg = {angles!r} must be a list of angles "
                         "(degrees)")
        n = raw.get("interfaces")
        if n is not None and n not in (1, 2):
            problems.add(fname, where("test", index, "interfaces"),
                         f"{label}: interfaces = {n!r} must be 2 (pull-out, between two plies) "
                         "or 1 (pull-through, over one)")
    case_file, case_path, used, forming_case = None, None, {}, None
    if names_case:
        for key in PAIR_KEYS:
            if key in raw and not _is_pair(raw[key]):
                problems.add(fname, where("test", index, key),
                             f"{label}: {key} = {raw[key]!r} must be [x, y]: two finite "
                             "numbers (mm)")
                raw = {k: v for k, v in raw.items() if k != key}
        case_file, case_path, used, forming_case = _read_case(
            folder, fname, raw, index, where, label, known, problems, read_case)
    # The keys a misspelt one likely means (named in the note that keeps it as a condition).
    spelled = {*known, *SETUP_KEYS[kind], *NOISE_KEYS, "ply_angles_deg",
               *(SETUP_OVERRIDE_KEYS if kind == "forming" else ())}
    for key, value in raw.items():
        if key in known:
            continue
        at = where("test", index, key)
        if msg := _unit_problem(key):
            problems.add(fname, at, f"{label}: {msg}")
        elif key in used:  # a value of the case, checked by its reader
            if isinstance(value, str):
                text_notes[key] = value  # e.g. holder_force_share
            elif key in PAIR_KEYS:
                setup[key] = [float(v) for v in value]
            else:
                setup[key] = float(value)
        elif kind == "forming" and not names_case and key in SETUP_OVERRIDE_KEYS:
            if key in PAIR_KEYS and not _is_pair(value):
                problems.add(fname, at, f"{label}: {key} = {value!r} must be [x, y]: two "
                                        "finite numbers (mm)")
            elif key not in PAIR_KEYS and not (_is_number(value) and math.isfinite(value)):
                problems.add(fname, at, f"{label}: {key} = {value!r} must be a finite number "
                                        "(degrees)")
            else:
                setup[key] = [float(v) for v in value] if key in PAIR_KEYS else float(value)
        elif key in SETUP_KEYS[kind] and (not names_case or key in CASE_DESCRIPTIVE_KEYS):
            if not (_is_number(value) and 0 < value < math.inf):
                problems.add(fname, at, f"{label}: {key} = {value!r} must be a positive number")
            else:
                setup[key] = float(value)
        elif _is_number(value):
            if not math.isfinite(value):
                problems.add(fname, at, f"{label}: condition {key} = {value} is not finite")
            conditions[key] = float(value)
            unknown.append(f"{fname}:{at}: {label}: key {key!r} kept as a test condition"
                           f"{_typo_note(key, spelled)}")
        else:
            text_notes[key] = str(value)
            unknown.append(f"{fname}:{at}: {label}: non-numeric key {key!r} kept as a note"
                           f"{_typo_note(key, spelled)}")
    raw_conditions = raw.get("conditions", {})
    if not isinstance(raw_conditions, dict):
        problems.add(fname, where("test", index, "conditions"),
                     f"{label}: conditions must be a table of numbers")
        raw_conditions = {}
    for key, value in raw_conditions.items():
        at = where("conditions", index, key)
        if kind == "forming" and key in OLD_CONDITIONS and OLD_CONDITIONS[key] not in (
                raw_conditions):
            key = old_name(f"{fname}:{at}: {label}: condition", key, OLD_CONDITIONS[key],
                           stacklevel=5)
        if msg := _unit_problem(key):
            problems.add(fname, at, f"{label}: {msg}")
        elif not (_is_number(value) and math.isfinite(value)):
            problems.add(fname, at, f"{label}: condition {key} = {value!r} must be a finite "
                                    "number")
        elif key in conditions:
            problems.add(fname, at, f"{label}: condition {key} given twice")
        else:
            conditions[key] = float(value)

    tows, tows_derived = setup.pop("tows", None), False
    if kind == "picture_frame":
        _check_frame(setup, fname, where, index, label, problems)
    if kind in ("tensile", "bias_extension", "picture_frame"):
        width = setup.get("fabric_side_mm" if kind == "picture_frame" else "width_mm")
        derived = derived_tows(kind, tows_per_mm, width) if tows_per_mm and width else None
        if tows is None and derived is None:
            side = "fabric_side_mm" if kind == "picture_frame" else "width_mm"
            problems.add(fname, line, f"{label}: needs tows (or {side} together with "
                                      "[bundle] tows_per_mm to derive it)")
        elif tows is None:
            tows, tows_derived = derived, True
            side = "fabric_side_mm" if kind == "picture_frame" else "width_mm"
            notes.append(f"{fname}:{line}: {label}: tows = {derived:.4g} derived from "
                         f"tows_per_mm × {side}{' / √2' if kind == 'bias_extension' else ''}")
        elif derived is not None and not (1 / _TOWS_TOLERANCE < tows / derived
                                          < _TOWS_TOLERANCE):
            problems.add(fname, where("test", index, "tows"),
                         f"{label}: tows = {tows:g} contradicts tows_per_mm × width_mm "
                         f"= {derived:.4g} (inconsistent units? tows_per_mm is per mm)")
    if len(problems.items) > before or not isinstance(file, str):
        return None
    csv_path = folder / file
    table = ({}, [], 0)
    if file:
        check = None
        if kind == "forming":  # every number plausible
            from fenicsx_drape.measurements.plausible import grid_table_check

            check = grid_table_check(setup, forming_case, fname, where("test", index, "grid_mm"))
        elif kind == "interply_friction":
            check = _pressure_check
        if not csv_path.is_file():
            problems.add(fname, where("test", index, "file"),
                         f"{label}: file = {file!r}: no such file {str(csv_path)!r} (the path "
                         "is relative to the bundle folder)")
            return None
        table = _read_table(csv_path, kind, label, problems, check)
    if table is None:
        return None
    columns, extra_columns, header_line = table
    unknown += [f"{csv_path}:{header_line}: {label}: extra column {name!r} kept in "
                "Test.columns" for name in extra_columns]
    speed = setup.get("speed_mm_per_min")
    if speed is not None and "displacement_mm" in columns:
        problem = _speed_problem(columns, speed)
        if problem:
            problems.add(fname, where("test", index, "speed_mm_per_min"),
                         f"{label}: {problem} in {file}")
            return None
    if kind == "picture_frame" and not _frame_table_ok(columns, setup, csv_path, fname, where,
                                                       index, label, table[2], problems):
        return None
    forming = {k: v for k, v in setup.items() if kind == "forming"}
    if "force_sd_N" in setup and "force_sd_rel" in setup:
        problems.add(fname, where("test", index, "force_sd_rel"),
                     f"{label}: give force_sd_N or force_sd_rel, not both")
        return None
    case_keys = ({k: v for k, v in raw.items() if _offered(k, v, known)} if names_case
                 else {})
    interply = {}
    if kind == "interply_friction":
        interply = {k: setup[k] for k in ("contact_length_mm", "contact_width_mm", "interfaces",
                                          "pressure_kPa") if k in setup}
        if angles is not None:
            interply["ply_angles_deg"] = [float(a) for a in angles]
    test = Test(
        id=test_id, kind=kind, file=file, columns=columns, line=line,
        gauge_length_mm=setup.get("gauge_length_mm"), length_mm=setup.get("length_mm"),
        width_mm=setup.get("width_mm"), tows=tows, tows_derived=tows_derived,
        frame_side_mm=setup.get("frame_side_mm"), fabric_side_mm=setup.get("fabric_side_mm"),
        speed_mm_per_min=speed, geometry=geometry if kind == "forming" else None,
        forming=forming, conditions=conditions, notes=text_notes, case=case_file,
        case_path=case_path, case_keys=case_keys, forming_case=forming_case,
        interply=interply,
    )
    own = {k: setup[k] for k in NOISE_KEYS if k in setup}
    return declared_noise(test, own, f"{fname} [[test]] {test_id!r}") if own else test


def _pressure_check(path, columns, lines):
    """An inter-ply friction table's ``pressure_kPa`` column: a pressure is never negative."""
    pressure = columns.get("pressure_kPa")
    bad = np.flatnonzero(pressure < 0) if pressure is not None else []
    if len(bad):
        yield (str(path), lines[bad[0]], f"column pressure_kPa: {pressure[bad[0]]:g} kPa is "
               f"negative (a pressure on the overlap is >= 0; {len(bad)} such row(s))")


def _check_frame(setup, fname, where, index, label, problems) -> None:
    """A picture frame's fabric must fit in its frame (spec version 3)."""
    frame, fabric = setup.get("frame_side_mm"), setup.get("fabric_side_mm")
    if frame is not None and fabric is not None and fabric > frame:
        problems.add(fname, where("test", index, "fabric_side_mm"),
                     f"{label}: fabric_side_mm = {fabric:g} is larger than frame_side_mm = "
                     f"{frame:g}: the sheared fabric must fit inside the frame")


def _frame_table_ok(columns, setup, csv_path, fname, where, index, label, header_line,
                    problems) -> bool:
    """False (problem added) when a displacement takes the frame to or past its lock."""
    frame = setup.get("frame_side_mm")
    if frame is None:
        return True
    lock = (2.0 - math.sqrt(2.0)) * frame  # γ = 90°: cos(π/4 − γ/2) = (√2 L + d)/(2 L) = 1
    d = columns["displacement_mm"]
    bad = np.flatnonzero((d >= lock) | (d <= -math.sqrt(2.0) * frame))
    if bad.size:
        problems.add(str(csv_path), header_line + 1 + int(bad[0]),  # blank lines aside
                     f"{label}: data row {bad[0] + 1}: displacement_mm = {d[bad[0]]:g} is "
                     "beyond the lock of the frame "
                     f"(frame_side_mm = {frame:g} at {fname}:"
                     f"{where('test', index, 'frame_side_mm')} locks at γ = 90°, d = "
                     f"(2 − √2) L_frame = {lock:.4g} mm)")
        return False
    return True


def declared_noise(test: Test, noise: Mapping[str, float], by: str) -> Test:
    """``test`` with a declared noise (``force_sd_N`` in N, or ``force_sd_rel``).

    Unless it already has one: its own column, or an earlier declaration (the test's own keys
    come first, then [bundle], then MODEL.toml's [noise]).
    """
    if test.force_sd_N is not None or test.noise_declared_by is not None or not noise:
        return test
    return dataclasses.replace(test, noise_sd_N=noise.get("force_sd_N"),
                               noise_rel=noise.get("force_sd_rel"), noise_declared_by=by)


def _offered(key: str, value: Any, known) -> bool:
    """Whether a [[test]] key is offered to the test's case as an override."""
    scalar = isinstance(value, (str, int, float)) and not isinstance(value, bool)
    scalar = scalar or (key in PAIR_KEYS and _is_pair(value))
    return (key not in known and key not in CASE_DESCRIPTIVE_KEYS and scalar
            and _unit_problem(key) is None)


def _read_case(folder, fname, raw, index, where, label, known, problems, reader):
    """The case file a forming test names, read with the test's keys as overrides.

    Returns ``(case as written, absolute path, the keys the case used, the case)``; the last
    two are empty/None without a reader or when the case has problems (added to
    ``problems``, each with the line of the test's ``case`` key, the case file and its key).
    """
    at = where("test", index, "case")
    written = raw["case"]
    if not isinstance(written, str) or not written.strip():
        problems.add(fname, at, f"{label}: case must be the path of a case file (a string, "
                                "relative to the bundle folder)")
        return None, None, {}, None
    path = (folder / written).resolve()
    if not path.is_file():
        problems.add(fname, at, f"{label}: case = {written!r}: no such file {str(path)!r} "
                                "(the path is relative to the bundle folder)")
        return written, path, {}, None
    keys = {k: v for k, v in raw.items() if _offered(k, v, known)}
    if reader is None:  # read when the test is simulated: every key is offered to the case
        return written, path, keys, None
    try:
        case, used = reader(path, keys)
    except DrapeInputError as err:
        for problem in getattr(err, "problems", None) or [str(err)]:
            problems.add(fname, at, f"{label}: case {written!r}: {problem}")
        return written, path, {}, None
    return written, path, dict(used), case


def _read_table(path: Path, kind: str, label: str, problems: _Problems, check=None):
    """The CSV table of a test as read-only float columns, or None (problems added).

    ``check(path, columns, lines)``, if given, returns more ``(file, line, problem)``.
    """
    fname = str(path)
    before = len(problems.items)
    read = read_rows(path, label, problems.add)
    if read is None:
        return None
    header, header_line, rows = read
    required, optional = COLUMNS[kind]
    for name in header:
        if msg := _unit_problem(name):
            problems.add(fname, header_line, f"{label}: column {msg}")
    missing = _missing(required, header)
    if missing:
        guesses = [f"; {c!r}: did you mean `{g}`?" for c in header
                   if c not in required + optional and (g := likely_typo(c, missing))]
        problems.add(fname, header_line, f"{label}: missing column(s) {', '.join(missing)} "
                                         f"(a {kind} table needs {', '.join(required)}; its "
                                         f"header: {', '.join(header)}){''.join(guesses)}")
    duplicated = sorted({c for c in header if header.count(c) > 1})
    if duplicated:
        problems.add(fname, header_line, f"{label}: duplicate column(s) {', '.join(duplicated)}")
    if "" in header:
        problems.add(fname, header_line, f"{label}: empty column name in the header")
    if len(rows) < 2:
        problems.add(fname, header_line, f"{label}: the table needs at least two data rows "
                                         f"(has {len(rows)})")
    if len(problems.items) > before:
        return None
    values = np.empty((len(rows), len(header)))
    for r, (number, cells) in enumerate(rows):
        if len(cells) != len(header):
            problems.add(fname, number, f"{label}: {len(cells)} cells, but the header has "
                                        f"{len(header)} columns{ragged_hint(cells)}")
            continue
        for c, cell in enumerate(cells):
            try:
                value = float(cell)
            except ValueError:
                problems.add(fname, number, f"{label}: column {header[c]}: {cell!r} is not a "
                                            "number")
                continue
            if not math.isfinite(value):
                problems.add(fname, number, f"{label}: column {header[c]}: {cell!r} is not a "
                                            "finite number")
            values[r, c] = value
    if len(problems.items) > before:
        return None
    numbers = [number for number, _ in rows]
    columns = {name: values[:, c] for c, name in enumerate(header)}
    if "time_s" in columns:
        dt = np.diff(columns["time_s"])
        bad = np.flatnonzero(dt <= 0)
        if bad.size:
            r = bad[0] + 1
            problems.add(fname, numbers[r], f"{label}: time_s must increase row by row "
                                            f"({columns['time_s'][r - 1]:g} then "
                                            f"{columns['time_s'][r]:g}; {bad.size} such row(s))")
    for sd in ("force_sd_N", "position_sd_mm"):
        if sd in columns and (bad := np.flatnonzero(columns[sd] <= 0)).size:
            problems.add(fname, numbers[bad[0]], f"{label}: {sd} must be positive (one standard "
                                                 f"deviation), got {columns[sd][bad[0]]:g}")
    if kind == "forming":
        ij = np.stack([columns["i"], columns["j"]], axis=1)
        bad = np.flatnonzero((ij != np.round(ij)).any(axis=1))
        if bad.size:
            problems.add(fname, numbers[bad[0]], f"{label}: grid indices i, j must be integers")
        if "ply" in columns:  # a node once per ply (spec version 4)
            ij = np.column_stack([ij, columns["ply"]])
        _, first, counts = np.unique(ij, axis=0, return_index=True, return_counts=True)
        if (counts > 1).any():
            r = int(first[np.argmax(counts > 1)])
            dup = [i for i in range(len(ij)) if (ij[i] == ij[r]).all()][1]
            problems.add(fname, numbers[dup], f"{label}: grid node (i, j) = "
                                              f"({ij[r, 0]:g}, {ij[r, 1]:g}) appears twice")
    if check is not None and len(problems.items) == before:
        for file, line, problem in check(path, columns, numbers):
            problems.add(file, line, f"{label}: {problem}")
    if len(problems.items) > before:
        return None
    for array in columns.values():
        array.setflags(write=False)
    extra = [name for name in header if name not in required + optional]
    return columns, extra, header_line


def _speed_problem(columns: Mapping[str, np.ndarray], speed_mm_per_min: float) -> str | None:
    """A message when the speed key contradicts the table by a unit factor (mm/s, m, min)."""
    rate = np.abs(np.diff(columns["displacement_mm"]) / np.diff(columns["time_s"])) * 60.0
    moving = rate[rate > 1e-3 * rate.max()]
    if rate.max() <= 0 or moving.size == 0:
        return None
    table_speed = float(np.median(moving))
    if 1 / _SPEED_TOLERANCE < table_speed / speed_mm_per_min < _SPEED_TOLERANCE:
        return None
    return (f"speed_mm_per_min = {speed_mm_per_min:g}, but the table moves at "
            f"{table_speed:.4g} mm/min (inconsistent units? displacement_mm must be in mm "
            "and time_s in s)")


# --------------------------------------------------------------------------------------------
# Writing


def _format_table(columns: Mapping[str, np.ndarray], comment: str = "") -> str:
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    out = [f"# {line}" for line in comment.splitlines()]
    out.append(",".join(names))
    out.extend(",".join(repr(float(v)) for v in row) for row in data)
    return "\n".join(out) + "\n"


def write_bundle(bundle: Bundle, path: str | Path, *, comment: str = "") -> Path:
    """Write ``bundle`` as a bundle folder at ``path``; returns the folder.

    Each file is written atomically and ``bundle.toml`` last, so the folder never holds a
    ``bundle.toml`` that names a missing or half-written table. ``comment`` heads every file.
    """
    folder = Path(path)
    for test in bundle.tests:
        atomic_write_text(folder / test.file, _format_table(test.columns, comment))
    head: dict[str, Any] = {"name": bundle.name}
    if bundle.material:
        head["material"] = bundle.material
    if bundle.tows_per_mm is not None:
        head["tows_per_mm"] = bundle.tows_per_mm
    head.update({k: v for k, v in bundle.extra.items() if not isinstance(v, dict)})
    tables = []
    for test in bundle.tests:
        d: dict[str, Any] = {"id": test.id, "kind": test.kind, "file": test.file}
        if test.geometry is not None:
            d["geometry"] = test.geometry
        if test.case is not None:
            d["case"] = test.case
        if test.ply is not None:
            d["file_ply"] = test.ply
        keys = ("gauge_length_mm", "length_mm", "width_mm", "frame_side_mm", "fabric_side_mm",
                "speed_mm_per_min")
        d.update({k: getattr(test, k) for k in keys if getattr(test, k) is not None})
        if test.tows is not None and not test.tows_derived:
            d["tows"] = test.tows
        if test.noise_sd_N is not None:
            d["force_sd_N"] = test.noise_sd_N
        if test.noise_rel is not None:
            d["force_sd_rel"] = test.noise_rel
        d.update(test.forming)
        d.update(test.notes)
        if test.conditions:
            d["conditions"] = dict(test.conditions)
        tables.append(d)
    text = toml_text({"bundle": head, "test": tables}, comment=comment)
    atomic_write_text(folder / "bundle.toml", text)
    return folder
