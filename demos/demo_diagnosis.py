# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# # Finding the missing physics: compare, diagnose, add, compare again
#
# **Not run on this site**: it takes about 2 minutes on two cores, so this page shows the
# code without its output and two of its pictures from a run (at the end);
# `./drape exec python3 demos/demo_diagnosis.py OUT` writes them all
# (`tests/test_demos_diagnosis.py` runs it under `make bench`; its steps are tested alone in
# `make test`).
#
# A model of a woven prepreg is only as good as the physics it includes. This walkthrough
# follows a user who calibrates the truss model of Skordos, Monroy Aceves & Sutcliffe on
# coupon tests, asks `fenicsx_drape` **how far** and **where** the model misses, asks
# **which effect** is missing, adds it, and watches the error fall -- first for an effect of
# the package's catalogue, then for physics the package never had, written by the user as a
# law of their own.
#
# The measurements here are synthetic, so that we know the truth: the material's shear
# diagonal has a *shear-thinning* resin (viscous stress growing like the square root of the
# rate: the demo user law `demos/user_laws/power_law_viscosity.py`, n = 0.5) and its tows
# decrimp (eq. 3). The user does not know either. Every step is also one command:
#
# ```
# ./drape compare BUNDLE --model MODEL.toml --out DIR
# ./drape diagnose BUNDLE --model MODEL.toml --json REPORT.json --out DIR
# ./drape history DIR1 DIR2 ... --out DIR
# ```

# +
import sys
from pathlib import Path

from fenicsx_drape.calibration import bias_test, synthetic_bundle, tensile_test
from fenicsx_drape.diagnosis import (
    compare,
    diagnose,
    history,
    history_table,
    summary,
    write_compare,
    write_diagnosis,
)
from fenicsx_drape.model import Model, default_parameters

# As a page of the docs the demo is a notebook run in demos/, without arguments.
SCRIPT = "__file__" in globals()
args = sys.argv[1:] if SCRIPT else []
here = Path(__file__).resolve().parent if SCRIPT else Path.cwd()
out = Path(args[0]) if args else here.parent / "results" / "demo_diagnosis"
law_file = here / "user_laws" / "power_law_viscosity.py"
# -

# ## The measurements
#
# Two bundles from the same (synthetic) material. The first is the paper's programme: a
# tensile test at 2 mm/min and bias extension at 10, 40 and 160 mm/min, with 2 % noise. The
# second comes later, from a better load cell (0.5 % noise) over three decades of crosshead
# speed, 1 to 1000 mm/min. Both are written as ordinary bundles (`bundle.toml` + CSV).

truth = Model(("power_law_viscosity", "decrimping", "tow_buckling"),
              default_parameters() | {"n_power": 0.5}, plugins=(law_file,))
coupons = [tensile_test("tensile", n_rows=40)]
paper = synthetic_bundle(
    truth, coupons + [bias_test(f"bias-{v:g}", v, n_rows=50) for v in (10.0, 40.0, 160.0)],
    noise_rel=0.02, seed=1, out_dir=out / "bundle-paper", name="paper-programme")
wide = synthetic_bundle(
    truth, coupons + [bias_test(f"bias-{v:g}", v, n_rows=50) for v in (1.0, 10.0, 100.0,
                                                                       1000.0)],
    noise_rel=0.005, seed=2, out_dir=out / "bundle-wide", name="wide-rates")

# ## Version 1: how far, and where?
#
# The user starts from the paper's shear law (rate dependence, strain-dependent viscosity)
# and, for simplicity, a linear tow. `compare` fits it and reports the error of each test in
# N and %, the noise floor estimated from the data (`force_sd_N` here) and the error's
# *location*: its share in each physically meaningful region.

v1 = Model(("rate_dependence", "strain_dependent_viscosity", "tow_buckling"),
           default_parameters())
result = compare(paper, v1)
write_compare(result, paper, out / "v1")
for c in result.tests:
    print(f"{c.id:10s} RMSE {c.rmse:7.3g} N ({c.percent:4.1f} %)  noise {c.noise:6.3g} N  "
          f"-> {c.normalised:5.2f} x noise")
print(f"normalised error {result.normalised:.2f} (1 = noise floor)")
for e in result.where()[:3]:
    print(f"{100 * e['share_of_error']:5.1f} % of the error: {e['test']}, {e['says']}")

# The tensile test carries the error, in its low-strain (crimp) region. The residual plots
# `v1/residual_<test>.png` show it, region by region; `v1/where.png` sums it up.
#
# ## Which effect is missing?
#
# `diagnose` refits the model with each catalogued effect added, judges each on tests (or
# rows) left out of its fit, and names the missing effect only when the gain is significant
# and the refit reaches the noise floor (normalised <= 1.5). Effects that these tests cannot
# exercise (the forming-only frictions) are listed as untestable.

report = diagnose(paper, v1)
write_diagnosis(report, out / "diagnose-v1" / "REPORT.json", out / "diagnose-v1",
                bundle=paper)
print(summary(report))

# ## Version 2: add it, compare again
#
# Adding the named effect is one call (or one more name in `effects` of MODEL.toml).

v2 = v1.with_effects(*report["add_effects"])
result = compare(paper, v2)
write_compare(result, paper, out / "v2")
print(f"v2 ({', '.join(v2.effects)}): normalised error {result.normalised:.2f}")

# ## New data, and physics the catalogue does not have
#
# The wide-rate bundle arrives. Version 2, refitted to it, misses again -- and no effect of
# the catalogue explains why: `missing_effect` is null, while `where` still says where the
# residual sits.

result = compare(wide, v2)
write_compare(result, wide, out / "v2-wide")
print(f"v2 on the wide-rate bundle: normalised error {result.normalised:.2f}")
report = diagnose(wide, v2)
write_diagnosis(report, out / "diagnose-v2-wide" / "REPORT.json", out / "diagnose-v2-wide",
                bundle=wide)
print(summary(report))

# The user suspects the resin: its viscosity may thin with the rate. They write that
# physics as a law of their own, `power_law_viscosity.py` (a dataclass with named parameters
# and a vectorised update, registered by name; read it), list the file as a plugin of the
# model, and diagnose again: the law is now a candidate like any catalogued effect.

v2_plugin = Model(v2.effects, v2.parameters, plugins=(law_file,))
report = diagnose(wide, v2_plugin)
write_diagnosis(report, out / "diagnose-v2-plugin" / "REPORT.json",
                out / "diagnose-v2-plugin", bundle=wide)
print(summary(report))

# ## Version 3: the user law in the model
#
# The named law replaces the built-in law of its role (shear) everywhere.

v3 = v2_plugin.with_effects(*report["add_effects"])
result = compare(wide, v3)
write_compare(result, wide, out / "v3-wide")
print(f"v3 ({', '.join(v3.effects)}): normalised error {result.normalised:.2f}")

# ## The history of the model
#
# Every `compare` recorded its version in a ledger; `history` lists them and plots the
# normalised error version by version against the noise floor (`history/history.png`).

versions = history([out / d for d in ("v1", "v2", "v2-wide", "v3-wide")], out / "history")
print(history_table(versions))

# From a run of this demo (fenicsx_drape 0.1.0, 3.7 min on a busy two-core machine): the user
# law named against the catalogue's candidates (`diagnose-v2-plugin/candidates.png`), and the
# model's versions (`history/history.png`).
#
# ![The diagnosis with the user law as a candidate](/demo_diagnosis_candidates.png)
#
# ![The normalised error version by version](/demo_diagnosis_history.png)
