"""Data before physics (spec version 4): measurements that cannot be of their case
are named as such, first, and no effect is named on their evidence.

The issue's examples, each built here from a formed part: the double dome and the square box
formed on coarse 20 mm cells (``drape form``'s bundle, its tools as meshes), then the double
dome's grid with x and z swapped, the square box's grid under the double-dome test, every flat
x shifted 3 mm, and a travel of the wrong sign (impossible: exit 2). ``compare`` checks before
it fits and fits nothing on suspect data, ``diagnose`` names no effect on them (both through
the command line). The lab's measurements without a grid (an outline in plan, a force curve, a
registered scan) are changed from the shipped ``demos/bundles/octagon-lab``; a flat frame
shifted without a symmetry plane is found on the octagon formed whole.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.cli import main
from fenicsx_drape.diagnosis.data_check import apply_data_check, data_check
from fenicsx_drape.forming.case.format import case_for_test, load_case
from fenicsx_drape.measurements.bundle import BundleError, load_bundle

pytestmark = pytest.mark.skip_in_parallel


@pytest.fixture(scope="module")
def formed(tmp_path_factory):
    """The bundles of the double dome and the square box, formed on 20 mm cells."""
    from fenicsx_drape.forming.running.outputs import form_case

    root = tmp_path_factory.mktemp("formed")
    for name in ("double_dome", "square_box"):
        form_case(root / name, load_case(name, cell_mm=20.0, step_mm=4.0), fields=False,
                  pictures=False, grid_mm=10.0)
    return root


def variant(formed: Path, folder: Path, change=None, grid_from: str = "double_dome",
            part: str = "double_dome") -> Path:
    """A part's bundle in ``folder`` with its grid changed (columns by name)."""
    shutil.copytree(formed / part / "bundle", folder)
    (csv,) = folder.glob("*_grid.csv")
    (source,) = (formed / (grid_from if part == "double_dome" else part) /
                 "bundle").glob("*_grid.csv")
    lines = [line for line in source.read_text().splitlines() if not line.startswith("#")]
    names = lines[0].split(",")
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    if change is not None:
        change({n: k for k, n in enumerate(names)}, rows)
    csv.write_text("\n".join([lines[0]] + [",".join(repr(float(v)) for v in r)
                                           for r in rows]) + "\n")
    return folder


def check(folder: Path) -> dict:
    (entry,) = data_check(load_bundle(folder, read_case=case_for_test))
    return entry


def test_the_formed_parts_own_grids_are_consistent(formed, tmp_path):
    for name in ("double_dome", "square_box"):
        entry = check(formed / name / "bundle")
        assert entry["measurement"] == "file" and entry["suspect"] is False


def test_a_grid_with_x_and_z_swapped_is_named(formed, tmp_path):
    def swap(c, rows):
        rows[:, [c["x_mm"], c["z_mm"]]] = rows[:, [c["z_mm"], c["x_mm"]]]

    entry = check(variant(formed, tmp_path / "b", swap))
    assert entry["suspect"]
    assert entry["why"].startswith("x and z look swapped: the measured z spans ")
    span = float(entry["why"].split("z spans ")[1].split(" mm")[0])
    assert 130.0 < span < 150.0 and entry["why"].endswith("the tools 40 mm")


def test_another_parts_grid_is_named(formed, tmp_path):
    # The square box's quarter (240 mm blank) under the double dome's test (300 × 200 mm).
    entry = check(variant(formed, tmp_path / "b", grid_from="square_box"))
    assert entry["suspect"] and "of the flat positions lie outside the case's blank (up to " \
        "(0, 120) mm): another part's grid?" in entry["why"]


