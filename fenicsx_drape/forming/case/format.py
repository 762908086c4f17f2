"""A forming case as a file: ``case.toml`` (tools, blank, holder, duration, model).

The format is documented in ``docs/case-format.md`` and ``docs/cases.md``; a case
is one folder in ``meshes/`` (``meshes/hemisphere/case.toml``) holding the case file and its
tool geometry. :func:`load_case` reads and checks a case file and returns a
:class:`FormingCase` (frozen dataclasses, units in the names); every problem is reported with
the file and the key (``case.toml: [[tool]] 2 'geometry': no such file 'punch.stp'``), all
problems of a file at once. Paths in the file are relative to the case file.

Keyword *overrides* change a loaded case the way a measured forming test's keys override the
case it names (``docs/measurements.md``, "forming tests on any part"):
``load_case(path, duration_s=8.0, holder_force_N=500.0)``; :data:`OVERRIDES` lists the names.

This module is plain NumPy (Gmsh only to sample an outline curve); the tools are built from
the case by :func:`build_tools`, the run is :func:`fenicsx_drape.forming.running.run.run_case`.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
import tomllib
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError, ParameterError
from fenicsx_drape.fe.grid import TrussGrid, outline_grid, polygon_area
from fenicsx_drape.forming.terms.holder import FORCE_SHARES
from fenicsx_drape.forming.tools.motion import RigidMotion
from fenicsx_drape.forming.tools.surfaces import sample_curve_loop
from fenicsx_drape.materials.base import fields_of
from fenicsx_drape.materials.interply import InterplyLaw
from fenicsx_drape.provenance import file_digest

ROLES = ("punch", "die", "holder", "surface")
BUILTIN = "builtin:hemisphere"
# Tool geometry sources (load_surface) and outline curves (Gmsh), by suffix.
GEOMETRY_SUFFIXES = (".geo", ".py", ".step", ".stp", ".iges", ".igs", ".brep", ".stl", ".msh")
OUTLINE_SUFFIXES = (".geo", ".geo_unrolled", ".msh", ".step", ".stp", ".iges", ".igs", ".brep")
SHEET_SIDES = ("+x", "-x", "+y", "-y", "+z", "-z")
DEFAULT_SHEET_SIDE = {"punch": "+z", "die": "-z", "holder": "+z", "surface": "+z"}

# Names a measured test (or a command line) may override, besides tool parameter names.
OVERRIDES = ("duration_s", "step_mm", "penalty_factor", "stabilisation_N_per_mm", "cell_mm",
             "ply_angle_deg", "symmetry", "sheet_mm", "holder_force_N", "mu",
             "holder_force_share", "travel_mm", "blank_offset_mm", "tool_offset_mm", "die",
             "hold_origin")
# The overrides of the holder's values: override name -> HolderSpec field. The friction
# coefficient is ``mu`` everywhere: [holder] mu, drape form --mu, the set-up candidate.
HOLDER_OVERRIDES = {"holder_force_N": "force_N", "mu": "mu", "holder_force_share": "force_share"}
# Earlier spellings of an override, read as the new name with a warning.
OLD_OVERRIDES = {"holder_mu": "mu"}
# Set-up overrides that move or turn something off the case's symmetry planes.
SETUP_OVERRIDES = ("ply_angle_deg", "blank_offset_mm", "tool_offset_mm")


class CaseError(DrapeInputError):
    """A case file (or case) that cannot be used; ``problems`` lists every problem."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        if len(problems) == 1:
            message = problems[0]
        else:
            message = f"{len(problems)} problems:\n  " + "\n  ".join(problems)
        super().__init__(message)


# --------------------------------------------------------------------------------------------
# The case


@dataclasses.dataclass(frozen=True)
class ToolSpec:
    """One rigid tool of a case: its geometry source, role and motion."""

    name: str
    role: str  # punch | die | holder | surface
    geometry: str  # "builtin:hemisphere" or the file as written in the case
    path: Path | None = None  # the geometry file (absolute), None for builtin tools
    parameters: tuple[tuple[str, float], ...] = ()  # numbers for the geometry source
    mesh_mm: float | None = None  # tool mesh size for sources Gmsh meshes
    order: int | None = None  # 1 or 2 (second-order triangles split into four)
    sheet_side: str | None = None  # side of the surface the sheet is on (default by role)
    motion: RigidMotion | None = None  # fixed when None (builtin tools move as the hemisphere's)

    @property
    def builtin(self) -> bool:
        """Whether the tool is a closed-form builtin tool."""
        return self.geometry == BUILTIN

    @property
    def params(self) -> dict[str, float]:
        """The parameters as a dict."""
        return dict(self.parameters)

    @property
    def side(self) -> str:
        """The sheet side (given, or the role's default)."""
        return self.sheet_side or DEFAULT_SHEET_SIDE[self.role]


@dataclasses.dataclass(frozen=True)
class BlankSpec:
    """The blank: its outline, the tow net (Δ, ply angle, origin) and symmetry planes."""

    outline: str  # "rectangle" | "polygon" | the curve file as written in the case
    cell_mm: float  # unit-cell size Δ (mm)
    size_mm: tuple[float, float] | None = None  # rectangle: sides along x, y
    centre_mm: tuple[float, float] = (0.0, 0.0)  # rectangle: centre
    points_mm: tuple[tuple[float, float], ...] | None = None  # polygon (or the sampled curve)
    path: Path | None = None  # the outline curve file (absolute)
    ply_angle_deg: float = 0.0  # warp at this angle to x, the net turned about origin_mm
    origin_mm: tuple[float, float] = (0.0, 0.0)  # a node of the net
    symmetry: tuple[str, ...] = ()  # "x" (x = 0) and/or "y" (y = 0)
    # The net's node at origin_mm held in its plane: what is left of the planes x = 0 and
    # y = 0 when a model drops them (with_overrides).
    hold_origin: bool = False

    def polygon(self) -> np.ndarray:
        """The whole blank's outline as polygon vertices (m, 2) in mm."""
        if self.outline == "rectangle":
            (a, b), (cx, cy) = self.size_mm, self.centre_mm
            return np.array([[cx - a / 2, cy - b / 2], [cx + a / 2, cy - b / 2],
                             [cx + a / 2, cy + b / 2], [cx - a / 2, cy + b / 2]])
        return np.asarray(self.points_mm, dtype=float)

    @property
    def area_mm2(self) -> float:
        """Area of the outline (mm²)."""
        return polygon_area(self.polygon())

    def grid(self) -> TrussGrid:
        """The structured net of the blank (the modelled part of it, by symmetry).

        A rectangle centred on the net's origin with the tows along its sides is the paper's
        sheet: Δ is adjusted so that a whole number of cells fits each half of the x side
        (:func:`~fenicsx_drape.fe.grid.sheet_grid`'s rule), and the y side holds the whole
        cells that fit. Any other blank uses Δ as given and keeps the whole cells inside
        the outline (:func:`~fenicsx_drape.fe.grid.outline_grid`).
        """
        planes = tuple(p for p in ("x", "y") if p in self.symmetry)
        if (self.outline == "rectangle" and self.ply_angle_deg == 0.0
                and tuple(self.centre_mm) == tuple(self.origin_mm)):
            (a, b), (cx, cy) = self.size_mm, self.centre_mm
            n_x = max(1, round(a / 2 / self.cell_mm))
            Δ = a / 2 / n_x
            n_y = max(1, math.floor(b / 2 / Δ + 1e-9))
            half_b = b / 2 if abs(n_y * Δ - b / 2) <= 1e-9 * b else n_y * Δ
            for axis, plane in enumerate(("x", "y")):
                if plane in planes and (cx, cy)[axis] != 0.0:
                    raise DrapeInputError(f"blank: symmetry {plane!r} needs the rectangle "
                                          f"centred on the plane {plane} = 0")
            both = planes == ("x", "y")
            symmetry = None if both or not planes else planes
            return TrussGrid(n_x if "x" in planes else 2 * n_x,
                             n_y if "y" in planes else 2 * n_y, Δ,
                             (0.0 if "x" in planes else cx - a / 2,
                              0.0 if "y" in planes else cy - half_b),
                             both, symmetry=symmetry)
        return outline_grid(self.polygon(), self.cell_mm, origin_mm=self.origin_mm,
                            ply_angle_deg=self.ply_angle_deg, symmetry=planes)


@dataclasses.dataclass(frozen=True)
class PlySpec:
    """One ply of a stack (``[[ply]]``), in order from the punch side."""

    angle_deg: float  # its warp's angle within the stack (the blank's ply_angle_deg turns all)
    thickness_mm: float  # its thickness (mm): adjacent mid-planes lie (t_k + t_k+1)/2 apart
    model: Path | None = None  # its own MODEL.toml (absolute); None: the case's model


INTERPLY_KEYS = (*(f.name for f in fields_of(InterplyLaw, "parameter")), "interply_friction")
"""The keys of ``[interply]``: the inter-ply law's parameters and its effect switch."""


