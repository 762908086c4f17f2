"""One error per model: the set-up as stated is the diagnosis's baseline.

The baseline fits the holder's μ where no case states it; the set-up stage judges its
candidates against the set-up as stated, and that is the baseline as fitted (the same
material, the same friction, the same noise), so a run gives the stated model one
normalised error. The holding force and μ act through μF only (eq. 1): where the baseline
fits μ, a factor on the force (or μ again) would only repeat that fit, and, fitted before
physics, would take up a restraint the model misses. They are untestable there.

A quarter hemisphere on 40 mm cells, 8 mm steps, at 400 N (a few seconds of runs): formed
with μ = 0.15,
diagnosed with the model's μ = 0.3 and no μ in the case.
"""

import pytest

from fenicsx_drape.diagnosis.kinds.forming import holder_mu_free
from fenicsx_drape.measurements.bundle import Bundle
from fenicsx_drape.model import default_model

CELL_MM = 40.0


@pytest.fixture(scope="module")
def stages():
    """The diagnosis's stages up to the set-up stage, as ``diagnose`` calls them."""
    pytest.importorskip("dolfinx")
    from fenicsx_drape.diagnosis import pipeline
    from fenicsx_drape.diagnosis.decision import setup_rules
    from fenicsx_drape.diagnosis.setup_stage import setup_stage
    from fenicsx_drape.diagnosis.synthetic import synthetic_case_test
    from fenicsx_drape.forming.case import load_case

    model = default_model()
    case = load_case("hemisphere", cell_mm=CELL_MM, step_mm=8.0, holder_force_N=400.0)
    test = synthetic_case_test(model.with_parameters(mu=0.15), case, seed=3)
    assert holder_mu_free(test)  # the case states no μ: the baseline fits it
    lines = []
    data = pipeline.prepare_tests(Bundle(name="mu-free", tests=(test,)))
    base = pipeline.baseline_stage(data, model, lines.append)
    stage = setup_stage(base.data.bundle, model, ["holder_force_N", "mu"], setup_rules(),
                        lines.append, baseline=base.model)
    return base, stage, lines


def test_the_set_up_as_stated_is_the_baseline_with_one_error(stages):
    base, stage, lines = stages
    assert base.model.parameters["mu"] == pytest.approx(0.15, rel=0.1)  # fitted, not 0.3
    assert stage.stated_model is base.model
    assert stage.stated_error["normalised"] == pytest.approx(base.normalised, rel=1e-9)
    assert stage.stated_error["per_test"] == pytest.approx(
        {c.id: c.rmse for c in base.compared}, rel=1e-9)
    # printed once each, the same number, the set-up's line naming it the baseline's
    (line,) = [x for x in lines if x.startswith("set-up as stated")]
    assert line.startswith(f"set-up as stated (the baseline): normalised error "
                           f"{base.normalised:.3g} ")


def test_the_holding_force_is_not_fitted_where_the_baseline_fits_mu(stages):
    _, stage, lines = stages
    assert stage.setup_error is None and stage.entries == () and stage.fitted == ("mu",)
    reasons = {u["effect"]: u["reason"] for u in stage.untestable}
    assert set(reasons) == {"holder_force_N", "mu"}
    assert all("μ is not stated" in r and "μF" in r for r in reasons.values())
    assert not any("holder_force_N scan" in x or "fit 1" in x for x in lines)  # no runs


def test_a_stated_mu_leaves_the_holding_force_to_the_set_up_stage():
    """μ in the case: the baseline does not fit it, so the force is a set-up candidate."""
    from dataclasses import replace
    from pathlib import Path

    from fenicsx_drape.diagnosis.setup_stage import taken_up
    from fenicsx_drape.forming.case.format import load_case
    from fenicsx_drape.measurements.bundle import Test

    case = load_case(Path(__file__).parents[1] / "meshes" / "double_dome" / "case.toml",
                     cell_mm=20.0, step_mm=4.0)

    def test_of(mu):
        c = replace(case, holder=replace(case.holder, mu=mu))
        return Test(id=f"t{mu}", kind="forming", file="t.csv", columns={},
                    case="case/case.toml", forming_case=c)

    names = ["ply_angle_deg", "holder_force_N", "mu"]
    free, stated = test_of(None), test_of(0.3)
    assert set(taken_up(names, [free], ("mu",))) == {"holder_force_N", "mu"}
    assert taken_up(names, [free], ()) == {}  # the stage alone: μ as given, not fitted
    assert taken_up(names, [stated], ("mu",)) == {}
    assert taken_up(names, [free, stated], ("mu",)) == {}  # one trial states it
