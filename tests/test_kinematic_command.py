"""``drape drape hemisphere``: the kinematic drape from the command line."""

import json

import numpy as np
import pytest

from fenicsx_drape.cli import main
from fenicsx_drape.forming.case.format import case_for_test
from fenicsx_drape.measurements.bundle import load_bundle


def test_drape_command_writes_summary_bundle_picture(tmp_path, capsys):
    out = tmp_path / "kin"
    assert main(["drape", "hemisphere", "--out", str(out)]) == 0
    assert "max shear 62.5°" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["max_shear_deg"] == pytest.approx(62.547440, abs=1e-5)
    assert summary["nodes"] == 625 and summary["unplaced_nodes"] == 0
    assert summary["start_mm"] == pytest.approx([0.0, 0.0, 80.0])
    (test,) = load_bundle(out / "bundle", read_case=case_for_test).tests
    assert test.kind == "forming" and test.case == "case/case.toml"  # a copy of the case
    assert len(test.columns["i"]) == 625  # the 10 mm drawn grid is the net
    apex = (test.columns["i"] == 0) & (test.columns["j"] == 0)
    assert test.columns["z_mm"][apex][0] == pytest.approx(80.0, abs=1e-9)
    assert np.nanmax(np.abs(test.columns["shear_deg"])) <= summary["max_shear_deg"]
    for name in ("shear.png", "provenance.json"):
        assert (out / name).stat().st_size > 0
    provenance = json.loads((out / "provenance.json").read_text())
    assert provenance["kinematic"]["generator"] == "geodesic"


def test_drape_command_options(tmp_path, capsys):
    out = tmp_path / "turned"
    assert main(["drape", "hemisphere", "--out", str(out), "--direction-deg", "30",
                 "--locking-angle-deg", "55", "--no-pictures"]) == 0
    assert "could not be placed" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["direction_deg"] == 30.0 and summary["max_shear_deg"] <= 55.0
    assert summary["unplaced_nodes"] > 0 and not (out / "shear.png").exists()


def test_drape_command_bad_input(tmp_path, capsys):
    assert main(["drape", "hemisphere", "--out", str(tmp_path), "--cell-mm", "-1"]) == 2
    assert "cell_mm" in capsys.readouterr().err
    assert main(["drape", "hemisphere", "--out", str(tmp_path), "--locking-angle-deg",
                 "120"]) == 2
    assert "locking_angle_deg" in capsys.readouterr().err
