"""Time of a forming diagnosis with and without the set-up candidates (speed).

A quarter-model double-dome bundle (the case's own 10 mm cells and 1 mm steps; the grid
"measured" on the whole blank with 0.3 mm noise, by a run formed with the ply turned by
``--ply-angle-deg``, default 4.37°, off the set-up scan's points) is diagnosed twice:

- effects only (``setup=()``): the candidates ``tool_friction`` and
  ``shear_tension_coupling``;
- set-up and effects: the five set-up candidates first, then the same effects.

Printed: the wall time of each, their ratio (target: the set-up adds at most 2×; the whole
diagnosis under 5 minutes on one core), the forming runs made, and the verdicts.
``--workers 1`` runs the forming solves on one process (one core); the default is the pool's
(:func:`~fenicsx_drape.runs.default_workers`); ``--cell-mm`` and ``--step-mm``
change the net and the step.

    ./drape exec python3 benchmarks/bench_setup_diagnose.py --workers 1
"""

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

from fenicsx_drape import runs
from fenicsx_drape.diagnosis import diagnose
from fenicsx_drape.diagnosis.setup_parameters import SETUP_PARAMETERS
from fenicsx_drape.diagnosis.synthetic import synthetic_case_test
from fenicsx_drape.forming.case.format import load_case, with_overrides
from fenicsx_drape.measurements.bundle import Bundle
from fenicsx_drape.model import default_model

CASE = Path(__file__).parents[1] / "meshes" / "double_dome" / "case.toml"
EFFECTS = ["tool_friction", "shear_tension_coupling"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--cell-mm", type=float, default=None)
    parser.add_argument("--step-mm", type=float, default=None)
    parser.add_argument("--ply-angle-deg", type=float, default=4.37)
    args = parser.parse_args()
    if args.workers:
        os.environ[runs.WORKERS_ENV] = str(args.workers)
    paper = default_model()
    stated = load_case(CASE, cell_mm=args.cell_mm, step_mm=args.step_mm)
    truth = with_overrides(stated, ply_angle_deg=args.ply_angle_deg)
    test = synthetic_case_test(paper, truth, sd_mm=0.3, seed=2028, full=True)
    bundle = Bundle(name="ply", tests=(dataclasses.replace(test, forming_case=stated,
                                                            case_keys={}),))
    print(f"double dome, cells {stated.blank.cell_mm:g} mm, steps {stated.step_mm:g} mm, "
          f"{runs.default_workers()} forming worker(s); bundle: the ply turned by "
          f"{args.ply_angle_deg:g}°",
          flush=True)
    times = {}
    for label, setup in (("effects only", ()), ("set-up and effects", SETUP_PARAMETERS)):
        runs.current().forget()
        start = time.perf_counter()
        report = diagnose(bundle, paper, candidates=EFFECTS, setup=setup,
                          progress=lambda line: print(line, file=sys.stderr, flush=True))
        times[label] = time.perf_counter() - start
        print(f"{label}: {times[label]:.0f} s, {runs.current().in_memory()} forming runs cached; "
              f"setup_error {report.get('setup_error')}, missing_effect "
              f"{report['missing_effect']}", flush=True)
        for s in report.get("setup", []):
            print(f"  {s['parameter']}: fitted {s['fitted']} ± {s['sd']} (fit alone "
                  f"± {s['sd_fit']}), normalised {s['error_after']['normalised']:.3g}, "
                  f"evidence {s['evidence']:.3g}, {s['runs']} new forming runs", flush=True)
    ratio = times["set-up and effects"] / times["effects only"]
    print(f"set-up and effects / effects only: {ratio:.2f}× (target <= 2); whole diagnosis "
          f"{times['set-up and effects'] / 60:.1f} min (target < 5 min on one core)")


if __name__ == "__main__":
    main()
