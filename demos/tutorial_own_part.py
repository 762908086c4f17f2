# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# # Tutorial: form a part of your own
#
# This tutorial builds a forming case from nothing: a punch written as a binary STL by a few
# lines of NumPy, a die from the same function, a blank holder as a Gmsh `.geo` script, and
# the `case.toml` that puts them together. It then forms the part, reads the outputs and
# shows the pictures. Everything goes into one folder; the same folder works from the
# command line:
#
#     ./drape exec python3 demos/tutorial_own_part.py results/own_part
#     ./drape form results/own_part/part/case.toml --out results/own_part/formed
#
# The part: a smooth round bump, 100 mm across and 25 mm high, drawn into a 200 mm square
# blank of the paper's prepreg through a holder with a 150 mm round opening.
#
# ## The rules of placement
#
# The case's frame is the measurement spec's: **z = 0 is the flat sheet**, x the warp and y
# the weft of a ply at 0°, **z along the punch's travel** (the punch moves towards +z), the
# origin on the part's axis. Tool files are read in these coordinates (millimetres).
#
# - **The punch starts below the sheet** and rises through it: its highest point a little
#   below z = 0 (here 0.5 mm), its motion table taking it up by the drawing depth. A punch
#   that starts above z = 0 starts inside the sheet; nothing checks that, and the first steps
#   then push the sheet through it. A run in which no node ever touches a punch or die says so
#   (a warning names the tools).
# - **The die sits where the punch ends**, fixed, on the other side of the sheet: the punch's
#   final surface lifted by the clearance plus the ply's thickness (here 0.5 + 0.3 mm), its
#   sheet side `-z` (the default of the role `die`). A die is optional (`drape form --no-die`).
# - **The holder is a surface in z = 0 that reaches past the blank** on every side, with an
#   opening wider than the punch plus its clearance. A node of the sheet is clamped (and
#   carries the holder's friction, eq. 1) only while its closest point on the holder is inside
#   the holder's surface: a node beyond the holder's outer edge or in its opening is free. A
#   holder that ends inside the blank leaves the blank's rim unclamped.
# - **Symmetry**: a quarter model (`symmetry = ["x", "y"]`) needs the tools and the blank
#   symmetric in x = 0 and y = 0 (the tools are not checked) and a net with nodes on both
#   planes.
# - **Mesh sizes**: a tool that Gmsh meshes (a `.geo`, a `.py` build function, STEP, IGES,
#   BREP) is meshed with the case's `mesh_mm` as Gmsh's largest target size
#   (`Mesh.MeshSizeMax`): it replaces a `Mesh.MeshSizeMax` the script sets and caps the sizes
#   of its points; without `mesh_mm` the script's own sizes hold. A script that meshes
#   itself (`Mesh 2;`), an STL and a `.msh` are taken as they are (`mesh_mm` does not
#   apply). Tool triangles need not follow the
#   sheet's cells; a tool mesh far finer than the sheet costs time for nothing (a warning
#   says so) and one too coarse for its curvature is warned about too.
# - **STL**: ASCII or binary, read by Gmsh; units are millimetres. Its triangles are oriented
#   on reading (the normals of an open surface towards `sheet_side`), so their order in the
#   file does not matter.

# +
import sys
from pathlib import Path

import numpy as np

SCRIPT = "__file__" in globals()  # as a page of the docs the tutorial is a notebook
args = sys.argv[1:] if SCRIPT else []
out = Path(args[0]) if args else Path("results/own_part")
part = out.resolve() / "part"  # absolute: geometry scripts run in a child process
part.mkdir(parents=True, exist_ok=True)
# -

# ## The punch and the die: an STL made in Python
#
# A surface of revolution z(r) sampled on rings and spokes: the bump z = h cos²(πr / 2a) for
# r < a and a flat brim out to r = 60 mm, shifted so that its top is 0.5 mm below the sheet.
# `write_stl` writes binary STL with NumPy alone (an 80-byte header, the number of triangles,
# then per triangle a normal, its three corners and two spare bytes).

# +
RADIUS_MM, HEIGHT_MM, BRIM_MM = 50.0, 25.0, 60.0
CLEARANCE_MM, PLY_MM = 0.5, 0.3