def test_a_flat_frame_shifted_by_3_mm_is_named_with_the_shift(formed, tmp_path):
    def shift(c, rows):
        rows[:, c["x0_mm"]] += 3.0

    entry = check(variant(formed, tmp_path / "b", shift))
    assert entry["suspect"] and entry["why"].startswith("every flat x looks shifted by 3 mm")
    assert "lies 3 mm outside the blank" in entry["why"]
    assert "not a set-up the fit can size" in entry["why"]

    # The other way, every flat position stays on the blank: a lab draws its grid where it
    # meant the blank to lie, so the blank placed 3 mm off-centre reads so (a set-up error).
    def back(c, rows):
        rows[:, c["x0_mm"]] -= 3.0

    offset = check(variant(formed, tmp_path / "o", back))
    assert offset["suspect"] is False
    assert offset["why"].startswith("chosen: a blank placed off-centre by about (3, 0) mm")
    # compare fills data_check (and exits 0: the numbers are plausible, just not this case's).
    assert main(["compare", str(tmp_path / "b"), "--out", str(tmp_path / "cmp"),
                 "--no-fit"]) == 0
    report = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert report["data_check"] == [entry]


def test_a_scan_in_metres_is_named(formed, tmp_path):
    def metres(c, rows):
        rows[:, [c["x_mm"], c["y_mm"], c["z_mm"]]] /= 1000.0

    entry = check(variant(formed, tmp_path / "b", metres))
    assert entry["suspect"] and entry["why"].endswith("the blank 300 mm: metres read as "
                                                      "millimetres?")


def test_a_travel_of_the_wrong_sign_is_bad_input(formed, tmp_path, capsys):
    folder = variant(formed, tmp_path / "b")
    toml = folder / "bundle.toml"
    toml.write_text(toml.read_text().replace("travel_mm = 40.0", "travel_mm = -40.0"))
    with pytest.raises(BundleError, match=r"travel_mm = -40: a travel against the tool's "
                                          r"motion"):
        load_bundle(folder, read_case=case_for_test)
    assert main(["compare", str(folder), "--out", str(tmp_path / "cmp"), "--no-fit"]) == 2
    assert "a travel against the tool's motion" in capsys.readouterr().err


def test_a_suspect_measurement_comes_first_and_names_no_effect():
    report = {"missing_effect": "tool_friction", "add_effects": ["tool_friction"],
              "conclusion": "tool_friction is missing.", "candidates": [{"effect": "x"}]}
    entries = [{"test": "dd", "measurement": "file", "suspect": True,
                "why": "x and z look swapped: the measured z spans 290 mm, the tools 40 mm"},
               {"test": "dd", "measurement": "outline", "suspect": False, "why": "fine"}]
    apply_data_check(report, entries)
    assert report["data_check"] == entries
    assert report["missing_effect"] is None and report["add_effects"] == []
    assert report["conclusion"].startswith("Check the data: dd/file: x and z look swapped")
    assert "tool_friction" not in report["conclusion"]
    assert report["candidates"] == [{"effect": "x"}]  # what the fit found stays
    clean = {"missing_effect": "tool_friction", "conclusion": "tool_friction is missing.",
             "notes": []}
    chosen = {"test": "dd", "measurement": "file", "suspect": False,
              "why": "chosen: a blank placed off-centre by about (-4, 0) mm"}
    apply_data_check(clean, [*entries[1:], chosen])
    assert clean["missing_effect"] == "tool_friction"
    assert clean["data_check"] == [*entries[1:], chosen]
    assert clean["notes"] == ["dd/file: chosen: a blank placed off-centre by about (-4, 0) mm"]


def swap_x_and_z(c, rows):
    rows[:, [c["x_mm"], c["z_mm"]]] = rows[:, [c["z_mm"], c["x_mm"]]]


