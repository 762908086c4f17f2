"""The kinematic drape of a forming case (case.toml): its formed surface, blank and options."""

import json
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.cli import main
from fenicsx_drape.forming.case.format import load_case, with_overrides
from fenicsx_drape.forming.running.kinematic import case_surface, drape_case, kinematic_drape
from fenicsx_drape.forming.tools.shapes import HemisphereTools

CASE = Path(__file__).resolve().parents[1] / "meshes" / "hemisphere" / "case.toml"


@pytest.fixture(scope="module")
def case():
    return load_case(CASE)


def test_the_hemisphere_case_drapes_as_todays_hemisphere(case):
    """The case's formed surface is the punch at full travel and the holder plane (the die
    is on the other side); the quarter model's blank is draped whole: today's net."""
    surface = case_surface(case)
    assert [p.tool.name for p in surface.parts] == ["punch", "holder"]
    assert all(p.time_s == case.duration_s for p in surface.parts)
    net = drape_case(case)
    today = kinematic_drape(HemisphereTools(), 10.0)
    np.testing.assert_allclose(net.x, today.x, atol=1e-8)
    assert np.abs(net.shear_deg()).max() == pytest.approx(62.547440, abs=1e-5)
    assert net.present.all() and net.unplaced_count == 0


def test_case_options_and_overrides(case):
    """Δ and the ply angle come from the case (or the call); the start is the net's origin."""
    coarse = drape_case(with_overrides(case, cell_mm=20.0))
    assert coarse.cell_mm == pytest.approx(20.0) and coarse.x.shape == (13, 13, 3)
    turned = drape_case(case, cell_mm=20.0, direction_deg=30.0)
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    np.testing.assert_allclose(turned.x, coarse.x @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]),
                               atol=1e-8)


def test_a_case_with_the_holders_earlier_keys_runs_with_a_note_naming_the_new_ones(tmp_path,
                                                                                  capsys):
    """``[holder] force_N`` and ``force_share`` (earlier names) are read as ``holder_force_N``
    and ``holder_force_share``; the command says so in one note line each."""
    old = tmp_path / "old.toml"
    old.write_text(CASE.read_text().replace("holder_force_N =", "force_N =")
                   .replace("holder_force_share =", "force_share ="))
    assert main(["drape", str(old), "--out", str(tmp_path / "kin"), "--cell-mm", "20",
                 "--no-pictures"]) == 0
    err = capsys.readouterr().err
    for key in ("force_N", "force_share"):
        assert (f"drape: note: {old}: [holder] '{key}' is now called 'holder_{key}'" in err), err
    assert "FutureWarning" not in err  # a note, not a traceback-like warning
    holder = json.loads((tmp_path / "kin" / "summary.json").read_text())["case"]["holder"]
    assert holder == {"tool": "holder", "holder_force_N": 133.0, "holder_force_share": "model"}


def test_drape_command_on_a_case_file(tmp_path, capsys):
    out = tmp_path / "kin"
    assert main(["drape", str(CASE), "--out", str(out), "--cell-mm", "20"]) == 0
    assert "max shear" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["nodes"] == 169 and summary["case"]["case"]["name"] == "hemisphere"
    assert (out / "bundle" / "case" / "case.toml").is_file()
    toml = (out / "bundle" / "bundle.toml").read_text()
    assert 'case = "case/case.toml"' in toml and "travel_mm = 80" in toml
    assert load_case(out / "bundle" / "case" / "case.toml").blank.cell_mm == 10.0
    for name in ("shear.png", "provenance.json", "bundle/kinematic_grid.csv"):
        assert (out / name).stat().st_size > 0


def test_drape_command_bad_case(tmp_path, capsys):
    assert main(["drape", str(tmp_path / "none.toml"), "--out", str(tmp_path)]) == 2
    assert "no such case file" in capsys.readouterr().err
    assert main(["drape", "dome", "--out", str(tmp_path)]) == 2
    assert "not a case file" in capsys.readouterr().err
