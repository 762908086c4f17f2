"""A set-up error can make a row wild: the set-up stage sees the stated set-up's outliers.

A punch off the die's axis by more than their clearance meets the matched die only as the
tools close: its mark is the force curve's last row (the octagon's punch 0.9 mm off: 340 N
where the stated set-up gives 39 N, 45 × the noise). Judged against the set-up as stated,
that row is an outlier and the baseline leaves it out. Where the set-up stage names nothing
without it, the stage is tried again with it (:func:`~fenicsx_drape.diagnosis.pipeline.
with_outlier_rows`), and at the fitted set-up the stated set-up's outliers are judged again
(:func:`~fenicsx_drape.diagnosis.pipeline.at_setup`): a row the fitted set-up explains
stays in, one still wild there is left out.

No forming run: a lab's force curve on the octagon's case (read, not formed), the
baseline's fits stood in for by the curves they would give.
"""

import dataclasses
import types

import numpy as np
import pytest

from fenicsx_drape.diagnosis import pipeline
from fenicsx_drape.measurements.bundle import load_bundle
from fenicsx_drape.model import default_model

CASE = """[case]
name = "octagon"
duration_s = 20.0
step_mm = 2.5

[blank]
outline = "polygon"
points_mm = [[-40.0, -95.0], [40.0, -95.0], [95.0, -40.0], [95.0, 40.0], [40.0, 95.0],
             [-40.0, 95.0], [-95.0, 40.0], [-95.0, -40.0]]
cell_mm = 20.0
symmetry = ["x"]

[holder]
tool = "holder"
holder_force_N = 100.0

[[tool]]
name = "punch"
role = "punch"
geometry = "builtin:hemisphere"
parameters = { punch_radius_mm = 40.0, fillet_radius_mm = 15.0, shoulder_radius_mm = 58.0, \
holder_opening_mm = 120.0, travel_mm = 55.0 }

[[tool]]
name = "die"
role = "die"
geometry = "builtin:hemisphere"
parameters = { punch_radius_mm = 40.0, fillet_radius_mm = 15.0, shoulder_radius_mm = 58.0, \
holder_opening_mm = 120.0, travel_mm = 55.0 }

[[tool]]
name = "holder"
role = "holder"
geometry = "builtin:hemisphere"
parameters = { punch_radius_mm = 40.0, fillet_radius_mm = 15.0, shoulder_radius_mm = 58.0, \
holder_opening_mm = 120.0, travel_mm = 55.0 }
"""

BUNDLE = """[bundle]
name = "clash"

[[test]]
id = "t1"
kind = "forming"
case = "case/case.toml"
punch_force = "t1_force.csv"
force_sd_N = 6.6
"""

ROWS = 34
SD = 6.6


def stated_curve(travel):
    """The stated set-up's punch force (N): rising, then a plateau."""
    return 40.0 * np.tanh(travel / 25.0)


@pytest.fixture
def lab(tmp_path):
    """The lab's force curve: the stated set-up's plus noise, and the clash in its last row."""
    rng = np.random.default_rng(5)
    travel = np.linspace(55.0 / ROWS, 55.0, ROWS)
    force = stated_curve(travel) + rng.normal(0.0, SD, ROWS)
    force[-1] = 340.0  # the punch meets the die off its axis as the tools close
    (tmp_path / "case").mkdir()
    (tmp_path / "case" / "case.toml").write_text(CASE.replace("\\\n", ""))
    (tmp_path / "bundle.toml").write_text(BUNDLE)
    lines = ["time_s,travel_mm,force_N"] + [f"{20.0 * s / 55.0:.6g},{s:.6g},{f:.6g}"
                                            for s, f in zip(travel, force)]
    (tmp_path / "t1_force.csv").write_text("\n".join(lines) + "\n")
    return pipeline.prepare_tests(load_bundle(tmp_path)), travel


def curves(data, travel, clash: float):
    """The comparisons of a model whose force curve ends at ``clash`` N (its fit's)."""
    (test,) = data.tests
    n = test.n_rows
    simulated = stated_curve(travel)
    if n == ROWS:
        simulated = simulated.copy()
        simulated[-1] = clash
    return data.compare({test.id: simulated[:n]})


