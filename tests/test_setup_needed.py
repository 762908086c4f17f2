"""The set-up error withdrawn when the best effect at the stated set-up does as well.

``pipeline.setup_needed_stage``'s rule, with the stages it calls stood in for (their runs
are tested elsewhere): the effect refitted at the stated set-up is judged on the same
held-out rows as with the set-up fitted, and the set-up error stands only when that fit
predicts them at least ``EVIDENCE_THRESHOLD`` times better. The scenario benchmark's tool
friction on the double dome (a holder force 351 N fitted for the 200 N stated) is the case
it was made for: evidence 1.0002, withdrawn.
"""

import dataclasses

import pytest

from fenicsx_drape.diagnosis import pipeline
from fenicsx_drape.diagnosis.decision import EVIDENCE_THRESHOLD
from fenicsx_drape.diagnosis.results import Candidate, HeldOut, SetupResult


def candidate(heldout: float, significant: bool = True) -> Candidate:
    return Candidate(effect="tool_friction", effects=("tool_friction",), acts_on="contact",
                     summary="", parameters={"mu_tool": 0.3}, error_after={"normalised": 1.2},
                     heldout_normalised=heldout, evidence=1.4, significant=significant,
                     sensitivity=3.0, where_after=(), setup_refitted=None, model=None,
                     after=(), tests=(), n_parameters=1)


def stage() -> SetupResult:
    entry = {"parameter": "holder_force_N", "stated": 200.0, "fitted": 350.6, "sd": 49.9}
    return SetupResult(entries=(entry,), setup_error="holder_force_N", untestable=(),
                       stated_error=None, stated_heldout_normalised=None, scheme=None,
                       rule=None, resolution=None, model_note=None, best=None, bundle=None,
                       stated_model=None, corrected=None)


@pytest.fixture
def stand_ins(monkeypatch):
    """The effect at the stated set-up predicts its held-out rows with ``alone['heldout']``."""
    alone = {"heldout": 1.2, "significant": True}
    monkeypatch.setattr(pipeline, "heldout_stage", lambda base, say: HeldOut(()))
    monkeypatch.setattr(pipeline, "effect_stage", lambda name, model, base, held, st, res,
                        say: candidate(alone["heldout"], alone["significant"]))
    return alone


def run(best):
    stated, at_setup, held = object(), object(), HeldOut(())
    return pipeline.setup_needed_stage(stage(), best, stated, at_setup, held, None, None,
                                       lambda line: None), stated, at_setup


@pytest.mark.parametrize("ratio", [1.0, 0.9 * EVIDENCE_THRESHOLD])
def test_a_set_up_error_the_effect_stands_behind_is_withdrawn(stand_ins, ratio):
    best = candidate(1.2)
    stand_ins["heldout"] = 1.2 * ratio
    (setup, named, base, _), stated, _ = run(best)
    assert setup.setup_error is None and setup.withdrawn == "holder_force_N"
    assert setup.entries[0]["withdrawn_for"] == "tool_friction"
    assert setup.entries[0]["evidence_with_effect"] == pytest.approx(ratio)
    # The effect at the stated set-up is the best, against the stated baseline.
    assert named.heldout_normalised == pytest.approx(1.2 * ratio) and base is stated


@pytest.mark.parametrize("ratio", [EVIDENCE_THRESHOLD, 3.0])
def test_a_set_up_error_that_adds_evidence_stands(stand_ins, ratio):
    best = candidate(1.2)
    stand_ins["heldout"] = 1.2 * ratio
    (setup, named, base, _), _, at_setup = run(best)
    assert setup.setup_error == "holder_force_N" and setup.withdrawn is None
    assert named is best and base is at_setup


def test_nothing_is_withdrawn_for_an_effect_not_significant_alone(stand_ins):
    stand_ins["significant"] = False
    best = candidate(1.2)
    (setup, named, _, _), _, _ = run(best)
    assert setup.setup_error == "holder_force_N" and named is best


def test_a_set_up_error_found_with_the_effect_is_not_looked_at_again(stand_ins):
    best = candidate(1.2)
    found = dataclasses.replace(stage(), found_with_effect="tool_friction")
    out = pipeline.setup_needed_stage(found, best, object(), object(), HeldOut(()), None, None,
                                      lambda line: None)
    assert out[0] is found and out[1] is best