@dataclasses.dataclass(frozen=True)
class HolderSpec:
    """The blank holder: the tool whose surface clamps, the force and eq. 1's reading."""

    tool: str  # name of the clamping tool (role holder)
    force_N: float  # total holding force on the whole part (N)
    mu: float | None = None  # overrides the model's μ (eq. 1)
    force_share: str = "symmetric_part"  # "symmetric_part" | "model"


@dataclasses.dataclass(frozen=True)
class FormingCase:
    """A forming case: tools, blank, holder, duration, model and numerical choices."""

    name: str
    duration_s: float  # forming time of the whole motion (s)
    blank: BlankSpec
    tools: tuple[ToolSpec, ...]
    holder: HolderSpec | None = None
    description: str = ""
    model: Path | None = None  # MODEL.toml (absolute); None: the paper's model
    step_mm: float = 1.0  # travel of the fastest tool per load step (mm)
    penalty_factor: float = 0.3  # contact (and clamping) stiffness in units of l_t E_o
    stabilisation_N_per_mm: float = 1.25  # out-of-plane spring to the extrapolated motion
    path: Path | None = None  # the case file it was read from
    # Where the case came from when that is data (a measurement bundle): its Python geometry
    # and its model's plugins then run only with --trust (fenicsx_drape.trust).
    origin: str | None = None
    # A stack of two or more plies ([[ply]], from the punch side); () is one ply, the blank's.
    plies: tuple[PlySpec, ...] = ()
    # The inter-ply law's values ([interply]; the rest take InterplyLaw's defaults).
    interply: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        problems = _case_problems(self)
        if problems:
            raise CaseError([f"forming case {self.name!r}: {p}" for p in problems])

    @property
    def stack(self) -> bool:
        """Whether the blank is a stack of two or more plies."""
        return len(self.plies) > 1

    def ply_blanks(self) -> list[BlankSpec]:
        """The blank of each ply: its net turned by the blank's angle plus its own.

        The plies share one cell size: a rectangle's tow-aligned ply fits whole cells to its
        sides (:meth:`BlankSpec.grid`), and the turned plies take that Δ too.
        """
        if not self.plies:
            return [self.blank]
        blanks = [dataclasses.replace(self.blank,
                                      ply_angle_deg=self.blank.ply_angle_deg + p.angle_deg)
                  for p in self.plies]
        fitted = set()
        for b in blanks:
            try:
                fitted.add(b.grid().cell_mm)
            except DrapeInputError:  # reported with the ply by whoever builds its grid
                pass
        fitted -= {self.blank.cell_mm}
        if fitted:
            blanks = [dataclasses.replace(b, cell_mm=min(fitted)) for b in blanks]
        return blanks

    def interply_law(self, model=None) -> InterplyLaw:
        """The inter-ply law of the stack (``[interply]`` over InterplyLaw's defaults).

        Whether the plies slide: the table's ``interply_friction`` when it says, else the
        effect ``interply_friction`` of ``model`` (spec version 4: without it the plies are
        bonded), else they slide.
        """
        values = dict(self.interply)
        if "interply_friction" not in values and model is not None:
            values["interply_friction"] = "interply_friction" in model.effects
        return InterplyLaw(**values)

    def tool(self, name: str) -> ToolSpec:
        """The tool of this name."""
        for t in self.tools:
            if t.name == name:
                return t
        raise KeyError(name)

    @property
    def planes(self) -> tuple[str, ...]:
        """The blank's symmetry planes, in the order ("x", "y")."""
        return tuple(p for p in ("x", "y") if p in self.blank.symmetry)

    @property
    def folder(self) -> Path:
        """The folder of the case file (where relative paths start), else the working one."""
        return self.path.parent if self.path is not None else Path.cwd()

    def reach_mm(self) -> float:
        """Largest distance of the blank from the frame's origin (for rotating tools)."""
        return float(np.linalg.norm(self.blank.polygon(), axis=1).max())

    def speed_mm_per_s(self, spec: ToolSpec) -> float:
        """Fastest speed (mm/s) of a tool over the forming time."""
        if spec.builtin:
            travel = _builtin_tools(spec).travel_mm
            return travel / self.duration_s if spec.role == "punch" else 0.0
        if spec.motion is None:
            return 0.0
        c = np.asarray(spec.motion.centre_mm)[:2]
        reach = float(np.linalg.norm(self.blank.polygon() - c, axis=1).max())
        return spec.motion.max_speed_mm_per_s(reach)

    @property
    def max_speed_mm_per_s(self) -> float:
        """Speed of the fastest tool (mm/s): load steps move it ``step_mm``."""
        return max((self.speed_mm_per_s(t) for t in self.tools), default=0.0)

    def travel_mm(self, t: float) -> float:
        """Travel (mm) of the fastest-moving tool at time ``t`` (the progress measure)."""
        best = 0.0
        for spec in self.tools:
            if spec.builtin:
                if spec.role == "punch":
                    best = max(best, self.speed_mm_per_s(spec) * t)
            elif spec.motion is not None:
                c = np.asarray(spec.motion.centre_mm)[:2]
                reach = float(np.linalg.norm(self.blank.polygon() - c, axis=1).max())
                best = max(best, spec.motion.travel_mm(t, reach))
        return best

    @property
    def total_travel_mm(self) -> float:
        """Travel of the fastest-moving tool at the end of the forming time (mm)."""
        return self.travel_mm(self.duration_s)


def _case_problems(case: FormingCase) -> list[str]:
    """Consistency of a case built in Python (the loader reports the same with keys)."""
    out = []
    for name in ("duration_s", "step_mm", "penalty_factor"):
        if not (_finite(getattr(case, name)) and getattr(case, name) > 0):
            out.append(f"{name} = {getattr(case, name)!r} must be a positive number")
    if not (_finite(case.stabilisation_N_per_mm) and case.stabilisation_N_per_mm >= 0):
        out.append(f"stabilisation_N_per_mm = {case.stabilisation_N_per_mm!r} must be >= 0")
    names = [t.name for t in case.tools]
    if len(set(names)) != len(names):
        out.append(f"tool names must be unique: {names}")
    for t in case.tools:
        if t.role not in ROLES:
            out.append(f"tool {t.name!r}: role {t.role!r} is not one of {', '.join(ROLES)}")
    holders = [t.name for t in case.tools if t.role == "holder"]
    if case.holder is not None:
        h = case.holder
        if h.tool not in names:
            out.append(f"holder: no tool named {h.tool!r} (tools: {', '.join(names)})")
        elif case.tool(h.tool).role != "holder":
            out.append(f"holder: tool {h.tool!r} has role {case.tool(h.tool).role!r}, not "
                       "'holder'")
        if not (_finite(h.force_N) and h.force_N >= 0):
            out.append(f"holder: force_N = {h.force_N!r} must be >= 0")
        if h.mu is not None and not (_finite(h.mu) and h.mu >= 0):
            out.append(f"holder: mu = {h.mu!r} must be >= 0")
        if h.force_share not in FORCE_SHARES:
            out.append(f"holder: force_share = {h.force_share!r} is not one of "
                       f"{', '.join(FORCE_SHARES)}")
    for name in holders:
        if case.holder is None or case.holder.tool != name:
            out.append(f"tool {name!r} has role 'holder' but no [holder] names it")
    if not [t for t in case.tools if t.role != "holder"]:
        out.append("no punch, die or surface: nothing forms the sheet")
    elif not out and not case.max_speed_mm_per_s > 0:
        out.append("no tool moves: nothing forms the sheet")
    b = case.blank
    if not (_finite(b.cell_mm) and b.cell_mm > 0):
        out.append(f"blank: cell_mm = {b.cell_mm!r} must be a positive number")
    if not set(b.symmetry) <= {"x", "y"}:
        out.append(f"blank: symmetry = {list(b.symmetry)}: planes are \"x\" and \"y\"")
    if not isinstance(b.hold_origin, bool):
        out.append(f"blank: hold_origin = {b.hold_origin!r} must be true or false")
    for k, ply in enumerate(case.plies, 1):
        if not _finite(ply.angle_deg):
            out.append(f"ply {k}: angle_deg = {ply.angle_deg!r} must be a number")
        if not (_finite(ply.thickness_mm) and ply.thickness_mm > 0):
            out.append(f"ply {k}: thickness_mm = {ply.thickness_mm!r} must be > 0")
    unknown = [k for k, _ in case.interply if k not in INTERPLY_KEYS]
    if unknown:
        out.append(f"interply: unknown key(s) {unknown} (known: {', '.join(INTERPLY_KEYS)})")
    else:
        try:
            case.interply_law()
        except DrapeInputError as err:
            out.append(f"interply: {err}")
    return out


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def builtin_tools(case: FormingCase):
    """The builtin (closed-form hemisphere) tools of a case, as its punch's parameters say.

    Raises:
        CaseError: the case has no builtin tool.
    """
    specs = [t for t in case.tools if t.builtin]
    if not specs:
        raise CaseError([f"case {case.name!r}: has no builtin tool ({BUILTIN!r})"])
    return _builtin_tools(next((t for t in specs if t.role == "punch"), specs[0]))


