"""diagnose on data with a hidden effect: it must name exactly that effect.

Each bundle is made by the project's forward model *with* the effect plus Gaussian noise
(2 % of each test's peak force, ``force_sd_N``); the baseline is the same model *without* it.
The test asserts that the baseline's error is well above the noise floor (normalised >= 2,
above the 1.5 at which a model counts as adequate),
that ``diagnose`` names exactly the hidden effect, and that with it added the refit is within
1.5 times the noise floor. The cases vary the material (three parameter sets) and the noise
seed; one case per effect runs in ``make test``, the other material and seed of each effect
is marked ``bench`` (``make bench``): the same path on other numbers, 20 to 40 s each.
"""

import pytest

from fenicsx_drape.calibration.synthetic import bias_test, synthetic_bundle, tensile_test
from fenicsx_drape.diagnosis import diagnose
from fenicsx_drape.diagnosis.decision import ADEQUATE
from fenicsx_drape.model import Model, default_parameters

COUPON = ("rate_dependence", "strain_dependent_viscosity", "decrimping", "tow_buckling")

# Materials: Table 2, and two others with parameters moved by 20-60 %.
MATERIALS = {
    "table2": {},
    "stiff": {"eta_o": 2.2, "sigma_o": 0.018, "eps_v_bar": 0.45, "E_o": 4400.0,
              "E_inf": 24000.0, "Ea_kJ_per_mol": 45.0},
    "soft": {"eta_o": 0.8, "sigma_o": 0.035, "s_inf": 3800.0, "eps_bar": 0.0018,
             "E_o": 2600.0, "Ea_kJ_per_mol": 75.0},
}


def coupon_tests(*, temperatures=None):
    """Tensile at 2 mm/min; bias at 10, 40, 160 mm/min, or at 40 mm/min and several °C."""
    tests = [tensile_test("tensile", n_rows=40)]
    if temperatures:
        return tests + [bias_test(f"bias-{t:g}C", 40.0, n_rows=50,
                                  conditions={"temperature_C": t}) for t in temperatures]
    return tests + [bias_test(f"bias-{v:g}", v, n_rows=50) for v in (10.0, 40.0, 160.0)]


CASES = [
    # (hidden effect, material, seed, bench)
    ("rate_dependence", "soft", 3, False),
    ("rate_dependence", "stiff", 4, True),
    ("strain_dependent_viscosity", "stiff", 5, False),
    ("strain_dependent_viscosity", "table2", 6, True),
    ("decrimping", "table2", 7, False),
    ("decrimping", "soft", 8, True),
    ("temperature_dependence", "table2", 9, False),
    ("temperature_dependence", "stiff", 10, True),
]


@pytest.mark.parametrize(
    ("effect", "material", "seed"),
    [pytest.param(e, m, s, marks=[pytest.mark.bench] if bench else [], id=f"{e}-{m}-{s}")
     for e, m, s, bench in CASES])
@pytest.mark.slow
def test_diagnose_names_the_hidden_effect(effect, material, seed):
    parameters = default_parameters() | MATERIALS[material]
    if effect == "temperature_dependence":
        truth = Model((*COUPON, effect), parameters)
        tests = coupon_tests(temperatures=(20.0, 45.0, 70.0))
    else:
        truth = Model(COUPON, parameters)
        tests = coupon_tests()
    bundle = synthetic_bundle(truth, tests, noise_rel=0.02, seed=seed)
    report = diagnose(bundle, truth.without_effects(effect))

    assert report["baseline"]["error"]["normalised"] >= 2.0  # well above the noise floor
    assert report["missing_effect"] == effect
    assert report["add_effects"] == [effect]
    (best,) = [c for c in report["candidates"] if c["effect"] == effect]
    assert best is report["candidates"][0]
    assert best["significant"]
    assert best["error_after"]["normalised"] <= ADEQUATE
    # No other candidate would have been named.
    for other in report["candidates"][1:]:
        assert not (other["significant"] and other["error_after"]["normalised"] <= ADEQUATE)
