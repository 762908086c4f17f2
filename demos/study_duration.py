# # Forming speed: durations 8 to 240 s at 133 N (the paper's Fig. 12a)
#
# The 10 mm quarter model formed over the 80 mm travel in 8 s (10 mm/s) to 240 s (0.33 mm/s),
# under both readings of eq. 1's force share (`fenicsx_drape.forming.paper.studies.READINGS`). The
# paper finds less wrinkling when forming slowly (1.1 % at high speed to 0.3 % at low speed,
# plateaus beyond 100 s) and a maximum shear that varies within about 3°.
# Writes `duration.csv` and `duration.png`.
#
#     ./drape exec python3 demos/study_duration.py --out results/study_duration [--quick]

import argparse
from pathlib import Path

from fenicsx_drape.forming import paper
from fenicsx_drape.forming.paper import (
    DURATIONS_S,
    READINGS,
    Variant,
    paper_case,
    plot_trend,
    run_variants,
    write_rows,
)
from fenicsx_drape.provenance import write_provenance

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("results/study_duration"))
parser.add_argument("--cache", type=Path, default=Path("results/study_cache"))
parser.add_argument("--quick", action="store_true", help="20 mm cells, three durations")
args = parser.parse_args()

durations = (8.0, 40.0, 240.0) if args.quick else DURATIONS_S
cell = 20.0 if args.quick else 10.0
series = {}
for reading in READINGS:
    series[reading], _ = run_variants(
        [Variant(f"{reading}: {d:g} s", paper_case(reading, cell_mm=cell, duration_s=d))
         for d in durations], cache=args.cache)

from mpi4py import MPI

if MPI.COMM_WORLD.rank == 0:
    rows = [r for reading in READINGS for r in series[reading]]
    write_rows(args.out / "duration.csv", rows,
               {"reading": [r for r in READINGS for _ in durations],
                "duration_s": list(durations) * len(READINGS)},
               f"hemisphere quarter, {cell:g} mm cells, 133 N, mu 0.3: forming duration "
               "(Fig. 12a)")
    plot_trend(args.out / "duration.png", durations, series, log_x=True,
               xlabel="forming duration (s)", title="forming speed at 133 N (Fig. 12a)",
               paper_x=paper.DURATION_RANGE_S, paper_wrinkling=paper.DURATION_WRINKLING,
               paper_shear=None)
    write_provenance(args.out, study="forming duration", durations_s=list(durations),
                     cell_mm=cell, readings=list(READINGS))
    for reading, rs in series.items():
        shear = [r.get("max_shear_deg") for r in rs]
        print(f"{reading}: max shear {shear[0]:.1f}° → {shear[-1]:.1f}° (span "
              f"{max(shear) - min(shear):.1f}°; paper ~3°), total wrinkling "
              f"{-100 * rs[0]['total_wrinkling_strain']:.2f} % → "
              f"{-100 * rs[-1]['total_wrinkling_strain']:.2f} % (paper 1.1 → 0.3 %)")
    print(f"wrote {args.out / 'duration.csv'} and {args.out / 'duration.png'}")