def bump(r, lift_mm=0.0):
    """The punch's height at radius r (mm), its top 0.5 mm below the sheet, plus ``lift_mm``."""
    inside = np.cos(np.pi * np.minimum(r, RADIUS_MM) / (2 * RADIUS_MM)) ** 2
    return HEIGHT_MM * inside - HEIGHT_MM - CLEARANCE_MM + lift_mm


def surface_of_revolution(height, rings=40, spokes=64):
    """Points and triangles of z = height(r) over the disc r <= BRIM_MM."""
    r = BRIM_MM * (np.arange(1, rings + 1) / rings) ** 1.3  # finer near the axis
    θ = 2 * np.pi * np.arange(spokes) / spokes
    R, T = np.meshgrid(r, θ, indexing="ij")
    ring_points = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel(),
                                   height(R).ravel()])
    points = np.vstack([[0.0, 0.0, height(np.array(0.0))], ring_points])
    k = 1 + np.arange(rings * spokes).reshape(rings, spokes)  # point index of ring i, spoke j
    nxt = np.roll(k, -1, axis=1)
    fan = np.column_stack([np.zeros(spokes, int), k[0], nxt[0]])
    a, b, c, d = k[:-1].ravel(), nxt[:-1].ravel(), k[1:].ravel(), nxt[1:].ravel()
    triangles = np.vstack([fan, np.column_stack([a, c, d]), np.column_stack([a, d, b])])
    return points, triangles


def write_stl(path, points, triangles):
    """Write a binary STL (millimetres)."""
    p = points[triangles]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("spare", "<u2")])
    rows = np.zeros(len(triangles), record)
    rows["normal"], rows["corners"] = normal, p
    with open(path, "wb") as f:
        f.write(b"tutorial_own_part".ljust(80, b" "))
        f.write(np.uint32(len(rows)).tobytes())
        f.write(rows.tobytes())


write_stl(part / "punch.stl", *surface_of_revolution(bump))
# The die: the punch at the end of its travel, lifted by the clearance and the ply.
write_stl(part / "die.stl",
          *surface_of_revolution(lambda r: bump(r, HEIGHT_MM + CLEARANCE_MM + PLY_MM)))
print("punch.stl:", (part / "punch.stl").stat().st_size, "bytes")
# -

# ## The holder: a Gmsh script
#
# The plane z = 0 outside a round opening of 150 mm (the punch's brim is 120 mm across, plus
# 15 mm all round), out to a 260 mm square, past the 200 mm blank on every side. Its
# `DefineConstant` values are defaults the case's `parameters` replace; its own
# `Mesh.MeshSizeMax` holds only when the case gives no `mesh_mm`.

(part / "holder.geo").write_text("""\
DefineConstant[ opening_mm = 150.0, outer_mm = 260.0 ];
SetFactory("OpenCASCADE");
Rectangle(1) = {-outer_mm / 2, -outer_mm / 2, 0, outer_mm, outer_mm};
Disk(2) = {0, 0, 0, opening_mm / 2};
BooleanDifference{ Surface{1}; Delete; }{ Surface{2}; Delete; }
Mesh.MeshSizeMax = 20.0;
""")

# ## The case
#
# The punch rises 25 mm in 20 s; the die and the holder stand still. The blank is a 200 mm
# square of 10 mm cells, a quarter model; 200 N on the holder (the whole blank's, as
# `holder_force_share = "symmetric_part"`, the default, reads it). Every key is in the
# {doc}`case format </case-format>`.

(part / "case.toml").write_text("""\
[case]
name = "bump"
description = "a round bump 100 mm across, 25 mm high (tutorial)"
duration_s = 20.0

[blank]
outline = "rectangle"
size_mm = [200.0, 200.0]
cell_mm = 10.0
symmetry = ["x", "y"]

[holder]
tool = "holder"
holder_force_N = 200.0

[[tool]]
name = "punch"
role = "punch"
geometry = "punch.stl"
[tool.motion]
time_s = [0.0, 20.0]
z_mm = [0.0, 25.0]

[[tool]]
name = "die"
role = "die"
geometry = "die.stl"

[[tool]]
name = "holder"
role = "holder"
geometry = "holder.geo"
mesh_mm = 10.0
""")

