"""The parts of the scenario benchmark and their case files, written by hand.

Each part has two case files:

- the **truth's** (the real tools): the project's own shapes (``builtin:hemisphere``, the
  double dome's and the square box's geometry scripts copied from ``meshes/``) or, for the
  user's part, an STL made finely (1 mm chords);
- the **lab's** (what the bundle brings): the same blank, holder and motion, its tools the
  lab's STL copy made by :mod:`tools` (3 mm chords) for the double dome, the square box and
  the user's part, the builtin tools for the hemisphere and the octagon (or an STL copy of
  nothing: the builtin tools are data, not code).

The nets: the lab's case on 20 mm cells (the hemisphere stack on 30 mm), a quarter or half
model where the part is symmetric. Each part's steps and travels keep a forming run at a few
seconds on that net.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import lab
import tools

ROOT = Path(__file__).resolve().parents[2]
MESHES = ROOT / "meshes"

HEMI = {"punch_radius_mm": 60.0, "fillet_radius_mm": 20.0, "shoulder_radius_mm": 84.0,
        "edge_radius_mm": 1.0, "holder_opening_mm": 170.0, "travel_mm": 80.0,
        "ply_thickness_mm": 0.3}
OCTA = {"punch_radius_mm": 40.0, "fillet_radius_mm": 15.0, "shoulder_radius_mm": 58.0,
        "holder_opening_mm": 120.0, "travel_mm": 55.0}
DD = {"dome_height_mm": 40.0, "dome_radius_mm": 60.0, "dome_centre_mm": 40.0}
BOX = {"half_side_mm": 50.0, "corner_radius_mm": 20.0, "fillet_radius_mm": 15.0,
       "foot_radius_mm": 5.0, "depth_mm": 25.0}
CUP = {"a": 65.0, "b": 40.0, "rc": 40.0, "rb": 12.0, "rf": 5.0, "depth": 24.0}

PARTS = {
    # name: blank, holder force (N, whole part), forming time (s), travel (mm), the lab case's
    # cell and step (mm), symmetry planes
    "hemisphere": {"blank": {"outline": "rectangle", "size_mm": [240.0, 240.0]},
                   "force_N": 400.0, "duration_s": 40.0, "travel_mm": 80.0, "cell_mm": 20.0,
                   "step_mm": 4.0, "symmetry": ["x", "y"], "centre": (0.0, 0.0)},
    "octagon": {"blank": {"outline": "polygon", "points_mm": [
        [-40.0, -95.0], [40.0, -95.0], [95.0, -40.0], [95.0, 40.0], [40.0, 95.0],
        [-40.0, 95.0], [-95.0, 40.0], [-95.0, -40.0]]},
        "force_N": 100.0, "duration_s": 20.0, "travel_mm": 55.0, "cell_mm": 20.0,
        "step_mm": 2.5, "symmetry": ["x"], "centre": (0.0, 0.0)},
    "double_dome": {"blank": {"outline": "rectangle", "size_mm": [300.0, 200.0]},
                    "force_N": 200.0, "duration_s": 40.0, "travel_mm": 40.0, "cell_mm": 20.0,
                    "step_mm": 2.0, "symmetry": ["x", "y"], "centre": (0.0, 0.0)},
    "square_box": {"blank": {"outline": "rectangle", "size_mm": [240.0, 240.0]},
                   "force_N": 200.0, "duration_s": 25.0, "travel_mm": 25.0, "cell_mm": 20.0,
                   "step_mm": 2.0, "symmetry": ["x", "y"], "centre": (0.0, 0.0)},
    "user_cup": {"blank": {"outline": "polygon", "points_mm": [
        [-130.0, -60.0], [-90.0, -100.0], [90.0, -100.0], [130.0, -60.0], [130.0, 60.0],
        [90.0, 100.0], [-90.0, 100.0], [-130.0, 60.0]]},
        "force_N": 150.0, "duration_s": 24.0, "travel_mm": 24.0, "cell_mm": 20.0,
        "step_mm": 2.0, "symmetry": ["x", "y"], "centre": (0.0, 0.0)},
}

STACK = {"plies": [{"angle_deg": 0.0, "thickness_mm": 0.3},
                   {"angle_deg": 45.0, "thickness_mm": 0.3}],
         "interply": {"tau0_MPa": 0.0, "mu_ply": 0.2, "eta_f_MPa_s_per_mm": 0.002,
                      "slip_mm": 0.1},
         "cell_mm": 30.0, "step_mm": 2.0, "duration_s": 8.0}
"""The [0/90, ±45] stack: on the hemisphere, the whole blank on 30 mm cells, 8 s, no die."""


def _tool(name: str, role: str, geometry: str, parameters=None, motion=None, mesh_mm=None
          ) -> str:
    keys = {"name": name, "role": role, "geometry": geometry}
    if parameters:
        keys["parameters"] = parameters
    if mesh_mm:
        keys["mesh_mm"] = mesh_mm
    text = lab.toml_table("[[tool]]", keys)
    if motion:
        text += lab.toml_table("[tool.motion]", motion)
    return text


def _stl_tools(part: str, folder: Path, chord_mm: float) -> dict[str, str]:
    """Write the part's tools as STL files; their geometry keys by tool name."""
    if part == "double_dome":
        F = tools.double_dome_height(DD["dome_height_mm"], DD["dome_radius_mm"],
                                     DD["dome_centre_mm"])
        shapes = {"punch": tools.height_field(F, 165.0, 115.0, chord_mm, z0=-40.5),
                  "die": tools.height_field(F, 165.0, 115.0, chord_mm, z0=0.3),
                  "holder": tools.holder_plate(115.0, 75.0, 15.0, 80.0)}
    elif part == "square_box":
        a, rc, rb, rf, d = (BOX[k] for k in ("half_side_mm", "corner_radius_mm",
                                              "fillet_radius_mm", "foot_radius_mm",
                                              "depth_mm"))
        shapes = {"punch": tools.swept_box(a, a, rc, rb, rf, d, -25.5, 130.0, chord_mm),
                  "die": tools.swept_box(a, a, rc, rb, rf, d, -0.5, 130.0, chord_mm,
                                         offset=0.8),
                  "holder": tools.holder_plate(70.0, 70.0, 40.0, 100.0)}
    elif part == "user_cup":
        c = CUP
        shapes = {"punch": tools.swept_box(c["a"], c["b"], c["rc"], c["rb"], c["rf"],
                                           c["depth"], -c["depth"] - 0.5, 120.0, chord_mm),
                  "die": tools.swept_box(c["a"], c["b"], c["rc"], c["rb"], c["rf"],
                                         c["depth"], -0.5, 120.0, chord_mm, offset=0.8),
                  "holder": tools.holder_plate(c["a"] + 20.0, c["b"] + 20.0, c["rc"] + 20.0,
                                               90.0)}
    else:
        raise ValueError(f"no STL tools for {part}")
    for name, triangles in shapes.items():
        lab.write_stl(folder / f"{name}.stl", triangles, name)
    return {name: f"{name}.stl" for name in shapes}


