# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# # Fitting the paper's material model to a measurement bundle
#
# This demo identifies the tow and shear parameters of the truss model (section 3.2 of
# Skordos, Monroy Aceves & Sutcliffe) from the demo bundle `demos/bundles/twill-table2`: a
# tensile test and bias-extension tests at three rates, made by the project's own forward
# model from Table 2 with 2 % noise (`demos/make_demo_bundle.py`). The same runs on the
# command line as
#
# ```
# ./drape fit demos/bundles/twill-table2 --out results/demo_fit
# ```

# +
import sys
from pathlib import Path

from fenicsx_drape.calibration import fit, format_table, write_fit
from fenicsx_drape.measurements import load_bundle
from fenicsx_drape.model import default_model, default_parameters

# -

# Load the bundle; the loader validates every file and reports what it kept or derived.

# As a page of the docs the demo is a notebook run in demos/, without arguments.
SCRIPT = "__file__" in globals()
args = sys.argv[1:] if SCRIPT else []
here = Path(__file__).resolve().parent if SCRIPT else Path.cwd()
bundle = load_bundle(here / "bundles" / "twill-table2")
print(f"{bundle.name}: {', '.join(t.id for t in bundle.tests)}")

# Fit the paper's model. The start comes from curve features (knees, slopes, the spread
# with rate), not from Table 2; the default model's Table 2 values are ignored as a start.

result = fit(bundle, default_model(), progress=print if SCRIPT else None)

# Errors per test kind, as the paper reports them (7.1 N tensile, 0.6 N bias, 7-9 %), and
# the normalised error (1 = at the noise floor).

for kind, e in result.errors_per_kind().items():
    print(f"{kind:15s} mean |error| {e['mean_abs_N']:.3g} N ({e['mean_abs_pct']:.2g} %)")
print(f"normalised error {result.normalised:.3f}, fit took {result.seconds:.1f} s")

# The parameters against Table 2 (which made the data), with the fit's 95 % intervals;
# flags name the parameters the tests cannot determine.

table2 = default_parameters()
for name in result.fitted:
    u = result.uncertainty.get(name, {})
    lo, hi = u.get("ci95", (float("nan"), float("nan")))
    print(f"{name:10s} fitted {float(result.model.parameters[name]):11.4g}   Table 2 "
          f"{float(table2[name]):11.4g}   95 % [{lo:.3g}, {hi:.3g}]")
for flag in result.flags:
    print("flag:", flag)
print(format_table(result.sensitivity))

# Write the fitted model (loadable with `load_model`), the report and the plots.

out = Path(args[0]) if args else here.parent / "results" / "demo_fit"
write_fit(result, out)
print(f"wrote {out}")

# ## The pictures

if not SCRIPT:  # as a page of the docs: the pictures inline
    from IPython.display import Image, display

    for png in sorted(out.glob("fit_*.png")):
        display(Image(filename=str(png)))
