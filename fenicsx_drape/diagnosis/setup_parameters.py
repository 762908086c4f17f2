"""The process set-up parameters: what each is, and how it is applied to a forming test.

The set-up stage (:mod:`~fenicsx_drape.diagnosis.setup_stage`) fits each parameter of
:data:`SETUP_PARAMETERS` to a bundle's forming tests, as a candidate of its own:

- ``ply_angle_deg``: the warp's angle to x as laid (the net turned by δθ); on a stack,
  ``ply_angle_deg/<k>`` is the k-th ply's angle within it (:func:`setup_names`);
- ``blank_offset_mm``: the blank (with its net) placed [x, y] mm off where the case puts it.
  The measured grid's flat positions are where the *stated* set-up puts the material, so the
  model with an offset d is read at (x0, y0) + d (:func:`corrected`);
- ``holder_force_N``: the holding force that acted (a factor on each test's stated force);
- ``mu``: the holder's friction coefficient (eq. 1; the case's ``[holder] mu`` if it has
  one, else the model's);
- ``tool_offset_mm``: the punch misaligned by [x, y] mm relative to the die and holder.

All start from the test's stated value (:func:`stated`: the case's, with the test's keys;
offsets 0) and are shared by the bundle's forming tests. A set-up that breaks a symmetry
plane of the case is formed without it (:func:`applied`;
:func:`~fenicsx_drape.forming.case.with_overrides` drops the plane): the full or half
model is chosen by the set-up, not by the user. Internally a point ``p`` is δθ (deg) for a
ply angle, [x, y] (mm) for an offset, the factor on the stated force for ``holder_force_N``
and μ itself for ``mu`` (:func:`stated_point`); :func:`fitted_of` and :func:`sd_of` give it in the
report's units. The tables :data:`SCAN`, :data:`STEP`, :data:`BOUNDS` and :data:`MAX_STEP`
say how each is fitted (:mod:`~fenicsx_drape.diagnosis.setup_fit`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds import is_formed
from fenicsx_drape.diagnosis.kinds.forming import case_of, forming_case_of, moved, names_case
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case import FormingCase, broken_planes, with_overrides

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

SETUP_PARAMETERS = ("ply_angle_deg", "blank_offset_mm", "holder_force_N", "mu", "tool_offset_mm")
# On a stack (spec version 4), ``ply_angle_deg/<k>`` is the k-th ply's angle within it (a ply
# laid at the wrong angle), tried with ``ply_angle_deg`` (the whole stack turned); its tables'
# entries are ``ply_angle_deg``'s.
PLY = "ply_angle_deg/"


def ply_index(name: str) -> int | None:
    """The ply k of a set-up parameter ``ply_angle_deg/<k>`` (on a stack), else None."""
    tail = name[len(PLY):] if name.startswith(PLY) else ""
    return int(tail) if tail.isdigit() and int(tail) >= 1 else None


def base_parameter(name: str) -> str:
    """The set-up parameter whose tables a name uses (``ply_angle_deg/<k>``: the ply angle's)."""
    return "ply_angle_deg" if ply_index(name) else name


class _Table(dict):
    """A table of the set-up parameters that answers ``ply_angle_deg/<k>`` as the ply angle.

    Its entry ``ply_angle_deg/`` (:data:`PLY`), where it has one, is every ply's own.
    """

    def __missing__(self, name: str):
        if base_parameter(name) == name:
            raise KeyError(name)
        return self[PLY] if PLY in self else self[base_parameter(name)]

    def get(self, name: str, default=None):
        if ply_index(name) and PLY in self:
            return self[PLY]
        return super().get(base_parameter(name), default)


def setup_names(names: Sequence[str], tests: Sequence[Test]) -> list[str]:
    """The set-up parameters to try: ``names``, with each ply's angle after the stack's.

    When the forming tests are on stacks, ``ply_angle_deg`` brings ``ply_angle_deg/<k>``
    for every ply k that all their stacks have.
    """
    plies = min((len(forming_case_of(t).plies) for t in tests), default=0)
    out = []
    for name in names:
        out.append(name)
        if name == "ply_angle_deg" and plies > 1:
            out += [f"{PLY}{k}" for k in range(1, plies + 1) if f"{PLY}{k}" not in names]
    return out


# The scan of each parameter about its stated value, per axis (one batch of runs: a set-up
# error may lie either side, and a turned net is clipped to the blank, so that the error is
# not smooth through θ = 0): degrees, mm, a change of the factor on the force, μ. The
# smallest positive move is the sensitivity's probe.
# Two points per axis, the Gauss-Newton fit moving from the best (four per axis
# were a quarter of the set-up stage's runs, all on the whole blank for a ply or an offset).
# A punch moved past its clearance to a matched die clashes with it (the double dome's die is
# 0.3 mm off the punch): at 3 mm its runs took 2.4× as long, with cut-backs; 1 mm is the
# finite-difference step, so a fit from the stated point reuses the scan's runs.
# A ply laid wrong within a stack is often off by more than the few degrees a whole blank
# is (35° for 45°, a ±45 ply laid at 0/90), and a turned net's error is not smooth enough for
# Gauss-Newton to walk far from a ±4° scan: each ply's angle is scanned by ±4° and ±10°.
SCAN = _Table({"ply_angle_deg": (-4.0, 4.0), "blank_offset_mm": (-8.0, 8.0),
               "holder_force_N": (-0.4, 0.8), "mu": (-0.15, 0.3), "tool_offset_mm": (-1.0, 1.0),
               PLY: (-10.0, -4.0, 4.0, 10.0)})

# The finite-difference step of the Gauss-Newton fit, per axis.
STEP = _Table({"ply_angle_deg": (1.0,), "blank_offset_mm": (1.5, 1.5), "holder_force_N": (0.2,),
               "mu": (0.05,), "tool_offset_mm": (1.0, 1.0)})
BOUNDS = _Table({"ply_angle_deg": (-45.0, 45.0), "blank_offset_mm": (-60.0, 60.0),
                 "holder_force_N": (0.05, 20.0), "mu": (0.0, 2.0),
                 "tool_offset_mm": (-30.0, 30.0)})
MAX_STEP = _Table({"ply_angle_deg": 10.0, "blank_offset_mm": 15.0, "holder_force_N": 2.0,
                   "mu": 0.3, "tool_offset_mm": 10.0})
# A value of each parameter that breaks every plane it can break (the model it needs).
GENERIC = _Table({"ply_angle_deg": 1.0, "blank_offset_mm": (1.0, 1.0),
                  "tool_offset_mm": (1.0, 1.0)})


# --------------------------------------------------------------------------------------------
# A set-up applied to a test


def forming_tests(bundle: Bundle) -> list[Test]:
    """The bundle's forming tests, each naming its case (a hemisphere test gets its case)."""
    out = []
    for test in bundle.tests:
        if not is_formed(test):
            continue
        if not names_case(test):
            test = dataclasses.replace(test, forming_case=case_of(test))
        out.append(test)
    return out


def stated(test: Test, name: str, model: Model) -> float | list[float]:
    """The test's stated value of a set-up parameter (offsets: [0, 0], where the case puts it)."""
    case = forming_case_of(test)
    if name == "ply_angle_deg":
        return case.blank.ply_angle_deg
    if ply_index(name):  # the ply's warp angle to x as laid: the stack's plus its own
        return case.blank.ply_angle_deg + case.plies[ply_index(name) - 1].angle_deg
    if name == "holder_force_N":
        return case.holder.force_N if case.holder is not None else math.nan
    if name == "mu":
        given = case.holder.mu if case.holder is not None else None
        return float(given if given is not None else np.max(model.parameters.get("mu", 0.0)))
    return [0.0, 0.0]


def applied(test: Test, name: str | None, p: Sequence[float], model: Model
            ) -> tuple[Test, np.ndarray]:
    """The test with set-up parameter ``name`` at ``p`` (internal units), and its read shift.

    ``p``: δθ (deg) for the ply angle, [x, y] (mm) for the offsets, the factor on the stated
    force for ``holder_force_N``, μ itself for ``mu``. The shift (mm) is added to the
    measured grid's flat positions where the model is read (a moved blank).
    """
    case = forming_case_of(test)
    shift = np.zeros(2)
    if name is None:  # the set-up as stated, on the case's own model
        return test, shift
    if name == "ply_angle_deg":
        changes = {"ply_angle_deg": case.blank.ply_angle_deg + float(p[0])}
    elif ply_index(name):  # one ply turned within the stack
        k = ply_index(name) - 1
        plies = list(case.plies)
        plies[k] = dataclasses.replace(plies[k], angle_deg=plies[k].angle_deg + float(p[0]))
        case = dataclasses.replace(case, plies=tuple(plies))
        changes = {}
    elif name == "blank_offset_mm":
        changes = {"blank_offset_mm": [float(p[0]), float(p[1])]}
        shift = np.array([float(p[0]), float(p[1])])
    elif name == "tool_offset_mm":
        changes = {"tool_offset_mm": [float(p[0]), float(p[1])]}
    elif name == "holder_force_N":
        changes = {"holder_force_N": case.holder.force_N * float(p[0])}
    elif name == "mu":
        changes = {"mu": float(p[0])}
    else:
        raise DrapeInputError(f"set-up parameter {name!r} is not one of "
                              f"{', '.join(SETUP_PARAMETERS)}")
    # The model the parameter needs at every value, its stated one too (the full or half
    # model, which may not form quite as the quarter does): the candidate is judged against
    # the stated set-up on that model.
    keep = [q for q in case.planes
            if q not in broken_planes({base_parameter(name): GENERIC.get(name)})]
    new = with_overrides(case, symmetry=keep, **changes)
    return dataclasses.replace(test, forming_case=new, case_keys={}), shift


def stated_point(name: str, test: Test, model: Model) -> np.ndarray:
    """The stated point in internal units."""
    if name == "holder_force_N":
        return np.array([1.0])
    if name == "mu":
        return np.array([float(stated(test, name, model))])
    return np.zeros(len(STEP[name]))


def why_not(name: str, tests: Sequence[Test]) -> str | None:
    """Why the part cannot have this set-up error at all (nothing it acts on), else None."""
    cases = [forming_case_of(t) for t in tests]
    if name in ("holder_force_N", "mu") and all(c.holder is None for c in cases):
        return "the part has no blank holder"
    if name == "tool_offset_mm" and all(not any(s.role == "punch" for s in c.tools)
                                        for c in cases):
        return "the part has no punch"
    if ply_index(name) and any(len(c.plies) < ply_index(name) for c in cases):
        return f"the part is not a stack of {ply_index(name)} or more plies"
    if name == "holder_force_N" and all(c.holder is None or c.holder.force_N == 0 for c in cases):
        return "the stated holding force is 0 (a factor on it changes nothing)"
    return None


def corrected(bundle: Bundle, name: str, p: Sequence[float], model: Model) -> Bundle:
    """The bundle with a fitted set-up applied to its forming tests.

    Each forming test names its case with the set-up applied (a hemisphere test, its case);
    for a blank offset the measured grid's flat positions are moved by it (the model is read
    where the material lay). Other tests are unchanged.
    """
    named = {t.id: t for t in forming_tests(bundle)}
    tests = []
    for test in bundle.tests:
        if test.id in named:
            test = moved(*applied(named[test.id], name, p, model))
        tests.append(test)
    return dataclasses.replace(bundle, tests=tuple(tests))


def fitted_value(bundle: Bundle, name: str, p: Sequence[float], model: Model):
    """A set-up point ``p`` (internal units) in the report's units."""
    return fitted_of(name, np.asarray(p, dtype=float), forming_tests(bundle)[0], model)


def fitted_case(case: FormingCase, entry: dict[str, Any]) -> FormingCase:
    """A case with a report's fitted set-up applied (``entry``: one of ``report["setup"]``)."""
    name, value = entry["parameter"], entry["fitted"]
    if ply_index(name):  # the ply's angle within the stack: the fitted one less the stack's
        k = ply_index(name) - 1
        plies = list(case.plies)
        plies[k] = dataclasses.replace(plies[k], angle_deg=value - case.blank.ply_angle_deg)
        return with_overrides(dataclasses.replace(case, plies=tuple(plies)),
                              symmetry=[q for q in case.planes
                                        if q not in broken_planes({PLY[:-1]: value})])
    return with_overrides(case, **{name: value})


def step_text(name: str) -> str:
    """The scan's smallest move of a parameter, in words."""
    v = min(u for u in SCAN[name] if u > 0)
    return {"ply_angle_deg": f"{v:g}°", "holder_force_N": f"a factor {1 + v:g}",
            "mu": f"{v:g}"}.get(base_parameter(name), f"{v:g} mm along x and along y")


def fitted_of(name: str, p: np.ndarray, test: Test, model: Model):
    """The fitted value in the report's units (and the stated one)."""
    s = stated(test, name, model)
    if base_parameter(name) == "ply_angle_deg":
        return s + float(p[0])
    if name == "holder_force_N":
        return s * float(p[0])
    if name == "mu":
        return float(p[0])
    return [float(p[0]), float(p[1])]


def sd_of(name: str, sd: np.ndarray, test: Test, model: Model):
    """An sd in internal units (per axis) in the report's units."""
    if name == "holder_force_N":
        return float(stated(test, name, model) * sd[0])
    if name in ("blank_offset_mm", "tool_offset_mm"):
        return [float(sd[0]), float(sd[1])]
    return float(sd[0])


def show(name: str, p: np.ndarray, test: Test, model: Model) -> str:
    """A point in internal units as the report's value, in words."""
    v = fitted_of(name, p, test, model)
    return f"[{v[0]:.3g}, {v[1]:.3g}]" if isinstance(v, list) else f"{v:.4g}"