def write_case(folder: Path, part: str, *, truth: bool, cell_mm: float | None = None,
               step_mm: float | None = None, duration_s: float | None = None,
               mu: float | None = None, stack: bool = False, model: str | None = None,
               stl_cache: Path | None = None) -> Path:
    """Write a part's case file (and its tool files) into ``folder``; its path.

    ``truth``: the real tools (else the lab's STL copy, or the builtin tools); ``mu``: the
    holder's friction coefficient stated in the case (``[holder] mu``); ``stack``: the
    [0/90, ±45] stack (the whole blank); ``model``: a model file the case names.
    ``stl_cache``: a folder keeping STL files made once (copied, not remade).
    """
    p = PARTS[part]
    folder.mkdir(parents=True, exist_ok=True)
    duration = duration_s or (STACK["duration_s"] if stack else p["duration_s"])
    head = {"name": part + ("_stack" if stack else ""), "duration_s": duration,
            "step_mm": step_mm or (STACK["step_mm"] if stack else p["step_mm"])}
    if model:
        head["model"] = model
    text = "# written by benchmarks/scenarios (a " + ("truth's" if truth else "lab's") + \
        " case)\n\n" + lab.toml_table("[case]", head) + "\n"
    blank = {**p["blank"], "cell_mm": cell_mm or (STACK["cell_mm"] if stack else p["cell_mm"]),
             "symmetry": [] if stack else p["symmetry"]}
    if stack:
        blank["hold_origin"] = True
    text += lab.toml_table("[blank]", blank) + "\n"
    holder = {"tool": "holder", "holder_force_N": p["force_N"]}
    if mu is not None:
        holder["mu"] = mu
    text += lab.toml_table("[holder]", holder) + "\n"
    travel = p["travel_mm"]
    motion = {"time_s": [0.0, duration], "z_mm": [0.0, travel]}
    if part in ("hemisphere", "octagon"):
        params = dict(HEMI if part == "hemisphere" else OCTA)
        if stack:
            params["ply_thickness_mm"] = 0.6
        # A stack is drawn by the punch through the holder without a die: with the die closing
        # on it, the bonded [0/90, ±45] stack on 30 mm cells stops 1-2 mm short of the travel.
        for name in ("punch", "holder") if stack else ("punch", "die", "holder"):
            text += _tool(name, name, "builtin:hemisphere", params) + "\n"
    elif truth and part in ("double_dome", "square_box"):
        source = MESHES / part
        script = f"{part}.py"
        for name in (script, "holder.geo"):
            shutil.copy(source / name, folder / name)
        if part == "double_dome":
            text += _tool("punch", "punch", script, {**DD, "z_base_mm": -40.5}, motion, 3.0)
            text += _tool("die", "die", script, {**DD, "offset_mm": 0.3}, mesh_mm=3.0)
        else:
            text += _tool("punch", "punch", script, {**BOX, "z_base_mm": -25.5}, motion, 3.0)
            text += _tool("die", "die", script, {**BOX, "z_base_mm": -0.5, "offset_mm": 0.8},
                          mesh_mm=3.0)
        text += _tool("holder", "holder", "holder.geo")
    else:
        chord = 1.5 if truth else 2.0
        key = f"{part}-{chord:g}mm"
        made = stl_cache / key if stl_cache else None
        if made and made.is_dir():
            geometry = {}
            for f in made.glob("*.stl"):
                shutil.copy(f, folder / f.name)
                geometry[f.stem] = f.name
        else:
            geometry = _stl_tools(part, folder, chord)
            if made:
                made.mkdir(parents=True, exist_ok=True)
                for name in geometry.values():
                    shutil.copy(folder / name, made / name)
        text += _tool("punch", "punch", geometry["punch"], motion=motion) + "\n"
        text += _tool("die", "die", geometry["die"]) + "\n"
        text += _tool("holder", "holder", geometry["holder"]) + "\n"
    if stack:
        for ply in STACK["plies"]:
            text += "\n" + lab.toml_table("[[ply]]", ply)
        text += "\n" + lab.toml_table("[interply]", STACK["interply"])
    path = folder / "case.toml"
    path.write_text(text)
    return path
