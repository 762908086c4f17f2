"""A case with some values changed: a command line's options, a measured test's keys, a set-up.

:func:`with_overrides` changes a :class:`~fenicsx_drape.forming.case.spec.FormingCase` the
way a measured forming test's keys override the case it names (``docs/measurements.md``,
"forming tests on any part"); :data:`OVERRIDES` lists the names besides the tools'
parameters. The changes are applied in groups, each a function below: the blank and its net
(:func:`_blank_changes`), the holder (:func:`_holder_changes`), the tools and their motion
(:func:`_tool_changes`); the changed case is then checked as a loaded one is.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError, InputFileError, did_you_mean
from fenicsx_drape.forming.case.size import check_run_size
from fenicsx_drape.forming.case.spec import (
    BlankSpec,
    FormingCase,
    HolderSpec,
    ToolSpec,
    _builtin_tools,
    _finite,
    where,
)
from fenicsx_drape.forming.tools.build import check_tool_sizes
from fenicsx_drape.forming.tools.motion import RigidMotion

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
# The forming keys of the measurement spec's hemisphere tests: in a test that names a case,
# they must name a value of the case (else they would be silently ignored).
SPEC_FORMING_KEYS = ("punch_radius_mm", "fillet_radius_mm", "holder_opening_mm", "sheet_mm",
                     "travel_mm", "duration_s", "holder_force_N")


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

    Raises:
        InputFileError: an unknown name or a value the case cannot take, naming the case file.
    """
    at = where(case)
    overrides = {renamed(k, at): v for k, v in overrides.items() if v is not None}
    unknown = sorted(set(overrides) - override_names(case))
    if unknown:
        raise InputFileError([f"{at}: override {key!r}: not a case value (known: "
                              f"{', '.join(OVERRIDES)}, or a tool parameter)"
                              f"{did_you_mean_override(key, case)}" for key in unknown])
    changes = {key: float(overrides[key]) for key in
               ("step_mm", "penalty_factor", "stabilisation_N_per_mm") if key in overrides}
    if "duration_s" in overrides:
        changes["duration_s"] = float(overrides["duration_s"])
        if not (_finite(changes["duration_s"]) and changes["duration_s"] > 0):
            raise InputFileError([f"{at}: override duration_s = {changes['duration_s']!r} "
                                  "must be > 0"])
    blank = _blank_changes(case.blank, overrides, at)
    holder = _holder_changes(case, blank, overrides, at)
    tools = _tool_changes(case, overrides, at)
    try:
        new_case = dataclasses.replace(case, blank=blank, tools=tuple(tools), holder=holder,
                                       **changes)
        for blank_k in dict.fromkeys(new_case.ply_blanks()):
            blank_k.grid()
        check_tool_sizes(new_case, warn=False)
        check_run_size(new_case)
        for t in new_case.tools:
            if t.builtin:
                _builtin_tools(t)
    except DrapeInputError as err:
        text = str(err).removeprefix(f"{at}: ")  # the file named once
        raise InputFileError([f"{at}: with overrides {overrides}: {text}"]) from None
    return new_case


def _blank_changes(blank: BlankSpec, overrides: Mapping[str, Any], at: str) -> BlankSpec:
    """The blank with its overrides: cell, ply angle, offset, symmetry planes, hold, size."""
    planes_before = set(blank.symmetry)
    if "cell_mm" in overrides:
        blank = dataclasses.replace(blank, cell_mm=float(overrides["cell_mm"]))
    if "ply_angle_deg" in overrides:
        blank = dataclasses.replace(blank, ply_angle_deg=float(overrides["ply_angle_deg"]))
    if "blank_offset_mm" in overrides:
        blank = _moved_blank(blank, _offset(overrides["blank_offset_mm"], "blank_offset_mm",
                                            at))
    broken = broken_planes(overrides)
    if "symmetry" in overrides:
        blank = dataclasses.replace(blank, symmetry=tuple(overrides["symmetry"]))
        kept = broken & set(blank.symmetry)
        if kept:
            raise InputFileError([f"{at}: the set-up {_setup_text(overrides)} breaks the "
                                  f"symmetry plane(s) {sorted(kept)}: model without them "
                                  "(symmetry = [], drape form --full)"])
    elif broken & set(blank.symmetry):
        blank = dataclasses.replace(blank, symmetry=tuple(
            p for p in blank.symmetry if p not in broken))
    if "hold_origin" in overrides:
        if not isinstance(overrides["hold_origin"], (bool, np.bool_)):
            raise InputFileError([f"{at}: override hold_origin = {overrides['hold_origin']!r} "
                                  "must be true or false"])
        blank = dataclasses.replace(blank, hold_origin=bool(overrides["hold_origin"]))
    elif planes_before == {"x", "y"} and set(blank.symmetry) != {"x", "y"}:
        blank = dataclasses.replace(blank, hold_origin=True)  # what the planes held
    if "sheet_mm" in overrides:
        if blank.outline != "rectangle":
            raise InputFileError([f"{at}: override sheet_mm: the blank is not a rectangle"])
        s = float(overrides["sheet_mm"])
        blank = dataclasses.replace(blank, size_mm=(s, s))
    return blank


