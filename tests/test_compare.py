"""compare: noise floor, errors, regions and their shares of the error."""

import dataclasses
import json

import numpy as np
import pytest

from fenicsx_drape.calibration.synthetic import bias_test, synthetic_bundle, tensile_test
from fenicsx_drape.cli import main
from fenicsx_drape.diagnosis import evaluate
from fenicsx_drape.diagnosis.comparison import Comparison, locate, normalised_error, trends, where
from fenicsx_drape.diagnosis.kinds import Region
from fenicsx_drape.diagnosis.kinds.coupon import _knees, _loading_phases
from fenicsx_drape.measurements.noise import noise_from_sd, noise_from_second_differences
from fenicsx_drape.model import Model, default_parameters, load_model


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_second_difference_noise_recovers_the_noise(seed):
    rng = np.random.default_rng(seed)
    # Non-uniform rows over a curve with a plateau and a steep rise (a bias-extension shape).
    t = np.sort(rng.uniform(0.0, 100.0, 400))
    sd = 0.05 * (1 + seed)
    f = 3 * (1 - np.exp(-t / 5)) + 0.01 * t + 5 * np.exp((t - 100) / 12)
    estimate = noise_from_second_differences(t, f + rng.normal(0, sd, t.size))
    # The estimator's own scatter is about 5 % at 400 rows: allow three of its deviations.
    assert estimate == pytest.approx(sd, rel=0.15)


def test_second_difference_noise_ignores_kinks_and_needs_rows():
    rng = np.random.default_rng(5)
    t = np.linspace(0, 60, 300)
    # Loading, a hold and unloading: the kinks must not inflate the estimate.
    f = np.interp(t, [0, 20, 40, 60], [0, 50, 30, 0]) + rng.normal(0, 0.2, t.size)
    assert noise_from_second_differences(t, f) == pytest.approx(0.2, rel=0.15)
    with pytest.raises(ValueError, match="at least 5 rows"):
        noise_from_second_differences(t[:4], f[:4])
    with pytest.raises(ValueError, match="increasing"):
        noise_from_second_differences(t[::-1], f)


def test_noise_from_sd_is_the_rms():
    assert noise_from_sd(np.array([3.0, 4.0])) == pytest.approx(np.sqrt(12.5))


def test_knees_of_a_three_segment_curve():
    rng = np.random.default_rng(1)
    x = np.linspace(0, 0.45, 800)
    y = np.interp(x, [0, 0.08, 0.3, 0.45], [0, 3.0, 4.0, 14.0]) + rng.normal(0, 0.02, x.size)
    # Tangent intersections of straight segments (longer than the 1/8 windows) are corners.
    k1, k2 = _knees(x, y, "stiff-soft-stiff")
    assert k1 == pytest.approx(0.08, abs=0.005)
    assert k2 == pytest.approx(0.30, abs=0.005)
    (k,) = _knees(x, np.interp(x, [0, 0.1, 0.45], [0, 1.0, 20.0]), "soft-stiff")
    assert k == pytest.approx(0.1, abs=1e-9)
    # A straight line has no knee: its regions merge.
    assert np.isnan(_knees(x, 2 * x, "soft-stiff")[0])


def test_loading_phases():
    t = np.arange(7.0)
    d = np.array([0, 1, 2, 2, 2, 1, 0.0])
    assert _loading_phases(t, d).tolist() == [1, 1, 1, 0, 0, -1, -1]


def _comparison(id_, residual, noise, regions=(), conditions=None, kind="bias_extension"):
    measured = np.linspace(1, 2, residual.size)
    return Comparison(id_, kind, "N", measured, measured - residual, noise, "force_sd_N",
                      tuple(regions), conditions or {})


def test_normalised_error_and_shares_follow_the_contract():
    rng = np.random.default_rng(0)
    r1, r2 = rng.normal(0, 1, 100), rng.normal(0, 3, 50)
    half = np.arange(100) < 30
    c1 = _comparison("a", r1, 0.5, [Region("diagonal_strain", (0, 0.1), "low", half),
                                    Region("diagonal_strain", (0.1, 0.4), "high", ~half)],
                     {"speed_mm_per_min": 10.0})
    c2 = _comparison("b", r2, 1.0, [], {"speed_mm_per_min": 40.0})
    expected = np.sqrt(0.5 * ((np.sqrt(np.mean(r1**2)) / 0.5) ** 2
                              + (np.sqrt(np.mean(r2**2)) / 1.0) ** 2))
    assert normalised_error([c1, c2]) == pytest.approx(expected)
    entries = locate([c1, c2])
    by = {(e["test"], e["says"]): e["share_of_error"] for e in entries}
    # The regions of a test share its part of the error; condition groups share the whole.
    share_a = (np.mean(r1**2) / 0.25) / (2 * expected**2)
    assert by["a", "low"] + by["a", "high"] == pytest.approx(share_a)
    assert by["a", "low"] == pytest.approx(np.sum(r1[half] ** 2) / 0.25 / 100 / 2
                                           / expected**2)
    speeds = [e for e in entries if e["variable"] == "speed_mm_per_min"]
    assert sum(e["share_of_error"] for e in speeds) == pytest.approx(1.0)
    assert [e["share_of_error"] for e in entries] == sorted(
        (e["share_of_error"] for e in entries), reverse=True)
    assert all(e["share_of_error"] >= 0.05 for e in where([c1, c2]))


