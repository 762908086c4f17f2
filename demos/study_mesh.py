# # Mesh convergence of the formed hemisphere (the paper's Fig. 9)
#
# The quarter model with unit cells from 60 mm (9 nodes) to 8.6 mm (225 nodes), 133 N, 40 s.
# For each: the maximum shear angle, the total wrinkling strain and the mean distance of the
# formed nodes from those of the finest model, taken over the 169 points of the 13 × 13 grid
# of 10 mm on the quarter sheet (the paper's measure). Writes `mesh.csv` and `mesh.png`.
#
#     ./drape exec python3 demos/study_mesh.py --out results/study_mesh [--quick]

import argparse
from pathlib import Path

import numpy as np

from fenicsx_drape.forming.hemisphere import HemisphereCase
from fenicsx_drape.forming.post import mean_distance
from fenicsx_drape.forming.studies import sweep, write_rows
from fenicsx_drape.provenance import save_figure, write_provenance

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("results/study_mesh"))
parser.add_argument("--quick", action="store_true", help="60 to 20 mm cells only")
args = parser.parse_args()

n_cells = range(2, 7) if args.quick else range(2, 15)
cells = [120.0 / n for n in n_cells]
rows, grids = sweep(HemisphereCase(cell_mm=c) for c in cells)
finest = grids[-1]
distance = [mean_distance(g, finest) if g is not None else np.nan for g in grids]

from mpi4py import MPI

if MPI.COMM_WORLD.rank == 0:
    write_rows(args.out / "mesh.csv", rows, {"cell_mm": cells, "mean_distance_mm": distance},
               "hemisphere quarter, 133 N, 40 s: mesh convergence (Fig. 9); distance from "
               f"the finest model ({cells[-1]:.3g} mm) over the 10 mm grid")

    import matplotlib.pyplot as plt

    nodes = [r.get("nodes", np.nan) for r in rows]
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    ax[0].plot(nodes, [r.get("max_shear_deg", np.nan) for r in rows], "o-")
    ax[0].axhline(51.4, color="k", ls=":", label="paper's model, 225 nodes")
    ax[0].set(ylabel="maximum shear angle (deg)")
    ax[1].plot(nodes, [-100 * r.get("total_wrinkling_strain", np.nan) for r in rows], "o-")
    ax[1].axhline(0.55, color="k", ls=":", label="paper's model (converged)")
    ax[1].set(ylabel="total wrinkling strain, magnitude (%)")
    ax[2].plot(nodes, distance, "o-")
    ax[2].set(ylabel="mean distance from the finest model (mm)")
    for a in ax:
        a.set(xlabel="nodes of the quarter model")
        a.grid(alpha=0.3)
    ax[0].legend()
    ax[1].legend()
    fig.suptitle("mesh convergence of the hemisphere (quarter, 133 N, 40 s)")
    save_figure(fig, args.out / "mesh.png")
    write_provenance(args.out, study="mesh convergence", cells_mm=cells)
    print(f"wrote {args.out / 'mesh.csv'} and {args.out / 'mesh.png'}")
