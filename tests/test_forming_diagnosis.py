"""Forming tests in compare and diagnose: grid matching, noise, regions, hidden effects."""

import json

import numpy as np
import pytest

from fenicsx_drape import runs
from fenicsx_drape.diagnosis.comparison import compare_tests, normalised_error
from fenicsx_drape.diagnosis.kinds import GRID
from fenicsx_drape.diagnosis.kinds import grid as gk
from fenicsx_drape.diagnosis.synthetic import synthetic_forming_test
from fenicsx_drape.forming.running.post import FormedGrid
from fenicsx_drape.measurements.bundle import Bundle, Test

SETUP = {"punch_radius_mm": 60.0, "fillet_radius_mm": 20.0, "holder_opening_mm": 170.0,
         "sheet_mm": 240.0, "travel_mm": 80.0, "duration_s": 40.0, "holder_force_N": 133.0,
         "grid_mm": 10.0}


def smooth_sheet(cell_mm: float = 5.0) -> FormedGrid:
    """A quarter sheet formed by a smooth made-up map (a dome and an inward pull)."""
    s = np.arange(0.0, 120.0 + 1e-9, cell_mm)
    X = np.stack([*np.meshgrid(s, s, indexing="ij"), np.zeros((s.size, s.size))], axis=-1)
    r2 = X[..., 0] ** 2 + X[..., 1] ** 2
    x = X.copy()
    x[..., :2] *= (1.0 - 0.15 * np.exp(-r2 / 80.0**2))[..., None]
    x[..., 2] = 70.0 * np.exp(-r2 / 60.0**2)
    return FormedGrid(X, x, True)


def grid_test(sheet: FormedGrid, grid_mm: float, sd_mm: float = 0.0, seed: int = 0,
              full: bool = False) -> Test:
    table = (sheet.full() if full else sheet).drawn_grid(grid_mm)
    columns = {k: np.asarray(v, float) for k, v in table.items()}
    rng = np.random.default_rng(seed)
    for c in ("x_mm", "y_mm", "z_mm"):
        columns[c] = columns[c] + rng.normal(0.0, sd_mm, columns[c].size)
    if sd_mm:
        columns["position_sd_mm"] = np.full(columns["i"].size, sd_mm)
    return Test(id="dome", kind="forming", file="dome.csv", columns=columns,
                geometry="hemisphere", forming=dict(SETUP, grid_mm=grid_mm))


def test_coarser_measured_grid_matches_a_finer_mesh_by_interpolation():
    fine = smooth_sheet(5.0)
    test = grid_test(fine, 20.0)  # the drawn grid is 4 times coarser than the mesh
    simulated = fine.sample(gk.reference_points(test)).ravel()
    np.testing.assert_allclose(simulated, GRID.measured(test), atol=1e-12)
    # A 10 mm mesh of the same map, bilinear between its nodes, is within the bilinear
    # interpolation error h²/8 (|f_xx| + |f_yy|) of the map (|f''| <= 2 · 70 / 60² per mm²).
    coarse = smooth_sheet(10.0)
    error = coarse.sample(gk.reference_points(test)).ravel() - simulated
    assert np.abs(error).max() < 1e-12  # the 20 mm grid's nodes are 10 mm mesh nodes
    off = grid_test(fine, 15.0)  # 15 mm points fall between the 10 mm nodes
    error = coarse.sample(gk.reference_points(off)) - fine.sample(gk.reference_points(off))
    assert 1e-3 < np.abs(error).max() < 10.0**2 / 8 * 2 * (2 * 70 / 60.0**2)


def test_full_grid_is_matched_by_mirroring_the_quarter():
    sheet = smooth_sheet(10.0)
    full = grid_test(sheet, 10.0, full=True)
    assert not gk.is_quarter(full) and gk.is_quarter(grid_test(sheet, 10.0))
    values = gk.sheet_for(full, sheet).sample(gk.reference_points(full)).ravel()
    np.testing.assert_allclose(values, GRID.measured(full), atol=1e-12)
    # 4 quadrants sharing the axes: (2n - 1)² nodes of the n × n quarter.
    assert full.n_rows == (2 * 13 - 1) ** 2


