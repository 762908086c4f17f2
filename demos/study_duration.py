# # Forming speed: durations 8 to 240 s at 133 N (the paper's Fig. 12a)
#
# The 10 mm quarter model formed over the 80 mm travel in 8 s (10 mm/s) to 240 s (0.33 mm/s).
# The paper finds less wrinkling when forming slowly (1.1 % at high speed to 0.3 % at low
# speed, plateaus beyond 100 s) and a maximum shear that varies within about 3°.
# Writes `duration.csv` and `duration.png`.
#
#     ./drape exec python3 demos/study_duration.py --out results/study_duration [--quick]

import argparse
from pathlib import Path

from fenicsx_drape.forming.hemisphere import HemisphereCase
from fenicsx_drape.forming.studies import sweep, write_rows
from fenicsx_drape.provenance import save_figure, write_provenance

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("results/study_duration"))
parser.add_argument("--quick", action="store_true", help="20 mm cells, three durations")
args = parser.parse_args()

durations = [8.0, 40.0, 240.0] if args.quick else [8.0, 12.0, 20.0, 40.0, 60.0, 100.0, 160.0,
                                                     240.0]
cell = 20.0 if args.quick else 10.0
rows, _ = sweep(HemisphereCase(cell_mm=cell, duration_s=d) for d in durations)

from mpi4py import MPI

if MPI.COMM_WORLD.rank == 0:
    write_rows(args.out / "duration.csv", rows, {"duration_s": durations},
               f"hemisphere quarter, {cell:g} mm cells, 133 N: forming duration (Fig. 12a)")

    import matplotlib.pyplot as plt

    fig, a = plt.subplots(figsize=(6.4, 4.2))
    a.semilogx(durations, [r.get("max_shear_deg") for r in rows], "o-", color="C0")
    a.set(xlabel="forming duration (s)", ylabel="maximum shear angle (deg)")
    b = a.twinx()
    b.semilogx(durations, [-100 * r.get("total_wrinkling_strain", 0) for r in rows], "s--",
               color="C3")
    b.set_ylabel("total wrinkling strain, magnitude (%)", color="C3")
    a.grid(alpha=0.3)
    a.set_title("forming speed at 133 N (Fig. 12a)")
    save_figure(fig, args.out / "duration.png")
    write_provenance(args.out, study="forming duration", durations_s=durations, cell_mm=cell)
    print(f"wrote {args.out / 'duration.csv'} and {args.out / 'duration.png'}")
