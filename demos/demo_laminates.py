# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# # Layups on the double dome and the hemisphere: how the plies of a stack form together
#
# **Not run on this site**: it forms a dozen stacks, a few minutes on two cores, too long
# for each build of the docs; this page shows the code without its output
# (`tests/test_demo_laminates.py` runs it). {doc}`Laminates </laminates>` shows its table and
# pictures.
#
# The double dome (`meshes/double_dome/case.toml`) formed from stacks of woven plies instead
# of one ply (docs/laminates.md): the [0/90, 0/90] and [0/90, ±45] stacks of two plies and a
# four-ply quasi-isotropic stack [0/90, ±45, ∓45, 90/0], against the single ply; then the
# [0/90, ±45] stack with the inter-ply Coulomb coefficient μ and the film viscosity η_f at the
# ends of their published ranges. The paper's hemisphere with a [0/90, ±45] stack is the
# second case. A coarse net (20 mm cells on the double dome, 30 mm on the hemisphere, the whole
# blank) and a fast stroke (8 s) keep it to a few minutes. `./drape form
# meshes/hemisphere/stack_0_45.toml --out DIR` forms one stack with every output. Run as a
# script, the names after the output folder (`"double dome/[0/90, ±45]"`, part/layup) form
# only those layups.

# +
import csv
import dataclasses
import sys
from pathlib import Path

import numpy as np

from fenicsx_drape.forming.case import PlySpec, load_case
from fenicsx_drape.forming.running import interply_maps, plot_interply, plot_shear, run_case

SCRIPT = "__file__" in globals()
args = sys.argv[1:] if SCRIPT else []
out = Path(args[0]) if args else Path("results/laminates")
out.mkdir(parents=True, exist_ok=True)
INTERPLY = {"tau0_MPa": 0.0, "mu_ply": 0.2, "eta_f_MPa_s_per_mm": 0.002, "slip_mm": 0.1}
# -

# ## The layups
#
# Each stack is its part's case with `[[ply]]` tables (angles from the punch side, 0.3 mm a
# ply), the `[interply]` values of `meshes/hemisphere/stack_0_45.toml` (μ = 0.2,
# η_f = 0.002 MPa·s/mm) unless the name says otherwise, and the tools' gap set to the stack's
# thickness (the double dome's die `offset_mm`, the hemisphere's `ply_thickness_mm`). The
# single ply is the same case with one ply, on the whole blank too.

# +
PARTS = {"double dome": ("double_dome", {"cell_mm": 20.0}, "offset_mm"),
         "hemisphere": ("hemisphere", {"cell_mm": 30.0}, "ply_thickness_mm")}


def layup(part, angles, **interply):
    name, net, gap = PARTS[part]
    case = load_case(name, symmetry=[], duration_s=8.0, **net, **{gap: 0.3 * len(angles)})
    if len(angles) == 1:
        return case
    return dataclasses.replace(case, plies=tuple(PlySpec(a, 0.3) for a in angles),
                               interply=tuple({**INTERPLY, **interply}.items()))


QI = (0.0, 45.0, -45.0, 90.0)
layups = {
    ("double dome", "single ply [0/90]"): layup("double dome", (0.0,)),
    ("double dome", "[0/90, 0/90]"): layup("double dome", (0.0, 0.0)),
    ("double dome", "[0/90, ±45]"): layup("double dome", (0.0, 45.0)),
    ("double dome", "[0/90, ±45, ∓45, 90/0]"): layup("double dome", QI),
    ("double dome", "[0/90, ±45], μ = 0.1"): layup("double dome", (0.0, 45.0), mu_ply=0.1),
    ("double dome", "[0/90, ±45], μ = 0.3"): layup("double dome", (0.0, 45.0), mu_ply=0.3),
    ("double dome", "[0/90, ±45], η_f = 0.0005"): layup("double dome", (0.0, 45.0),
                                                        eta_f_MPa_s_per_mm=0.0005),
    ("double dome", "[0/90, ±45], η_f = 0.01"): layup("double dome", (0.0, 45.0),
                                                      eta_f_MPa_s_per_mm=0.01),
    ("hemisphere", "single ply [0/90]"): layup("hemisphere", (0.0,)),
    ("hemisphere", "[0/90, ±45]"): layup("hemisphere", (0.0, 45.0)),
}
if args[1:]:  # only the layups named (part/layup)
    unknown = set(args[1:]) - {f"{part}/{name}" for part, name in layups}
    if unknown:
        sys.exit(f"no such layup: {', '.join(sorted(unknown))}")
    layups = {k: v for k, v in layups.items() if f"{k[0]}/{k[1]}" in args[1:]}
