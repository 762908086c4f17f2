"""Compare and diagnose on any forming case: bundles naming a case, symmetry, regions, runs.

The generic part of these tests is a small case of its own (:data:`OCTAGON`): an octagonal
polygon blank, half model (symmetry plane x = 0), over a smaller hemisphere punch, die and
holder (builtin closed-form tools), on 20 mm cells: 39 nodes, a few seconds a run.
"""

import dataclasses
import json
import shutil
import types
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape import runs
from fenicsx_drape.cli import main
from fenicsx_drape.diagnosis.kinds import grid as gk
from fenicsx_drape.diagnosis.kinds.forming import case_of, forming_case_of, model_planes
from fenicsx_drape.diagnosis.kinds.part import CASE_REGION_NAMES
from fenicsx_drape.diagnosis.synthetic import synthetic_case_test, write_case_bundle
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case.format import case_for_test, load_case
from fenicsx_drape.forming.running.post import FormedGrid
from fenicsx_drape.measurements.bundle import BundleError, Test, load_bundle, write_bundle

ROOT = Path(__file__).resolve().parents[1]
TOOLS = ("punch_radius_mm = 40.0, fillet_radius_mm = 15.0, shoulder_radius_mm = 58.0, "
         "holder_opening_mm = 120.0, travel_mm = 55.0")
OCTAGON = (ROOT / "meshes" / "octagon" / "case.toml").read_text()
NO_BUCKLING = ('effects = ["rate_dependence", "strain_dependent_viscosity", "decrimping", '
               '"holder_friction"]\n')


def write_case(folder: Path, text: str = OCTAGON) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(text)
    return folder / "case.toml"


def grid_rows(points: np.ndarray, z_mm: float = 0.0) -> str:
    """A forming table: the flat points, formed in place (lifted by z_mm)."""
    lines = ["i,j,x0_mm,y0_mm,x_mm,y_mm,z_mm"]
    for k, (x, y) in enumerate(points):
        lines.append(f"{k},0,{x},{y},{x},{y},{z_mm}")
    return "\n".join(lines) + "\n"


def write_bundle_toml(folder: Path, keys: str, case: str = "part/case.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "oct.csv").write_text(grid_rows(np.array([[0.0, 0.0], [20.0, 0.0],
                                                        [0.0, 20.0], [20.0, 20.0]])))
    case_line = f'case = "{case}"\n' if case else ""
    (folder / "bundle.toml").write_text(
        '[bundle]\nname = "b"\n\n[[test]]\nid = "oct"\nkind = "forming"\nfile = "oct.csv"\n'
        f"{case_line}{keys}")
    return folder


def half_sheet(cell_mm: float = 10.0, planes=("x",)) -> FormedGrid:
    """A half (or quarter) sheet formed by a smooth made-up map, not symmetric in y."""
    xs = np.arange(0.0, 100.0 + 1e-9, cell_mm)
    ys = xs if "y" in planes else np.arange(-100.0, 100.0 + 1e-9, cell_mm)
    X = np.stack([*np.meshgrid(xs, ys, indexing="ij"), np.zeros((xs.size, ys.size))], axis=-1)
    r2 = X[..., 0] ** 2 + X[..., 1] ** 2
    x = X.copy()
    x[..., :2] *= (1.0 - 0.1 * np.exp(-r2 / 70.0**2))[..., None]
    x[..., 2] = 50.0 * np.exp(-r2 / 50.0**2) + (0.0 if "y" in planes else 0.05 * X[..., 1])
    return FormedGrid(X, x, planes == ("x", "y"), tuple(planes))


# --------------------------------------------------------------------------------------------
# Bundles naming a case


