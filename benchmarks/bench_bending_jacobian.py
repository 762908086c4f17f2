"""The tow bending's Jacobian: full stencils against its diagonal alone.

Forms the hemisphere case on cells of ``CELL_MM`` (default 10) with
``SolverOptions(bending_jacobian="full")`` and ``"diagonal"``, and prints each run's wall
time, whether it reached full travel, and the largest distance between the two formed sheets.

    ./drape exec python3 benchmarks/bench_bending_jacobian.py 5
"""

import sys
import time
from pathlib import Path

import numpy as np

from fenicsx_drape.fe.solver import SolverOptions
from fenicsx_drape.forming.case.format import load_case
from fenicsx_drape.forming.running.run import run_case

CASE = Path(__file__).resolve().parents[1] / "meshes" / "hemisphere" / "case.toml"


def main() -> None:
    cell = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    case = load_case(CASE, cell_mm=cell)
    out = {}
    for mode in ("full", "diagonal"):
        start = time.perf_counter()
        run = run_case(case, options=SolverOptions(bending_jacobian=mode), allow_incomplete=True)
        out[mode] = (time.perf_counter() - start, run.grid.x)
        print(f"{mode}: {out[mode][0]:.1f} s, "
              + (f"stopped at {run.travel_mm:.1f} mm" if run.stopped else "full travel"),
              flush=True)
    d = np.nanmax(np.linalg.norm(out["full"][1] - out["diagonal"][1], axis=-1))
    print(f"cells {cell:g} mm: largest node distance {d:.4f} mm; "
          f"time diagonal/full {out['diagonal'][0] / out['full'][0]:.2f}")


if __name__ == "__main__":
    main()