def _moved_blank(blank: BlankSpec, d: tuple[float, float]) -> BlankSpec:
    """The blank and its net moved by ``d`` (mm) on the tools."""
    def shift(p):
        return (float(p[0] + d[0]), float(p[1] + d[1]))

    moved: dict[str, Any] = {"origin_mm": shift(blank.origin_mm)}
    if blank.outline == "rectangle":
        moved["centre_mm"] = shift(blank.centre_mm)
    else:  # a polygon, or a curve's sampled points: the moved points are the outline
        moved.update(outline="polygon", path=None,
                     points_mm=tuple(shift(p) for p in blank.points_mm))
    return dataclasses.replace(blank, **moved)


def _holder_changes(case: FormingCase, blank: BlankSpec, overrides: Mapping[str, Any],
                    at: str) -> HolderSpec | None:
    """The holder with its overrides (force, μ, force share) on the changed blank."""
    holder = case.holder
    if holder is None:
        if any(k in HOLDER_OVERRIDES for k in overrides):
            raise InputFileError([f"{at}: holder overrides given, but the case has no "
                                  "[holder]"])
        return None
    holder = dataclasses.replace(
        holder, force_N=float(overrides.get("holder_force_N", holder.force_N)),
        mu=overrides.get("mu", holder.mu),
        force_share=overrides.get("holder_force_share", holder.force_share))
    if holder.force_share == "model" and "holder_force_share" not in overrides:
        # "model" shares F over the model's own nodes: the same press on a model with fewer
        # symmetry planes keeps each node's force, F × 2 per plane dropped (a whole blank
        # formed for a set-up is pressed as the stated quarter was).
        dropped = len(case.blank.symmetry) - len(blank.symmetry)
        holder = dataclasses.replace(holder, force_N=holder.force_N * 2.0**dropped)
    return holder


def _tool_changes(case: FormingCase, overrides: Mapping[str, Any], at: str) -> list[ToolSpec]:
    """The tools with their overrides.

    In this order: the duration (motion tables stretched), the travel (motion tables
    scaled), parameters by name, the dies left out, the punch moved.
    """
    tools = list(case.tools)
    duration = float(overrides.get("duration_s", case.duration_s))
    if "duration_s" in overrides:
        f = duration / case.duration_s
        tools = [dataclasses.replace(t, motion=t.motion.scaled(time=f)) if t.motion else t
                 for t in tools]
    builtin_names = _builtin_parameter_names(case)
    params = {k: float(v) for k, v in overrides.items()
              if k in _parameter_names(case) | builtin_names}
    if "travel_mm" in overrides:
        travel = float(overrides["travel_mm"])
        if not (math.isfinite(travel) and travel > 0):
            raise InputFileError([f"{at}: override travel_mm = {travel:g}: a travel against "
                                  "the tool's motion (travel is the distance the fastest tool "
                                  "moves along its motion, > 0)"])
        moving = [t for t in tools if not t.builtin and t.motion is not None]
        if moving:
            now = max(t.motion.travel_mm(t.motion.time_s[-1]) for t in moving)
            if not now > 0:
                raise InputFileError([f"{at}: override travel_mm: no tool translates"])
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
            raise InputFileError([f"{at}: override die = false: the case has no tool of role "
                                  "'die'"])
        tools = [t for t in tools if t.role != "die"]
    if "tool_offset_mm" in overrides:  # after travel_mm, which scales the motion tables
        d = _offset(overrides["tool_offset_mm"], "tool_offset_mm", at)
        tools = _offset_punches(tools, d, duration, at)
    return tools


def _parameter_names(case: FormingCase) -> set[str]:
    """The parameters the case's tools give (geometry scripts' and builtin tools')."""
    return {k for t in case.tools for k, _ in t.parameters}


def _builtin_parameter_names(case: FormingCase) -> set[str]:
    """The parameters of the builtin tools, when the case has any (else none)."""
    if not any(t.builtin for t in case.tools):
        return set()
    from fenicsx_drape.forming.tools.shapes import HemisphereTools

    return {f.name for f in dataclasses.fields(HemisphereTools)}


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


def _offset(value: Any, key: str, at: str) -> tuple[float, float]:
    """An [x, y] offset in mm, checked."""
    try:
        d = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        d = ()
    if len(d) != 2 or not all(math.isfinite(v) for v in d):
        raise InputFileError([f"{at}: override {key} = {value!r} must be [x, y] in mm"])
    return d


def _offset_punches(tools: list[ToolSpec], d: tuple[float, float], duration: float,
                    at: str) -> list[ToolSpec]:
    """The tools with every punch moved by ``d`` (mm) in x and y, die and holder in place."""
    punches = [t for t in tools if t.role == "punch"]
    if not punches:
        raise InputFileError([f"{at}: override tool_offset_mm: the case has no tool of role "
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


def override_names(case: FormingCase) -> set[str]:
    """The names :func:`with_overrides` accepts for ``case``: :data:`OVERRIDES` and parameters."""
    return set(OVERRIDES) | _parameter_names(case) | _builtin_parameter_names(case)


def did_you_mean_override(key: str, case: FormingCase) -> str:
    """`` (did you mean `x`?)`` when ``key`` is a likely typo of a name the case takes."""
    return did_you_mean(key, sorted(override_names(case)))


def renamed(key: str, at: str) -> str:
    """An override's name, an earlier spelling (:data:`OLD_OVERRIDES`) read as today's."""
    if key in OLD_OVERRIDES:
        warnings.warn(f"{at}: {key} is now called {OLD_OVERRIDES[key]} (read as "
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