def stated_baseline(data, travel):
    """The baseline as ``baseline_stage`` makes it: the clash row an outlier, left out."""
    from fenicsx_drape.diagnosis.comparison import error_record, find_outliers

    compared = curves(data, travel, stated_curve(travel[-1]))
    outliers = find_outliers(compared, data.tests, data.bundle.path)
    assert [o["row"] for o in outliers] == [ROWS - 1]  # one wild row, 45 × the noise
    kept = pipeline.prepare_tests(pipeline._without_outliers(data.bundle, outliers))
    return pipeline.Baseline(kept, default_model(), tuple(curves(kept, travel, 0.0)),
                             tuple(outliers), error_record(compared), {}, None)


def fitted_at(monkeypatch, travel, clash: float) -> list[int]:
    """``_baseline_fit`` stood in for: the model at the fitted set-up ends at ``clash`` N."""
    calls = []

    def fit(data, model):
        calls.append(data.tests[0].n_rows)
        return model, tuple(curves(data, travel, clash)), None

    monkeypatch.setattr(pipeline, "_baseline_fit", fit)
    return calls


def test_the_set_up_stage_is_given_the_stated_set_ups_outlier_rows(lab):
    data, travel = lab
    base = stated_baseline(data, travel)
    assert base.data.tests[0].n_rows == ROWS - 1
    given = pipeline.setup_rows(data, base)
    assert given.tests[0].n_rows == ROWS  # the clash row is the set-up stage's to judge
    # No outlier: the baseline's own bundle, nothing else.
    clean = pipeline.Baseline(data, base.model, (), (), {}, {}, None)
    assert pipeline.setup_rows(data, clean) is data.bundle


def stage_naming(bundle, best):
    """A set-up stage's result that names ``best`` (or nothing) on ``bundle``."""
    return types.SimpleNamespace(best=best, bundle=bundle, corrected=bundle)


def test_the_set_up_stage_is_tried_again_with_them_when_it_names_nothing(lab, monkeypatch):
    data, travel = lab
    base = stated_baseline(data, travel)
    calls = []

    def stand_in(bundle, model, parameters, rules, say, **keys):
        calls.append(bundle.tests[0].n_rows)
        return stage_naming(bundle, "tool_offset_mm" if bundle.tests[0].n_rows == ROWS
                            else None)

    monkeypatch.setattr(pipeline, "setup_stage", stand_in)
    first = stage_naming(base.data.bundle, None)
    again = pipeline.with_outlier_rows(first, data, base, default_model(), None, print)
    assert calls == [ROWS] and again.best == "tool_offset_mm"  # the clash row in
    # Named without them: they stay out (a missing effect's wild rows would dilute it).
    named = stage_naming(base.data.bundle, "holder_force_N")
    assert pipeline.with_outlier_rows(named, data, base, default_model(), None, print) is named
    # Nothing named with them either: the stage without them stands.
    monkeypatch.setattr(pipeline, "setup_stage", lambda bundle, *a, **k: stage_naming(bundle,
                                                                                    None))
    assert pipeline.with_outlier_rows(first, data, base, default_model(), None, print) is first
    # No outlier: nothing tried again.
    clean = pipeline.Baseline(data, base.model, (), (), {}, {}, None)
    assert pipeline.with_outlier_rows(first, data, clean, default_model(), None, print) is first
    assert calls == [ROWS]


@pytest.mark.parametrize("clash, kept", [(331.0, ROWS), (39.0, ROWS - 1)])
def test_the_stated_outliers_are_judged_again_at_the_fitted_set_up(lab, monkeypatch, clash,
                                                                    kept):
    # 331 N: the fitted offset makes the clash (the row stays); 39 N: a set-up that does not
    # explain the row, still wild there (left out again, the baseline refitted without it).
    data, travel = lab
    base = stated_baseline(data, travel)
    given = pipeline.setup_rows(data, base)
    stage = types.SimpleNamespace(best=object(), bundle=given, corrected=given)
    calls = fitted_at(monkeypatch, travel, clash)
    at = pipeline.at_setup(base, stage, default_model(), lambda line: None)
    assert at.data.tests[0].n_rows == kept
    assert [o["row"] for o in at.outliers] == ([] if kept == ROWS else [ROWS - 1])
    assert calls == ([ROWS] if kept == ROWS else [ROWS, ROWS - 1])


