"""Wall time and Newton iterations of the hemisphere, and how they grow with the nodes.

    ./drape exec python3 benchmarks/bench_forming.py            # quarter 10 and 5 mm
    ./drape exec python3 benchmarks/bench_forming.py --full     # + the full sheet at 2.5 mm
    ./drape --np 2 exec python3 benchmarks/bench_forming.py --full

The first case is run twice: the first run compiles the forms (FFCx JIT), the second is timed.
"""

import argparse
import time

from mpi4py import MPI

import numpy as np

from fenicsx_drape.forming.hemisphere import HemisphereCase, run_hemisphere

parser = argparse.ArgumentParser()
parser.add_argument("--full", action="store_true", help="also the full sheet at 2.5 mm")
parser.add_argument("--cells", type=float, nargs="*", default=[10.0, 5.0],
                    help="cell sizes of the quarter model (mm)")
args = parser.parse_args()
comm = MPI.COMM_WORLD

cases = [HemisphereCase(cell_mm=c) for c in args.cells]
if args.full:
    cases.append(HemisphereCase(cell_mm=2.5, quarter=False))
run_hemisphere(HemisphereCase(cell_mm=30.0, duration_s=8.0))  # JIT warm-up
rows = []
for case in cases:
    start = time.perf_counter()
    run = run_hemisphere(case)
    wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    nodes = run.grid.X[..., 0].size
    rows.append((nodes, wall))
    if comm.rank == 0:
        print(f"{'quarter' if case.quarter else 'full'} {case.cell_mm:5.2f} mm: {nodes:6d} nodes "
              f"{3 * nodes:6d} unknowns, {comm.size} rank(s): {wall:7.1f} s, {run.steps} steps, "
              f"{run.cutbacks} cut back, {run.iterations} Newton iterations "
              f"({1e3 * wall / max(run.iterations, 1):.1f} ms each), max shear "
              f"{np.abs(run.grid.shear_deg()).max():.1f}°", flush=True)
if comm.rank == 0 and len(rows) > 1:
    n, t = np.array(rows, dtype=float).T
    slope = np.polyfit(np.log(n), np.log(t), 1)[0]
    print(f"wall time grows as nodes^{slope:.2f} over {int(n.min())}-{int(n.max())} nodes")
