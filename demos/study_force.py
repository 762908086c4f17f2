# # Blank-holder force: 70 to 800 N at 40 s (the paper's Fig. 12b)
#
# The 10 mm quarter model formed in 40 s with total holding forces of 70 to 800 N. The paper
# finds the wrinkling falling from 0.7 % at 70 N to 0.25 % at 800 N (nearly constant beyond
# 500 N) and the maximum shear rising at low forces, then slowly falling beyond 200 N.
# Writes `force.csv` and `force.png`.
#
#     ./drape exec python3 demos/study_force.py --out results/study_force [--quick]

import argparse
from pathlib import Path

from fenicsx_drape.forming.hemisphere import HemisphereCase
from fenicsx_drape.forming.studies import sweep, write_rows
from fenicsx_drape.provenance import save_figure, write_provenance

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("results/study_force"))
parser.add_argument("--quick", action="store_true", help="20 mm cells, three forces")
args = parser.parse_args()

forces = [70.0, 133.0, 800.0] if args.quick else [70.0, 100.0, 133.0, 200.0, 300.0, 400.0,
                                                   500.0, 650.0, 800.0]
cell = 20.0 if args.quick else 10.0
rows, _ = sweep(HemisphereCase(cell_mm=cell, holder_force_N=f) for f in forces)

from mpi4py import MPI

if MPI.COMM_WORLD.rank == 0:
    write_rows(args.out / "force.csv", rows, {"holder_force_N": forces},
               f"hemisphere quarter, {cell:g} mm cells, 40 s: holding force (Fig. 12b)")

    import matplotlib.pyplot as plt

    fig, a = plt.subplots(figsize=(6.4, 4.2))
    a.plot(forces, [r.get("max_shear_deg") for r in rows], "o-", color="C0")
    a.set(xlabel="total holding force (N)", ylabel="maximum shear angle (deg)")
    b = a.twinx()
    b.plot(forces, [-100 * r.get("total_wrinkling_strain", 0) for r in rows], "s--",
           color="C3")
    b.set_ylabel("total wrinkling strain, magnitude (%)", color="C3")
    a.grid(alpha=0.3)
    a.set_title("holding force at 40 s (Fig. 12b)")
    save_figure(fig, args.out / "force.png")
    write_provenance(args.out, study="holding force", forces_N=forces, cell_mm=cell)
    print(f"wrote {args.out / 'force.csv'} and {args.out / 'force.png'}")