def test_no_set_up_error_leaves_the_baseline_as_it_was(lab, monkeypatch):
    data, travel = lab
    base = stated_baseline(data, travel)
    given = pipeline.setup_rows(data, base)
    calls = fitted_at(monkeypatch, travel, 331.0)
    none = types.SimpleNamespace(best=None, bundle=given, corrected=given)
    assert pipeline.at_setup(base, none, default_model(), lambda line: None) is base
    assert calls == []


def test_a_set_up_that_explains_the_row_is_judged_with_it(lab, monkeypatch):
    # The friction round's second set-up explains the clash (320 N for 340: 3 × the noise,
    # kept) and is a little farther from the data on its own rows than the first, which
    # leaves the row out (still wild at 39 N): on every row it is the nearer, and kept.
    from fenicsx_drape.diagnosis.results import SetupBest

    data, travel = lab
    stated = stated_baseline(data, travel)
    given = pipeline.setup_rows(data, stated)
    stage = types.SimpleNamespace(best=object(), bundle=given, corrected=given)
    fitted_at(monkeypatch, travel, 39.0)
    first = pipeline.at_setup(stated, stage, default_model(), lambda line: None)
    fitted_at(monkeypatch, travel, 320.0)
    explains = pipeline.at_setup(stated, stage, default_model(), lambda line: None)
    assert [o["row"] for o in first.outliers] == [ROWS - 1] and explains.outliers == ()
    assert explains.normalised > first.normalised  # on their own rows: the row left out wins
    assert pipeline.on_same_rows(explains, first) == (
        explains.error_with_outliers["normalised"], first.error_with_outliers["normalised"])
    assert pipeline.on_same_rows(explains, explains) == (explains.normalised,) * 2

    model = default_model()
    entry = {"parameter": "tool_offset_mm", "stated": [0.0, 0.0], "fitted": [1.06, 0.0],
             "error_after": {"normalised": 3.09, "per_test": {"t1/punch_force": 3.09}}}
    Stage = dataclasses.make_dataclass(
        "Stage", ["best", "fitted", "stated_model", "bundle", "entries", "corrected"])
    found = Stage(SetupBest("tool_offset_mm", (1.06, 0.0)), ("mu",),
                  model.with_parameters(mu=0.342), given, (entry,), given)
    monkeypatch.setattr(pipeline, "refit_setup", lambda *a: np.array([0.0, -1.0]))
    monkeypatch.setattr(pipeline, "corrected", lambda bundle, name, p, m: tuple(p))
    monkeypatch.setattr(pipeline, "fitted_value", lambda bundle, name, p, m: list(p))
    monkeypatch.setattr(pipeline, "at_setup", lambda base, st, m, say: explains)
    again, base = pipeline.friction_round(found, stated, first, model, lambda line: None)
    assert base is explains and again.entries[0]["fitted"] == [0.0, -1.0]


def test_the_stated_set_up_is_judged_on_the_fitted_set_ups_rows(lab, monkeypatch):
    # The fitted set-up explains the clash row (331 N): the stated baseline the effects are
    # refitted at is refitted with it in, as the fitted one is; where the row is still wild
    # at the fitted set-up (39 N), or no set-up was fitted, the stated baseline as it was.
    data, travel = lab
    stated = stated_baseline(data, travel)
    given = pipeline.setup_rows(data, stated)
    stage = types.SimpleNamespace(best=object(), bundle=given, corrected=given)
    say = lambda line: None  # noqa: E731
    fitted_at(monkeypatch, travel, 331.0)
    at = pipeline.at_setup(stated, stage, default_model(), say)
    calls = fitted_at(monkeypatch, travel, 40.0)  # the stated set-up: the clash missed
    on_rows = pipeline.stated_on_rows(data, stated, at, default_model(), say)
    assert calls == [ROWS] and on_rows.data.tests[0].n_rows == at.data.tests[0].n_rows == ROWS
    assert on_rows.outliers == () and on_rows.normalised > 5.0  # the clash row, 45 × noise
    assert on_rows.error_with_outliers == stated.error_with_outliers
    fitted_at(monkeypatch, travel, 39.0)
    still_wild = pipeline.at_setup(stated, stage, default_model(), say)
    calls = fitted_at(monkeypatch, travel, 40.0)
    assert pipeline.stated_on_rows(data, stated, still_wild, default_model(), say) is stated
    assert pipeline.stated_on_rows(data, stated, stated, default_model(), say) is stated
    assert calls == []