# `load_case` checks the whole file and reports every problem with its key at once; the tool
# meshes are read when the run builds the tools. Here the holder's triangles at the case's
# `mesh_mm` and at the script's own size, to see which one holds:

# +
from fenicsx_drape.forming import load_case
from fenicsx_drape.forming.tools import load_surface


def longest_edge(surface):
    p = np.asarray(surface.points)[np.asarray(surface.triangles)]
    return np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).max()


case = load_case(part / "case.toml")
print(f"{case.name}: {len(case.tools)} tools, blank {case.blank.size_mm} mm, "
      f"cells {case.blank.cell_mm:g} mm, symmetry {list(case.blank.symmetry)}")
for size in (10.0, None):
    holder = load_surface(part / "holder.geo", mesh_size_mm=size)
    print(f"holder.geo with mesh_mm = {size}: {len(holder.triangles)} triangles, "
          f"longest edge {longest_edge(holder):.1f} mm")
# -

# ## Form it
#
# `form_case` is `drape form` in Python. The outputs: `summary.json` (maximum shear,
# wrinkling, draw-in, steps, Newton iterations, the kinematic drape beside it), the pictures,
# `tool_forces.csv`, the formed sheet as a measurement bundle (`bundle/`, for `drape compare`
# later) and `provenance.json`.

# +
from fenicsx_drape.forming import form_case

run, summary = form_case(out / "formed", case, fields=False)
print(f"max shear {summary['max_shear_deg']:.1f}°, total wrinkling "
      f"{100 * summary['total_wrinkling_strain']:.2f} %, {summary['steps']} steps, "
      f"{summary['snes_iterations']} Newton iterations")
print(f"kinematic drape: {summary['kinematic_placed_nodes']} of "
      f"{summary['kinematic_blank_nodes']} nodes placed, max shear "
      f"{summary['kinematic_max_shear_deg']:.1f}°")
print("peak force of each tool (N):",
      {k: round(v, 1) for k, v in summary["max_tool_force_N"].items()})
# -

# Each tool's force is its reaction along its direction of motion, for the whole part: the
# punch's is the press force, the die's is negative (it holds the blank back), and the
# holder's stays near zero, because the holder clamps the blank in its plane and resists the
# draw-in by friction, across the travel rather than along it.
#
# ## The pictures
#
# The formed sheet coloured by shear angle (the quarter mirrored to the whole part), and the
# force of each tool against the punch's travel.

if not SCRIPT:
    from IPython.display import Image, display

    for name in ("shear.png", "tool_forces.png"):
        display(Image(filename=str(out / "formed" / name)))

# ## Next
#
# - A finer sheet: `./drape form results/own_part/part/case.toml --out DIR --cell-mm 5`; the
#   whole blank rather than a quarter: `--full`; a turned ply: `--ply-angle-deg 30`.
# - The formed part is a measurement bundle (`results/own_part/formed/bundle/`: its node grid
#   and a copy of the case). A model that lacks an effect misses it, and `diagnose` names
#   the effect. Here the model is the paper's without tow buckling: `compare` gives a
#   normalised error of 9.7 (40 % of it on the flat base, 37 % under the holder), and
#   `diagnose` (6 min on a busy two-core machine) names `tow_buckling`, which brings its
#   baseline's 15.1 (refitted, two outlying nodes left out) to 0:
#   the formed grid carries no noise, so the model with the effect meets it exactly
#   (evidence `inf`); a measured part has its noise, given as `position_sd_mm`.
#
#       ./drape compare results/own_part/formed/bundle \
#           --model demos/models/without_tow_buckling.toml --out results/own_part/v1
#       ./drape diagnose results/own_part/formed/bundle \
#           --model demos/models/without_tow_buckling.toml \
#           --json results/own_part/REPORT.json --out results/own_part/diagnose
#
#   `results/own_part/diagnose/residual_bump-200N-20s.png` from that run: the baseline's
#   error at each node of the drawn grid, the winner's, and the error by region of the part.
#
#   ![The own part's diagnosis: the error without and with tow buckling](/own_part_diagnosis.png)
#
#   A measured part is a bundle of the same kind, with the lab's own measurements:
#   {doc}`the diagnosis </diagnosis>` and {doc}`lab measurements </lab-measurements>`.