def _builtin_tools(spec: ToolSpec):
    from fenicsx_drape.forming.tools.shapes import HemisphereTools

    return HemisphereTools(**spec.params)


# --------------------------------------------------------------------------------------------
# Reading


class _Reader:
    """Collects the problems of one case file, each named by file and key."""

    def __init__(self, fname: str):
        self.fname = fname
        self.problems: list[str] = []

    def add(self, where: str, message: str) -> None:
        self.problems.append(f"{self.fname}: {where}{': ' if where else ''}{message}")

    def raise_if_any(self) -> None:
        if self.problems:
            raise CaseError(self.problems)

    # Typed getters: add a problem and return the default when the value is bad.

    def number(self, table: Mapping, key: str, where: str, *, default=None, positive=False,
               nonnegative=False, required=False):
        if key not in table:
            if required:
                self.add(where, f"'{key}' is required")
            return default
        v = table[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            self.add(f"{where} '{key}'".strip(), f"{v!r} is not a number")
            return default
        if positive and not v > 0:
            self.add(f"{where} '{key}'".strip(), f"{v!r} must be > 0")
            return default
        if nonnegative and not v >= 0:
            self.add(f"{where} '{key}'".strip(), f"{v!r} must be >= 0")
            return default
        return float(v)

    def string(self, table: Mapping, key: str, where: str, *, default=None, required=False,
               choices=None):
        if key not in table:
            if required:
                self.add(where, f"'{key}' is required")
            return default
        v = table[key]
        if not isinstance(v, str) or not v:
            self.add(f"{where} '{key}'".strip(), f"{v!r} is not a (non-empty) string")
            return default
        if choices is not None and v not in choices:
            self.add(f"{where} '{key}'".strip(),
                     f"{v!r} is not one of {', '.join(repr(c) for c in choices)}")
            return default
        return v

    def vector(self, table: Mapping, key: str, where: str, n: int, *, default=None,
               positive=False, required=False):
        if key not in table:
            if required:
                self.add(where, f"'{key}' is required")
            return default
        v = table[key]
        at = f"{where} '{key}'".strip()
        if (not isinstance(v, list) or len(v) != n
                or not all(_finite(c) for c in v)):
            self.add(at, f"{v!r} must be a list of {n} numbers")
            return default
        if positive and not all(c > 0 for c in v):
            self.add(at, f"{v!r}: sizes must be > 0")
            return default
        return tuple(float(c) for c in v)

    def unknown(self, table: Mapping, known, where: str) -> None:
        for key in table:
            if key not in known:
                self.add(where, f"unknown key '{key}' (known: {', '.join(sorted(known))})")

    def table(self, raw: Mapping, key: str, where: str, required=False) -> dict | None:
        if key not in raw:
            if required:
                self.add("", f"[{key}] is required")
            return None
        v = raw[key]
        if not isinstance(v, dict):
            self.add(where, f"'{key}' must be a table")
            return None
        return v


# The cases of the repository, by name: ``meshes/NAME/case.toml`` (the paper's hemisphere,
# the double dome, the square box).
CASES_FOLDER = Path(__file__).resolve().parents[3] / "meshes"


def case_file(case: str | os.PathLike) -> Path:
    """The file of a case: a path as given, or a case of the repository by its name.

    ``"hemisphere"`` is ``meshes/hemisphere/case.toml`` (and so on for every folder of
    ``meshes/`` holding a ``case.toml``); anything with a suffix or a folder is a path.
    """
    path = Path(case)
    if path.suffix or len(path.parts) != 1 or path.exists():
        return path
    named = CASES_FOLDER / path.name / "case.toml"
    if not named.is_file():
        known = sorted(p.parent.name for p in CASES_FOLDER.glob("*/case.toml"))
        raise CaseError([f"{str(case)!r}: not a case file (.toml) nor a named case "
                         f"({', '.join(known) or 'none found in ' + str(CASES_FOLDER)})"])
    return named


def load_case(path: str | os.PathLike, **overrides: Any) -> FormingCase:
    """Read and check a forming case file; ``overrides`` change it (:data:`OVERRIDES`).

    Args:
        path: The ``case.toml`` file, or a named case (:func:`case_file`: ``"hemisphere"``).
        **overrides: e.g. ``duration_s=8.0, holder_force_N=500.0, cell_mm=20.0`` or a tool
            parameter by name (``punch_radius_mm=50.0``): see :func:`with_overrides`.

    Raises:
        CaseError: with every problem of the file, each naming the file and the key.
    """
    path = case_file(path)
    fname = str(path)
    if not path.is_file():
        raise CaseError([f"{fname}: no such case file"])
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise CaseError([f"{fname}: cannot read the case file ({err})"]) from err
    except tomllib.TOMLDecodeError as err:
        raise CaseError([f"{fname}: not valid TOML ({err})"]) from err
    r = _Reader(fname)
    folder = path.resolve().parent
    r.unknown(raw, ("case", "blank", "holder", "tool", "ply", "interply"), "")

    c = r.table(raw, "case", "[case]", required=True) or {}
    r.unknown(c, ("name", "description", "duration_s", "model", "step_mm", "penalty_factor",
                  "stabilisation_N_per_mm"), "[case]")
    name = r.string(c, "name", "[case]", required=True, default="case")
    description = r.string(c, "description", "[case]", default="") if "description" in c else ""
    duration = r.number(c, "duration_s", "[case]", positive=True, required=True, default=1.0)
    step = r.number(c, "step_mm", "[case]", positive=True, default=1.0)
    penalty = r.number(c, "penalty_factor", "[case]", positive=True, default=0.3)
    stab = r.number(c, "stabilisation_N_per_mm", "[case]", nonnegative=True, default=1.25)
    model = None
    if (m := r.string(c, "model", "[case]")) is not None:
        model = (folder / m).resolve()
        if not model.is_file():
            r.add("[case] 'model'", f"no such file {m!r}")

    blank = _read_blank(r, raw, folder)
    tools = _read_tools(r, raw, folder, duration)
    plies = _read_plies(r, raw, folder)
    interply = ()
    if (ip := r.table(raw, "interply", "[interply]")) is not None:
        r.unknown(ip, INTERPLY_KEYS, "[interply]")
        for key, value in ip.items():
            if key == "interply_friction":
                if not isinstance(value, bool):
                    r.add("[interply] 'interply_friction'", f"{value!r} must be true or false")
            elif key in INTERPLY_KEYS:
                r.number(ip, key, "[interply]", nonnegative=True)
        interply = tuple(ip.items())
        if not r.problems:
            try:
                InterplyLaw(**ip)
            except DrapeInputError as err:
                r.add("[interply]", str(err))
    if len(plies) == 1:  # one ply is today's case: its angle turns the blank's net
        blank = dataclasses.replace(blank, ply_angle_deg=blank.ply_angle_deg + plies[0].angle_deg)
        model = plies[0].model or model
        plies = []
    holder = None
    if (h := r.table(raw, "holder", "[holder]")) is not None:
        r.unknown(h, ("tool", "force_N", "mu", "force_share"), "[holder]")
        tool = r.string(h, "tool", "[holder]", required=True, default="")
        force = r.number(h, "force_N", "[holder]", nonnegative=True, required=True, default=0.0)
        mu = r.number(h, "mu", "[holder]", nonnegative=True)
        share = r.string(h, "force_share", "[holder]", choices=FORCE_SHARES,
                         default="symmetric_part")
        holder = HolderSpec(tool, force, mu, share)
        names = {t.name: t for t in tools}
        if tool and tool not in names:
            r.add("[holder] 'tool'", f"no tool named {tool!r} (tools: "
                                     f"{', '.join(names) or 'none'})")
        elif tool in names and names[tool].role != "holder":
            r.add("[holder] 'tool'", f"tool {tool!r} has role {names[tool].role!r}; the "
                                     "clamping tool needs role = \"holder\"")
    r.raise_if_any()
    try:
        case = FormingCase(name=name, duration_s=duration, blank=blank, tools=tuple(tools),
                           holder=holder, description=description, model=model, step_mm=step,
                           penalty_factor=penalty, stabilisation_N_per_mm=stab, path=path,
                           plies=tuple(plies), interply=interply)
    except CaseError as err:
        raise CaseError([f"{fname}: {p.split(': ', 1)[1]}" for p in err.problems]) from None
    if any(v is not None for v in overrides.values()):
        # Overrides first (--full removes the planes an off-centre blank breaks), then the
        # check of the blank, in with_overrides.
        case = with_overrides(case, **overrides)
    else:
        for k, blank_k in enumerate(case.ply_blanks(), 1):
            try:
                blank_k.grid()
            except DrapeInputError as err:
                at = f"[[ply]] {k}" if case.plies else "[blank]"
                raise CaseError([f"{fname}: {at}: {err}"]) from None
    try:
        check_tool_sizes(case, warn=False)  # sizes before memory: refused at once
        check_run_size(case)  # and the run's length
    except DrapeInputError as err:
        raise CaseError([str(err)]) from None
    return case


def _read_blank(r: _Reader, raw: Mapping, folder: Path) -> BlankSpec:
    b = r.table(raw, "blank", "[blank]", required=True) or {}
    at = "[blank]"
    r.unknown(b, ("outline", "size_mm", "centre_mm", "points_mm", "cell_mm", "ply_angle_deg",
                  "origin_mm", "symmetry", "hold_origin"), at)
    outline = r.string(b, "outline", at, required=True, default="rectangle")
    cell = r.number(b, "cell_mm", at, positive=True, required=True, default=10.0)
    angle = r.number(b, "ply_angle_deg", at, default=0.0)
    origin = r.vector(b, "origin_mm", at, 2, default=(0.0, 0.0))
    symmetry: tuple[str, ...] = ()
    if "symmetry" in b:
        s = b["symmetry"]
        if (not isinstance(s, list) or not all(p in ("x", "y") for p in s)
                or len(set(s)) != len(s)):
            r.add(f"{at} 'symmetry'", f"{s!r} must be a list of planes \"x\" (x = 0) and/or "
                                      "\"y\" (y = 0), each once")
        else:
            symmetry = tuple(p for p in ("x", "y") if p in s)
    hold_origin = b.get("hold_origin", False)
    if not isinstance(hold_origin, bool):
        r.add(f"{at} 'hold_origin'", f"{hold_origin!r} must be true or false")
        hold_origin = False
    size = centre = points = path = None
    centre = (0.0, 0.0)
    rect_keys, poly_keys = ("size_mm", "centre_mm"), ("points_mm",)
    if outline == "rectangle":
        size = r.vector(b, "size_mm", at, 2, positive=True, required=True, default=(1.0, 1.0))
        centre = r.vector(b, "centre_mm", at, 2, default=(0.0, 0.0))
        wrong = poly_keys
    elif outline == "polygon":
        wrong = rect_keys
        if "points_mm" not in b:
            r.add(at, "'points_mm' is required for outline = \"polygon\"")
        else:
            v = b["points_mm"]
            if (not isinstance(v, list) or len(v) < 3
                    or not all(isinstance(p, list) and len(p) == 2 and all(_finite(c) for c in p)
                               for p in v)):
                r.add(f"{at} 'points_mm'", "must be a list of at least three [x, y] points (mm)")
            else:
                points = tuple((float(x), float(y)) for x, y in v)
                if not polygon_area(np.array(points)) > 0:
                    r.add(f"{at} 'points_mm'", "the polygon encloses no area")
    else:
        wrong = rect_keys + poly_keys
        path = (folder / outline).resolve()
        if path.suffix.lower() not in OUTLINE_SUFFIXES:
            r.add(f"{at} 'outline'", f"{outline!r} is not \"rectangle\", \"polygon\" or a Gmsh "
                                     f"file ({', '.join(OUTLINE_SUFFIXES)})")
        elif not path.is_file():
            r.add(f"{at} 'outline'", f"no such file {outline!r}")
        elif cell is not None:
            try:
                points = sample_outline(path, spacing_mm=cell / 4)
            except DrapeInputError as err:
                r.add(f"{at} 'outline'", str(err))
    for key in wrong:
        if key in b:
            r.add(f"{at} '{key}'", f"does not apply to outline = {outline!r}")
    return BlankSpec(outline=outline, cell_mm=cell, size_mm=size, centre_mm=centre,
                     points_mm=points, path=path, ply_angle_deg=angle, origin_mm=origin,
                     symmetry=symmetry, hold_origin=hold_origin)


def _read_plies(r: _Reader, raw: Mapping, folder: Path) -> list[PlySpec]:
    """The ``[[ply]]`` tables, in order from the punch side (none: the blank is one ply)."""
    items = raw.get("ply", [])
    if not isinstance(items, list) or not all(isinstance(p, dict) for p in items):
        r.add("", "'ply' must be an array of tables ([[ply]])")
        return []
    plies = []
    for k, p in enumerate(items, 1):
        at = f"[[ply]] {k}"
        r.unknown(p, ("angle_deg", "thickness_mm", "model"), at)
        angle = r.number(p, "angle_deg", at, required=True, default=0.0)
        thickness = r.number(p, "thickness_mm", at, positive=True, required=True, default=0.3)
        model = None
        if (m := r.string(p, "model", at)) is not None:
            model = (folder / m).resolve()
            if not model.is_file():
                r.add(f"{at} 'model'", f"no such file {m!r}")
        plies.append(PlySpec(angle, thickness, model))
    return plies


def _read_tools(r: _Reader, raw: Mapping, folder: Path, duration: float) -> list[ToolSpec]:
    if "tool" not in raw:
        r.add("", "no [[tool]]: a case needs at least one tool")
        return []
    items = raw["tool"]
    if not isinstance(items, list) or not all(isinstance(t, dict) for t in items):
        r.add("", "'tool' must be an array of tables [[tool]]")
        return []
    tools, seen = [], set()
    for k, t in enumerate(items, start=1):
        at = f"[[tool]] {k}"
        r.unknown(t, ("name", "role", "geometry", "parameters", "mesh_mm", "order",
                      "sheet_side", "motion"), at)
        name = r.string(t, "name", at, required=True, default=f"tool{k}")
        if name in seen:
            r.add(f"{at} 'name'", f"{name!r} is used by another tool")
        seen.add(name)
        role = r.string(t, "role", at, required=True, choices=ROLES, default="surface")
        geometry = r.string(t, "geometry", at, required=True, default=BUILTIN)
        params: dict[str, float] = {}
        if "parameters" in t:
            p = t["parameters"]
            if not isinstance(p, dict):
                r.add(f"{at} 'parameters'", "must be a table of numbers")
            else:
                for key, v in p.items():
                    if not _finite(v):
                        r.add(f"{at} 'parameters' '{key}'", f"{v!r} is not a number")
                    else:
                        params[key] = float(v)
        mesh = r.number(t, "mesh_mm", at, positive=True)
        order = None
        if "order" in t:
            if t["order"] not in (1, 2) or isinstance(t["order"], bool):
                r.add(f"{at} 'order'", f"{t['order']!r} must be 1 or 2")
            else:
                order = int(t["order"])
        side = r.string(t, "sheet_side", at, choices=SHEET_SIDES)
        motion = None
        if "motion" in t:
            motion = _read_motion(r, t["motion"], f"{at} [tool.motion]", duration)
        path = None
        if geometry.startswith("builtin:"):
            if geometry != BUILTIN:
                r.add(f"{at} 'geometry'", f"{geometry!r}: the builtin geometry is {BUILTIN!r}")
            else:
                _check_builtin(r, at, role, params, mesh, order, side, motion)
        else:
            path = (folder / geometry).resolve()
            if path.suffix.lower() not in GEOMETRY_SUFFIXES:
                r.add(f"{at} 'geometry'", f"{geometry!r}: unknown kind of file (known: "
                                          f"{', '.join(GEOMETRY_SUFFIXES)}, or {BUILTIN!r})")
            elif not path.is_file():
                r.add(f"{at} 'geometry'", f"no such file {geometry!r}")
            elif path.suffix.lower() == ".geo":
                _check_geo_tool(r, at, path, params)
        tools.append(ToolSpec(name=name, role=role, geometry=geometry, path=path,
                              parameters=tuple(params.items()), mesh_mm=mesh, order=order,
                              sheet_side=side, motion=motion))
    return tools


def _check_geo_tool(r: _Reader, at: str, path: Path, params: Mapping[str, float]) -> None:
    """A Gmsh script tool: nothing beyond geometry (unless trusted), every parameter used."""
    from fenicsx_drape.trust import geo_defines, geo_problems, trusted

    if not trusted():
        for problem in geo_problems(path):
            r.add(f"{at} 'geometry'", f"{problem} (pass --trust to run it anyway)")
    for key in params:
        if not geo_defines(path, key):
            r.add(f"{at} 'parameters' '{key}'", f"not used by {path.name} (a misspelt name "
                                                "would be silently ignored)")


def _check_builtin(r: _Reader, at: str, role, params, mesh, order, side, motion) -> None:
    from fenicsx_drape.forming.tools.shapes import HemisphereTools

    if role not in ("punch", "die", "holder"):
        r.add(f"{at} 'role'", f"{BUILTIN!r} gives the hemisphere's punch, die or holder, "
                              f"not a {role!r}")
    known = [f.name for f in dataclasses.fields(HemisphereTools)]
    for key in params:
        if key not in known:
            r.add(f"{at} 'parameters' '{key}'", f"not a parameter of {BUILTIN!r} (known: "
                                                f"{', '.join(known)})")
    for key, value in (("mesh_mm", mesh), ("order", order), ("sheet_side", side),
                       ("motion", motion)):
        if value is not None:
            r.add(f"{at} '{key}'", f"does not apply to {BUILTIN!r} (its tools are exact "
                                   "surfaces and move as the paper's)")
    if all(key in known for key in params):
        try:
            HemisphereTools(**params)
        except ParameterError as err:
            r.add(f"{at} 'parameters'", str(err))


def _read_motion(r: _Reader, m, at: str, duration: float | None) -> RigidMotion | None:
    if not isinstance(m, dict):
        r.add(at, "must be a table")
        return None
    r.unknown(m, ("time_s", "x_mm", "y_mm", "z_mm", "rotation_deg", "axis", "centre_mm"), at)
    before = len(r.problems)
    columns = {}
    for key in ("time_s", "x_mm", "y_mm", "z_mm", "rotation_deg"):
        if key not in m:
            continue
        v = m[key]
        if not isinstance(v, list) or not v or not all(_finite(c) for c in v):
            r.add(f"{at} '{key}'", f"{v!r} must be a list of numbers")
        else:
            columns[key] = tuple(float(c) for c in v)
    if "time_s" not in m:
        r.add(at, "'time_s' is required")
    if not any(k in m for k in ("x_mm", "y_mm", "z_mm", "rotation_deg")):
        r.add(at, "needs at least one of x_mm, y_mm, z_mm, rotation_deg")
    if len(r.problems) > before:
        return None
    t = columns["time_s"]
    for key, col in columns.items():
        if len(col) != len(t):
            r.add(f"{at} '{key}'", f"{len(col)} values for {len(t)} times in 'time_s'")
    if t[0] != 0.0:
        r.add(f"{at} 'time_s'", f"must start at 0 (the start of forming), not {t[0]:g}")
    if any(b <= a for a, b in itertools.pairwise(t)):
        r.add(f"{at} 'time_s'", "must increase from row to row")
    if duration is not None and t[-1] > duration * (1 + 1e-12):
        r.add(f"{at} 'time_s'", f"the motion runs to {t[-1]:g} s, past [case] duration_s = "
                                f"{duration:g}")
    axis = r.vector(m, "axis", at, 3, default=(0.0, 0.0, 1.0))
    centre = r.vector(m, "centre_mm", at, 3, default=(0.0, 0.0, 0.0))
    if not np.linalg.norm(axis) > 0:
        r.add(f"{at} 'axis'", "must not be zero")
    if "rotation_deg" not in columns:
        for key in ("axis", "centre_mm"):
            if key in m:
                r.add(f"{at} '{key}'", "applies only with 'rotation_deg'")
    if len(r.problems) > before:
        return None
    return RigidMotion(time_s=t, x_mm=columns.get("x_mm"), y_mm=columns.get("y_mm"),
                       z_mm=columns.get("z_mm"), rotation_deg=columns.get("rotation_deg"),
                       axis=axis, centre_mm=centre, where=at)


def sample_outline(path: str | os.PathLike, spacing_mm: float) -> tuple[tuple[float, float], ...]:
    """The closed curve loop of a Gmsh-readable file as a polygon in the sheet plane.

    The file (a ``.geo`` script, ``.msh``, STEP, IGES or BREP) must hold one closed chain of
    curves at z = 0; its curves are meshed with segments of ``spacing_mm`` (a mesh in the file
    is used as it is) and the segments chained into one loop.

    A ``.geo`` script is checked (:func:`~fenicsx_drape.trust.check_geo`) and runs in a
    child process with a time limit (:func:`~fenicsx_drape.limits.run_script`).

    Raises:
        DrapeInputError: no curve, not one closed loop, or not in the plane z = 0.
    """
    path = Path(path)
    if path.suffix.lower() in (".geo", ".geo_unrolled") and path.is_file():
        from fenicsx_drape.limits import run_script
        from fenicsx_drape.trust import check_geo

        check_geo(path)
        return run_script(sample_curve_loop, (path, spacing_mm), path)
    return sample_curve_loop(path, spacing_mm)


# --------------------------------------------------------------------------------------------
# Overrides


def with_overrides(case: FormingCase, **overrides: Any) -> FormingCase:
    """The case with some values changed, as a measured test's keys override its case.

    Names (:data:`OVERRIDES`): ``duration_s`` (motion tables are stretched to it),
    ``step_mm``, ``penalty_factor``, ``stabilisation_N_per_mm``, ``cell_mm``,
    ``ply_angle_deg``, ``symmetry`` (a list of planes; ``[]`` for the full blank),
    ``sheet_mm`` (a square rectangle blank), ``holder_force_N``, ``mu`` (the holder's
    friction coefficient; ``holder_mu``, its earlier name, is read as ``mu`` with a warning),
    ``holder_force_share``, ``travel_mm`` (builtin tools' parameter; motion tables are
    scaled so that the fastest tool travels it), ``blank_offset_mm`` ([x, y]: the blank and
    its net moved on the tools), ``tool_offset_mm`` ([x, y]: the punch moved off the die and
    holder), ``die`` (False: the case's dies left out), ``hold_origin`` (the net's node at
    ``origin_mm`` held in plane), and any tool parameter by name (every tool that has it, e.g.
    ``punch_radius_mm``). None values are ignored.

    A set-up override (:data:`SETUP_OVERRIDES`) that breaks a symmetry plane of the case
    removes that plane (the model needs the part of the blank the plane would mirror) unless
    ``symmetry`` is given too; :func:`broken_planes` says which.

    A holder whose ``force_share`` is ``"model"`` (the force shared over the model's own nodes)
    keeps its press when planes are dropped: its force is doubled per plane dropped, so that
    the whole blank formed for a set-up is held as the stated quarter was.

    When a case symmetric in both planes loses one (``symmetry``, a set-up), the net's node
    at ``origin_mm`` (the blank's centre; it moves with ``blank_offset_mm``) is held in plane
    (``hold_origin``, unless given), as the planes held it. Without it a sheet on
    frictionless tools, once the holder's friction bars (eq. 1) yield, slides on the tools
    as a whole to where small differences take it (``docs/setup-diagnosis.md``). With a
    turned ply or the whole sheet the part keeps the planes' half turn about x = y = 0, so
    the hold is exact; with an offset it stands for the friction that keeps a placed blank
    in place.
    """
    where = str(case.path) if case.path is not None else f"case {case.name!r}"
    overrides = {renamed(k, where): v for k, v in overrides.items() if v is not None}
    param_names = {k for t in case.tools for k, _ in t.parameters}
    builtin_names = set()
    if any(t.builtin for t in case.tools):
        from fenicsx_drape.forming.tools.shapes import HemisphereTools

        builtin_names = {f.name for f in dataclasses.fields(HemisphereTools)}
    problems = []
    for key in overrides:
        if key not in OVERRIDES and key not in param_names | builtin_names:
            problems.append(f"{where}: override {key!r}: not a case value (known: "
                            f"{', '.join(OVERRIDES)}, or a tool parameter)")
    if problems:
        raise CaseError(problems)
    changes: dict[str, Any] = {}
    blank = case.blank
    tools = list(case.tools)
    holder = case.holder
    for key in ("step_mm", "penalty_factor", "stabilisation_N_per_mm"):
        if key in overrides:
            changes[key] = float(overrides[key])
    if "duration_s" in overrides:
        new = float(overrides["duration_s"])
        if not (_finite(new) and new > 0):
            raise CaseError([f"{where}: override duration_s = {new!r} must be > 0"])
        f = new / case.duration_s
        tools = [dataclasses.replace(t, motion=t.motion.scaled(time=f)) if t.motion else t
                 for t in tools]
        changes["duration_s"] = new
    if "cell_mm" in overrides:
        blank = dataclasses.replace(blank, cell_mm=float(overrides["cell_mm"]))
    if "ply_angle_deg" in overrides:
        blank = dataclasses.replace(blank, ply_angle_deg=float(overrides["ply_angle_deg"]))
    if "blank_offset_mm" in overrides:
        d = _offset(overrides["blank_offset_mm"], "blank_offset_mm", where)
        def shift(p):
            return (float(p[0] + d[0]), float(p[1] + d[1]))

        moved = {"origin_mm": shift(blank.origin_mm)}
        if blank.outline == "rectangle":
            moved["centre_mm"] = shift(blank.centre_mm)
        else:  # a polygon, or a curve's sampled points: the moved points are the outline
            moved.update(outline="polygon", path=None,
                         points_mm=tuple(shift(p) for p in blank.points_mm))
        blank = dataclasses.replace(blank, **moved)
    if "symmetry" in overrides:
        blank = dataclasses.replace(blank, symmetry=tuple(overrides["symmetry"]))
        kept = broken_planes(overrides) & set(blank.symmetry)
        if kept:
            raise CaseError([f"{where}: the set-up {_setup_text(overrides)} breaks the "
                             f"symmetry plane(s) {sorted(kept)}: model without them "
                             "(symmetry = [], drape form --full)"])
    elif broken_planes(overrides) & set(blank.symmetry):
        blank = dataclasses.replace(blank, symmetry=tuple(
            p for p in blank.symmetry if p not in broken_planes(overrides)))
    if "hold_origin" in overrides:
        if not isinstance(overrides["hold_origin"], (bool, np.bool_)):
            raise CaseError([f"{where}: override hold_origin = {overrides['hold_origin']!r} "
                             "must be true or false"])
        blank = dataclasses.replace(blank, hold_origin=bool(overrides["hold_origin"]))
    elif set(case.blank.symmetry) == {"x", "y"} and set(blank.symmetry) != {"x", "y"}:
        blank = dataclasses.replace(blank, hold_origin=True)
    if "sheet_mm" in overrides:
        if blank.outline != "rectangle":
            raise CaseError([f"{where}: override sheet_mm: the blank is not a rectangle"])
        s = float(overrides["sheet_mm"])
        blank = dataclasses.replace(blank, size_mm=(s, s))
    if holder is None and any(k in HOLDER_OVERRIDES for k in overrides):
        raise CaseError([f"{where}: holder overrides given, but the case has no [holder]"])
    if holder is not None:
        holder = dataclasses.replace(
            holder, force_N=float(overrides.get("holder_force_N", holder.force_N)),
            mu=overrides.get("mu", holder.mu),
            force_share=overrides.get("holder_force_share", holder.force_share))
        if holder.force_share == "model" and "holder_force_share" not in overrides:
            # "model" shares F over the model's own nodes: the same press on a model with
            # fewer symmetry planes keeps each node's force, F × 2 per plane dropped (a whole
            # blank formed for a set-up is pressed as the stated quarter was).
            dropped = len(case.blank.symmetry) - len(blank.symmetry)
            holder = dataclasses.replace(holder, force_N=holder.force_N * 2.0**dropped)
    params = {k: float(v) for k, v in overrides.items() if k in param_names | builtin_names}
    if "travel_mm" in overrides:
        travel = float(overrides["travel_mm"])
        if not (math.isfinite(travel) and travel > 0):
            raise CaseError([f"{where}: override travel_mm = {travel:g}: a travel against the "
                             "tool's motion (travel is the distance the fastest tool moves "
                             "along its motion, > 0)"])
        moving = [t for t in tools if not t.builtin and t.motion is not None]
        if moving:
            now = max(t.motion.travel_mm(t.motion.time_s[-1]) for t in moving)
            if not now > 0:
                raise CaseError([f"{where}: override travel_mm: no tool translates"])
            tools = [dataclasses.replace(t, motion=t.motion.scaled(travel=travel / now))
                     if t in moving else t for t in tools]
        if any(t.builtin for t in tools):
            params["travel_mm"] = travel
    if params:
        def applies(t: ToolSpec, k: str) -> bool:
            return (t.builtin and k in builtin_names) or k in t.params

        tools = [dataclasses.replace(t, parameters=tuple({**t.params, **{
            k: v for k, v in params.items() if applies(t, k)}}.items())) for t in tools]
    if "die" in overrides and not overrides["die"]:
        if not any(t.role == "die" for t in tools):
            raise CaseError([f"{where}: override die = false: the case has no tool of role "
                             "'die'"])
        tools = [t for t in tools if t.role != "die"]
    if "tool_offset_mm" in overrides:  # after travel_mm, which scales the motion tables
        tools = _offset_punches(tools, _offset(overrides["tool_offset_mm"], "tool_offset_mm",
                                               where), changes.get("duration_s",
                                                                   case.duration_s), where)
    try:
        new_case = dataclasses.replace(case, blank=blank, tools=tuple(tools), holder=holder,
                                       **changes)
        for blank_k in new_case.ply_blanks():
            blank_k.grid()
        check_tool_sizes(new_case, warn=False)
        check_run_size(new_case)
        for t in new_case.tools:
            if t.builtin:
                _builtin_tools(t)
    except DrapeInputError as err:
        raise CaseError([f"{where}: with overrides {overrides}: {err}"]) from None
    return new_case


def broken_planes(overrides: Mapping[str, Any]) -> set[str]:
    """The symmetry planes (``"x"``: x = 0, ``"y"``: y = 0) a set-up's overrides break.

    A ply turned by other than a multiple of 90° breaks both; an offset of the blank or the
    punch along x breaks the plane x = 0, along y the plane y = 0.
    """
    out = set()
    θ = overrides.get("ply_angle_deg")
    if θ is not None and float(θ) % 90.0 != 0.0:
        out |= {"x", "y"}
    for key in ("blank_offset_mm", "tool_offset_mm"):
        d = overrides.get(key)
        if d is not None:
            out |= {p for p, v in zip(("x", "y"), np.ravel(np.asarray(d, dtype=float)))
                    if v != 0.0}
    return out


def _setup_text(overrides: Mapping[str, Any]) -> str:
    return ", ".join(f"{k} = {overrides[k]}" for k in SETUP_OVERRIDES if k in overrides)


def _offset(value: Any, key: str, where: str) -> tuple[float, float]:
    """An [x, y] offset in mm, checked."""
    try:
        d = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        d = ()
    if len(d) != 2 or not all(math.isfinite(v) for v in d):
        raise CaseError([f"{where}: override {key} = {value!r} must be [x, y] in mm"])
    return d


def _offset_punches(tools: list[ToolSpec], d: tuple[float, float], duration: float,
                    where: str) -> list[ToolSpec]:
    """The tools with every punch moved by ``d`` (mm) in x and y, die and holder in place."""
    punches = [t for t in tools if t.role == "punch"]
    if not punches:
        raise CaseError([f"{where}: override tool_offset_mm: the case has no tool of role "
                         "'punch'"])
    out = []
    for t in tools:
        if t.role != "punch":
            out.append(t)
        elif t.builtin:
            p = t.params
            p["punch_x_mm"] = p.get("punch_x_mm", 0.0) + d[0]
            p["punch_y_mm"] = p.get("punch_y_mm", 0.0) + d[1]
            out.append(dataclasses.replace(t, parameters=tuple(p.items())))
        else:
            m = t.motion or RigidMotion(time_s=(0.0, duration))
            # A constant translation added to the motion's table: the same travel and speed.
            out.append(dataclasses.replace(t, motion=dataclasses.replace(
                m, x_mm=tuple(v + d[0] for v in m.x_mm), y_mm=tuple(v + d[1] for v in m.y_mm))))
    return out


# The forming keys of the measurement spec's hemisphere tests: in a test that names a case,
# they must name a value of the case (else they would be silently ignored).
SPEC_FORMING_KEYS = ("punch_radius_mm", "fillet_radius_mm", "holder_opening_mm", "sheet_mm",
                     "travel_mm", "duration_s", "holder_force_N")


def override_names(case: FormingCase) -> set[str]:
    """The names :func:`with_overrides` accepts for ``case``: :data:`OVERRIDES` and parameters."""
    names = set(OVERRIDES) | {k for t in case.tools for k, _ in t.parameters}
    if any(t.builtin for t in case.tools):
        from fenicsx_drape.forming.tools.shapes import HemisphereTools

        names |= {f.name for f in dataclasses.fields(HemisphereTools)}
    return names


def renamed(key: str, where: str) -> str:
    """An override's name, an earlier spelling (:data:`OLD_OVERRIDES`) read as today's."""
    if key in OLD_OVERRIDES:
        warnings.warn(f"{where}: {key} is now called {OLD_OVERRIDES[key]} (read as "
                      f"{OLD_OVERRIDES[key]})", FutureWarning, stacklevel=3)
    return OLD_OVERRIDES.get(key, key)


def case_value(case: FormingCase, key: str) -> Any:
    """The case's own value of an override name (None when it has none to compare)."""
    if key in ("duration_s", "step_mm", "penalty_factor", "stabilisation_N_per_mm"):
        return getattr(case, key)
    if key == "travel_mm":
        return case.total_travel_mm
    if key in ("cell_mm", "ply_angle_deg"):
        return getattr(case.blank, key)
    if key in ("blank_offset_mm", "tool_offset_mm"):
        return None  # offsets are relative to the case: every value given moves something
    if key == "sheet_mm" and case.blank.outline == "rectangle":
        a, b = case.blank.size_mm
        return a if a == b else None
    if key in HOLDER_OVERRIDES:
        return None if case.holder is None else getattr(case.holder, HOLDER_OVERRIDES[key])
    values = {dict(t.parameters).get(key) for t in case.tools if key in dict(t.parameters)}
    return values.pop() if len(values) == 1 else None


def case_for_test(path: str | os.PathLike, keys: Mapping[str, Any]
                  ) -> tuple[FormingCase, dict[str, Any]]:
    """The case a measured forming test names, its keys applied as overrides.

    The reader the bundle loader is given (``load_bundle(path, read_case=case_for_test)``; the
    spec's "forming tests on any part"): a key that names a value of the case
    (:func:`override_names`) overrides it, unless it equals the case's own value (then it
    only repeats it: e.g. ``travel_mm`` of a bundle written by ``form_case``); the other keys
    are the test's conditions. A hemisphere key of the spec (:data:`SPEC_FORMING_KEYS`) the
    case has no value for is an error, not a silently ignored condition.

    Returns:
        The case with the overrides, and the keys it used (overrides and repeats).

    Raises:
        CaseError: a malformed case file (every problem with the file and key), or a key the
            case cannot take.
    """
    case = load_case(path)
    names = override_names(case)
    used: dict[str, Any] = {}
    changes: dict[str, Any] = {}
    problems = []
    for written, value in keys.items():
        key = renamed(written, f"{path}: test key")
        if key not in names:
            if key in SPEC_FORMING_KEYS:
                problems.append(f"{path}: test key {key} = {value!r}: the case has no such "
                                "value (a tool parameter of that name, or an override: "
                                f"{', '.join(OVERRIDES)})")
            continue
        used[written] = value  # as the bundle spells it (the loader looks its keys up)
        own = case_value(case, key)
        same = (own == value if isinstance(value, str) or isinstance(own, str) or own is None
                else math.isclose(float(own), float(value), rel_tol=1e-9, abs_tol=1e-12))
        if not same:
            changes[key] = value
    problems += _untrusted_code(case, path)
    if problems:
        raise CaseError(problems)
    case = dataclasses.replace(case, origin=f"the case {path} of a measurement bundle")
    return (with_overrides(case, **changes) if changes else case), used


def _untrusted_code(case: FormingCase, path) -> list[str]:
    """The code a bundle's case would run (its .py tools, its model's plugins), untrusted.

    Reported when the bundle is read, at once; the runs check again
    (:func:`fenicsx_drape.trust.require_trust`).
    """
    from fenicsx_drape.trust import trusted

    if trusted():
        return []
    out = [f"{path}: [[tool]] {k} 'geometry': {t.geometry!r} is Python code that would run: "
           "a case a measurement bundle brings is data; pass --trust if you trust it"
           for k, t in enumerate(case.tools, start=1)
           if t.path is not None and t.path.suffix.lower() == ".py"]
    if case.model is not None:
        try:
            plugins = tomllib.loads(case.model.read_text(encoding="utf-8")).get("plugins")
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
            plugins = None  # reported when the model is read
        if plugins:
            out.append(f"{path}: [case] 'model': {case.model.name} has plugins {plugins} "
                       "(Python code) that would run: a case a measurement bundle brings is "
                       "data; pass --trust if you trust it")
    return out


# --------------------------------------------------------------------------------------------
# Tools


def build_tools(case: FormingCase, skip: tuple[str, ...] = ()) -> dict[str, object]:
    """The rigid tools of a case by name (builtin: closed form; files: meshed surfaces).

    A builtin punch moves ``travel_mm`` in the case's ``duration_s``; the builtin die is fixed
    at the punch's final position; the builtin holder is the plane z = 0 outside the opening
    (:class:`~fenicsx_drape.forming.terms.holder.FlatHolder`). Tools named in ``skip`` are left out.
    """
    from fenicsx_drape.forming.terms.holder import FlatHolder

    check_tool_sizes(case, skip)
    out: dict[str, object] = {}
    for spec in case.tools:
        if spec.name in skip:
            continue
        if spec.builtin:
            tools = _builtin_tools(spec)
            if spec.role == "punch":
                tool = tools.punch(case.duration_s)
            elif spec.role == "die":
                tool = tools.die()
            else:
                tool = FlatHolder(tools.opening_radius_mm, name=spec.name)
            if getattr(tool, "name", spec.name) != spec.name and spec.role != "holder":
                tool = dataclasses.replace(tool, name=spec.name)
            out[spec.name] = tool
        else:
            out[spec.name] = _meshed_tool(case, spec)
    return out


# A tool mesh finer than the sheet's cell by this factor costs memory and time for nothing.
FINE_MESH_FACTOR = 20.0
# A tool mesh whose triangles miss the curved geometry by more than this share of the
# sheet's cell changes the formed part (the sag h·θ/6 of triangles whose edge bends by θ).
COARSE_CHORD_OF_CELL = 0.1
# Edges bending more than this are taken as the geometry's own creases, not its curvature.
CREASE_DEG = 60.0


def tool_triangles(case: FormingCase, spec: ToolSpec) -> float | None:
    """About how many triangles a tool's mesh will have, from the case alone (None: unknown).

    A source Gmsh meshes at ``mesh_mm`` covers about the blank's box widened by the case's
    travel on every side; an STL or ``.msh`` file about its size over 50 bytes a triangle.
    """
    if spec.builtin or spec.path is None:
        return 0.0
    from fenicsx_drape.limits import triangles_for

    if spec.path.suffix.lower() in (".stl", ".msh"):
        try:
            return spec.path.stat().st_size / 50.0
        except OSError:
            return None
    if spec.mesh_mm is None:
        return None
    w, h = np.ptp(case.blank.polygon(), axis=0)
    travel = case.total_travel_mm
    return triangles_for((w + 2 * travel) * (h + 2 * travel), spec.mesh_mm, spec.order or 1)


def check_tool_sizes(case: FormingCase, skip: tuple[str, ...] = (), warn: bool = True) -> None:
    """Refuse tool meshes beyond the memory limit, warn of ones much finer than the sheet.

    Raises:
        DrapeInputError: with the estimate and the limit (:mod:`fenicsx_drape.limits`).
    """
    from fenicsx_drape.limits import check_triangles

    where = str(case.path or case.name)
    total, named = 0.0, []
    for spec in case.tools:
        n = None if spec.name in skip else tool_triangles(case, spec)
        if n:
            total += n
            named.append(f"{spec.name} {n:.3g}")
        Δ = case.blank.cell_mm
        if warn and spec.mesh_mm is not None and spec.mesh_mm * FINE_MESH_FACTOR < Δ:
            warnings.warn(f"{where}: tool {spec.name!r}: mesh_mm = {spec.mesh_mm:g} is "
                          f"{Δ / spec.mesh_mm:.3g} times finer than the sheet's cell "
                          f"{Δ:g} mm (about {n or 0:.3g} triangles): time and memory for no "
                          "accuracy", stacklevel=3)
    if total:
        check_triangles(total, f"{where}: tools ({', '.join(named)})")


def run_size(case: FormingCase) -> dict[str, float]:
    """A run's length from the case alone: load steps, nodes and seconds (one rank).

    The steps are the fastest tool's travel over ``step_mm`` (cut-backs add a few); the
    nodes the net's lattice; the time :func:`fenicsx_drape.limits.run_seconds`.
    """
    from fenicsx_drape.limits import run_seconds

    grid = case.blank.grid()
    steps = float(math.ceil(case.total_travel_mm / case.step_mm - 1e-9))
    nodes = float((grid.nx + 1) * (grid.ny + 1))
    return {"steps": steps, "nodes": nodes, "seconds": run_seconds(steps, nodes),
            "travel_mm": case.total_travel_mm}


def check_run_size(case: FormingCase) -> dict[str, float]:
    """Refuse a run longer than the step limit at once (:func:`fenicsx_drape.limits.check_steps`).

    Returns:
        :func:`run_size`.
    """
    from fenicsx_drape.limits import check_steps

    size = run_size(case)
    check_steps(size["steps"], size["nodes"], str(case.path or f"case {case.name!r}"),
                f"{size['travel_mm']:g} mm of travel at step_mm = {case.step_mm:g}")
    return size


def coarse_mesh_problem(surface, cell_mm: float) -> str | None:
    """A message when a tool's triangles miss its curved geometry by much (None if not).

    Over the edges between two triangles that bend by θ below :data:`CREASE_DEG` (curvature,
    not a crease), h·θ/6 for an edge of length h is how far the middle of a flat triangle
    sits from the sphere through its corners (radius ρ = h/θ: the sag r²/(2ρ) at the centre
    of an equilateral triangle, r = h/√3 its corners' distance); beyond
    :data:`COARSE_CHORD_OF_CELL` of the sheet's cell the formed part changes.
    """
    n = surface.face_normals
    nbr = surface.neighbours
    tri = np.repeat(np.arange(len(n)), 3)
    other = nbr.ravel()
    ok = other > tri  # each inner edge once
    tri, other = tri[ok], other[ok]
    θ = np.arccos(np.clip(np.einsum("ij,ij->i", n[tri], n[other]), -1.0, 1.0))
    p, t = surface.points, surface.triangles
    side = np.flatnonzero(ok) % 3
    a = p[t[tri, side]]
    b = p[t[tri, (side + 1) % 3]]
    h = np.linalg.norm(b - a, axis=1)
    curved = θ < np.radians(CREASE_DEG)
    if not curved.any():
        return None
    chord = h[curved] * θ[curved] / 6.0
    worst = int(np.argmax(chord))
    if chord[worst] <= COARSE_CHORD_OF_CELL * cell_mm:
        return None
    return (f"the tool mesh is coarse for its curved geometry: its flat triangles miss the "
            f"surface by up to about {chord[worst]:.3g} mm (an edge of {h[curved][worst]:.3g} "
            f"mm bending by {np.degrees(θ[curved][worst]):.3g}°), more than "
            f"{COARSE_CHORD_OF_CELL:g} of the sheet's cell {cell_mm:g} mm; give a smaller "
            "mesh_mm (or order = 2)")


def _meshed_tool(case: FormingCase, spec: ToolSpec):
    """A tool from a geometry file: its surface meshed once by Gmsh, moved rigidly."""
    from fenicsx_drape.forming.tools.shapes import MeshedTool
    from fenicsx_drape.forming.tools.surfaces import load_surface
    from fenicsx_drape.trust import require_trust

    k = case.tools.index(spec) + 1
    where = f"{case.path or case.name}: [[tool]] {k} ({spec.name!r})"
    if spec.path.suffix.lower() == ".py":
        require_trust(spec.path, "the Python geometry of tool " + repr(spec.name), case.origin)
    surface = load_surface(spec.path, spec.params or None, spec.mesh_mm, spec.order or 1,
                           sheet_side=spec.side)
    if spec.role != "holder":  # a holder's opening is a hole by design
        from fenicsx_drape.forming.tools.checks import holes, pieces

        parts = pieces(surface)
        if len(parts) > 1:
            each = ", ".join(f"{m} triangles around ("
                             + ", ".join(f"{v:g}" for v in np.round(c, 1) + 0.0) + ") mm"
                             for m, c in parts[:3])
            raise CaseError([f"{where}: {spec.path.name}: the {spec.role}'s surface is "
                             f"{len(parts)} separate pieces ({each}): a {spec.role} must be "
                             "one closed surface or one surface (a second shell in the "
                             "file?)"])
        found = holes(surface)
        if found:
            centre, size = found[0]
            at = ", ".join(f"{v:g}" for v in np.round(centre, 1) + 0.0)
            raise CaseError([f"{where}: {spec.path.name}: the {spec.role}'s surface has "
                             f"{len(found)} hole(s): one of {size:.3g} mm across at ({at}) "
                             f"mm (a {spec.role} must be closed or one surface without "
                             "holes: the sheet would sink into it)"])
    coarse = coarse_mesh_problem(surface, case.blank.cell_mm)
    if coarse:
        warnings.warn(f"{where}: {coarse}", stacklevel=3)
    return MeshedTool(spec.name, surface, spec.motion)


# --------------------------------------------------------------------------------------------
# Writing


def case_key(case) -> str:
    """What a forming run of ``case`` depends on, as text.

    A :class:`FormingCase` by content: its tables (paths relative to its folder, the model file
    left out: the run's model is given) and the digests of the geometry files it reads, so
    that the same case read from two copies (a bundle's and the mesh folder's) shares its
    runs (:mod:`~fenicsx_drape.diagnosis.forming_runs`) and its geometry check.
    """
    tables = case_dict(case, case.folder)
    tables["case"].pop("model", None)
    files = [t.path for t in case.tools if t.path is not None]
    if case.blank.path is not None:
        files.append(case.blank.path)
    files += [p.model for p in case.plies if p.model is not None]  # a ply's own model
    digests = [file_digest(Path(p)) if Path(p).is_file() else f"missing {p}" for p in files]
    return json.dumps([tables, digests], sort_keys=True, default=str)


def case_dict(case: FormingCase, relative_to: str | os.PathLike | None = None) -> dict:
    """The case as the plain tables of its file (paths relative to ``relative_to``)."""
    base = Path(relative_to).resolve() if relative_to is not None else None

    def rel(p: Path | None, written: str) -> str:
        if p is None or base is None:
            return written
        return os.path.relpath(p, base)

    c: dict[str, Any] = {"name": case.name}
    if case.description:
        c["description"] = case.description
    c["duration_s"] = case.duration_s
    if case.model is not None:
        c["model"] = rel(case.model, str(case.model))
    c.update(step_mm=case.step_mm, penalty_factor=case.penalty_factor,
             stabilisation_N_per_mm=case.stabilisation_N_per_mm)
    b = case.blank
    blank: dict[str, Any] = {"outline": rel(b.path, b.outline) if b.path else b.outline}
    if b.outline == "rectangle":
        blank.update(size_mm=list(b.size_mm), centre_mm=list(b.centre_mm))
    elif b.outline == "polygon":
        blank["points_mm"] = [list(p) for p in b.points_mm]
    blank.update(cell_mm=b.cell_mm, ply_angle_deg=b.ply_angle_deg, origin_mm=list(b.origin_mm),
                 symmetry=list(b.symmetry))
    if b.hold_origin:
        blank["hold_origin"] = True
    out: dict[str, Any] = {"case": c, "blank": blank}
    if case.holder is not None:
        h = case.holder
        out["holder"] = {"tool": h.tool, "force_N": h.force_N, "force_share": h.force_share}
        if h.mu is not None:
            out["holder"]["mu"] = h.mu
    tools = []
    for t in case.tools:
        d: dict[str, Any] = {"name": t.name, "role": t.role,
                             "geometry": rel(t.path, t.geometry) if t.path else t.geometry}
        if t.parameters:
            d["parameters"] = dict(t.parameters)
        for key in ("mesh_mm", "order", "sheet_side"):
            if getattr(t, key) is not None:
                d[key] = getattr(t, key)
        if t.motion is not None:
            m = t.motion
            d["motion"] = {"time_s": list(m.time_s), "x_mm": list(m.x_mm),
                           "y_mm": list(m.y_mm), "z_mm": list(m.z_mm)}
            if m.rotation_deg is not None:
                d["motion"].update(rotation_deg=list(m.rotation_deg), axis=list(m.axis),
                                   centre_mm=list(m.centre_mm))
        tools.append(d)
    out["tool"] = tools
    if case.plies:
        out["ply"] = [{"angle_deg": p.angle_deg, "thickness_mm": p.thickness_mm,
                       **({"model": rel(p.model, str(p.model))} if p.model else {})}
                      for p in case.plies]
    if case.interply:
        out["interply"] = dict(case.interply)
    return out


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def case_toml(case: FormingCase, relative_to: str | os.PathLike | None = None,
              comment: str = "") -> str:
    """The text of a case file for ``case`` (the format :func:`load_case` reads)."""
    d = case_dict(case, relative_to)
    lines = [f"# {line}" for line in comment.splitlines()]
    for table in ("case", "blank", "holder", "interply"):
        if table in d:
            lines += ["", f"[{table}]"] if lines else [f"[{table}]"]
            lines += [f"{k} = {_toml(v)}" for k, v in d[table].items()]
    for t in d["tool"]:
        lines += ["", "[[tool]]"]
        lines += [f"{k} = {_toml(v)}" for k, v in t.items() if k != "motion"]
        if "motion" in t:
            lines.append("[tool.motion]")
            lines += [f"{k} = {_toml(v)}" for k, v in t["motion"].items()]
    for p in d.get("ply", []):
        lines += ["", "[[ply]]"] + [f"{k} = {_toml(v)}" for k, v in p.items()]
    return "\n".join(lines) + "\n"


def write_case(case: FormingCase, folder: str | os.PathLike, *, name: str = "case.toml",
               comment: str = "", surfaces: Mapping[str, Any] | None = None) -> Path:
    """Write the case into ``folder`` with copies of its geometry files: a self-contained case.

    Tool geometry and the outline curve are copied next to the case file (renamed on a
    clash) and named relative to it; the model file is not copied (a bundle names no model).
    A tool named in ``surfaces`` (its
    :class:`~fenicsx_drape.forming.tools.surfaces.TriangleSurface`, as a run meshed it) is
    written as that mesh instead, ``<name>.msh``:
    data that any reader takes without ``--trust``, at the resolution the run used.
    Returns the written case file.
    """
    from fenicsx_drape.forming.tools.surfaces import write_msh
    from fenicsx_drape.provenance import atomic_write_bytes, atomic_write_text

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    used: set[str] = {name}
    copies: dict[Path, Path] = {}

    def copy(p: Path) -> Path:
        if p in copies:
            return copies[p]
        target = p.name
        k = 1
        while target in used:
            target = f"{p.stem}_{k}{p.suffix}"
            k += 1
        used.add(target)
        atomic_write_bytes(folder / target, p.read_bytes())
        copies[p] = folder / target
        return copies[p]

    def meshed(t: ToolSpec) -> ToolSpec:
        target = f"{t.name}.msh" if f"{t.name}.msh" not in used else f"{t.name}_tool.msh"
        used.add(target)
        write_msh(surfaces[t.name], folder / target)
        return dataclasses.replace(t, geometry=target, path=folder / target, parameters=(),
                                   mesh_mm=None, order=None)

    surfaces = surfaces or {}
    tools = tuple(meshed(t) if t.name in surfaces and t.path else
                  dataclasses.replace(t, path=copy(t.path)) if t.path else t
                  for t in case.tools)
    blank = case.blank
    if blank.path is not None:
        blank = dataclasses.replace(blank, path=copy(blank.path))
    plies = tuple(dataclasses.replace(p, model=None) for p in case.plies)
    local = dataclasses.replace(case, tools=tools, blank=blank, model=None, path=None,
                                plies=plies)
    text = case_toml(local, relative_to=folder, comment=comment)
    return atomic_write_text(folder / name, text)
