"""One parameter set for several labs, sizes and kinds: leave-one-group-out."""

import dataclasses

import numpy as np
import pytest

from fenicsx_drape.calibration import consistency, fit
from fenicsx_drape.calibration.agreement import groups
from fenicsx_drape.calibration.synthetic import bias_test, picture_frame_test, synthetic_bundle
from fenicsx_drape.model import Model

DRY = ("strain_dependent_viscosity", "decrimping", "tow_buckling")
TRUTH = {"sigma_o": 0.03, "E_p": 0.8, "s_o": 20.0, "s_inf": 2000.0, "alpha_v": 20.0,
         "eps_v_bar": 0.4}


def _bundle(offset=1.0):
    """Four labs: A and B on the HKUST frame, C and D on the UT frame, bias extension at D;
    lab C's forces multiplied by ``offset`` (a load-cell or normalisation error)."""
    tests = [picture_frame_test("A", 10.0, n_rows=30),
             picture_frame_test("B", 20.0, n_rows=30),
             picture_frame_test("C", 10.0, n_rows=30, frame_side_mm=250.0, fabric_side_mm=180.0),
             picture_frame_test("D", 20.0, n_rows=30, frame_side_mm=250.0, fabric_side_mm=180.0),
             bias_test("D-bias", 10.0, n_rows=30)]
    labs = {"A": "A", "B": "B", "C": "C", "D": "D", "D-bias": "D"}
    tests = [dataclasses.replace(t, notes={"lab": labs[t.id]}) for t in tests]
    bundle = synthetic_bundle(Model(DRY, TRUTH), tests, noise_rel=0.02, seed=4)
    made = []
    for t in bundle.tests:
        if t.id == "C":
            t = dataclasses.replace(t, columns={**t.columns, "force_N": offset * t.force_N})
        made.append(t)
    return dataclasses.replace(bundle, tests=tuple(made))


def test_groups():
    bundle = _bundle()
    assert groups(bundle.tests, "lab") == {"A": ["A"], "B": ["B"], "C": ["C"],
                                           "D": ["D", "D-bias"]}
    sizes = groups(bundle.tests, "size")
    assert sorted(map(len, sizes.values())) == [1, 2, 2]
    assert set(groups(bundle.tests, "kind")) == {"picture_frame", "bias_extension"}


def test_consistent_labs_sizes_and_kinds():
    bundle = _bundle()
    report = consistency(bundle, fit(bundle, Model(DRY), analyse=False), by=("lab", "kind"))
    assert report["verdict"] == "consistent", report["says"]
    assert report["joint"]["normalised"] < 1.5
    assert all(r["held_out"] < 2.0 for r in report["groups"])


def test_lab_offset_is_found_and_told_from_size():
    """Lab C reads 40 % high: the joint fit cannot follow every test; left out, C is
    predicted 1/1.4 low by the others, who then fit at their noise. Its size group (C and D)
    explains it too, but the smallest group that does is lab C."""
    bundle = _bundle(offset=1.4)
    result = fit(bundle, Model(DRY), analyse=False)
    assert result.normalised > 1.5
    report = consistency(bundle, result, by=("lab", "size"))
    assert report["verdict"] == "lab_offset", report["says"]
    lab_c = next(r for r in report["groups"] if r["by"] == "lab" and r["group"] == "C")
    assert lab_c["explains"] and lab_c["rest_after"] <= 1.5
    np.testing.assert_allclose(lab_c["scale"], 1.4, rtol=0.03)
    others = [r for r in report["groups"] if r["by"] == "lab" and r["group"] != "C"]
    assert not any(r["disagrees"] for r in others)


def test_missing_physics_when_no_group_explains():
    """A prepreg (rate-dependent) at three speeds fitted by a dry, rate-independent model:
    whichever speed is left out, the other two still disagree."""
    from fenicsx_drape.model import default_model

    tests = [picture_frame_test(f"pf-{v:g}", v, n_rows=30) for v in (2.0, 20.0, 200.0)]
    bundle = synthetic_bundle(default_model(), tests, noise_rel=0.01, seed=2)
    report = consistency(bundle, fit(bundle, Model(DRY), analyse=False), by=("test",))
    assert report["verdict"] == "missing_physics", report["says"]
    assert all(r["rest_after"] > 1.5 for r in report["groups"])


def test_command_line(tmp_path):
    import json

    from fenicsx_drape.cli import main
    from fenicsx_drape.measurements.bundle import load_bundle, write_bundle

    write_bundle(_bundle(offset=1.4), tmp_path / "b")
    assert load_bundle(tmp_path / "b").test("C").notes["lab"] == "C"
    (tmp_path / "MODEL.toml").write_text(f"effects = {list(DRY)!r}\n".replace("'", '"'))
    assert main(["fit", str(tmp_path / "b"), "--model", str(tmp_path / "MODEL.toml"),
                 "--out", str(tmp_path / "out"), "--consistency", "lab"]) == 0
    report = json.loads((tmp_path / "out" / "consistency.json").read_text())
    assert report["verdict"] == "lab_offset"


@pytest.mark.slow
def test_diagnosis_tells_a_lab_offset_from_missing_physics():
    """diagnose runs the check when a bundle has several labs: lab C's offset is named in
    the conclusion instead of a call for new physics (about 20 s)."""
    from fenicsx_drape.diagnosis import diagnose

    report = diagnose(_bundle(offset=1.4), Model(DRY))
    assert report["consistency"]["verdict"] == "lab_offset"
    assert report["missing_effect"] is None
    assert report["conclusion"].startswith("Not missing physics but a lab offset: lab 'C'")


def test_size_effect_as_a_trend():
    """Bias extension of three aspect ratios whose forces carry the share of the gauge region
    that Harrison's three zones shear fully, (L − 1.25 W)/(L − W) (0.75, 0.83, 0.88), at
    0.3 % noise: no single size explains the misfit (any two left differ beyond their noise),
    but the held-out scales follow the shape. The sizes' strain rates differ (one crosshead
    speed), which the verdict says."""
    sizes = (200.0, 250.0, 300.0)
    tests = [bias_test(f"un-100x{L:g}", 10.0, n_rows=30, length_mm=L, width_mm=100.0,
                       max_displacement_mm=0.3 * (L - 100.0)) for L in sizes]
    bundle = synthetic_bundle(Model(DRY, TRUTH), tests, noise_rel=0.003, seed=3)
    made = tuple(dataclasses.replace(t, columns={**t.columns, "force_N": t.force_N * (
        t.length_mm - 1.25 * t.width_mm) / (t.length_mm - t.width_mm)}) for t in bundle.tests)
    bundle = dataclasses.replace(bundle, tests=made)
    report = consistency(bundle, fit(bundle, Model(DRY), analyse=False), by=("size",))
    assert report["verdict"] == "size_effect", report["says"]
    assert not any(r["explains"] for r in report["groups"]) and "rate" in report["says"]
    scales = [r["scale"] for r in sorted(report["groups"], key=lambda r: r["size_measure"])]
    assert scales[0] < 1.0 < scales[-1]
