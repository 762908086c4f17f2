"""A run's size from its case alone, and whether its stack fits the tools, before it runs.

:func:`run_size` counts what a forming run will cost before anything is built: its load
steps (the fastest tool's travel over ``step_mm``), its nodes (every ply's net: nodes ×
plies) and a time estimate from both (:func:`fenicsx_drape.limits.run_seconds`);
:func:`check_run_size` refuses a run beyond the limits (:func:`fenicsx_drape.limits.check_steps`:
the steps and the work, node-steps), with the numbers.

:func:`stack_fit` compares a stack of plies with the gap its builtin die leaves over the punch
(``ply_thickness_mm``): plies whose mid-planes cannot fit in it are refused, naming the plies
and the gap; a stack thicker than the gap (the die squeezes it) is warned. Meshed tools' gaps
are measured on their surfaces before the first step
(:mod:`~fenicsx_drape.forming.running.geometry`, the same messages).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from fenicsx_drape.forming.case.spec import FormingCase, where
from fenicsx_drape.forming.tools.build import builtin_tool_set

# A stack's thickness may exceed the gap by this share before it is refused: the rounding of
# a case file's numbers (builtin tools, whose gap is exact), and the chords of meshed tools
# (two surfaces meshed apart come nearer than their offset by about h²/8R: 0.02 mm for 3 mm
# triangles on the double dome's 60 mm domes, 3 % of a 0.6 mm stack).
GAP_TOLERANCE = 1e-6
MESHED_GAP_TOLERANCE = 0.1


def run_size(case: FormingCase) -> dict[str, float]:
    """A run's length from the case alone: load steps, nodes, plies and seconds (one rank).

    The steps are the fastest tool's travel over ``step_mm`` (cut-backs add a few); the
    nodes the lattices of every ply's net (one net per distinct ply blank, counted once per
    ply); the time :func:`fenicsx_drape.limits.run_seconds` of steps and nodes.
    """
    from fenicsx_drape.limits import run_seconds

    lattices: dict = {}
    nodes = 0.0
    blanks = case.ply_blanks()
    for blank in blanks:
        if blank not in lattices:
            grid = blank.grid()
            lattices[blank] = float((grid.nx + 1) * (grid.ny + 1))
        nodes += lattices[blank]
    steps = float(math.ceil(case.total_travel_mm / case.step_mm - 1e-9))
    return {"steps": steps, "nodes": nodes, "plies": float(len(blanks)),
            "seconds": run_seconds(steps, nodes), "travel_mm": case.total_travel_mm}


def size_text(case: FormingCase, size: dict[str, float]) -> str:
    """The estimate as printed before the first step (``about 80 load steps ... (estimate)``)."""
    from fenicsx_drape.limits import duration_text

    plies = int(size.get("plies", 1))
    nodes = (f"{size['nodes']:.0f} nodes ({plies} plies of "
             f"{size['nodes'] / plies:.0f})" if plies > 1 else f"{size['nodes']:.0f} nodes")
    return (f"{case.name}: about {size['steps']:.0f} load steps ({size['travel_mm']:g} mm at "
            f"{case.step_mm:g} mm) on {nodes}, about {duration_text(size['seconds'])} "
            "(estimate)")


def check_run_size(case: FormingCase) -> dict[str, float]:
    """Refuse a run beyond the limits at once, with the numbers.

    Its nodes (all plies' nets: the memory), its load steps and its work, node-steps
    (:func:`fenicsx_drape.limits.check_steps`).

    Returns:
        :func:`run_size`.
    """
    from fenicsx_drape.limits import check_nodes, check_steps

    size = run_size(case)
    at = where(case)
    plies = int(size["plies"])
    if plies > 1:
        check_nodes(size["nodes"], f"{at}: {plies} plies of {size['nodes'] / plies:.0f} nodes")
    check_steps(size["steps"], size["nodes"], at,
                f"{size['travel_mm']:g} mm of travel at step_mm = {case.step_mm:g}",
                plies=plies)
    return size


def plies_text(thickness_mm: Sequence[float]) -> str:
    """The plies' thicknesses in a message: ``0.3 + 1000 mm``, or ``500 plies of 0.3 mm``."""
    t = [float(v) for v in thickness_mm]
    if len(t) <= 4:
        return " + ".join(f"{v:g}" for v in t) + " mm"
    if min(t) == max(t):
        return f"{len(t)} plies of {t[0]:g} mm"
    return f"{len(t)} plies of {min(t):g} to {max(t):g} mm"


def stack_fit(thickness_mm: Sequence[float], gap_mm: float, between: str,
              tolerance: float = GAP_TOLERANCE) -> list[str]:
    """Why plies of these thicknesses do not fit a gap (empty when they do).

    The plies lie with their mid-planes (t_k + t_k+1)/2 apart, ply 1's on the punch, and
    keep their thickness: a die that closes on a stack thicker than its gap would press the
    plies into each other at the end of the motion, a result the model has no law for
    (no compaction), so such a stack is refused, as one whose mid-planes do not fit.

    Args:
        thickness_mm: The plies' thicknesses, from the punch side.
        gap_mm: The gap between punch and die at the end of the motion.
        between: The tools in the message ("the punch 'punch' and the die 'die'").
        tolerance: The share by which the stack may exceed the gap (:data:`GAP_TOLERANCE`,
            :data:`MESHED_GAP_TOLERANCE` for meshed tools).
    """
    t = [float(v) for v in thickness_mm]
    if len(t) < 2:
        return []
    total = sum(t)
    span = total - (t[0] + t[-1]) / 2
    gap = float(gap_mm)
    plies = ((f"{len(t)} plies: " if len(t) <= 4 else "") + f"{plies_text(t)}, {total:g} mm thick")
    fix = f"make the gap the stack's thickness ({total:g} mm) or check the plies' thickness_mm"
    if span > gap * (1 + tolerance) + 1e-12:
        return [f"the stack ({plies}) cannot fit between {between}: the plies' mid-planes "
                f"span {span:g} mm, more than the gap of {gap:g} mm the tools leave at the end "
                f"of the motion; {fix}"]
    if total > gap * (1 + tolerance) + 1e-12:
        return [f"the stack ({plies}) is thicker than the gap of {gap:g} mm between {between} "
                f"at the end of the motion: the die would press the plies into each other; "
                f"{fix}"]
    return []


def builtin_stack_fit(case: FormingCase, thickness_mm: Sequence[float] | None = None
                      ) -> list[str]:
    """:func:`stack_fit` of the case's plies against each builtin die's gap.

    The builtin die is the punch offset by its ``ply_thickness_mm``, at the punch's end.
    ``thickness_mm`` gives the plies (default: the case's stack; a case of one ply has none).
    """
    if thickness_mm is None:
        thickness_mm = [p.thickness_mm for p in case.plies]
    punch = next((t.name for t in case.tools if t.role == "punch"), None)
    errors = []
    for die in (t for t in case.tools if t.builtin and t.role == "die"):
        between = (f"the punch {punch!r} and the die {die.name!r}" if punch else
                   f"the punch and the die {die.name!r}")
        errors += stack_fit(thickness_mm, builtin_tool_set(die).ply_thickness_mm,
                            between + " (its ply_thickness_mm)")
    return errors