def test_regions_of_a_kind_are_summed_over_its_tests():
    rng = np.random.default_rng(3)
    low = np.arange(60) < 20
    comps = [_comparison(i, rng.normal(0, 1, 60), 1.0,
                         [Region("diagonal_strain", (0.0, 0.1), "plateau", low),
                          Region("diagonal_strain", (0.1, 0.4 + k), "lock-up", ~low)])
             for k, i in enumerate(("a", "b"))]
    entries = locate(comps)
    (summed,) = [e for e in entries if e["tests"] == ["a", "b"] and e["region"] == "lock-up"]
    parts = [e["share_of_error"] for e in entries
             if len(e["tests"]) == 1 and e["region"] == "lock-up"]
    assert summed["share_of_error"] == pytest.approx(sum(parts))
    assert summed["range"] == [0.1, 1.4] and summed["share_of_rows"] == pytest.approx(2 / 3)
    assert summed["says"] == "lock-up, all bias extension tests"


def test_trend_says_the_error_grows_with_speed():
    rng = np.random.default_rng(2)
    comps = [_comparison(f"bias-{v}", rng.normal(0, s, 80), 1.0, [],
                         {"speed_mm_per_min": float(v)})
             for v, s in ((10, 1.0), (40, 2.0), (160, 4.0))]
    (trend,) = trends(comps)
    assert trend["spearman"] == pytest.approx(1.0)
    assert "grows with crosshead speed" in trend["says"]
    flat = [_comparison(f"bias-{v}", rng.normal(0, 1.0, 80), 1.0, [],
                        {"speed_mm_per_min": float(v)}) for v in (10, 40, 160)]
    assert trends(flat)[0]["says"] == ""


@pytest.mark.slow
def test_compare_command_writes_every_output(tmp_path, capsys):
    model = Model(("rate_dependence", "strain_dependent_viscosity", "decrimping",
                   "tow_buckling"), default_parameters())
    tests = [tensile_test("tensile", n_rows=40), bias_test("bias-10", 10.0, n_rows=50),
             bias_test("bias-160", 160.0, n_rows=50)]
    synthetic_bundle(model, tests, noise_rel=0.02, seed=3, out_dir=tmp_path / "bundle")
    (tmp_path / "model.toml").write_text(model.to_toml())
    out = tmp_path / "out"
    assert main(["compare", str(tmp_path / "bundle"), "--model", str(tmp_path / "model.toml"),
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "normalised error" in printed and "where the error sits" in printed
    record = json.loads((out / "compare.json").read_text())
    assert set(record["per_test"]) == {"tensile", "bias-10", "bias-160"}
    for entry in record["per_test"].values():
        assert entry["noise_source"] == "force_sd_N" and entry["unit"] == "N"
        assert entry["normalised"] == pytest.approx(entry["rmse"] / entry["noise"])
    # The model made the data: after the fit it sits at the noise floor.
    assert record["error"]["normalised"] < 1.3
    assert record["model"]["effects"] == list(model.effects)
    # The strain ranges of the tests partition the error.
    assert sum(e["share_of_error"] for e in record["regions"] if len(e["tests"]) == 1
               and e["variable"] in ("tow_strain", "diagonal_strain")) == pytest.approx(1.0)
    for name in ("residual_tensile.png", "residual_bias-10.png", "where.png"):
        assert (out / name).stat().st_size > 1000
    assert load_model(out / "model.toml").effects == model.effects
    assert json.loads((out / "provenance.json").read_text())["effects"] == list(model.effects)
    (entry,) = [json.loads(line) for line in (out / "ledger.jsonl").read_text().splitlines()]
    assert entry["normalised"] == pytest.approx(record["error"]["normalised"])


def test_compare_without_sd_uses_the_model_free_noise(tmp_path):
    model = Model(("decrimping",), default_parameters())
    bundle = synthetic_bundle(model, [tensile_test("tensile", n_rows=120)], noise_sd_N=5.0,
                              seed=4)
    (test,) = bundle.tests
    columns = {k: v for k, v in test.columns.items() if k != "force_sd_N"}
    bundle = dataclasses.replace(bundle, tests=(dataclasses.replace(test, columns=columns),))
    result = evaluate(bundle, model)
    (c,) = result.tests
    assert c.noise_source == "second_differences"
    assert c.noise == pytest.approx(5.0, rel=0.2)
    assert result.to_dict()["noise_floor"]["source"] == "second_differences"


def test_the_summary_leaves_out_a_percentage_of_nothing():
    """An outline's measured values are distances to the edge, all 0: its % is of nothing."""
    from fenicsx_drape.commands.compare import summary
    from fenicsx_drape.diagnosis.comparison import CompareResult

    rng = np.random.default_rng(4)
    force = _comparison("bias", rng.normal(0, 1, 40), 0.5, [], {})
    edge = dataclasses.replace(_comparison("dd/outline", rng.normal(0, 1, 12), 0.3, [], {}),
                               unit="mm", measured=np.zeros(12))
    result = CompareResult("b", Model(("rate_dependence",), default_parameters()), (force, edge),
                           metrics={"dd/outline": {"unmatched": 0}})
    text = summary(result)
    assert "nan" not in text.lower()
    rows = {line.split()[0]: line for line in text.splitlines()[2:4]}
    assert f"{force.percent:.1f}" in rows["bias"]
    assert len(rows["dd/outline"].split()) == len(rows["bias"].split()) - 1  # the % left out
    assert "left blank where the measured values are all 0" in text
    # Without a blank, no note.
    assert "left blank" not in summary(dataclasses.replace(result, tests=(force,), metrics={}))
