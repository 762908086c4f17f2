# Time of a full fit (tensile + three bias rates) of the paper's model to the demo bundle,
# from the curve-feature initial guess. Target: under 20 s on one core.
#
#   python3 benchmarks/bench_fit.py [BUNDLE]

import sys
import time
from pathlib import Path

from fenicsx_drape.calibration.fit import fit
from fenicsx_drape.measurements.bundle import load_bundle
from fenicsx_drape.model import default_model

path = Path(sys.argv[1]) if len(sys.argv) > 1 else (
    Path(__file__).resolve().parents[1] / "demos" / "bundles" / "twill-table2")
bundle = load_bundle(path)
model = default_model()
start = time.perf_counter()
result = fit(bundle, model, analyse=False)
t_fit = time.perf_counter() - start
start = time.perf_counter()
result = fit(bundle, model)
t_all = time.perf_counter() - start
rows = sum(t.n_rows for t in bundle.tests)
print(f"bundle {bundle.name}: {len(bundle.tests)} tests, {rows} rows")
for block in result.blocks:
    print(f"  {block['label']}: {block['iterations']} iterations, "
          f"{block['evaluations']} parameter-set evaluations")
print(f"full fit: {t_fit:.2f} s; with sensitivities and uncertainties: {t_all:.2f} s "
      f"(target < 20 s); normalised error {result.normalised:.3f}")
