"""Time of the default diagnosis on a lab bundle against a grid bundle of the same part.

The double dome (quarter model, the case's own net unless ``--cell-mm``) formed by the
paper's model with the ply turned by ``--ply-angle-deg`` (default 4.37°, off the set-up scan)
is measured twice from the same run:

- as a grid (the whole blank's nodes on a 20 mm drawn grid, 0.3 mm noise): the diagnosis as
  it was before lab kinds entered the set-up stage;
- as a lab would (shear along two lines, the edge, the press force: three kinds).

Each is diagnosed with the default path (every set-up candidate, the resolution check, every
effect) of the paper's model. Printed: the wall time of each, their ratio (target: the lab
bundle's ≤ 2× the grid's), and the verdicts.

    ./drape exec python3 benchmarks/bench_lab_diagnose.py
    ./drape exec python3 benchmarks/bench_lab_diagnose.py --cell-mm 20 --step-mm 4
"""

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

from fenicsx_drape import runs
from fenicsx_drape.diagnosis import diagnose
from fenicsx_drape.diagnosis.lab_synthetic import lab_tables, write_lab_bundle
from fenicsx_drape.diagnosis.synthetic import synthetic_case_test
from fenicsx_drape.forming.case.format import case_for_test, load_case, with_overrides
from fenicsx_drape.measurements.bundle import Bundle, load_bundle
from fenicsx_drape.model import default_model
from fenicsx_drape.trust import trusting

CASE = Path(__file__).parents[1] / "meshes" / "double_dome" / "case.toml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cell-mm", type=float, default=None)
    parser.add_argument("--step-mm", type=float, default=None)
    parser.add_argument("--ply-angle-deg", type=float, default=4.37)
    args = parser.parse_args()
    paper = default_model()
    stated = load_case(CASE, cell_mm=args.cell_mm, step_mm=args.step_mm)
    truth = with_overrides(stated, ply_angle_deg=args.ply_angle_deg)
    grid_test = synthetic_case_test(paper, truth, sd_mm=0.3, seed=2028, full=True)
    grid = Bundle(name="grid", tests=(dataclasses.replace(grid_test, forming_case=stated,
                                                          case_keys={}),))
    (sheet,) = runs.form_many([(truth, paper)])
    tables = lab_tables(sheet, runs.tool_forces(truth, paper), seed=2028)
    scratch = tempfile.TemporaryDirectory(prefix="bench-lab-")  # removed when it goes
    folder = Path(scratch.name)
    write_lab_bundle(folder, stated, tables, measurements=["shear_points", "outline",
                                                           "punch_force"])
    with trusting():  # the bundle's case copy names the shipped double dome's .py geometry
        lab = load_bundle(folder, read_case=case_for_test)
    print(f"double dome, cells {stated.blank.cell_mm:g} mm, steps {stated.step_mm:g} mm; "
          f"the ply turned by {args.ply_angle_deg:g}°", flush=True)
    times = {}
    for label, bundle in (("grid", grid), ("lab: shear lines, edge, force", lab)):
        runs.current().forget()
        start = time.perf_counter()
        with trusting():
            report = diagnose(bundle, paper)
        times[label] = time.perf_counter() - start
        setup = report["setup"][0] if report["setup"] else {}
        print(f"{label:32s} {times[label]:7.1f} s  setup_error {report['setup_error']} "
              f"({setup.get('fitted')} ± {setup.get('sd')}), missing_effect "
              f"{report['missing_effect']}, resolution checked "
              f"{len(report['resolution'])}", flush=True)
    grid_s, lab_s = times.values()
    print(f"ratio lab / grid: {lab_s / grid_s:.2f} (target <= 2)")


if __name__ == "__main__":
    main()