def test_compare_checks_the_data_before_it_fits_and_fits_nothing_on_them(formed, tmp_path,
                                                                         capsys):
    from fenicsx_drape.model import default_model

    folder = variant(formed, tmp_path / "b", swap_x_and_z)
    assert main(["compare", str(folder), "--out", str(tmp_path / "cmp")]) == 0
    out, err = capsys.readouterr()
    # The first line of progress, before any fit, and the first line of the summary.
    assert err.splitlines()[0].startswith("check the data: double_dome-200N-40s/file: x and z "
                                          "look swapped")
    assert out.splitlines()[0].startswith("Check the data: double_dome-200N-40s/file: x and z "
                                          "look swapped")
    report = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert report["conclusion"].startswith("Check the data: double_dome-200N-40s/file: x and "
                                           "z look swapped")
    assert "No parameter was fitted on them" in report["conclusion"]
    assert [e["suspect"] for e in report["data_check"]] == [True]
    # The only test is suspect: no parameter moved from the model given.
    default = default_model().parameters
    assert report["model"]["parameters"] == {k: float(v) for k, v in sorted(default.items())}
    assert any("not fitted on double_dome-200N-40s" in s for s in report["skipped"])
    # The part's own grid: nothing suspect, the conclusion is the error alone.
    assert main(["compare", str(formed / "double_dome" / "bundle"), "--out",
                 str(tmp_path / "own"), "--no-fit"]) == 0
    own = json.loads((tmp_path / "own" / "compare.json").read_text())
    assert own["conclusion"].startswith("The model is ") and not own["data_check"][0]["suspect"]


@pytest.mark.slow
def test_diagnose_names_the_data_first_and_no_effect(formed, tmp_path, capsys):
    # One candidate (tool friction, every other effect in the model), no set-up and 40 mm
    # cells, to keep the test short: the data check does not depend on them. The default
    # path (every candidate and set-up) runs on a lab bundle in test_lab_user_path.py.
    from fenicsx_drape.effects import EFFECTS
    from fenicsx_drape.model import default_model

    folder = variant(formed, tmp_path / "b", swap_x_and_z)
    model = default_model().with_effects(*[e for e in EFFECTS if e != "tool_friction"])
    (tmp_path / "model.toml").write_text(model.to_toml())
    assert main(["diagnose", str(folder), "--model", str(tmp_path / "model.toml"), "--setup",
                 "--forming-cell-mm", "40", "--json", str(tmp_path / "r.json")]) == 0
    out, err = capsys.readouterr()
    assert err.splitlines()[0].startswith("check the data: double_dome-200N-40s/file: x and z "
                                          "look swapped")
    assert out.splitlines()[0].startswith("Check the data: double_dome-200N-40s/file")
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["conclusion"].startswith("Check the data: double_dome-200N-40s/file: x and "
                                           "z look swapped")
    assert report["missing_effect"] is None and report["add_effects"] == []
    assert "tool_friction" not in report["conclusion"]


LAB = Path(__file__).resolve().parents[1] / "demos" / "bundles" / "octagon-lab"


def lab_variant(folder: Path, name: str, change=None, toml: str = "") -> Path:
    """The shipped lab bundle with one CSV's numeric columns changed (by name)."""
    shutil.copytree(LAB, folder)
    path = folder / name
    lines = path.read_text().splitlines()
    head = next(k for k, line in enumerate(lines) if not line.startswith("#"))
    names = lines[head].split(",")
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[head + 1:]])
    if change is not None:
        change({n: k for k, n in enumerate(names)}, rows)
    path.write_text("\n".join(lines[:head + 1] + [",".join(repr(float(v)) for v in r)
                                                   for r in rows]) + "\n")
    (folder / "bundle.toml").write_text((folder / "bundle.toml").read_text() + toml)
    return folder


def lab_entries(folder: Path) -> dict[str, dict]:
    return {e["measurement"]: e for e in data_check(load_bundle(folder, read_case=case_for_test))}


