"""Lab measurements against a forming run (spec version 3): the double dome on 20 mm cells.

The "lab" reads a part formed by the model itself (:func:`~fenicsx_drape.diagnosis.
lab_synthetic.lab_tables`: shear lines, a scan with holes, an outline and the punch's force
curve, with lab-like noise), so the model is at the noise floor; then the bundle is made odd
the ways labs make it: one wild row, the scan in another frame, a third of the part scanned,
an outline only, shear magnitudes only. One forming run (about 6 s) serves every test here.
"""

from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.diagnosis import evaluate, write_compare
from fenicsx_drape.diagnosis.comparison import OUTLIER_SD
from fenicsx_drape.diagnosis.lab_synthetic import lab_tables, write_lab_bundle
from fenicsx_drape.forming.case.format import case_for_test
from fenicsx_drape.measurements.bundle import load_bundle
from fenicsx_drape.measurements.lab import rotation
from fenicsx_drape.trust import trusting

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow  # one forming run (20 s with JIT) serves the module


@pytest.fixture(autouse=True, scope="module")
def _trust_our_own_case():
    """The bundles here name the repository's double dome, whose tools are Python geometry."""
    with trusting():
        yield


@pytest.fixture(scope="module")
def part():
    """The double dome (quarter model, 20 mm cells) formed by the paper's model."""
    pytest.importorskip("dolfinx")
    from fenicsx_drape import runs
    from fenicsx_drape.forming.case.format import load_case, with_overrides
    from fenicsx_drape.model import default_model

    case = with_overrides(load_case(ROOT / "meshes/double_dome/case.toml"), cell_mm=20.0)
    model = default_model()
    (grid,) = runs.form_many([(case, model)])
    return case, model, grid, runs.tool_forces(case, model)


def bundle_of(tmp_path, part, measurements=None, keys=(), frame=None, **options):
    case, _, grid, curves = part
    tables = lab_tables(grid, curves, seed=7, holes=[(30.0, 20.0, 15.0)], **options)
    folder = write_lab_bundle(tmp_path / "bundle", case, tables, measurements=measurements,
                              keys=dict(keys), frame=frame)
    return load_bundle(folder, read_case=case_for_test), tables


def test_the_model_reports_its_tools_forces_for_the_whole_part(part):
    _, _, _, curves = part
    assert set(curves) >= {"time_s", "travel_mm", "punch", "die", "holder"}
    assert curves["travel_mm"][-1] == pytest.approx(40.0)
    # The punch pushes the blank up into the die: it drives, the die holds back.
    assert curves["punch"][-1] > 0.0 > curves["die"][-1]
    assert np.all(np.diff(curves["travel_mm"]) > 0)


def test_a_null_lab_bundle_is_at_the_noise_floor(tmp_path, part):
    bundle, _ = bundle_of(tmp_path, part)
    result = evaluate(bundle, part[1])
    normalised = {c.id: c.normalised for c in result.tests}
    assert set(normalised) == {"part/shear_points", "part/surface", "part/outline",
                               "part/punch_force"}
    assert all(0.6 < v < 1.5 for v in normalised.values()), normalised
    assert result.outliers == ()
    units = {c.id.split("/")[1]: c.unit for c in result.tests}
    assert units == {"shear_points": "deg", "surface": "mm", "outline": "mm",
                     "punch_force": "N"}
    m = result.metrics["part/surface"]
    assert m["unmatched"] == 0 and 0.9 < m["coverage"] <= 1.0  # the holes are small
    # where names positions along the measuring lines and regions of the part.
    says = {e["says"] for e in result.to_dict()["regions"]}
    assert any(s.startswith("line A, ") for s in says) and "end of the travel" in says
    path = write_compare(result, bundle, tmp_path / "compare")
    assert {p.name for p in path.parent.glob("residual_*.png")} == {
        "residual_part_shear_points.png", "residual_part_surface.png",
        "residual_part_outline.png", "residual_part_punch_force.png"}


def test_one_wild_row_is_listed_with_file_and_line_and_the_error_given_without_it(tmp_path,
                                                                                  part):
    bundle, _ = bundle_of(tmp_path, part, measurements=["shear_points"])
    path = bundle.path / "shear.csv"
    lines = path.read_text().splitlines()
    cells = lines[12].split(",")
    cells[3] = str(float(cells[3]) + 40.0)  # a misread angle, 40 noise sd off
    lines[12] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    bundle = load_bundle(bundle.path, read_case=case_for_test)
    record = evaluate(bundle, part[1]).to_dict()
    (wild,) = record["outliers"]
    assert wild["test"] == "part" and wild["measurement"] == "shear_points"
    assert wild["file"] == "shear.csv" and wild["line"] == 13
    assert wild["residual"] > OUTLIER_SD
    assert record["error"]["normalised"] > 3.0
    assert record["error_without_outliers"]["normalised"] < 1.5


