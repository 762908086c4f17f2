"""Does a fitted set-up's sd cover its error? The blank offset on the hemisphere, many trials.

Each fitted set-up should lie "within its reported uncertainty (or two of them)". One
bundle cannot say whether an sd is honest; this study repeats the fit. Per trial, a blank
offset is drawn in the study's range (x 5-15 mm, y ±5 mm, ``numpy.random.default_rng(--seed)``),
the whole hemisphere is formed with it (the paper's case, ``--cell-mm`` net, solver
tolerances 100× tighter than the diagnosis's), its lab grid (``--grid-mm``) is drawn on the
blank where the stated case puts it and given 0.3 mm of Gaussian noise (seed ``--seed`` + trial),
and the ``blank_offset_mm`` candidate is fitted to the stated (centred, quarter) case. Printed
per trial: the truth, the fit ± sd and the error in sds per axis; at the end the share of
axes within 1 and 2 sd (a Gaussian's 68 % and 95 %) and the RMS of the error in sds (1 when
the sd is honest).

    ./drape exec python3 benchmarks/study_setup_coverage.py --trials 12 --json coverage.json
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from study_setup_diagnose import measured_test

from fenicsx_drape.diagnosis.decision import setup_rules
from fenicsx_drape.diagnosis.setup_stage import fit_setup
from fenicsx_drape.forming.case.format import load_case
from fenicsx_drape.measurements.bundle import Bundle
from fenicsx_drape.model import default_model


def fit(test, model) -> dict:
    bundle = Bundle(name="coverage", tests=(test,))
    stage = fit_setup(bundle, model, setup_rules(), parameters=["blank_offset_mm"])
    (entry,) = stage.entries
    return entry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=12)
    parser.add_argument("--seed", type=int, default=4711, help="the truths' and noise's seed")
    parser.add_argument("--cell-mm", type=float, default=20.0)
    parser.add_argument("--grid-mm", type=float, default=10.0, help="the lab grid's pitch")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    model = default_model()
    stated = load_case("hemisphere", cell_mm=args.cell_mm)
    rng = np.random.default_rng(args.seed)
    rows = []
    for trial in range(args.trials):
        truth = [round(float(rng.uniform(5.0, 15.0)), 2), round(float(rng.uniform(-5.0, 5.0)), 2)]
        start = time.perf_counter()
        test = measured_test(stated, {"blank_offset_mm": truth}, model, f"trial-{trial}",
                             args.seed + trial, grid_mm=args.grid_mm)
        entry = fit(test, model)
        z = (np.subtract(entry["fitted"], truth) / np.abs(entry["sd"])).tolist()
        rows.append({"truth": truth, "fitted": entry["fitted"], "sd": entry["sd"], "z": z,
                     "runs": entry["runs"], "seconds": time.perf_counter() - start})
        print(f"trial {trial:2d}: truth [{truth[0]:6.2f}, {truth[1]:5.2f}] fitted "
              f"[{entry['fitted'][0]:7.3f}, {entry['fitted'][1]:6.3f}] ± "
              f"[{entry['sd'][0]:.3f}, {entry['sd'][1]:.3f}] mm, off by "
              f"[{z[0]:5.2f}, {z[1]:5.2f}] sd, {entry['runs']} runs, "
              f"{rows[-1]['seconds']:.0f} s", flush=True)
        if args.json:
            Path(args.json).write_text(json.dumps(rows, indent=1))
    z = np.abs([r["z"] for r in rows]).ravel()
    print(f"\n{z.size} axes: within 1 sd {np.mean(z <= 1):.0%} (Gaussian 68 %), within 2 sd "
          f"{np.mean(z <= 2):.0%} (95 %); RMS error {np.sqrt(np.mean(z**2)):.2f} sd "
          "(1 when the sd is honest)")


if __name__ == "__main__":
    sys.exit(main())