def test_noise_from_position_sd_and_model_free_estimate_recovers_it():
    sheet = smooth_sheet(5.0)
    with_sd = grid_test(sheet, 5.0, sd_mm=0.3, seed=3)
    assert gk.noise(with_sd) == (pytest.approx(0.3), "position_sd_mm")
    columns = {k: v for k, v in with_sd.columns.items() if k != "position_sd_mm"}
    bare = Test(id="dome", kind="forming", file="dome.csv", columns=columns,
                geometry="hemisphere", forming=with_sd.forming)
    level, source = gk.noise(bare)
    assert source == "fourth_differences"
    assert level == pytest.approx(0.3, rel=0.15)  # 625 nodes: the median's scatter is ~5 %


def test_regions_partition_the_part_and_shares_sum_to_the_error():
    sheet = smooth_sheet(5.0)
    test = grid_test(sheet, 10.0, sd_mm=0.3, seed=1)
    regions = gk.part_regions(test)
    assert [r.says for r in regions] == list(gk.REGION_NAMES)
    masks = np.array([r.rows for r in regions])
    np.testing.assert_array_equal(masks.sum(axis=0), 1)  # each value in exactly one region
    # An error placed only on the apex nodes is all in the apex region.
    truth = GRID.measured(test)
    shifted = truth.copy()
    shifted[regions[0].rows] += 2.0
    (c,) = compare_tests([test], {"dome": shifted})
    from fenicsx_drape.diagnosis.comparison import locate

    entries = {e["says"]: e["share_of_error"] for e in locate([c])}
    assert entries["apex"] == pytest.approx(1.0, abs=0.01)
    assert c.normalised == pytest.approx(np.sqrt(np.mean((truth - shifted) ** 2)) / 0.3)


def test_paper_measures_mean_distance_and_percent():
    sheet = smooth_sheet(10.0)
    test = grid_test(sheet, 10.0)
    exact = GRID.measured(test)
    moved = exact + np.tile([0.0, 0.0, 1.5], test.n_rows)  # every node 1.5 mm off
    m = gk.metrics(test, moved)
    assert m["mean_distance_mm"] == pytest.approx(1.5)
    P = gk.reference_points(test)
    d = np.linalg.norm(gk.measured_positions(test) - np.column_stack([P, 0 * P[:, 0]]), axis=1)
    assert m["percent_of_displacement"] == pytest.approx(100 * 1.5 / d.mean())


# --------------------------------------------------------------------------------------------
# Diagnosis on simulated forming bundles (coarse 20 mm mesh, both cores)

@pytest.fixture(scope="module")
def dolfinx():
    return pytest.importorskip("dolfinx")  # the forming runs need DOLFINx


# Tool friction is told from the holder's friction by the draw-in of the free sheet against the
# flange's; it is hidden under a holder force per node of the whole sheet's 133 N (the quarter
# carries 133/4 N under the default "model" share), where the holder does not drown it.
LIGHT_HOLDER_N = 133.0 / 4


def _diagnose(truth, baseline, candidates, seed, holder_force_N=133.0):
    """Data formed and diagnosed on the same coarse 20 mm mesh (4× cheaper than 10 mm)."""
    from fenicsx_drape.diagnosis import diagnose

    with runs.resolution(runs.SCREEN_CELL_MM):
        test = synthetic_forming_test(truth, seed=seed, sd_mm=0.3,
                                         cell_mm=runs.SCREEN_CELL_MM,
                                         holder_force_N=holder_force_N)
        return diagnose(Bundle(name="hidden", tests=(test,)), baseline, candidates=candidates)


@pytest.mark.slow
@pytest.mark.bench  # make test checks the same on the demo's bundle (test_demos_diagnosis.py)
@pytest.mark.skip_in_parallel
def test_diagnose_names_hidden_tow_buckling_in_a_forming_bundle(dolfinx):
    """Hidden tow buckling on the hemisphere's grid at 20 mm, 0.3 mm noise. ``make test`` makes
    these checks on the forming diagnosis demo's report (the same part, cells and noise, one
    more candidate: ``test_demos_diagnosis.py``)."""
    from fenicsx_drape.model import default_model

    report = _diagnose(default_model(), default_model().without_effects("tow_buckling"),
                       ["tow_buckling", "tool_friction"], seed=11)
    assert report["missing_effect"] == "tow_buckling"
    assert report["baseline"]["error"]["normalised"] > 3.0
    best = report["candidates"][0]
    assert best["error_after"]["normalised"] <= 1.5
    assert report["metrics"]["tow_buckling"]["hemisphere"]["mean_distance_mm"] < \
        report["metrics"]["baseline"]["hemisphere"]["mean_distance_mm"]
    assert report["where"][0]["variable"] == "r0_mm"
    json.dumps(report)  # the report is JSON