# -

# ## Form them
#
# For every ply: the largest shear angle, the total wrinkling strain (the sum of the
# compressive tow strains, eq. 4's measure) and the draw-in of the middle of each side of
# the blank (x: the end across the domes' axis, y: the long side); for every stack, the
# largest sliding between its plies. The single ply carries the holder's friction on its
# own; in a stack the two outer plies share it.

# +


def draw_in(X, x, direction):
    """How far the middle of the blank's side across ``direction`` moved inwards (mm).

    The node farthest along ``direction`` nearest the axis through the centre (on a ply at
    45°, the tip of its ragged edge).
    """
    along = np.where(np.isnan(X[..., 0]), -np.inf, X @ direction)
    across = np.abs(X @ np.array([-direction[1], direction[0]]))
    edge = along >= along.max() - 1e-6 * np.abs(along.max())
    i, j = np.unravel_index(np.argmin(np.where(edge, across, np.inf)), along.shape)
    return float(X[i, j] @ direction - x[i, j] @ direction)


rows = []
for (part, name), case in layups.items():
    run = run_case(case, allow_incomplete=True)  # a run that stops short says how far it got
    print(f"{part}, {name}: {run.steps} steps, {run.iterations} Newton iterations, "
          f"{run.travel_mm:.1f} of {case.total_travel_mm:.0f} mm")
    grids = run.plies or [run.grid]
    sliding = (float(np.linalg.norm(run.interply.sliding_mm, axis=1).max(initial=0.0))
               if run.interply is not None else 0.0)
    for k, g in enumerate(grids, 1):
        X, x = g.X[..., :2], g.x[..., :2]
        rows.append({"part": part, "layup": name, "ply": k,
                     "angle_deg": case.ply_blanks()[k - 1].ply_angle_deg if case.plies else 0.0,
                     "max_shear_deg": float(np.nanmax(np.abs(g.shear_deg()))),
                     "total_wrinkling_pct": 100 * g.total_wrinkling_strain(),
                     "draw_in_x_mm": draw_in(X, x, np.array([1.0, 0.0])),
                     "draw_in_y_mm": draw_in(X, x, np.array([0.0, 1.0])),
                     "max_sliding_mm": sliding, "travel_mm": run.travel_mm})
    if name == "[0/90, ±45]":
        stem = part.replace(" ", "_")
        for k, g in enumerate(grids, 1):
            plot_shear(g, out / f"{stem}_shear_ply{k}.png",
                       f"{part}, [0/90, ±45]: ply {k} ({'0/90' if k == 1 else '±45'}), shear")
        faces = [dict(face, name=face["interface"]) for face in interply_maps(run)]
        plot_interply(faces, out / f"{stem}_interply.png",
                      f"{part}, [0/90, ±45]: where the plies slid, and their pressure")
with open(out / "layups.csv", "w", newline="") as f:
    writer = csv.DictWriter(f, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
print(f"{'part':12s} {'layup':28s} ply  angle  shear  wrinkling  draw-in x  draw-in y  sliding"
      "  travel")
for r in rows:
    print(f"{r['part']:12s} {r['layup']:28s} {r['ply']:3d} {r['angle_deg']:6.0f} "
          f"{r['max_shear_deg']:6.1f} {r['total_wrinkling_pct']:9.2f} % {r['draw_in_x_mm']:9.1f}"
          f" {r['draw_in_y_mm']:10.1f} {r['max_sliding_mm']:8.2f} {r['travel_mm']:7.1f}")
# -

# The plies of a stack do not form alike: the ply at 45° shears where the one at 0° does not,
# and the inter-ply friction carries load between them; a higher μ or η_f lets them slide less
# (the sliding column, mm) and drags the plies towards forming as one.
