"""The named regions of a formed part: what each point touches at the end of forming.

Used by the forming kinds to say where on the part their error sits: the grid's nodes
(:func:`~fenicsx_drape.diagnosis.kinds.grid.case_regions`) and the lab's formed points
(:func:`~fenicsx_drape.diagnosis.kinds.lab.part_region_of_points`). At the end of forming, a
point is under the holder when the clamping tool covers it and it lies on its surface; else on
a punch, die or surface tool when within :data:`CONTACT_MM` + 3 × noise of it: on a *wall*
where that surface is steeper than :data:`WALL_DEG` to the plane normal to the travel (split
by the point's direction from the tool axis in the tow frame: within 22.5° of a tow axis, or
nearer a bias diagonal), else the *punch top* when in the upper half of the part's depth and
the *flat base* when lower; else free.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds.forming import forming_case_of
from fenicsx_drape.forming.case import case_key
from fenicsx_drape.runs import memo

if TYPE_CHECKING:
    from fenicsx_drape.forming.case import FormingCase
    from fenicsx_drape.measurements.bundle import Test

# Regions of the part a case forms (module doc): by what a point touches at the end and, on
# the walls, by its direction from the tool axis in the tow frame.
CASE_REGION_NAMES = ("punch top", "walls along the tow axes", "walls on the bias diagonals",
                     "flat base", "flange under the holder", "free sheet (no tool contact)")
CONTACT_MM = 1.0  # a node within this (plus three times the noise) of a surface touches it
WALL_DEG = 30.0  # a surface steeper than this to the plane normal to the travel is a wall
CONTACT_ROLES = ("punch", "die", "surface")
def _tools_of(case: FormingCase) -> dict[str, Any]:
    """The built tools of a case (kept by the case's content: meshing costs seconds)."""
    from fenicsx_drape.forming.tools.build import build_tools

    tools, key = memo("part.tools", 16), case_key(case)
    hit = tools.get(key)
    return hit if hit is not None else tools.put(key, build_tools(case))


def travel_axis(case: FormingCase) -> np.ndarray:
    """The unit direction the case's fastest tool travels (the frame's z for the hemisphere)."""
    speeds = [case.speed_mm_per_s(t) for t in case.tools]
    spec = case.tools[int(np.argmax(speeds))]
    if spec.motion is not None:
        d = spec.motion.translation(spec.motion.time_s[-1]) - spec.motion.translation(0.0)
        if np.linalg.norm(d) > 0:
            return d / np.linalg.norm(d)
    return np.array([0.0, 0.0, 1.0])


def region_of_points(test: Test, x: np.ndarray, direction_deg: np.ndarray,
                     noise_mm: float) -> np.ndarray:
    """Index into :data:`CASE_REGION_NAMES` of formed points (n, 3) of a case's test.

    With their directions (deg, 0-45) from the nearest tow axis and the positions' noise (mm)
    (module doc). Points of a whole part are folded into the modelled part first (the tools
    need only be given there).
    """
    case = forming_case_of(test)
    tools = _tools_of(case)
    t = case.duration_s
    x = np.array(x, float)
    for plane in case.planes:
        axis = {"x": 0, "y": 1}[plane]
        x[:, axis] = np.abs(x[:, axis])
    tol = CONTACT_MM + 3.0 * noise_mm
    n = len(x)
    best = np.full(n, np.inf)
    normal = np.zeros((n, 3))
    for spec in case.tools:
        if spec.role in CONTACT_ROLES:
            g = tools[spec.name].gap(x, t)
            closer = (np.abs(g.phi) < tol) & (np.abs(g.phi) < best)
            best = np.where(closer, np.abs(g.phi), best)
            normal[closer] = g.normal[closer]
    touching = np.isfinite(best)
    e = travel_axis(case)
    cos = np.abs(normal @ e) / np.maximum(np.linalg.norm(normal, axis=1), 1e-300)
    wall = touching & (cos < math.cos(math.radians(WALL_DEG)))
    height = x @ e
    top = touching & ~wall & (height >= 0.5 * max(float(height.max()), 0.0))
    bias = np.asarray(direction_deg) >= 22.5
    which = np.select([wall & ~bias, wall & bias, top, touching], [1, 2, 0, 3], default=5)
    if case.holder is not None:
        holder = tools[case.holder.tool]
        under = np.asarray(holder.covers(x, t), bool) & (np.abs(holder.gap(x, t).phi) < tol)
        which = np.where(under, 4, which)
    return which
