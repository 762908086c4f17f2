"""diagnose: folds, ranking, candidates, the null case, order independence, the command."""

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.calibration.synthetic import bias_test, synthetic_bundle, tensile_test
from fenicsx_drape.cli import main
from fenicsx_drape.diagnosis import diagnose
from fenicsx_drape.diagnosis.decision import EVIDENCE_THRESHOLD, rank
from fenicsx_drape.diagnosis.folds import folds_of, without_rows
from fenicsx_drape.diagnosis.refits import candidate_names
from fenicsx_drape.diagnosis.report import CONTRACT
from fenicsx_drape.effects import EFFECTS
from fenicsx_drape.model import Model, default_parameters

COUPON = ("rate_dependence", "strain_dependent_viscosity", "decrimping", "tow_buckling")
PLUGIN = Path(__file__).parents[1] / "demos" / "user_laws" / "power_law_viscosity.py"

# The contract's fields (docs/measurements.md, "The diagnosis contract").
CONTRACT_FIELDS = {"contract", "baseline", "noise_floor", "where", "candidates", "untestable",
                   "missing_effect"}
CANDIDATE_FIELDS = {"effect", "error_after", "heldout_normalised", "evidence", "significant",
                    "explanation"}
WHERE_FIELDS = {"test", "variable", "range", "share_of_error", "says"}
ERROR_FIELDS = {"rmse_N", "normalised", "per_test"}


def small_tests(speeds=(10.0, 40.0, 160.0)):
    tests = [tensile_test("tensile", n_rows=40)]
    return tests + [bias_test(f"bias-{v:g}", v, n_rows=50) for v in speeds]


def test_folds_predict_every_row_once():
    bundle = synthetic_bundle(Model(COUPON), small_tests(), noise_rel=0.02, seed=0)
    folds, scheme = folds_of(bundle)
    assert "leave-one-test-out over the 3 bias_extension tests" in scheme
    assert "tensile" in scheme and "interleaved" in scheme
    for test in bundle.tests:
        masks = [f.rows for f in folds if f.predicts == test.id]
        # Each row is predicted by exactly one fold ...
        assert np.array_equal(np.sum(masks, axis=0), np.ones(test.n_rows))
        for fold in (f for f in folds if f.predicts == test.id):
            if test.kind == "bias_extension":  # ... that did not fit this test at all,
                assert test.id not in fold.fitted
                assert all(bundle.test(i).kind == test.kind for i in fold.fitted)
            else:  # or gave its rows no weight.
                sd = fold.bundle.test(test.id).force_sd_N
                assert np.all(np.isinf(sd[fold.rows])) and np.all(np.isfinite(sd[~fold.rows]))


def test_held_out_rows_get_infinite_sd_and_others_keep_their_weight():
    rng = np.random.default_rng(0)
    test = bias_test("b", 10.0, n_rows=300)
    force = np.linspace(0, 10, 300) + rng.normal(0, 0.25, 300)
    test = dataclasses.replace(test, columns={**test.columns, "force_N": force})
    rows = np.arange(300) % 3 == 1
    held = without_rows(test, rows)
    assert np.all(held.force_sd_N[rows] == np.inf)
    # Without force_sd_N, the other rows get the model-free noise estimate.
    assert np.all(held.force_sd_N[~rows] == held.force_sd_N[0])
    assert held.force_sd_N[0] == pytest.approx(0.25, rel=0.15)
    assert np.array_equal(held.force_N, test.force_N)


def test_ranking_prefers_the_parsimonious_near_best():
    from fenicsx_drape.diagnosis.results import Candidate

    def cand(name, heldout, n):
        return Candidate(effect=name, effects=(name,), acts_on="shear", summary="", parameters={},
                         error_after={}, heldout_normalised=heldout, evidence=1.0,
                         significant=False, sensitivity=1.0, where_after=(),
                         setup_refitted=None, model=None, after=(), tests=(), n_parameters=n)

    ranked = rank([cand("a", 1.00, 4), cand("b", 1.04, 1), cand("c", 0.5 + 2, 0)])
    assert [c.effect for c in ranked] == ["b", "a", "c"]  # b within 5 % of a, fewer params
    ranked = rank([cand("a", 1.00, 4), cand("b", 1.10, 1)])
    assert [c.effect for c in ranked] == ["a", "b"]
    assert rank([]) == []


def test_candidates_are_the_catalogue_and_the_models_own_plugins():
    model = Model(COUPON)
    assert candidate_names(model) == [e for e in EFFECTS if e not in COUPON]
    with_plugin = Model(COUPON, plugins=(PLUGIN,))
    assert candidate_names(with_plugin)[-1] == "power_law_viscosity"
    # Registered (by the plugin above) but not one of this model's plugins: not a candidate.
    assert "power_law_viscosity" not in candidate_names(model)


