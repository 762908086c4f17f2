"""The set-up error withdrawn when an effect at the stated set-up does as well.

``pipeline.setup_needed_stage``'s rule, with the stages it calls stood in for (their runs
are tested elsewhere): the effect refitted at the stated set-up is judged on the same
held-out rows as with the set-up fitted, and the set-up error stands only when that fit
predicts them at least ``EVIDENCE_THRESHOLD`` times better. The scenario benchmark's tool
friction on the double dome (a holder force 351 N fitted for the 200 N stated) is the case
it was made for: evidence 1.0002, withdrawn. With a holding force named and no significant
effect (the effects refitted at the fitted force gain nothing: a hidden viscosity that grows
with strain taken up by a force of 633 N for 400 N stated), every ranked candidate is tried
at the stated set-up; so too with a placement named as set apart only (a sliding stack's
plies, bonded in the model, took the punch 1 mm off).
"""

import dataclasses

import pytest

from fenicsx_drape.diagnosis import pipeline
from fenicsx_drape.diagnosis.decision import EVIDENCE_THRESHOLD
from fenicsx_drape.diagnosis.results import Candidate, Effects, HeldOut, SetupResult


def candidate(heldout: float, significant: bool = True, name: str = "tool_friction"
              ) -> Candidate:
    return Candidate(effect=name, effects=(name,), acts_on="contact",
                     summary="", parameters={"mu_tool": 0.3}, error_after={"normalised": 1.2},
                     heldout_normalised=heldout, evidence=1.4, significant=significant,
                     sensitivity=3.0, where_after=(), setup_refitted=None, model=None,
                     after=(), tests=(), n_parameters=1)


def stage(parameter: str = "holder_force_N") -> SetupResult:
    entry = {"parameter": parameter, "stated": 200.0, "fitted": 350.6, "sd": 49.9}
    return SetupResult(entries=(entry,), setup_error=parameter, untestable=(),
                       stated_error=None, stated_heldout_normalised=None, scheme=None,
                       rule=None, resolution=None, model_note=None, best=None, bundle=None,
                       stated_model=None, corrected=None)


@pytest.fixture
def stand_ins(monkeypatch):
    """The effect at the stated set-up predicts its held-out rows with ``alone['heldout']``
    (by effect, ``alone['by_name']``); ``alone['tried']`` lists the effects tried there."""
    alone = {"heldout": 1.2, "significant": True, "by_name": {}, "tried": []}

    def effect_stage(name, model, base, held, st, res, say):
        alone["tried"].append(name)
        return candidate(alone["by_name"].get(name, alone["heldout"]), alone["significant"],
                         name)

    monkeypatch.setattr(pipeline, "heldout_stage", lambda base, say: HeldOut(()))
    monkeypatch.setattr(pipeline, "effect_stage", effect_stage)
    return alone


def run(best, effects=None, at=None, held=None):
    stated, at_setup, held = object(), object(), held or HeldOut(())
    return pipeline.setup_needed_stage(at or stage(), best, stated, at_setup, held, None,
                                       None, lambda line: None, effects=effects
                                       ), stated, at_setup


class Held(HeldOut):
    """A held-out error of a given size (the baseline at the fitted set-up)."""

    def __init__(self, value):
        super().__init__(())
        object.__setattr__(self, "value", value)

    @property
    def normalised(self):
        return self.value


@pytest.mark.parametrize("ratio", [1.0, 0.9 * EVIDENCE_THRESHOLD])
def test_a_set_up_error_the_effect_stands_behind_is_withdrawn(stand_ins, ratio):
    best = candidate(1.2)
    stand_ins["heldout"] = 1.2 * ratio
    (setup, named, base, *_), stated, _ = run(best)
    assert setup.setup_error is None and setup.withdrawn == "holder_force_N"
    assert setup.entries[0]["withdrawn_for"] == "tool_friction"
    assert setup.entries[0]["evidence_with_effect"] == pytest.approx(ratio)
    # The effect at the stated set-up is the best, against the stated baseline.
    assert named.heldout_normalised == pytest.approx(1.2 * ratio) and base is stated


@pytest.mark.parametrize("ratio", [EVIDENCE_THRESHOLD, 3.0])
def test_a_set_up_error_that_adds_evidence_stands(stand_ins, ratio):
    best = candidate(1.2)
    stand_ins["heldout"] = 1.2 * ratio
    (setup, named, base, *_), _, at_setup = run(best)
    assert setup.setup_error == "holder_force_N" and setup.withdrawn is None
    assert named is best and base is at_setup


