"""Reading a case file: ``case.toml`` checked, every problem with its file and key.

:func:`load_case` reads and checks a case file (``docs/case-format.md``) and returns a
:class:`~fenicsx_drape.forming.case.spec.FormingCase`; every problem is reported with the file
and the key (``case.toml: [[tool]] 2 'geometry': no such file 'punch.stp'``), all problems of
a file at once, a misspelt key with the key it likely means. Paths in the file are relative to
the case file. :func:`case_for_test` reads the case a measured forming test names, the test's
keys applied as overrides (:mod:`~fenicsx_drape.forming.case.overrides`).

Data runs no code unless the user says so (:mod:`fenicsx_drape.trust`): a model a case names
(``[case] model``, ``[[ply]] model``) with ``plugins`` is refused here unless trusted, and so
is a bundle's case with Python geometry; Gmsh scripts (tools, outline) are checked before
they run, in a child process with a time limit (:func:`sample_outline`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fenicsx_drape.errors import (
    DrapeInputError,
    InputFileError,
    ParameterError,
    did_you_mean,
    old_name,
)
from fenicsx_drape.fe.grid import polygon_area
from fenicsx_drape.forming.case.overrides import (
    OVERRIDES,
    SPEC_FORMING_KEYS,
    case_value,
    override_names,
    renamed,
    with_overrides,
)
from fenicsx_drape.forming.case.size import builtin_stack_fit, check_run_size
from fenicsx_drape.forming.case.spec import (
    BUILTIN,
    GEOMETRY_SUFFIXES,
    HOLDER_KEYS,
    INTERPLY_KEYS,
    OLD_HOLDER_KEYS,
    OUTLINE_SUFFIXES,
    ROLES,
    SHEET_SIDES,
    BlankSpec,
    FormingCase,
    HolderSpec,
    PlySpec,
    ToolSpec,
    _finite,
)
from fenicsx_drape.forming.terms.holder import FORCE_SHARES
from fenicsx_drape.forming.tools.build import check_tool_sizes
from fenicsx_drape.forming.tools.motion import RigidMotion
from fenicsx_drape.forming.tools.surfaces import sample_curve_loop
from fenicsx_drape.materials.interply import InterplyLaw


class _Reader:
    """Collects the problems of one case file, each named by file and key."""

    def __init__(self, fname: str):
        self.fname = fname
        self.problems: list[str] = []

    def add(self, where: str, message: str) -> None:
        self.problems.append(f"{self.fname}: {where}{': ' if where else ''}{message}")

    def raise_if_any(self) -> None:
        if self.problems:
            raise InputFileError(self.problems)

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
                self.add(where, f"unknown key '{key}'{did_you_mean(key, known)} (known: "
                                f"{', '.join(sorted(known))})")

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
        raise InputFileError([f"{str(case)!r}: not a case file (.toml) nor a named case "
                         f"({', '.join(known) or 'none found in ' + str(CASES_FOLDER)})"])
    return named


def load_case(path: str | os.PathLike, **overrides: Any) -> FormingCase:
    """Read and check a forming case file; ``overrides`` change it (:data:`OVERRIDES`).

    Every problem of the file is reported at once, each naming the file and the key; the
    checks that cost nothing come before any geometry runs: the code the case would run
    (:func:`_read_model`), the stack against the builtin die's gap, the nets' and the
    tools' sizes and the run's length (:mod:`~fenicsx_drape.forming.case.size`).

    Args:
        path: The ``case.toml`` file, or a named case (:func:`case_file`: ``"hemisphere"``).
        **overrides: e.g. ``duration_s=8.0, holder_force_N=500.0, cell_mm=20.0`` or a tool
            parameter by name (``punch_radius_mm=50.0``): see :func:`with_overrides`.

    Raises:
        InputFileError: with every problem of the file, each naming the file and the key.
    """
    path = case_file(path)
    fname = str(path)
    raw = _toml_of(path, "case file")
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
    model = _read_model(r, c, "[case]", folder)

    blank = _read_blank(r, raw, folder)
    tools = _read_tools(r, raw, folder, duration)
    plies = _read_plies(r, raw, folder)
    interply = _read_interply(r, raw)
    holder = _read_holder(r, raw, tools)
    r.raise_if_any()
    stated = [p.thickness_mm for p in plies]
    if len(plies) == 1:  # one ply is today's case: its angle turns the blank's net
        blank = dataclasses.replace(blank, ply_angle_deg=blank.ply_angle_deg + plies[0].angle_deg)
        model = plies[0].model or model
        plies = []
    case = FormingCase(name=name, duration_s=duration, blank=blank, tools=tuple(tools),
                       holder=holder, description=description, model=model, step_mm=step,
                       penalty_factor=penalty, stabilisation_N_per_mm=stab, path=path,
                       plies=tuple(plies), interply=interply)
    if any(v is not None for v in overrides.values()):
        # Overrides first (--full removes the planes an off-centre blank breaks), then the
        # check of the blank, in with_overrides.
        case = with_overrides(case, **overrides)
    else:
        blanks = case.ply_blanks()
        for blank_k, k in {b: k for k, b in reversed(list(enumerate(blanks, 1)))}.items():
            try:  # each distinct ply's net once, named by its first ply
                blank_k.grid()
            except DrapeInputError as err:
                at = f"[[ply]] {k}" if case.plies else "[blank]"
                raise InputFileError([f"{fname}: {at}: {err}"]) from None
    errors = builtin_stack_fit(case, stated)  # the tools as overridden (a gap, no die)
    if errors:
        raise InputFileError([f"{fname}: [[ply]]: {e}" for e in errors])
    try:
        check_tool_sizes(case, warn=False)  # sizes before memory: refused at once
        check_run_size(case)  # and the run's length
    except InputFileError:
        raise
    except DrapeInputError as err:
        raise InputFileError([str(err)]) from None
    return case


def _toml_of(path: Path, what: str) -> dict:
    """The tables of a TOML file, its size checked before it is read."""
    from fenicsx_drape.limits import check_file_size

    fname = str(path)
    if not path.is_file():
        raise InputFileError([f"{fname}: no such {what}"])
    try:
        check_file_size(path, what)
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise InputFileError([f"{fname}: cannot read the {what} ({err})"]) from err
    except tomllib.TOMLDecodeError as err:
        raise InputFileError([f"{fname}: not valid TOML ({err})"]) from err
    except DrapeInputError as err:
        raise InputFileError([str(err)]) from None


def _read_model(r: _Reader, table: Mapping, at: str, folder: Path) -> Path | None:
    """The MODEL.toml a table names (``[case] model``, ``[[ply]] model``), checked.

    A model a case names is data: its ``plugins`` (Python code) are refused here, with the
    file and the key, unless the user trusts them (:mod:`fenicsx_drape.trust`).
    """
    if (m := r.string(table, "model", at)) is None:
        return None
    model = (folder / m).resolve()
    if not model.is_file():
        r.add(f"{at} 'model'", f"no such file {m!r}")
    elif problem := _untrusted_model(model):
        r.add(f"{at} 'model'", problem)
    return model


def _untrusted_model(model: Path) -> str | None:
    """A message when a model file a case names has plugins and the user does not trust them."""
    from fenicsx_drape.trust import trusted

    if trusted():
        return None
    try:
        plugins = tomllib.loads(model.read_text(encoding="utf-8")).get("plugins")
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return None  # reported when the model is read
    if not plugins:
        return None
    return (f"{model.name} has plugins {plugins} (Python code) that would run: a model a "
            "case names is data; pass --trust (or set DRAPE_TRUST=1) if you trust it, or "
            "give it yourself with --model")


def _read_interply(r: _Reader, raw: Mapping) -> tuple[tuple[str, Any], ...]:
    """The ``[interply]`` table: the inter-ply law's values (the rest its defaults)."""
    if (ip := r.table(raw, "interply", "[interply]")) is None:
        return ()
    before = len(r.problems)
    r.unknown(ip, INTERPLY_KEYS, "[interply]")
    for key, value in ip.items():
        if key == "interply_friction":
            if not isinstance(value, bool):
                r.add("[interply] 'interply_friction'", f"{value!r} must be true or false")
        elif key in INTERPLY_KEYS:
            r.number(ip, key, "[interply]", nonnegative=True)
    if len(r.problems) == before:
        try:
            InterplyLaw(**ip)
        except DrapeInputError as err:
            r.add("[interply]", str(err))
    return tuple(ip.items())