@pytest.mark.slow
@pytest.mark.bench  # make bench: minutes of forming runs
@pytest.mark.skip_in_parallel
def test_diagnose_names_hidden_tool_friction_in_a_forming_bundle(dolfinx):
    """Punch/die friction μ_tool = 0.8 hidden; the baseline refits the holder's μ.

    A larger holder μ mimics most of the tool friction (both raise the drawing tension), so
    the diagnosis must find what is left: the draw-in of the free sheet between die and
    holder against that of the flange. At μ_tool = 0.3 a refitted holder μ absorbs it to
    below the noise (docs/diagnosis.md, forming tests).
    """
    from fenicsx_drape.model import default_model

    truth = default_model().with_effects("tool_friction").with_parameters(mu_tool=0.8)
    report = _diagnose(truth, default_model(), ["tool_friction", "shear_tension_coupling"],
                       seed=13, holder_force_N=LIGHT_HOLDER_N)
    assert report["missing_effect"] == "tool_friction"
    assert report["baseline"]["error"]["normalised"] > 1.25
    best = report["candidates"][0]
    assert best["evidence"] >= 1.2
    assert best["error_after"]["normalised"] <= 1.5
    metrics = report["metrics"]
    assert metrics["tool_friction"]["hemisphere"]["mean_distance_mm"] < \
        metrics["baseline"]["hemisphere"]["mean_distance_mm"]


@pytest.mark.slow
@pytest.mark.bench  # make bench: minutes of forming runs
@pytest.mark.skip_in_parallel
def test_mixed_bundle_reports_coupons_and_forming_and_names_the_forming_effect(dolfinx):
    """Coupons and a formed part in one bundle; the hidden effect acts on the part only."""
    from fenicsx_drape.calibration.synthetic import standard_tests, synthetic_bundle
    from fenicsx_drape.diagnosis import diagnose
    from fenicsx_drape.model import default_model

    truth = default_model().with_effects("tool_friction").with_parameters(mu_tool=0.8)
    coupons = synthetic_bundle(truth, standard_tests(bias_speeds_mm_per_min=(10.0, 160.0)),
                               noise_rel=0.02, seed=5)
    with runs.resolution(runs.SCREEN_CELL_MM):
        formed = synthetic_forming_test(truth, seed=14, sd_mm=0.3, cell_mm=runs.SCREEN_CELL_MM,
                                           holder_force_N=LIGHT_HOLDER_N)
        bundle = Bundle(name="mixed", tests=(*coupons.tests, formed))
        # One candidate (and so no set-up stage), for time: the default path on forming
        # bundles is run by test_lab_user_path.py (the README's command) and the set-up tests.
        report = diagnose(bundle, default_model(), candidates=["tool_friction"])
    ids = {t.id for t in bundle.tests}
    assert set(report["baseline"]["error"]["per_test"]) == ids  # the report covers all tests
    assert "bias_extension" in report["heldout_scheme"] and "forming" in report["heldout_scheme"]
    (best,) = report["candidates"]
    after = best["error_after"]["per_test"]
    # The coupons are unchanged by a forming effect; the part's error falls.
    for t in coupons.tests:
        assert after[t.id] == pytest.approx(report["baseline"]["error"]["per_test"][t.id],
                                            rel=0.02)
    assert after["hemisphere"] < 0.8 * report["baseline"]["error"]["per_test"]["hemisphere"]
    # Judged on the forming test it acts on, not diluted by the coupons' held-out error.
    assert report["missing_effect"] == "tool_friction"
    pooled = report["baseline"]["heldout_normalised"] / best["heldout_normalised"]
    assert best["evidence"] >= 1.2 and best["evidence"] > pooled


@pytest.mark.slow
@pytest.mark.bench  # make bench: minutes of forming runs
@pytest.mark.skip_in_parallel
def test_null_forming_bundle_gives_null(dolfinx):
    from fenicsx_drape.model import default_model

    report = _diagnose(default_model(), default_model(), ["tool_friction"], seed=12)
    assert report["missing_effect"] is None
    assert report["baseline"]["error"]["normalised"] < 1.5
    assert normalised_error(report.comparisons["baseline"]) == pytest.approx(
        report["baseline"]["error"]["normalised"])
