"""A forming case as data: frozen dataclasses of its tools, blank, plies and holder.

A :class:`FormingCase` is what a ``case.toml`` says (``docs/case-format.md``), read and checked
by :func:`~fenicsx_drape.forming.case.reading.load_case` or built in Python; units are in the
names. A case built in Python is checked as a file is (:func:`_case_problems`), each problem
naming the case (:func:`where`: its file when it has one).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError, InputFileError
from fenicsx_drape.fe.grid import TrussGrid, outline_grid, polygon_area
from fenicsx_drape.forming.terms.holder import FORCE_SHARES
from fenicsx_drape.forming.tools.build import builtin_tool_set
from fenicsx_drape.forming.tools.motion import RigidMotion
from fenicsx_drape.materials.base import fields_of
from fenicsx_drape.materials.interply import InterplyLaw

ROLES = ("punch", "die", "holder", "surface")
BUILTIN = "builtin:hemisphere"
# Tool geometry sources (load_surface) and outline curves (Gmsh), by suffix.
GEOMETRY_SUFFIXES = (".geo", ".py", ".step", ".stp", ".iges", ".igs", ".brep", ".stl", ".msh")
OUTLINE_SUFFIXES = (".geo", ".geo_unrolled", ".msh", ".step", ".stp", ".iges", ".igs", ".brep")
SHEET_SIDES = ("+x", "-x", "+y", "-y", "+z", "-z")
DEFAULT_SHEET_SIDE = {"punch": "+z", "die": "-z", "holder": "+z", "surface": "+z"}

# The error of a case that cannot be used: the package's one error for bad input files.
CaseError = InputFileError


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
MODEL_INTERPLY = ("mu_ply", "eta_f_MPa_s_per_mm", "tau0_MPa")
"""The inter-ply law's values a model gives (``interply_friction``'s parameters) where the
case's ``[interply]`` table does not."""


HOLDER_KEYS = ("tool", "holder_force_N", "mu", "holder_force_share")
"""The keys of ``[holder]``: each the name the value has everywhere (a test's key, an override,
``drape form``'s option, the set-up candidate)."""
OLD_HOLDER_KEYS = {"force_N": "holder_force_N", "force_share": "holder_force_share"}
"""Earlier names of ``[holder]`` keys, read as today's with a note (for one release)."""


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
            raise InputFileError([f"{where(self)}: {p}" for p in problems])

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
        for b in dict.fromkeys(blanks):  # each distinct net once (a stack repeats its angles)
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
        bonded), else they slide. μ, η_f and τ₀ the table does not give are the model's
        (:data:`MODEL_INTERPLY`: the effect's parameters, which inter-ply friction tests fit,
        and a forming fit μ and η_f).
        """
        values = dict(self.interply)
        if "interply_friction" not in values and model is not None:
            values["interply_friction"] = "interply_friction" in model.effects
        for name in MODEL_INTERPLY:
            if name not in values and model is not None and name in model.parameters:
                values[name] = float(model.parameters[name])
        return InterplyLaw(**values)

    def interply_given(self, name: str) -> bool:
        """Whether the ``[interply]`` table fixes the inter-ply law's ``name`` (else the model)."""
        return any(key == name for key, _ in self.interply)

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
            out.append(f"holder: holder_force_N = {h.force_N!r} must be >= 0")
        if h.mu is not None and not (_finite(h.mu) and h.mu >= 0):
            out.append(f"holder: mu = {h.mu!r} must be >= 0")
        if h.force_share not in FORCE_SHARES:
            out.append(f"holder: holder_force_share = {h.force_share!r} is not one of "
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
        InputFileError: the case has no builtin tool.
    """
    specs = [t for t in case.tools if t.builtin]
    if not specs:
        raise InputFileError([f"{where(case)}: has no builtin tool ({BUILTIN!r})"])
    return _builtin_tools(next((t for t in specs if t.role == "punch"), specs[0]))


def _builtin_tools(spec: ToolSpec):
    return builtin_tool_set(spec)


def where(case: FormingCase) -> str:
    """How messages name a case: its file, else ``case 'name'`` (a case built in Python)."""
    return str(case.path) if case.path is not None else f"case {case.name!r}"
