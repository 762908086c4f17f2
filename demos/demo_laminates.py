# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# # Layups on the hemisphere: how the plies of a stack form together
#
# **Not run on this site**: it forms several stacks, about a minute on two cores, too long
# for each build of the docs; this page shows the code without its output
# (`tests/test_demo_laminates.py` runs it). {doc}`Laminates </laminates>` shows a stack's
# pictures and this demo's table.
#
# The paper's hemisphere formed from stacks of woven plies instead of one ply: the
# [0/90, 0/90] and [0/90, ±45] stacks of two plies and a four-ply quasi-isotropic stack
# [0/90, ±45, ∓45, 90/0], against the single ply; then the [0/90, ±45] stack with the
# inter-ply Coulomb coefficient μ and the film viscosity η_f at the ends of their published
# ranges. A coarse net (30 mm cells, the whole blank) and a fast stroke (8 s) keep it short.
# `./drape form meshes/hemisphere/stack_0_45.toml --out DIR` forms one stack with every output.

# +
import csv
import dataclasses
import sys
from pathlib import Path

import numpy as np

from fenicsx_drape.forming.case.format import PlySpec, load_case
from fenicsx_drape.forming.running.plots import plot_shear
from fenicsx_drape.forming.running.run import run_case

SCRIPT = "__file__" in globals()
args = sys.argv[1:] if SCRIPT else []
out = Path(args[0]) if args else Path("results/laminates")
out.mkdir(parents=True, exist_ok=True)
COARSE = {"cell_mm": 30.0, "duration_s": 8.0}
# -

# ## The layups
#
# Each stack is the case file `meshes/hemisphere/stack_0_45.toml` with other `[[ply]]` tables
# (angles from the punch side) and the tools' gap set to the stack's thickness (0.3 mm a ply).
# The single ply is the hemisphere's own case without its symmetry planes.

# +
STACK = "meshes/hemisphere/stack_0_45.toml"


def stack(angles, **interply):
    case = load_case(STACK, ply_thickness_mm=0.3 * len(angles), **COARSE)
    values = {**dict(case.interply), **interply}
    return dataclasses.replace(case, plies=tuple(PlySpec(a, 0.3) for a in angles),
                               interply=tuple(values.items()))


layups = {
    "single ply [0/90]": load_case("hemisphere", symmetry=[], **COARSE),
    "[0/90, 0/90]": stack((0.0, 0.0)),
    "[0/90, ±45]": stack((0.0, 45.0)),
    "[0/90, ±45, ∓45, 90/0]": stack((0.0, 45.0, -45.0, 90.0)),
    "[0/90, ±45], μ = 0.1": stack((0.0, 45.0), mu_ply=0.1),
    "[0/90, ±45], μ = 0.3": stack((0.0, 45.0), mu_ply=0.3),
    "[0/90, ±45], η_f = 0.0005": stack((0.0, 45.0), eta_f_MPa_s_per_mm=0.0005),
    "[0/90, ±45], η_f = 0.01": stack((0.0, 45.0), eta_f_MPa_s_per_mm=0.01),
}
# -

# ## Form them
#
# For every ply: the largest shear angle, the total wrinkling strain and the draw-in of the
# middle of a side; for every interface, the largest sliding. The single ply carries the
# holder's friction on its own; in a stack the two outer plies share it.

# +
rows = []
for name, case in layups.items():
    run = run_case(case, allow_incomplete=True)  # a run that stops short says how far it got
    print(f"{name}: {run.steps} steps, {run.iterations} Newton iterations, "
          f"{run.travel_mm:.1f} of {case.total_travel_mm:.0f} mm")
    grids = run.plies or [run.grid]
    sliding = (max(np.linalg.norm(run.interply.sliding_mm, axis=1).max(initial=0.0), 0.0)
               if run.interply is not None else 0.0)
    for k, g in enumerate(grids, 1):
        X, x = g.X[..., :2], g.x[..., :2]
        edge = np.nanargmin(np.linalg.norm(X - (np.nanmax(X[..., 0]), 0.0), axis=-1))
        i, j = np.unravel_index(edge, X.shape[:2])
        rows.append({"layup": name, "ply": k,
                     "angle_deg": case.ply_blanks()[k - 1].ply_angle_deg if case.plies else 0.0,
                     "max_shear_deg": float(np.nanmax(np.abs(g.shear_deg()))),
                     "total_wrinkling_pct": 100 * g.total_wrinkling_strain(),
                     "draw_in_mm": float(np.linalg.norm(X[i, j]) - np.linalg.norm(x[i, j])),
                     "max_sliding_mm": sliding, "travel_mm": run.travel_mm})
    if name == "[0/90, ±45]":
        for k, g in enumerate(grids, 1):
            plot_shear(g, out / f"shear_ply{k}.png", f"[0/90, ±45]: ply {k}, shear angle")
with open(out / "layups.csv", "w", newline="") as f:
    writer = csv.DictWriter(f, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
print(f"{'layup':28s} ply  angle  shear  wrinkling  draw-in  sliding  travel")
for r in rows:
    print(f"{r['layup']:28s} {r['ply']:3d} {r['angle_deg']:6.0f} {r['max_shear_deg']:6.1f}"
          f" {r['total_wrinkling_pct']:9.2f} % {r['draw_in_mm']:7.1f} {r['max_sliding_mm']:8.2f}"
          f" {r['travel_mm']:7.1f}")
# -

# The plies of a stack do not form alike: the ply at 45° shears where the one at 0° does not,
# and the inter-ply friction carries load between them; a higher μ or η_f lets them slide less
# (the last column, mm) and drags the plies towards forming as one.