def test_a_scan_in_another_frame_is_registered_with_its_uncertainty(tmp_path, part):
    R, t = rotation([1.5, -1.0, 4.0]), np.array([6.0, -4.0, 3.0])
    case, model, grid, curves = part
    tables = lab_tables(grid, curves, seed=3, frame=(R, t))
    folder = write_lab_bundle(tmp_path / "moved", case, tables, measurements=["surface"])
    unregistered = evaluate(load_bundle(folder, read_case=case_for_test), model)
    assert unregistered.tests[0].normalised > 10.0  # the scan misses the part as it lies
    folder = write_lab_bundle(tmp_path / "registered", case, tables, measurements=["surface"],
                              frame={"register": True})
    result = evaluate(load_bundle(folder, read_case=case_for_test), model)
    reg = result.metrics["part/surface"]["registration"]
    assert not reg["far"]
    assert result.tests[0].normalised < 1.5
    # The fitted frame is the one the scan was taken in, within a few standard deviations.
    assert np.allclose(reg["rotation_deg"], [1.5, -1.0, 4.0],
                       atol=4 * max(reg["sd_rotation_deg"]) + 0.05)
    assert np.allclose(reg["translation_mm"], t, atol=0.5)
    assert max(reg["sd_rotation_deg"]) < 0.1 and max(reg["sd_translation_mm"]) < 0.1
    # A ball of points is another part: no registration brings it onto this sheet.
    from fenicsx_drape.diagnosis.kinds.lab import register, sheet_mesh

    rng = np.random.default_rng(0)
    ball = rng.normal(size=(500, 3))
    ball = 30.0 * ball / np.linalg.norm(ball, axis=1, keepdims=True) + [0.0, 0.0, 120.0]
    assert register(sheet_mesh(grid), ball, 0.15)["far"]


def test_a_scan_of_a_third_of_the_part(tmp_path, part):
    bundle, _ = bundle_of(tmp_path, part, measurements=["surface"],
                          scan_where=lambda x: x[:, 0] < -50.0)
    result = evaluate(bundle, part[1])
    m = result.metrics["part/surface"]
    assert 0.2 < m["coverage"] < 0.45
    assert result.tests[0].normalised < 1.5 and m["unmatched"] == 0


def test_an_outline_only_sees_the_draw_in(tmp_path, part):
    bundle, _ = bundle_of(tmp_path, part, measurements=["outline"])
    (test,) = bundle.tests
    assert test.id == "part/outline"
    at_floor = evaluate(bundle, part[1]).tests[0].normalised
    gripped = evaluate(bundle, part[1].with_parameters(mu=1.5)).tests[0]
    assert at_floor < 1.5 < gripped.normalised
    # More holder friction draws less in: the measured edge lies inside the model's.
    assert np.mean(gripped.residual) < 0.0
    # With the measured draw-in (here the model's own at each edge point, plus 0.3 mm
    # noise), each row gives two values: its distance to the edge and its draw-in.
    from fenicsx_drape.forming.running import measure

    path = bundle.path / "edge.csv"
    table = np.genfromtxt(path, delimiter=",", names=True)
    edge = measure.closest_on_edge(measure.SheetMesh.of(part[2]),
                                   np.column_stack([table["x_mm"], table["y_mm"]]))
    rng = np.random.default_rng(1)
    draw_in = edge["draw_in"] + rng.normal(0.0, 0.3, len(table))
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0] + ",draw_in_mm"] + [
        f"{line},{d:.4f}" for line, d in zip(lines[1:], draw_in)]) + "\n")
    (test,) = load_bundle(bundle.path, read_case=case_for_test).tests
    result = evaluate(load_bundle(bundle.path, read_case=case_for_test), part[1]).tests[0]
    assert result.residual.size == 2 * test.n_rows and result.normalised < 1.5
    assert np.allclose(result.measured[1::2], test.columns["draw_in_mm"])
    again = load_bundle(bundle.path, read_case=case_for_test)
    gripped = evaluate(again, part[1].with_parameters(mu=1.5)).tests[0]
    assert np.mean(gripped.residual[1::2]) > 0.0  # measured draw-in beyond the gripped model's


def test_shear_magnitudes_only(tmp_path, part):
    bundle, _ = bundle_of(tmp_path, part, measurements=["shear_points"],
                          keys={"shear_magnitude": True}, magnitude=True)
    (test,) = bundle.tests
    assert test.lab.shear_magnitude and (test.columns["shear_deg"] >= 0).all()
    result = evaluate(bundle, part[1])
    assert result.tests[0].normalised < 1.5
    assert result.tests[0].noise_source == "shear_sd_deg key"
