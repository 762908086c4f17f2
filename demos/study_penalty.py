# # Penalty stiffness of the contact: penetration falls as 1/k
#
# The contact stiffness is k = factor · l_t E_o (the axial stiffness of one tow bar, 2.4 kN/mm
# for Table 2; the default factor is 0.3). This study forms the 10 mm quarter with factors
# 0.01 to 3 and reports the deepest penetration of a node into the punch or die at the end,
# and how little the results move. Writes `penalty.csv` and `penalty.png`.
#
#     ./drape exec python3 demos/study_penalty.py --out results/study_penalty [--quick]

import argparse
from pathlib import Path

import numpy as np

from fenicsx_drape.forming import load_case
from fenicsx_drape.forming.paper import sweep, write_rows
from fenicsx_drape.provenance import save_figure, write_provenance

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("results/study_penalty"))
parser.add_argument("--quick", action="store_true", help="20 mm cells")
args = parser.parse_args()

factors = [0.01, 0.03, 0.1, 0.3, 1.0, 3.0]
cell = 20.0 if args.quick else 10.0
rows, _ = sweep(load_case("hemisphere", cell_mm=cell, penalty_factor=f) for f in factors)

from mpi4py import MPI

if MPI.COMM_WORLD.rank == 0:
    write_rows(args.out / "penalty.csv", rows, {"penalty_factor": factors},
               f"hemisphere quarter, {cell:g} mm cells, 133 N, 40 s: contact penalty "
               "k = factor * l_t * E_o")

    import matplotlib.pyplot as plt

    depth = np.array([r.get("max_penetration_mm", np.nan) for r in rows])
    fig, a = plt.subplots(figsize=(5.6, 4.2))
    a.loglog(factors, depth, "o-", label="deepest penetration at the end")
    ref = factors.index(0.3)
    a.loglog(factors, depth[ref] * factors[ref] / np.array(factors), "k:", label="∝ 1/k")
    a.set(xlabel="penalty factor (k / l_t E_o)", ylabel="penetration (mm)")
    a.grid(alpha=0.3, which="both")
    a.legend()
    save_figure(fig, args.out / "penalty.png")
    write_provenance(args.out, study="penalty stiffness", factors=factors, cell_mm=cell)
    print(f"wrote {args.out / 'penalty.csv'} and {args.out / 'penalty.png'}")
