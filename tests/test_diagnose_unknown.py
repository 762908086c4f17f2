"""Physics the catalogue does not have: null first, then named once written as a user law.

The bundle is made with the demo user law ``power_law_viscosity`` (a shear-thinning dashpot,
viscous stress ~ rate^n with n = 0.5) over three decades of crosshead speed, noise 0.5 % of
each test's peak force. The paper's shear law cannot follow it; no catalogued effect explains
the residual, so ``missing_effect`` is null while ``where`` still locates the residual. With
the user law's file listed as a plugin of the model, the law becomes a candidate, is named,
and adding it brings the normalised error to <= 1.5.
"""

from pathlib import Path

import pytest

from fenicsx_drape.calibration.synthetic import bias_test, synthetic_bundle, tensile_test
from fenicsx_drape.diagnosis import diagnose
from fenicsx_drape.diagnosis.decision import ADEQUATE
from fenicsx_drape.model import Model, default_parameters

COUPON = ("rate_dependence", "strain_dependent_viscosity", "decrimping", "tow_buckling")
PLUGIN = Path(__file__).parents[1] / "demos" / "user_laws" / "power_law_viscosity.py"


@pytest.fixture(scope="module")
def bundle():
    truth = Model(("power_law_viscosity", "decrimping", "tow_buckling"),
                  default_parameters() | {"n_power": 0.5}, plugins=(PLUGIN,))
    tests = [tensile_test("tensile", n_rows=40)]
    tests += [bias_test(f"bias-{v:g}", v, n_rows=50) for v in (1.0, 10.0, 100.0, 1000.0)]
    return synthetic_bundle(truth, tests, noise_rel=0.005, seed=21)


@pytest.fixture(scope="module")
def without_plugin(bundle):
    return diagnose(bundle, Model(COUPON, default_parameters()))


@pytest.mark.slow
def test_unknown_physics_gives_null_and_locates_the_residual(without_plugin):
    report = without_plugin
    assert report["baseline"]["error"]["normalised"] > 2 * ADEQUATE
    assert report["missing_effect"] is None
    assert "power_law_viscosity" not in [c["effect"] for c in report["candidates"]]
    assert report["where"], "the residual's location is still reported"
    assert sum(e["share_of_error"] for e in report["where"]) > 0.5
    assert "not in the catalogue" in report["conclusion"]


@pytest.mark.slow
def test_the_user_law_as_a_plugin_is_named_and_fits(bundle, without_plugin):
    report = diagnose(bundle, Model(COUPON, default_parameters(), plugins=(PLUGIN,)))
    assert report["missing_effect"] == "power_law_viscosity"
    best = report["candidates"][0]
    assert best["effect"] == "power_law_viscosity" and best["significant"]
    assert best["error_after"]["normalised"] <= ADEQUATE
    # The baseline is the same fit as without the plugin: only the candidates changed.
    assert report["baseline"]["error"]["normalised"] == pytest.approx(
        without_plugin["baseline"]["error"]["normalised"])