def test_nothing_is_withdrawn_for_an_effect_not_significant_alone(stand_ins):
    stand_ins["significant"] = False
    best = candidate(1.2)
    (setup, named, *_), _, _ = run(best)
    assert setup.setup_error == "holder_force_N" and named is best


def test_a_set_up_error_found_with_the_effect_is_not_looked_at_again(stand_ins):
    best = candidate(1.2)
    found = dataclasses.replace(stage(), found_with_effect="tool_friction")
    out = pipeline.setup_needed_stage(found, best, object(), object(), HeldOut(()), None, None,
                                      lambda line: None)
    assert stand_ins["tried"] == []
    assert out[0] is found and out[1] is best


def test_an_effect_the_force_took_the_place_of_is_named_at_the_stated_set_up(stand_ins):
    """No significant effect with the force fitted: each ranked candidate is refitted at the
    stated force; the one that predicts the held-out rows as well as the fitted force does
    (1.1 against 1.05: evidence 1.05) is the best, and the force is withdrawn for it."""
    ranked = (candidate(1.1, False, "tool_friction"),
              candidate(1.3, False, "strain_dependent_viscosity"))
    stand_ins["by_name"] = {"tool_friction": 1.6, "strain_dependent_viscosity": 1.1}
    looked, stated, _ = run(ranked[0], Effects(ranked, ()), held=Held(1.05))
    assert stand_ins["tried"] == ["tool_friction", "strain_dependent_viscosity"]
    assert looked.stage.setup_error is None and looked.stage.withdrawn == "holder_force_N"
    assert looked.stage.entries[0]["withdrawn_for"] == "strain_dependent_viscosity"
    assert looked.stage.entries[0]["evidence_with_effect"] == pytest.approx(1.1 / 1.05)
    assert looked.best.effect == "strain_dependent_viscosity" and looked.base is stated
    # the ranking is the stated set-up's: every candidate there, the best first
    assert [c.effect for c in looked.effects.ranked] == [
        "strain_dependent_viscosity", "tool_friction"]


def test_a_force_that_predicts_better_than_any_effect_at_the_stated_set_up_stands(stand_ins):
    """The force fitted predicts the held-out rows 1.3 × better than the best effect at the
    stated set-up: it stands, and the candidates stay as ranked at the fitted force."""
    ranked = (candidate(1.1, False),)
    stand_ins["heldout"] = 1.3 * 1.0
    looked, _, at_setup = run(ranked[0], Effects(ranked, ()), held=Held(1.0))
    assert looked.stage.setup_error == "holder_force_N" and looked.base is at_setup
    assert looked.best is ranked[0] and looked.effects.ranked == ranked


def test_a_placement_is_not_looked_at_again_for_effects_not_significant(stand_ins):
    """A ply angle named as significant is not a restraint an effect stands in for: with no
    significant effect, nothing is refitted at the stated set-up (no runs)."""
    ranked = (candidate(1.1, False),)
    named = stage("ply_angle_deg")
    named = dataclasses.replace(named, entries=({**named.entries[0], "significant": True,
                                                 "set_apart": True},))
    looked, _, at_setup = run(ranked[0], Effects(ranked, ()), at=named, held=Held(1.0))
    assert stand_ins["tried"] == [] and looked.stage.setup_error == "ply_angle_deg"
    assert looked.base is at_setup


def set_apart_only(parameter: str = "tool_offset_mm") -> SetupResult:
    """A placement named as set apart only: the small sliding-stack scenario's tool offset."""
    entry = {"parameter": parameter, "stated": [0.0, 0.0], "fitted": [1.0, 1.0],
             "sd": [0.659, 0.661], "sd_fit": [0.0461, 0.0464], "significant": False,
             "set_apart": True}
    return dataclasses.replace(stage(parameter), entries=(entry,))


def test_an_effect_a_placement_set_apart_only_took_the_place_of_is_named(stand_ins):
    """A tool offset named as set apart only (its fit's own sd leaves out what a missing
    effect leaves), no effect significant at it: each ranked candidate is refitted at the
    stated set-up, and the one that predicts the held-out rows better than the offset did
    (the small sliding-stack scenario: interply_friction 5.89 × the noise at the offset,
    9.42 the offset alone) is named, the offset withdrawn."""
    ranked = (candidate(5.89, False, "interply_friction"),
              candidate(8.35, False, "tool_friction"))
    stand_ins["by_name"] = {"interply_friction": 1.1, "tool_friction": 12.0}
    looked, stated, _ = run(ranked[0], Effects(ranked, ()), at=set_apart_only(),
                            held=Held(9.42))
    assert stand_ins["tried"] == ["interply_friction", "tool_friction"]
    assert looked.stage.setup_error is None and looked.stage.withdrawn == "tool_offset_mm"
    assert looked.stage.entries[0]["withdrawn_for"] == "interply_friction"
    assert looked.stage.entries[0]["evidence_with_effect"] == pytest.approx(1.1 / 5.89)
    assert looked.best.effect == "interply_friction" and looked.base is stated


