# # Mesh convergence of the formed hemisphere (the paper's Fig. 9)
#
# The quarter model with unit cells from 60 mm (9 nodes) to 8.6 mm (225 nodes), 133 N, 40 s,
# under both readings of eq. 1's force share. For each: the maximum shear angle, the total
# wrinkling strain and the mean distance of the formed nodes from those of the finest model,
# taken over the 169 points of the 13 × 13 grid of 10 mm on the quarter sheet (the paper's
# measure). The paper: maximum shear on a plateau beyond 100 nodes, total wrinkling stable at
# about 0.55 % from 10 mm cells (169 nodes), 0.25 mm mean distance at 10 mm.
# Writes `mesh.csv` and `mesh.png`.
#
#     ./drape exec python3 demos/study_mesh.py --out results/study_mesh [--quick]

import argparse
from pathlib import Path

import numpy as np

from fenicsx_drape.forming import paper
from fenicsx_drape.forming.paper import (
    MESH_CELLS_MM,
    READINGS,
    Variant,
    mesh_distances,
    paper_case,
    run_variants,
    write_rows,
)
from fenicsx_drape.provenance import save_figure, write_provenance

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("results/study_mesh"))
parser.add_argument("--cache", type=Path, default=Path("results/study_cache"))
parser.add_argument("--quick", action="store_true", help="60 to 24 mm cells only")
args = parser.parse_args()

cells = MESH_CELLS_MM[:5] if args.quick else MESH_CELLS_MM
series, distance = {}, {}
for reading in READINGS:
    series[reading], grids = run_variants(
        [Variant(f"{reading}: {c:.3g} mm", paper_case(reading, cell_mm=c)) for c in cells],
        cache=args.cache)
    distance[reading] = mesh_distances(grids)

from mpi4py import MPI

if MPI.COMM_WORLD.rank == 0:
    rows = [dict(r, mean_distance_mm=d) for reading in READINGS
            for r, d in zip(series[reading], distance[reading])]
    write_rows(args.out / "mesh.csv", rows,
               {"reading": [r for r in READINGS for _ in cells],
                "cell_mm": list(cells) * len(READINGS)},
               "hemisphere quarter, 133 N, 40 s, mu 0.3: mesh convergence (Fig. 9); distance "
               f"from the finest model ({cells[-1]:.3g} mm) over the 10 mm grid")

    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    for k, reading in enumerate(READINGS):
        rs = series[reading]
        nodes = [r.get("nodes", np.nan) for r in rs]
        ax[0].plot(nodes, [r.get("max_shear_deg", np.nan) for r in rs], "o-", color=f"C{k}",
                   label=reading)
        ax[1].plot(nodes, [-100 * r.get("total_wrinkling_strain", np.nan) for r in rs], "o-",
                   color=f"C{k}", label=f"{reading}, Green-Lagrange")
        ax[1].plot(nodes, [-100 * r.get("total_wrinkling_engineering", np.nan) for r in rs],
                   ":", color=f"C{k}", label=f"{reading}, length change")
        ax[2].plot(nodes, distance[reading], "o-", color=f"C{k}", label=reading)
    ax[0].axhline(paper.MAX_SHEAR_MODEL_DEG, color="k", ls=":", label="paper's model, 225 nodes")
    ax[0].axvline(paper.SHEAR_PLATEAU_FROM_NODES, color="0.6", ls="--", lw=0.8)
    ax[0].set(ylabel="maximum shear angle (deg)")
    ax[1].axhline(-100 * paper.TOTAL_WRINKLING_MODEL, color="k", ls=":",
                  label="paper's model (converged)")
    ax[1].set(ylabel="total wrinkling strain, magnitude (%)")
    ax[2].plot([169], [paper.MEAN_DISTANCE_10MM_MM], "k*", ms=10, label="paper, 10 mm")
    ax[2].set(ylabel="mean distance from the finest model (mm)")
    for a in ax:
        a.set(xlabel="nodes of the quarter model")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle("mesh convergence of the hemisphere (quarter, 133 N, 40 s)")
    save_figure(fig, args.out / "mesh.png")
    write_provenance(args.out, study="mesh convergence", cells_mm=list(cells),
                     readings=list(READINGS))
    print(f"wrote {args.out / 'mesh.csv'} and {args.out / 'mesh.png'}")
