# # The out-of-plane stabilisation: halve it and see what moves
#
# The flat, slack sheet needs a small out-of-plane spring to the extrapolated motion
# (fenicsx_drape/forming/terms/stabilisation.py); it is part of the model. This study halves its
# stiffness from the default (1.25 N/mm) twice and doubles it once, and reports the change of
# the maximum shear angle, the wrinkling and the node positions against the default.
# Writes `stabilisation.csv` and `stabilisation.png`.
#
#     ./drape exec python3 demos/study_stabilisation.py --out results/study_stab [--quick]

import argparse
from pathlib import Path

import numpy as np

from fenicsx_drape.forming import load_case
from fenicsx_drape.forming.paper import sweep, write_rows
from fenicsx_drape.forming.running import mean_distance
from fenicsx_drape.provenance import save_figure, write_provenance

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("results/study_stabilisation"))
parser.add_argument("--quick", action="store_true", help="20 mm cells")
args = parser.parse_args()

default = load_case("hemisphere").stabilisation_N_per_mm
stiffness = [2 * default, default, default / 2, default / 4]
cell = 20.0 if args.quick else 10.0
rows, grids = sweep(load_case("hemisphere", cell_mm=cell, stabilisation_N_per_mm=c)
                    for c in stiffness)
ref = grids[1]
moved = [mean_distance(g, ref) if g is not None else np.nan for g in grids]
largest = [float(np.abs(g.x - ref.x).max()) if g is not None else np.nan for g in grids]

from mpi4py import MPI

if MPI.COMM_WORLD.rank == 0:
    write_rows(args.out / "stabilisation.csv", rows,
               {"stabilisation_N_per_mm": stiffness, "mean_node_change_mm": moved,
                "max_node_change_mm": largest},
               f"hemisphere quarter, {cell:g} mm cells, 133 N, 40 s: out-of-plane "
               f"stabilisation; node changes against the default {default} N/mm")

    import matplotlib.pyplot as plt

    fig, a = plt.subplots(figsize=(6.0, 4.2))
    a.semilogx(stiffness, [r.get("max_shear_deg") for r in rows], "o-", color="C0")
    a.set(xlabel="stabilisation stiffness (N/mm)", ylabel="maximum shear angle (deg)")
    b = a.twinx()
    b.semilogx(stiffness, [-100 * r.get("total_wrinkling_strain", 0) for r in rows], "s--",
               color="C3")
    b.set_ylabel("total wrinkling strain, magnitude (%)", color="C3")
    a.axvline(default, color="k", ls=":")
    a.grid(alpha=0.3)
    save_figure(fig, args.out / "stabilisation.png")
    write_provenance(args.out, study="stabilisation", stiffness_N_per_mm=stiffness, cell_mm=cell)
    print(f"wrote {args.out / 'stabilisation.csv'} and {args.out / 'stabilisation.png'}")