def test_a_bundle_naming_a_case_loads_and_its_keys_override_the_case(tmp_path, monkeypatch):
    write_case(tmp_path / "b" / "part")
    keys = ("duration_s = 10.0\nholder_force_N = 250.0\ntravel_mm = 55.0\ngrid_mm = 20.0\n"
            'temperature_C = 20.0\nholder_force_share = "model"\n')
    bundle = load_bundle(write_bundle_toml(tmp_path / "b", keys), read_case=case_for_test)
    (test,) = bundle.tests
    case = test.forming_case
    assert test.case == "part/case.toml"
    assert test.case_path == (tmp_path / "b" / "part" / "case.toml").resolve()
    # The test's keys override the case (travel_mm repeats its value), the rest are conditions.
    assert case.duration_s == 10.0 and case.holder.force_N == 250.0
    assert case.holder.force_share == "model"
    assert case.speed_mm_per_s(case.tool("punch")) == pytest.approx(55.0 / 10.0)
    assert dict(test.forming) == {"duration_s": 10.0, "holder_force_N": 250.0,
                                  "travel_mm": 55.0, "grid_mm": 20.0}
    assert dict(test.conditions) == {"temperature_C": 20.0}
    assert any("temperature_C" in line for line in bundle.unknown_keys)
    assert not any("holder_force_N" in line for line in bundle.unknown_keys)

    # The overridden case reaches the run, on the case's own cells or the resolution's.
    jobs = []

    def fake_form_many(batch):
        jobs.extend(batch)
        return [half_sheet() for _ in batch]

    monkeypatch.setattr(gk, "form_many", fake_form_many)
    model = types.SimpleNamespace(parameters={})
    gk.simulate(test, model)
    with runs.resolution(30.0):
        gk.simulate(test, model)
    (first, _), (coarse, _) = jobs
    assert first.duration_s == 10.0 and first.holder.force_N == 250.0
    assert first.blank.cell_mm == 20.0 and coarse.blank.cell_mm == 30.0
    assert coarse.duration_s == 10.0 and coarse.holder.force_N == 250.0
    # A test loaded before the forming layer registered its reader reads its case when run.
    late = dataclasses.replace(test, forming_case=None)
    assert forming_case_of(late) == case

    # Written back (with a copy of its case), the bundle loads the same case.
    write_case_bundle("again", bundle.tests, tmp_path / "again")
    (again,) = load_bundle(tmp_path / "again", read_case=case_for_test).tests
    assert runs.case_key(again.forming_case) == runs.case_key(case)
    assert again.case == "part/case.toml" and dict(again.forming) == dict(test.forming)


def test_a_bundle_naming_the_hemisphere_case_file(tmp_path):
    shutil.copytree(ROOT / "meshes" / "hemisphere", tmp_path / "b" / "hemisphere")
    keys = "travel_mm = 60.0\npunch_radius_mm = 50.0\nduration_s = 30.0\ngrid_mm = 10.0\n"
    (test,) = load_bundle(write_bundle_toml(tmp_path / "b", keys, "hemisphere/case.toml"),
                          read_case=case_for_test).tests
    case = test.forming_case
    assert case.tool("punch").params["punch_radius_mm"] == 50.0
    assert case.total_travel_mm == pytest.approx(60.0) and case.duration_s == 30.0
    assert case_of(test).blank.cell_mm == 10.0 and model_planes(test) == ("x", "y")
    # The same case read from two copies is the same run (cached by content, not path).
    shutil.copytree(tmp_path / "b", tmp_path / "c")
    (copy,) = load_bundle(tmp_path / "c", read_case=case_for_test).tests
    assert copy.case_path != test.case_path
    assert runs.case_key(copy.forming_case) == runs.case_key(case)


STL = "solid s\nendsolid s\n"
MESHED = """[case]
name = "plate"
duration_s = 10.0

[blank]
outline = "rectangle"
size_mm = [100.0, 100.0]
cell_mm = 20.0

[[tool]]
name = "punch"
role = "punch"
geometry = "punch.stl"
[tool.motion]
time_s = [0.0, 10.0]
z_mm = [0.0, 20.0]
"""
_DIE = ('geometry = "builtin:hemisphere"\nparameters = { ' + TOOLS
        + ' }\n\n[[tool]]\nname = "holder"')
NO_HOLDER = OCTAGON.replace('[holder]\ntool = "holder"\nholder_force_N = 100.0\n', "")
NO_HOLDER = NO_HOLDER[:NO_HOLDER.rindex("[[tool]]")]


