"""The inter-ply sliding of a [0/90, ±45] stack on the double dome as the net is refined.

    ./drape exec python3 benchmarks/bench_stack_sliding.py            # 20, 10 and 5 mm cells
    ./drape exec python3 benchmarks/bench_stack_sliding.py --cell-mm 20 10

The double dome's whole blank (a ply at 45° breaks the quarter symmetry) as a stack of two
0.3 mm plies, [0/90, ±45], the die at the stack's gap, the paper's model with sliding plies
(μ = 0.2, η_f = 0.002 MPa·s/mm, the inter-ply law's defaults), the pairs following the plies.
Every line: the cell (as asked and as fitted to the blank), nodes, steps, Newton iterations,
CPU time, the largest and mean inter-ply sliding and the pressure, each ply's maximum shear;
the largest sliding of the pairs at least :data:`INSIDE_MM` (the coarsest cell) inside the
flat blank's edge, the same material on every net (the largest of all lies at the ±45 ply's
ragged edge, whose tip each net cuts at another place); then the change of both from each
net to the next finer one.
"""

import argparse
import dataclasses
import os
import time

import numpy as np

from fenicsx_drape.forming.case import PlySpec, load_case
from fenicsx_drape.forming.running.run import run_case

parser = argparse.ArgumentParser()
parser.add_argument("--cell-mm", type=float, nargs="+", default=[20.0, 10.0, 5.0])
args = parser.parse_args()

INSIDE_MM = 20.0
"""The interior's margin: pairs whose flat place is this far inside the blank's edge."""

print(f"load average {os.getloadavg()[0]:.2f}")
largest = []
for cell in args.cell_mm:
    case = load_case("double_dome", cell_mm=cell, symmetry=[], offset_mm=0.6)
    case = dataclasses.replace(case, plies=(PlySpec(0.0, 0.3), PlySpec(45.0, 0.3)),
                               interply=(("mu_ply", 0.2), ("eta_f_MPa_s_per_mm", 0.002)))
    cpu = time.process_time()
    run = run_case(case)
    cpu = time.process_time() - cpu
    (face,) = run.interply.summary()
    contact = run.interply
    flat = contact.X[contact.a[(contact.interface == 0) & contact.active], :2]
    half = np.array(case.blank.size_mm) / 2
    inside = np.all(np.abs(flat - case.blank.centre_mm) <= half - INSIDE_MM, axis=1)
    interior = float(face["sliding_mm"][inside].max(initial=0.0))
    largest.append((face["max_sliding_mm"], interior))
    shear = ", ".join(f"{np.nanmax(np.abs(g.shear_deg())):.2f}" for g in run.plies)
    print(f"cell {cell:g} mm ({run.plies[0].cell_mm:.4g} fitted): {run.problem.num_owned} nodes, "
          f"{run.steps} steps, {run.cutbacks} cut-backs, {run.iterations} Newton, CPU {cpu:.0f} s; "
          f"sliding largest {face['max_sliding_mm']:.3f} mm, mean {face['mean_sliding_mm']:.3f} "
          f"mm, {100 * face['sliding_fraction']:.0f} % of the pairs; pressure up to "
          f"{face['max_pressure_MPa']:.3f} MPa; max shear per ply {shear} deg; largest "
          f"sliding {INSIDE_MM:g} mm inside the edge {interior:.3f} mm", flush=True)
for (a, sa), (b, sb) in zip(zip(args.cell_mm, largest), zip(args.cell_mm[1:], largest[1:])):
    print(f"largest sliding {a:g} → {b:g} mm cells: {sa[0]:.3f} → {sb[0]:.3f} mm "
          f"({100 * (sb[0] - sa[0]) / sb[0]:+.1f} % of the finer); {INSIDE_MM:g} mm inside the "
          f"edge {sa[1]:.3f} → {sb[1]:.3f} mm ({100 * (sb[1] - sa[1]) / sb[1]:+.1f} %)")
