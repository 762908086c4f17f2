# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# # Diagnosis on a formed hemisphere: a grid "measured" with a hidden effect
#
# **Not run on this site**: it takes 4 to 8 minutes on two cores, so this page shows the
# code without its output and one of its pictures from a run (at the end); run it as below
# to get them all (`tests/test_demos_diagnosis.py` runs it on 20 mm cells).
#
# 1. A quarter-hemisphere grid (10 mm drawn grid) is "measured": formed by the paper's model,
#    which has `tow_buckling` (tows carry no compression, eq. 4), plus 0.3 mm of noise per
#    coordinate (`position_sd_mm`), written as a forming bundle.
# 2. The baseline lacks `tow_buckling`: `compare` shows its error map over the part and the
#    error by region (apex, bias diagonals, tow axes at the fillet, flange).
# 3. `diagnose` tries the forming candidates (forming runs on 10 mm cells, the paper's Δ)
#    and names the missing effect.
# 4. The effect is added: the error map falls to the noise floor, and the paper's mean
#    distance with it.
#
#     ./drape exec python3 demos/demo_forming_diagnosis.py [OUT] [CELL_MM]
#
# (CELL_MM: the unit cell of the measured part and of the forming runs, 10 mm by default;
# its test runs it on 20 mm cells.)
#
# Pictures for a report: `OUT/compare/residual_hemisphere.png` (baseline error map),
# `OUT/diagnose/residual_hemisphere.png` (baseline and winner side by side),
# `OUT/diagnose/candidates.png`, `OUT/diagnose/where.png`.

# +
import sys
from pathlib import Path

from fenicsx_drape import runs
from fenicsx_drape.diagnosis import (
    diagnose,
    evaluate,
    summary,
    synthetic_forming_test,
    write_compare,
    write_diagnosis,
)
from fenicsx_drape.forming import case_for_test
from fenicsx_drape.measurements import Bundle, load_bundle, write_bundle
from fenicsx_drape.model import default_model

# As a page of the docs the demo is a notebook run in demos/, without arguments.
SCRIPT = "__file__" in globals()
args = sys.argv[1:] if SCRIPT else []
out = Path(args[0] if args else "results/demo_forming_diagnosis")
cell_mm = float(args[1]) if len(args) > 1 else 10.0  # the paper's Δ
CANDIDATES = ["tow_buckling", "tool_friction", "shear_tension_coupling"]
# -

# ## The measured part, the baseline's error, and the diagnosis
#
# The forming runs of `compare` (`evaluate`) and `diagnose` use cells of `cell_mm`
# (`--forming-cell-mm` on the command line). `diagnose` adds each candidate to the baseline,
# refits the forming parameters and judges it by its prediction of grid nodes left out.

# +
truth, baseline = default_model(), default_model().without_effects("tow_buckling")
test = synthetic_forming_test(truth, cell_mm=cell_mm, grid_mm=10.0, sd_mm=0.3, seed=2007)
write_bundle(Bundle(name="hemisphere-hidden-buckling", tests=(test,)), out / "bundle",
             comment="demo: formed with tow_buckling, 0.3 mm noise per coordinate")
bundle = load_bundle(out / "bundle", read_case=case_for_test)
with runs.resolution(cell_mm):
    result = evaluate(bundle, baseline)
    write_compare(result, bundle, out / "compare")
    report = diagnose(bundle, baseline, candidates=CANDIDATES,
                      progress=lambda line: print(line, flush=True))
    write_diagnosis(report, out / "diagnose" / "REPORT.json", out / "diagnose", bundle=bundle)
m = result.metrics["hemisphere"]
print(f"baseline without tow_buckling: mean distance {m['mean_distance_mm']:.2f} mm "
      f"({m['percent_of_displacement']:.1f} % of the mean displacement), "
      f"{result.normalised:.2f} × noise")
print(summary(report))
# -

# ## With the effect added

errors = {"baseline": report["baseline"]["error"]}
errors.update({c["effect"]: c["error_after"] for c in report["candidates"][:1]})
for label, error in errors.items():
    e = report["metrics"][label]["hemisphere"]
    print(f"{label}: {error['normalised']:.2f} × noise, mean distance "
          f"{e['mean_distance_mm']:.2f} mm ({e['percent_of_displacement']:.1f} % of the "
          "mean displacement)")
print(f"pictures: {out / 'compare'} and {out / 'diagnose'}")

# From a run of this demo (fenicsx_drape 0.1.0, 7.7 min on a busy two-core machine):
# `diagnose/residual_hemisphere.png`, the baseline's error at each node of the drawn grid,
# the winner's, and the baseline's error by region of the part.
#
# ![The hemisphere's diagnosis, without and with tow buckling](/demo_forming_diagnosis.png)