@pytest.mark.parametrize("text, keys, expected", [
    # A malformed case file: the case file and its key are named.
    (OCTAGON.replace(_DIE, 'geometry = "die.stp"\n\n[[tool]]\nname = "holder"'), "",
     ["case.toml: [[tool]] 2 'geometry': no such file 'die.stp'"]),
    (OCTAGON.replace("cell_mm = 20.0", 'cell_mm = 20.0\ncolour = "red"'), "",
     ["case.toml: [blank]: unknown key 'colour'"]),
    # A key of the test the case cannot take.
    (NO_HOLDER, "holder_force_N = 300.0\n",
     ["case.toml: holder overrides given, but the case has no [holder]"]),
    (MESHED, "fillet_radius_mm = 10.0\n",
     ["case.toml: test key fillet_radius_mm = 10.0: the case has no such value"]),
], ids=["missing geometry file", "unknown key", "no holder", "no such value"])
def test_a_malformed_case_named_by_a_bundle_names_the_file_and_key(tmp_path, capsys, text, keys,
                                                                    expected):
    assert text != OCTAGON and "[holder]" not in NO_HOLDER
    write_case(tmp_path / "b" / "part", text)
    (tmp_path / "b" / "part" / "punch.stl").write_text(STL)
    folder = write_bundle_toml(tmp_path / "b", keys)
    with pytest.raises(BundleError) as info:
        load_bundle(folder, read_case=case_for_test)
    message = str(info.value)
    assert f"{folder / 'bundle.toml'}:8: test 'oct': case 'part/case.toml': " in message
    for fragment in expected:
        assert fragment in message
    # drape compare reports it as bad input (exit status 2), before anything runs.
    assert main(["compare", str(folder), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert all(fragment in err for fragment in expected)
    assert not (tmp_path / "out").exists()


def test_bundle_problems_of_the_case_key_itself(tmp_path):
    write_case(tmp_path / "b" / "part")
    with pytest.raises(BundleError, match="no such file"):
        load_bundle(write_bundle_toml(tmp_path / "b", "", "part/nothing.toml"),
                    read_case=case_for_test)
    with pytest.raises(BundleError, match="either geometry"):
        load_bundle(write_bundle_toml(tmp_path / "b", 'geometry = "hemisphere"\n'),
                    read_case=case_for_test)
    with pytest.raises(BundleError, match=r"needs geometry .* or case"):
        load_bundle(write_bundle_toml(tmp_path / "b", "duration_s = 40.0\n", case=""),
                    read_case=case_for_test)
    folder = write_bundle_toml(tmp_path / "b", "", case="")
    text = (folder / "bundle.toml").read_text()
    (folder / "bundle.toml").write_text(text.replace('kind = "forming"',
                                                     'kind = "forming"\ncase = 3'))
    with pytest.raises(BundleError, match="case must be the path"):
        load_bundle(folder, read_case=case_for_test)


# --------------------------------------------------------------------------------------------
# Symmetry, sampling, regions (no runs)


@pytest.mark.parametrize("planes", [("x",), ("x", "y")])
def test_a_whole_measured_grid_is_matched_by_mirroring_the_modelled_part(planes):
    part = half_sheet(10.0, planes)
    whole = part.full().drawn_grid(10.0)
    test = Test(id="t", kind="forming", file="t.csv",
                columns={k: np.asarray(v, float) for k, v in whole.items()})
    assert not gk.in_part(test, planes)
    values = gk.sample(gk.sheet_for(test, part), gk.reference_points(test))
    np.testing.assert_allclose(values, gk.measured_positions(test), atol=1e-12)
    # A grid of the modelled part is compared with the part itself.
    own = part.drawn_grid(10.0)
    test = Test(id="t", kind="forming", file="t.csv",
                columns={k: np.asarray(v, float) for k, v in own.items()})
    assert gk.in_part(test, planes) and gk.sheet_for(test, part) is part


def test_a_node_past_a_ragged_edge_takes_the_nearest_cells_map():
    # An affine map is reproduced exactly by the extended bilinear map of any cell.
    s = np.arange(0.0, 50.0 + 1e-9, 10.0)
    X = np.stack([*np.meshgrid(s, s, indexing="ij"), np.zeros((6, 6))], axis=-1)
    A = np.array([[0.9, 0.1, 0.0], [-0.05, 1.1, 0.0], [0.2, 0.3, 0.0]])
    x = X @ A.T + [1.0, 2.0, 3.0]
    X[4:, 4:] = np.nan  # a clipped corner: cells (3..4, 3..4) gone
    x[4:, 4:] = np.nan
    sheet = FormedGrid(X, x, False, ())
    points = np.array([[45.0, 45.0], [50.0, 38.0], [12.0, 17.0], [55.0, 20.0]])
    exact = np.column_stack([points, np.zeros(4)]) @ A.T + [1.0, 2.0, 3.0]
    assert np.isnan(sheet.sample(points[:2])).all()
    np.testing.assert_allclose(gk.sample(sheet, points), exact, atol=1e-12)
    with pytest.raises(DrapeInputError, match=r"more than 1\.5 cells"):
        gk.sample(sheet, np.array([[90.0, 10.0]]), "t")


def test_regions_of_a_case_are_named_by_the_tool_each_node_touches(tmp_path):
    case_file = write_case(tmp_path / "part")
    case = load_case(case_file)
    # Measured positions at the end: the punch apex at z = 55, its sphere (R 40) centred at
    # z = 15, the die 0.3 mm above; holder at z = 0 beyond r = 60; flat sheet reference points
    # chosen for the direction from the axis.
    c = np.array([0.0, 0.0, 15.0])

    def on_sphere(angle_deg, azimuth_deg):
        a, b = np.radians(angle_deg), np.radians(azimuth_deg)
        return c + 40.0 * np.array([np.sin(a) * np.cos(b), np.sin(a) * np.sin(b), np.cos(a)])

    nodes = [  # (x0, y0), formed x, expected region
        ((0.0, 0.0), on_sphere(0, 90), "punch top"),
        ((10.0, 10.0), on_sphere(15, 45), "punch top"),
        ((0.0, 60.0), on_sphere(60, 90), "walls along the tow axes"),
        ((45.0, 45.0), on_sphere(60, 45), "walls on the bias diagonals"),
        ((0.0, -90.0), np.array([0.0, -80.0, 0.0]), "flange under the holder"),
        ((60.0, 0.0), np.array([45.0, 0.0, 40.0]), "free sheet (no tool contact)"),
        ((0.0, 75.0), np.array([0.0, 57.0, 0.3]), "flat base"),
    ]
    P = np.array([n[0] for n in nodes])
    x = np.array([n[1] for n in nodes])
    columns = {"i": np.arange(7.0), "j": np.zeros(7), "x0_mm": P[:, 0], "y0_mm": P[:, 1],
               "x_mm": x[:, 0], "y_mm": x[:, 1], "z_mm": x[:, 2],
               "position_sd_mm": np.full(7, 0.1)}
    test = Test(id="t", kind="forming", file="t.csv", columns=columns, case="part/case.toml",
                forming_case=case)
    names = [CASE_REGION_NAMES[k] for k in gk.case_region_of_nodes(test)]
    assert names == [n[2] for n in nodes]
    regions = gk.part_regions(test)
    np.testing.assert_array_equal(np.sum([r.rows for r in regions], axis=0), 1)  # a partition
    assert {r.variable for r in regions} == {"height_mm"}
    # A whole grid is folded into the half model: the mirror image of a wall node is a wall.
    mirrored = dict(columns, x_mm=-columns["x_mm"], x0_mm=-columns["x0_mm"])
    test = dataclasses.replace(test, columns=mirrored)
    assert [CASE_REGION_NAMES[k] for k in gk.case_region_of_nodes(test)] == names


# --------------------------------------------------------------------------------------------
# Runs (DOLFINx)


@pytest.fixture(scope="module")
def dolfinx():
    return pytest.importorskip("dolfinx")


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_compare_on_the_bundle_form_case_writes(tmp_path, capsys, dolfinx):
    from fenicsx_drape.forming.running.outputs import form_case

    case = load_case(write_case(tmp_path / "part"))
    form_case(tmp_path / "formed", case, fields=False, pictures=False)
    bundle = tmp_path / "formed" / "bundle"
    assert main(["compare", str(bundle), "--out", str(tmp_path / "same")]) == 0
    same = json.loads((tmp_path / "same" / "compare.json").read_text())
    (entry,) = same["per_test"].values()
    # The case compared with the model that formed it: nothing between them.
    assert entry["normalised"] < 1e-6 and entry["mean_distance_mm"] < 1e-6
    assert entry["noise_source"] == "fourth_differences"
    names = {e["says"] for e in same["regions"] if "region" in e}
    assert names <= set(CASE_REGION_NAMES) and "flange under the holder" in names
    # Against a model without tow buckling the error is far above the noise.
    (tmp_path / "model.toml").write_text(NO_BUCKLING)
    assert main(["compare", str(bundle), "--model", str(tmp_path / "model.toml"), "--no-fit",
                 "--out", str(tmp_path / "other")]) == 0
    other = json.loads((tmp_path / "other" / "compare.json").read_text())
    (entry,) = other["per_test"].values()
    assert entry["normalised"] > 2.0 and entry["mean_distance_mm"] > 1.0
    assert (tmp_path / "other" / f"residual_{next(iter(other['per_test']))}.png").is_file()
    printed = capsys.readouterr().out
    assert "mean distance" in printed and "flange under the holder" in printed


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_a_quarter_model_matches_a_whole_grid_of_the_whole_model(tmp_path, dolfinx):
    """The quarter model, mirrored, against the grid of a run of the whole blank.

    Mirroring is exact (a whole grid drawn from the mirrored quarter compares at zero). The
    whole blank's own run is symmetric too and differs from the mirrored quarter by 0.13 mm at
    most (0.5 % of the corners' draw-in under the holder, whose friction is path-dependent
    and follows each model's own load steps): below a typical 0.3 mm grid noise.
    """
    from fenicsx_drape.diagnosis import evaluate
    from fenicsx_drape.measurements.bundle import Bundle
    from fenicsx_drape.model import default_model

    path = write_case(tmp_path / "part", OCTAGON.replace('symmetry = ["x"]',
                                                        'symmetry = ["x", "y"]'))
    quarter, whole = load_case(path), load_case(path, symmetry=[])
    mirrored = synthetic_case_test(default_model(), quarter, sd_mm=0.0, full=True)
    own = synthetic_case_test(default_model(), whole, sd_mm=0.0)
    own = dataclasses.replace(own, forming_case=quarter)  # the quarter model against it
    assert mirrored.n_rows == own.n_rows and not gk.in_part(own, ("x", "y"))
    np.testing.assert_allclose(gk.simulate(mirrored, default_model()),
                               gk.measured_positions(mirrored).ravel(), atol=1e-12)
    values = gk.simulate(own, default_model()).reshape(-1, 3)
    assert np.abs(values - gk.measured_positions(own)).max() < 0.2
    result = evaluate(Bundle("b", (mirrored,)), default_model())
    assert result.tests[0].rmse < 1e-12


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_diagnose_names_a_hidden_effect_on_a_generic_case(tmp_path, dolfinx):
    """The octagon formed with tow buckling, 0.3 mm noise, whole grid; the model lacks it."""
    from fenicsx_drape.diagnosis import diagnose
    from fenicsx_drape.model import default_model

    case = load_case(write_case(tmp_path / "part"))
    test = synthetic_case_test(default_model(), case, sd_mm=0.3, seed=3, full=True)
    write_case_bundle("hidden", [test], tmp_path / "bundle")
    bundle = load_bundle(tmp_path / "bundle", read_case=case_for_test)
    # Two candidates (no set-up stage), for time: the default path is test_lab_user_path.py's.
    report = diagnose(bundle, default_model().without_effects("tow_buckling"),
                      candidates=["tow_buckling", "tool_friction"])
    assert report["missing_effect"] == "tow_buckling"
    best = report["candidates"][0]
    assert report["baseline"]["error"]["normalised"] > 3.0
    assert best["evidence"] > 3.0 and best["error_after"]["normalised"] < 1.5
    metrics = report["metrics"]
    assert metrics["tow_buckling"]["octagon"]["mean_distance_mm"] < \
        0.3 * metrics["baseline"]["octagon"]["mean_distance_mm"]
    assert report["where"][0]["says"] in CASE_REGION_NAMES
    json.dumps(report)


def test_write_bundle_writes_the_case_key(tmp_path):
    columns = {k: np.asarray(v, float) for k, v in half_sheet().drawn_grid(20.0).items()}
    test = Test(id="t", kind="forming", file="t.csv", columns=columns, case="c/case.toml",
                forming={"duration_s": 10.0, "grid_mm": 20.0})
    from fenicsx_drape.measurements.bundle import Bundle

    write_bundle(Bundle("b", (test,)), tmp_path)
    text = (tmp_path / "bundle.toml").read_text()
    assert 'case = "c/case.toml"' in text and "geometry" not in text
