# # Tool-mesh convergence: the hemisphere with meshed tools against the closed form
#
# `meshes/hemisphere/case_meshed.toml` forms the paper's hemisphere with its punch and die
# meshed by Gmsh from `punch.geo` and `die.geo` and held as a smooth signed distance
# (`fenicsx_drape.forming.tools.distance`: a cubic B-spline on a grid of spacing h, the flat
# triangle size). Here the punch and die are meshed at several sizes and orders (the holder,
# a plane, is exact at any size and stays as in the case file), the quarter is formed at Δ = 10 mm
# and compared with `meshes/hemisphere/case.toml` (the exact closed-form tools): max shear,
# its difference, the largest and mean distance between the formed nodes, the steps,
# cut-backs, Newton iterations and the run's wall time (tools built beforehand; the field's
# build or cache read is the separate column `tools_s`). Writes `tool_mesh.csv`.
#
#     ./drape exec python3 demos/study_tool_mesh.py --out results/study_tool_mesh [--quick]

import argparse
import csv
import dataclasses
import time
from pathlib import Path

import numpy as np

from fenicsx_drape.forming import load_case, run_case
from fenicsx_drape.forming.tools import build_tools

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("results/study_tool_mesh"))
parser.add_argument("--quick", action="store_true", help="4 and 2 mm, order 1 only")
parser.add_argument("--cell-mm", type=float, default=10.0)
args = parser.parse_args()

HERE = Path(__file__).resolve().parent.parent / "meshes" / "hemisphere"
MESHES = [(4.0, 1), (4.0, 2), (2.0, 1), (2.0, 2), (1.0, 1)]
if args.quick:
    MESHES = [(4.0, 1), (2.0, 1)]

# ## The closed-form reference

exact = run_case(load_case(HERE / "case.toml", cell_mm=args.cell_mm))
shear_exact = float(np.nanmax(np.abs(exact.grid.shear_deg())))
print(f"closed form: max shear {shear_exact:.3f}°, {exact.steps} steps, {exact.cutbacks} "
      f"cut-backs, {exact.iterations} Newton iterations, {exact.wall_time_s:.1f} s")


# ## Meshed punch and die at each size


def with_mesh(case, mesh_mm: float, order: int):
    """The case with its punch and die meshed at ``mesh_mm`` and ``order``."""
    tools = type(case.tools)(dataclasses.replace(t, mesh_mm=mesh_mm, order=order)
                             if t.role in ("punch", "die") else t for t in case.tools)
    return dataclasses.replace(case, tools=tools)


rows = []
for mesh_mm, order in MESHES:
    case = with_mesh(load_case(HERE / "case_meshed.toml", cell_mm=args.cell_mm), mesh_mm, order)
    start = time.perf_counter()
    tools = build_tools(case)
    tools_s = time.perf_counter() - start
    run = run_case(case, tools=tools, allow_incomplete=True)
    shear = float(np.nanmax(np.abs(run.grid.shear_deg())))
    d = np.linalg.norm(run.grid.x - exact.grid.x, axis=-1)
    rows.append({
        "tool_mesh_mm": mesh_mm, "order": order, "h_mm": round(tools["punch"].field.h, 2),
        "travel_mm": round(run.travel_mm, 2), "max_shear_deg": round(shear, 3),
        "d_max_shear_deg": round(abs(shear - shear_exact), 3),
        "node_max_mm": round(float(np.nanmax(d)), 4),
        "node_mean_mm": round(float(np.nanmean(d)), 4), "steps": run.steps,
        "cutbacks": run.cutbacks, "newton": run.iterations,
        "wall_s": round(run.wall_time_s, 1), "tools_s": round(tools_s, 1)})
    print(rows[-1], flush=True)

# ## The table

args.out.mkdir(parents=True, exist_ok=True)
with open(args.out / "tool_mesh.csv", "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
head = ("mesh (mm)", "order", "h (mm)", "travel", "max shear", "|Δ shear|", "node max",
        "node mean", "steps", "cut-backs", "Newton", "wall (s)", "tools (s)")
print(" | ".join(head))
for r in rows:
    print(" | ".join(str(v) for v in r.values()))
print(f"closed form | - | - | 80 | {shear_exact:.3f} | 0 | 0 | 0 | {exact.steps} | "
      f"{exact.cutbacks} | {exact.iterations} | {exact.wall_time_s:.1f} | -")
