# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# # Which physics is a formed double dome missing? Diagnosis on any forming case
#
# **Not run on this site**: it takes one to two minutes on two cores, so this page shows the
# code without its output and one of its pictures from a run (at the end); run it as below
# to get them all (`tests/test_demos_diagnosis.py` runs it on a copy of the double dome with
# 20 mm cells).
#
# A part is formed, its drawn grid is measured, and the model that should predict it misses:
# which physical effect is it lacking? The hemisphere's demo (`demo_forming_diagnosis.py`)
# answers this for the paper's part; here the part is any forming case (`case.toml`), by
# default the double dome of the international woven-composite forming benchmark
# (`meshes/double_dome/case.toml`, tools from Gmsh).
#
# 1. The "measurement": the double dome formed by the paper's model, which has
#    `tow_buckling` (tows carry no compression, eq. 4), read on the drawn grid of the whole
#    blank (the model is a symmetric part, mirrored) with 0.3 mm of noise per coordinate,
#    written as a bundle whose test names a copy of the case (`case = "case/case.toml"`).
# 2. The model to judge lacks `tow_buckling`: `compare` maps its error over the part, by
#    regions named from the case's tools (punch top, walls along the tow axes or on the bias
#    diagonals, flat base, flange under the holder, free sheet).
# 3. `diagnose` tries the forming candidates and names the missing effect.
# 4. With the effect added the error map falls to the noise floor.
#
#     ./drape exec python3 demos/demo_case_diagnosis.py [OUT] [CASE.toml]
#
# Pictures: `OUT/compare/residual_<test>.png` (the baseline's error map),
# `OUT/diagnose/residual_<test>.png` (baseline and winner side by side, error by region),
# `OUT/diagnose/candidates.png`, `OUT/after/residual_<test>.png` (the model with the effect).

# +
import sys
import time
from pathlib import Path

from fenicsx_drape import runs
from fenicsx_drape.diagnosis import (
    diagnose,
    evaluate,
    summary,
    synthetic_case_test,
    write_case_bundle,
    write_compare,
    write_diagnosis,
)
from fenicsx_drape.forming import case_for_test, load_case
from fenicsx_drape.measurements import load_bundle
from fenicsx_drape.model import default_model
from fenicsx_drape.trust import set_trusted

# As a page of the docs the demo is a notebook run in demos/, without arguments.
SCRIPT = "__file__" in globals()
args = sys.argv[1:] if SCRIPT else []
ROOT = (Path(__file__).resolve().parent if SCRIPT else Path.cwd()).parent
out = Path(args[0]) if args else Path("results/demo_case_diagnosis")
case_file = Path(args[1]) if len(args) > 1 else ROOT / "meshes/double_dome/case.toml"
HIDDEN = "tow_buckling"
CANDIDATES = ["tow_buckling", "tool_friction", "shear_tension_coupling"]
SD_MM = 0.3  # measurement noise per coordinate (mm)
start = time.perf_counter()
# -

# ## The part and the "measurement"
#
# The case as its file says (tools, blank, symmetry planes, holder, forming time). The truth
# is the paper's model with the blank holder's μ at 0.35 (the model to judge starts from the
# literature's 0.3 and fits it).

# +
case = load_case(case_file)
# The bundle below is written here from our own case, whose tools are Python geometry: we
# trust its code, as `--trust` says on the command line (a bundle is data otherwise).
set_trusted(True)
truth = default_model().with_parameters(mu=0.35)
print(f"case {case.name!r}: {case.description}")
print(f"  blank {case.blank.outline}, cells {case.blank.cell_mm:g} mm, symmetry "
      f"{list(case.planes) or 'none'}, {len(case.blank.grid().nodes)} nodes; "
      f"travel {case.total_travel_mm:g} mm in {case.duration_s:g} s")
test = synthetic_case_test(truth, case, sd_mm=SD_MM, seed=2007, full=True)
write_case_bundle(f"{case.name}-hidden-{HIDDEN}", [test], out / "bundle",
                     comment=f"demo: {case.name} formed with {HIDDEN}, {SD_MM} mm noise per "
                             "coordinate, whole blank")
bundle = load_bundle(out / "bundle", read_case=case_for_test)
(test,) = bundle.tests
print(f"measured grid: {test.n_rows} nodes (whole blank), its case {test.case}")
# -

# ## The model to judge, compared
#
# It lacks tow buckling: its tows carry compression with their tension law mirrored.

# +
baseline = default_model().without_effects(HIDDEN)
result = evaluate(bundle, baseline)
write_compare(result, bundle, out / "compare")
m = result.metrics[test.id]
print(f"baseline without {HIDDEN}: mean distance {m['mean_distance_mm']:.2f} mm "
      f"({m['percent_of_displacement']:.1f} % of the mean displacement), "
      f"{result.normalised:.2f} × noise")
for entry in result.where()[:4]:
    print(f"  {100 * entry['share_of_error']:5.1f} % of the error: {entry['says']}")
# -

# ## Diagnose
#
# Every candidate is added to the baseline, the forming parameters (μ of the holder, μ_tool)
# refitted, and judged by its prediction of grid nodes left out of its fit (three
# interleaved folds).

# +
runs_before = runs.execution_record()["runs"]["formed"]  # formed so far in this process
report = diagnose(bundle, baseline, candidates=CANDIDATES,
                  progress=lambda line: print(line, flush=True))
write_diagnosis(report, out / "diagnose" / "REPORT.json", out / "diagnose", bundle=bundle)
print(summary(report))
# -

# ## With the effect added

# +
winner = report.models[report["candidates"][0]["effect"]]
after = evaluate(bundle, winner)
write_compare(after, bundle, out / "after")
for label, r in (("baseline", result), (report["candidates"][0]["effect"], after)):
    e = r.metrics[test.id]
    print(f"{label}: {r.normalised:.2f} × noise, mean distance {e['mean_distance_mm']:.2f} mm "
          f"({e['percent_of_displacement']:.1f} % of the mean displacement)")
print(f"missing_effect: {report['missing_effect']} (hidden: {HIDDEN}); "
      f"{runs.execution_record()['runs']['formed'] - runs_before} forming runs, "
      f"{time.perf_counter() - start:.0f} s in all")
print(f"pictures: {out / 'compare'}, {out / 'diagnose'}, {out / 'after'}")
# -

# From a run of this demo on the double dome's 10 mm net (fenicsx_drape 0.1.0, 34 forming
# runs, 4.2 min on a busy two-core machine): `diagnose/residual_double_dome.png`, the
# baseline's error at each node of the drawn grid, the winner's, and the baseline's error by
# region of the part.
#
# ![The double dome's diagnosis: the error without and with tow buckling](/demo_case_diagnosis.png)