@pytest.fixture(scope="module")
def null_case():
    """A bundle made by the baseline itself (without tow_buckling), and its diagnosis."""
    parameters = default_parameters() | {"eta_o": 1.9, "sigma_o": 0.02, "E_o": 4000.0}
    model = Model(COUPON[:3], parameters)
    bundle = synthetic_bundle(model, small_tests(), noise_rel=0.02, seed=11)
    return bundle, model, diagnose(bundle, model)


@pytest.mark.slow
def test_null_bundle_gives_no_missing_effect(null_case):
    _, _, report = null_case
    assert set(report) >= CONTRACT_FIELDS
    assert report["contract"] == CONTRACT
    assert set(report["baseline"]) >= {"effects", "error"}
    assert set(report["baseline"]["error"]) >= ERROR_FIELDS
    assert set(report["noise_floor"]) >= {"rmse_N", "per_test", "source"}
    assert all(set(u) >= {"effect", "reason"} for u in report["untestable"])
    assert report["missing_effect"] is None
    assert report["baseline"]["error"]["normalised"] < 1.2
    assert not any(c["significant"] for c in report["candidates"])
    # Forming-only effects, and tow buckling where no tow is compressed, are reported as
    # untestable, not ranked.
    untestable = {u["effect"] for u in report["untestable"]}
    assert {"holder_friction", "tool_friction", "tow_buckling"} <= untestable
    assert untestable.isdisjoint(c["effect"] for c in report["candidates"])
    for c in report["candidates"]:
        assert set(c) >= CANDIDATE_FIELDS and set(c["error_after"]) >= ERROR_FIELDS
        assert c["evidence"] == pytest.approx(report["baseline"]["heldout_normalised"]
                                              / c["heldout_normalised"])
        assert c["significant"] == (c["evidence"] >= EVIDENCE_THRESHOLD)
    assert all(set(e) >= WHERE_FIELDS for e in report["where"])
    assert set(report["noise_floor"]["per_test"]) == {"tensile", "bias-10", "bias-40",
                                                      "bias-160"}
    assert report["noise_floor"]["source"] == "force_sd_N"
    json.dumps(report)  # JSON-ready as it is


@pytest.mark.slow
def test_diagnosis_does_not_depend_on_the_order_of_the_tests(null_case):
    bundle, model, report = null_case
    reverse = diagnose(dataclasses.replace(bundle, tests=bundle.tests[::-1]), model)
    strip = [{k: v for k, v in r.items() if k not in ("seconds", "cost")}
             for r in (report, reverse)]
    assert json.dumps(strip[0]) == json.dumps(strip[1])


def test_diagnose_command_bad_input_exits_2(tmp_path, capsys):
    assert main(["diagnose", str(tmp_path / "nothing"), "--json", str(tmp_path / "r.json")]) == 2
    assert "bundle.toml" in capsys.readouterr().err
    synthetic_bundle(Model(COUPON), small_tests((10.0,)), noise_rel=0.02, seed=0,
                     out_dir=tmp_path / "b")
    (tmp_path / "m.toml").write_text('effects = ["rate_dependence", "no_such_effect"]\n')
    assert main(["diagnose", str(tmp_path / "b"), "--model", str(tmp_path / "m.toml"),
                 "--json", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err
    assert "m.toml:1" in err and "no_such_effect" in err
    assert not (tmp_path / "r.json").exists()


@pytest.mark.slow
def test_diagnose_command_writes_the_report(tmp_path, capsys):
    model = Model((*COUPON, "holder_friction"), default_parameters())
    tests = [tensile_test("tensile", n_rows=30), bias_test("bias-40", 40.0, n_rows=40)]
    synthetic_bundle(model, tests, noise_rel=0.02, seed=2, out_dir=tmp_path / "b")
    (tmp_path / "m.toml").write_text(model.to_toml())
    report_path, out = tmp_path / "REPORT.json", tmp_path / "out"
    assert main(["diagnose", str(tmp_path / "b"), "--model", str(tmp_path / "m.toml"),
                 "--json", str(report_path), "--out", str(out), "--quiet"]) == 0
    report = json.loads(report_path.read_text())
    assert set(report) >= CONTRACT_FIELDS and report["missing_effect"] is None
    assert "leave-every-third-row-out" in report["heldout_scheme"]
    # One bias speed and one temperature: neither rate nor temperature can be judged.
    assert "temperature_dependence" in {u["effect"] for u in report["untestable"]}
    assert (out / "candidates.png").is_file() and (out / "where.png").is_file()
    assert (out / "residual_bias-40.png").is_file() and (out / "provenance.json").is_file()
    # How forming runs were made: none here (coupons only), in the default cache folder (the
    # session's, tests/conftest.py).
    made = json.loads((out / "provenance.json").read_text())["forming_runs"]
    assert made["runs"]["asked"] == made["runs"]["formed"] == 0
    assert made["cache"] == os.environ["DRAPE_CACHE"]
    assert made["executor"] in ("processes", "this process") and made["workers"] >= 1
    assert "missing_effect: None" in capsys.readouterr().out
