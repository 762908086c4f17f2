# Time of `diagnose` on a bundle of four tests with five testable candidates, held-out folds
# included. Target: under 120 s on one core.
#
#   python3 benchmarks/bench_diagnose.py [ROWS]
#
# The bundle: a tensile test and bias extension at 10, 40 and 160 mm/min (ROWS rows each,
# default 150 as in the demo bundle), made by the paper's model with temperature dependence
# at 20, 35 and 50 °C, 2 % noise. The baseline keeps only tow_buckling, so decrimping,
# rate_dependence, strain_dependent_viscosity, rate_dependence+temperature_dependence and
# shear_tension_coupling are refitted and held out; holder and tool friction are untestable.

import sys
import time

from fenicsx_drape.calibration.synthetic import bias_test, synthetic_bundle, tensile_test
from fenicsx_drape.diagnosis import diagnose
from fenicsx_drape.model import Model, default_parameters

rows = int(sys.argv[1]) if len(sys.argv) > 1 else 150
effects = ("rate_dependence", "strain_dependent_viscosity", "decrimping", "tow_buckling",
           "temperature_dependence")
truth = Model(effects, default_parameters())
tests = [tensile_test("tensile", n_rows=rows, conditions={"temperature_C": 20.0})]
tests += [bias_test(f"bias-{v:g}", v, n_rows=rows, conditions={"temperature_C": t})
          for v, t in ((10.0, 20.0), (40.0, 35.0), (160.0, 50.0))]
bundle = synthetic_bundle(truth, tests, noise_rel=0.02, seed=5)

marks = []
start = time.perf_counter()


def progress(line):
    if not line.startswith("    "):
        marks.append((time.perf_counter() - start, line))


report = diagnose(bundle, Model(("tow_buckling",), default_parameters()), progress=progress)
total = time.perf_counter() - start
print(f"bundle: {len(bundle.tests)} tests, {sum(t.n_rows for t in bundle.tests)} rows; "
      f"{len(report['candidates'])} candidates refitted, {len(report['untestable'])} "
      "untestable")
for (t0, line), (t1, _) in zip(marks, [*marks[1:], (total, "")]):
    print(f"  {t1 - t0:6.1f} s  {line}")
for c in report["candidates"]:
    print(f"  {c['effect']:45s} after {c['error_after']['normalised']:6.3g}  held-out "
          f"{c['heldout_normalised']:6.3g}  evidence {c['evidence']:6.3g}")
print(f"missing_effect: {report['missing_effect']}")
print(f"diagnose: {total:.1f} s (target < 120 s on one core)")