def test_a_placement_set_apart_only_that_predicts_better_stands(stand_ins):
    """The same, but the offset predicts the held-out rows 1.3 × better than any effect at
    the stated set-up: it stands, the candidates as ranked at it."""
    ranked = (candidate(5.89, False, "interply_friction"),)
    stand_ins["heldout"] = 1.3 * 5.89
    looked, _, at_setup = run(ranked[0], Effects(ranked, ()), at=set_apart_only(),
                              held=Held(9.42))
    assert stand_ins["tried"] == ["interply_friction"]
    assert looked.stage.setup_error == "tool_offset_mm" and looked.base is at_setup
    assert looked.best is ranked[0] and looked.effects.ranked == ranked


def test_the_set_up_is_fitted_again_at_the_friction_refitted_with_it(monkeypatch):
    """``pipeline.friction_round``: the baseline's μ, fitted with the set-up as stated, took up
    part of a turned ply (0.333 for 0.3). The ply is fitted again at the μ refitted with it
    (when it moved) and at the model's given μ, and the one whose baseline comes nearest the
    data is kept: the entry reports the new value and the first one."""
    from fenicsx_drape.diagnosis.results import SetupBest
    from fenicsx_drape.model import default_model

    model = default_model()  # μ given: 0.3
    stage_model = model.with_parameters(mu=0.333)
    asked = []
    ply_at = {0.333: 4.21, 0.32: 4.1, 0.3: 4.0}  # the ply each μ fits
    error_at = {4.21: 1.39, 4.1: 1.2, 4.0: 0.97}  # the baseline refitted at each ply

    def refit_setup(bundle, name, p, with_model, say):
        mu = round(float(with_model.parameters["mu"]), 3)
        asked.append(mu)
        return [ply_at[mu]]

    Base = dataclasses.make_dataclass("Base", ["model", "normalised", ("compared", tuple, ()),
                                               ("outliers", tuple, ())])
    monkeypatch.setattr(pipeline, "refit_setup", refit_setup)
    monkeypatch.setattr(pipeline, "corrected", lambda bundle, name, p, m: float(p[0]))
    monkeypatch.setattr(pipeline, "fitted_value", lambda bundle, name, p, m: float(p[0]))
    monkeypatch.setattr(pipeline, "at_setup",
                        lambda base, st, m, say: Base(None, error_at[st.corrected]))
    entry = {"parameter": "ply_angle_deg", "stated": 0.0, "fitted": 4.21, "sd": 1.43,
             "error_after": {"normalised": 2.3, "per_test": {"t": 0.69}}}
    first = dataclasses.replace(stage(), entries=(entry,), setup_error="ply_angle_deg",
                                best=SetupBest("ply_angle_deg", (4.21,)),
                                stated_model=stage_model, fitted=("mu",))
    stated, say = object(), lambda line: None
    base = Base(model.with_parameters(mu=0.32), 1.39)  # μ moved with the ply applied
    again, new_base = pipeline.friction_round(first, stated, base, model, say)
    assert asked == [0.32, 0.3]  # the μ refitted with the ply, then the given one
    assert again.best.p == (4.0,) and again.entries[0]["fitted"] == 4.0
    assert again.entries[0]["fitted_at_stated_friction"] == 4.21
    assert again.entries[0]["error_after_at_stated_friction"] == 2.3
    assert new_base.normalised == 0.97
    # μ refitted to the stage's own and the given one no nearer: the set-up as it was
    error_at[4.0] = 1.5
    asked.clear()
    base = Base(stage_model, 1.39)
    assert pipeline.friction_round(first, stated, base, model, say) == (first, base)
    assert asked == [0.3]
    # μ not fitted by the baseline (stated in the case): nothing to do, no runs
    unfitted = dataclasses.replace(first, fitted=())
    asked.clear()
    assert pipeline.friction_round(unfitted, stated, base, model, say) == (unfitted, base)
    assert asked == []