def _read_holder(r: _Reader, raw: Mapping, tools: list[ToolSpec]) -> HolderSpec | None:
    """The ``[holder]`` table, its tool among the case's tools with role holder."""
    if (h := r.table(raw, "holder", "[holder]")) is None:
        return None
    h = dict(h)
    for old, new in OLD_HOLDER_KEYS.items():
        if old in h and new in h:
            h.pop(old)
            r.add("[holder]", f"'{old}' and '{new}' name one value: give '{new}' only")
        elif old in h:
            h[old_name(f"{r.fname}: [holder]", old, new, stacklevel=4)] = h.pop(old)
    r.unknown(h, HOLDER_KEYS, "[holder]")
    tool = r.string(h, "tool", "[holder]", required=True, default="")
    force = r.number(h, "holder_force_N", "[holder]", nonnegative=True, required=True,
                     default=0.0)
    mu = r.number(h, "mu", "[holder]", nonnegative=True)
    share = r.string(h, "holder_force_share", "[holder]", choices=FORCE_SHARES,
                     default="symmetric_part")
    names = {t.name: t for t in tools}
    if tool and tool not in names:
        r.add("[holder] 'tool'", f"no tool named {tool!r} (tools: "
                                 f"{', '.join(names) or 'none'})")
    elif tool in names and names[tool].role != "holder":
        r.add("[holder] 'tool'", f"tool {tool!r} has role {names[tool].role!r}; the "
                                 "clamping tool needs role = \"holder\"")
    return HolderSpec(tool, force, mu, share)


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
        plies.append(PlySpec(angle, thickness, _read_model(r, p, at, folder)))
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
        InputFileError: a malformed case file (every problem with the file and key), or a key the
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
        raise InputFileError(problems)
    case = dataclasses.replace(case, origin=f"the case {path} of a measurement bundle")
    return (with_overrides(case, **changes) if changes else case), used


def _untrusted_code(case: FormingCase, path) -> list[str]:
    """The Python geometry a bundle's case would run (its ``.py`` tools), untrusted.

    Reported when the bundle is read, at once; the runs check again
    (:func:`fenicsx_drape.trust.require_trust`). The plugins of the models a case names are
    refused by :func:`load_case` itself, for every case.
    """
    from fenicsx_drape.trust import trusted

    if trusted():
        return []
    return [f"{path}: [[tool]] {k} 'geometry': {t.geometry!r} is Python code that would run: "
            "a case a measurement bundle brings is data; pass --trust if you trust it"
            for k, t in enumerate(case.tools, start=1)
            if t.path is not None and t.path.suffix.lower() == ".py"]
