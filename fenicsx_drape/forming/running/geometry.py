"""A case's geometry checked before the first step, in the user's terms.

A case can be wrong about where its parts are, and the solve then ends far from the cause
("did not converge", "no warp bar on the grid"). :func:`geometry_problems` looks at the flat
blank and the built tools before any step and names the tool and the distance:

- *the blank and the tools never meet*: over the whole motion (:data:`TIMES` instants), no
  punch, die or surface comes to the flat blank (its signed distance never reaches 0);
- *a tool on the wrong side of the sheet*: at the start, nodes of the blank lie inside a
  punch, die or surface by more than :data:`WRONG_SIDE_MM` (the sheet must start on the
  tool's ``sheet_side``);
- *a holder that does not reach the blank*: at the start its clamping surface covers none of
  the blank's nodes;
- *a punch that never reaches the die* (a warning: a test stopped short is one): at the end
  of the motion, the die's surface is still more than a sheet cell from the punch;
- *a stack that does not fit between punch and die*: thicker than the gap the tools leave at
  the end of the motion (refused, naming the plies and the gap;
  :func:`~fenicsx_drape.forming.case.size.stack_fit`). Every ply's nodes, at its height,
  are checked for the wrong side of a tool.

The distances are exact for meshed tools (closest points on the triangles) and closed form
for the builtin ones.
"""

from __future__ import annotations

import numpy as np

#: Instants of the motion at which the blank and the tools are looked at.
TIMES = 11
#: A node this far (mm) inside a tool at the start is on the wrong side of it.
WRONG_SIDE_MM = 1.0
#: Points of each surface looked at (a subsample of a fine one).
DIE_POINTS = 2000


def _distance(tool, x: np.ndarray, t: float) -> np.ndarray:
    """Signed distance (n,) of points to a tool at time t: positive on the sheet's side."""
    exact = getattr(tool, "signed_distance", None)
    return exact(x, t) if exact is not None else tool.gap(x, t).phi


def geometry_problems(case, tools: dict, nodes: np.ndarray) -> tuple[list[str], list[str]]:
    """Errors and warnings about where the blank and the tools are (module docstring).

    Args:
        case: The :class:`~fenicsx_drape.forming.case.spec.FormingCase`.
        tools: Its built tools by name.
        nodes: The flat blank's nodes (n, 3) in mm.

    Returns:
        ``(errors, warnings)``, each message naming the tool and the distance.
    """
    from fenicsx_drape.forming.case.size import builtin_stack_fit

    errors: list[str] = []
    warns: list[str] = []
    x = np.asarray(nodes, dtype=float).reshape(-1, 3)
    contact = [t for t in case.tools if t.role in ("punch", "die", "surface")]
    if len(case.plies) > 1:
        errors = builtin_stack_fit(case)
        heights = _ply_heights(case)
        for spec in contact:  # the other plies lie over the first: the top one first
            def depth(k, spec=spec):
                return -float(_distance(tools[spec.name], x + np.array([0.0, 0.0, heights[k][0]]),
                                        0.0).min())

            if depth(-1) <= WRONG_SIDE_MM:
                continue
            first = next(k for k in range(1, len(heights)) if depth(k) > WRONG_SIDE_MM)
            z, thickness = heights[first]
            which = (f"ply {first + 1} of the stack starts" if first + 1 == len(heights) else
                     f"plies {first + 1} to {len(heights)} of the stack start")
            errors.append(f"{which} inside the "
                          f"{spec.role} {spec.name!r} (ply {first + 1}, {thickness:g} mm "
                          f"thick, lies with its mid-plane {z:g} mm above ply 1's; the top "
                          f"ply up to {depth(-1):.3g} mm deep): the stack does not fit where "
                          "the tools start (check the plies' thickness_mm)")
    nearest = {}
    for spec in contact:
        tool = tools[spec.name]
        d0 = _distance(tool, x, 0.0)
        inside = d0 < -WRONG_SIDE_MM
        if inside.any():
            errors.append(f"tool {spec.name!r} ({spec.role}) starts on the wrong side of the "
                          f"sheet: {int(inside.sum())} of the blank's {len(x)} nodes start "
                          f"inside it, up to {-d0.min():.3g} mm deep (the sheet must start on "
                          f"its sheet_side {spec.side!r})")
        nearest[spec.name] = float(d0.min())
    if contact and not errors:
        for t in np.linspace(0.0, case.duration_s, TIMES)[1:]:
            if min(nearest.values()) <= 0.0:
                break
            for spec in contact:
                if nearest[spec.name] > 0.0:
                    nearest[spec.name] = min(nearest[spec.name],
                                             float(_distance(tools[spec.name], x, t).min()))
        if min(nearest.values()) > 0.0:
            far = ", ".join(f"{n!r} comes no nearer than {d:.3g} mm" for n, d in nearest.items())
            errors.append(f"the blank and the tools never meet: over the motion {far} to the "
                          "flat blank (check where the blank and the tools are, and the "
                          "motions)")
    if case.holder is not None:
        holder = tools[case.holder.tool]
        if not np.any(holder.covers(x, 0.0)):
            gap = float(np.abs(_distance(holder, x, 0.0)).min())
            where = (f"the nearest node is {gap:.3g} mm from it" if gap > 1e-6 else
                     "the blank lies within its opening")
            errors.append(f"the holder {case.holder.tool!r} does not reach the blank: its "
                          f"surface covers none of the blank's nodes at the start ({where})")
    end = case.duration_s
    for punch in (t for t in contact if t.role == "punch"):
        for die in (t for t in contact if t.role == "die"):
            p, d = tools[punch.name], tools[die.name]
            if not (hasattr(p, "surface") and hasattr(d, "surface")):
                continue  # the builtin die sits on the builtin punch's end by construction
            # Both ways: the corners of each surface to the other (a coarse plate has few).
            gap = min(float(a.closest(b.motion.apply(pts, end), end)[1].min()) for a, b in
                      ((p, d), (d, p)) if hasattr(b, "surface")
                      for pts in [b.surface.points[:: max(1, len(b.surface.points)
                                                        // DIE_POINTS)]])
            if gap > case.blank.cell_mm:
                warns.append(f"the punch {punch.name!r} never reaches the die {die.name!r}: "
                             f"at the end of the motion they are still {gap:.3g} mm apart "
                             f"(more than the sheet's cell {case.blank.cell_mm:g} mm)")
            elif len(case.plies) > 1:
                from fenicsx_drape.forming.case.size import MESHED_GAP_TOLERANCE, stack_fit

                errors += stack_fit([p.thickness_mm for p in case.plies], gap,
                                    f"the punch {punch.name!r} and the die {die.name!r}",
                                    MESHED_GAP_TOLERANCE)
    return errors, warns


def _ply_heights(case) -> list[tuple[float, float]]:
    """Each ply's mid-plane height over ply 1's (mm) and its thickness, from the punch side."""
    t = [p.thickness_mm for p in case.plies]
    z = np.concatenate([[0.0], np.cumsum(0.5 * (np.array(t[:-1]) + np.array(t[1:])))])
    return [(float(zk), float(tk)) for zk, tk in zip(z, t)]
