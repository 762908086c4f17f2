# # The demo bundle: the paper's material made by the project's own forward model
#
# Writes `demos/bundles/twill-table2/`: a tensile test at 2 mm/min (100 mm gauge, 25 mm
# wide) and bias-extension tests at 10, 40 and 160 mm/min (210 × 70 mm), simulated with the
# paper's Table 2 parameters and the four coupon effects, plus Gaussian noise of one standard
# deviation = 2 % of each test's peak force (seed 2007), stated in the `force_sd_N` column.
#
# Run from the repository root: `python3 demos/make_demo_bundle.py`.

from pathlib import Path

from fenicsx_drape.calibration import standard_tests, synthetic_bundle
from fenicsx_drape.model import default_model

NOISE_REL = 0.02  # noise standard deviation: 2 % of the peak force of each test
SEED = 2007

out = Path(__file__).parent / "bundles" / "twill-table2"
bundle = synthetic_bundle(default_model(), standard_tests(), noise_rel=NOISE_REL, seed=SEED,
                          out_dir=out, name="twill-table2",
                          material="4x4 twill 3k carbon/1947 epoxy (synthetic: Table 2 + noise)")
for test in bundle.tests:
    print(f"{test.id:10s} {test.n_rows:4d} rows, peak {abs(test.force_N).max():8.3f} N, "
          f"noise sd {test.force_sd_N[0]:.3f} N")
print(f"wrote {out}")
