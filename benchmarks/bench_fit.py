# Time of a full coupon fit (tensile + three bias rates) of the paper's model to the demo
# bundle, from the curve-feature initial guess: with the global stage (the default; target
# under 30 s on one core) and without it, and the starts that found the best.
#
#   python3 benchmarks/bench_fit.py [BUNDLE]

import sys
import time
from pathlib import Path

from fenicsx_drape.calibration import fit
from fenicsx_drape.measurements.bundle import load_bundle
from fenicsx_drape.model import default_model

path = Path(sys.argv[1]) if len(sys.argv) > 1 else (
    Path(__file__).resolve().parents[1] / "demos" / "bundles" / "twill-table2")
bundle = load_bundle(path)
model = default_model()
rows = sum(t.n_rows for t in bundle.tests)
print(f"bundle {bundle.name}: {len(bundle.tests)} tests, {rows} rows")
start = time.perf_counter()
local = fit(bundle, model, analyse=False, global_stage=False)
t_local = time.perf_counter() - start
start = time.perf_counter()
result = fit(bundle, model, analyse=False)
t_global = time.perf_counter() - start
start = time.perf_counter()
fit(bundle, model)
t_all = time.perf_counter() - start
for block in result.blocks:
    print(f"  {block['label']}: {block['global']['statement']}; "
          f"{block['evaluations']} parameter-set evaluations in the last local fit")
print(f"fit with the global stage: {t_global:.2f} s (target < 30 s), normalised error "
      f"{result.normalised:.3f}; local fit only: {t_local:.2f} s, normalised "
      f"{local.normalised:.3f}; with sensitivities and uncertainties: {t_all:.2f} s")
