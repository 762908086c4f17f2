"""Data before physics (spec version 4): measurements that cannot be of their case
are named as such, first, and no effect is named on their evidence.

The issue's examples, each built here from a formed part: the double dome and the square box
formed on coarse 20 mm cells (``drape form``'s bundle, its tools as meshes), then the double
dome's grid with x and z swapped, the square box's grid under the double-dome test, every flat
x shifted 3 mm, and a travel of the wrong sign (impossible: exit 2).
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


def variant(formed: Path, folder: Path, change=None, grid_from: str = "double_dome") -> Path:
    """The double dome's bundle in ``folder`` with its grid changed (columns by name)."""
    shutil.copytree(formed / "double_dome" / "bundle", folder)
    (csv,) = folder.glob("*_grid.csv")
    (source,) = (formed / grid_from / "bundle").glob("*_grid.csv")
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
    assert "not a set-up the fit can size" in entry["why"]
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
    clean = {"missing_effect": "tool_friction", "conclusion": "tool_friction is missing."}
    apply_data_check(clean, entries[1:])
    assert clean["missing_effect"] == "tool_friction" and clean["data_check"] == entries[1:]