def test_outlines_force_curves_and_registered_scans_are_checked(tmp_path):
    # The shipped lab bundle (formed with noise on the octagon's own tools): nothing suspect,
    # also when its frame is to be registered.
    entries = lab_entries(lab_variant(tmp_path / "own", "edge.csv"))
    assert set(entries) == {"shear_points", "surface", "outline", "punch_force"}
    assert not any(e["suspect"] for e in entries.values())
    registered = "[test.frame]\nregister = true\n"
    entries = lab_entries(lab_variant(tmp_path / "reg", "edge.csv", toml=registered))
    assert not any(e["suspect"] for e in entries.values())

    # The outline of a part twice as large (another part's): outside the 190 mm octagon.
    def doubled(c, rows):
        rows[:, [c["x_mm"], c["y_mm"]]] *= 2.0

    why = lab_entries(lab_variant(tmp_path / "o", "edge.csv", doubled))["outline"]
    assert why["suspect"] and "of the outline lies farther than a cell (20 mm) outside the " \
        "flat blank" in why["why"]

    # The force curve's travel of the wrong sign, then of twice the case's 55 mm.
    def negative(c, rows):
        rows[:, c["travel_mm"]] *= -1.0

    why = lab_entries(lab_variant(tmp_path / "f", "force.csv", negative))["punch_force"]
    assert why["suspect"] and why["why"].startswith("the force curve's travel runs from -55 "
                                                    "to -1 mm, mostly ≤ 0: a travel of the "
                                                    "wrong sign")

    def longer(c, rows):
        rows[:, c["travel_mm"]] *= 2.0

    why = lab_entries(lab_variant(tmp_path / "g", "force.csv", longer))["punch_force"]
    assert why["suspect"] and why["why"].startswith(
        "the force curve's travel reaches 110 mm, the case's tools travel 55 mm (allowed "
        "59.75 mm)")

    # A registered scan of a part twice as large: too large in any frame.
    def scaled(c, rows):
        rows[:, [c["x_mm"], c["y_mm"], c["z_mm"]]] *= 2.0

    why = lab_entries(lab_variant(tmp_path / "s", "scan.csv", scaled, registered))["surface"]
    assert why["suspect"] and why["why"].startswith("the registered scan is ")
    across = float(why["why"].split("scan is ")[1].split(" mm")[0])
    allowed = float(why["why"].split("allows (")[1].split(" mm")[0])
    assert across > allowed > 300.0


@pytest.fixture(scope="module")
def whole_octagon(tmp_path_factory):
    """The octagon formed whole (no symmetry plane) on 20 mm cells."""
    from fenicsx_drape.forming.case.format import with_overrides
    from fenicsx_drape.forming.running.outputs import form_case

    root = tmp_path_factory.mktemp("whole")
    form_case(root / "octagon", with_overrides(load_case("octagon", cell_mm=20.0, step_mm=4.0),
                                               symmetry=[]), fields=False, pictures=False,
              grid_mm=10.0)
    return root


def test_a_shift_without_a_symmetry_plane_is_found_or_read_as_a_blank_offset(whole_octagon,
                                                                              tmp_path):
    entry = check(variant(whole_octagon, tmp_path / "own", part="octagon"))
    assert entry["suspect"] is False and entry["why"].startswith("consistent")

    def shift(dx):
        def change(c, rows):
            rows[:, c["x0_mm"]] += dx
        return change

    # 20 mm: flat positions off the 190 mm octagon (a grid on the blank lies on it).
    entry = check(variant(whole_octagon, tmp_path / "far", shift(20.0), part="octagon"))
    assert entry["suspect"] and entry["why"].startswith("every flat position looks shifted "
                                                        "(x by +20 mm)")
    assert "lies 5 mm outside the blank" in entry["why"]
    # 4 mm: every flat position still on the blank: a blank offset of -4 mm, chosen and said.
    entry = check(variant(whole_octagon, tmp_path / "near", shift(4.0), part="octagon"))
    assert entry["suspect"] is False
    assert entry["why"].startswith("chosen: a blank placed off-centre by about (-4, ")
    assert "blank_offset_mm" in entry["why"] and "every flat position lies on the blank" \
        in entry["why"]
    # compare says the reading it chose in its conclusion.
    assert main(["compare", str(tmp_path / "near"), "--out", str(tmp_path / "cmp"),
                 "--no-fit"]) == 0
    report = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert report["data_check"] == [entry]
    assert report["conclusion"].endswith(f"octagon-100N-20s/file: {entry['why']}.")
