"""Bundles written by ``drape form`` are data: their case carries the tools as the
run meshed them, so ``compare`` and ``diagnose`` read them without ``--trust`` and reproduce
the run; a stopped geometry script leaves no temporary file behind."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.cli import main
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case.format import case_for_test
from fenicsx_drape.forming.tools.surfaces import TriangleSurface, load_surface, write_msh
from fenicsx_drape.measurements.bundle import load_bundle
from fenicsx_drape.trust import trusted


def test_a_surface_written_as_msh_reads_back_the_same(tmp_path):
    # A bent strip, open, its sheet below (-z): points with digits a float32 would lose.
    x = np.linspace(0.0, 1.0, 7) * np.pi / 3.0
    points = np.array([[np.sin(a) * 60.0 + 1e-9, y, np.cos(a) * 60.0] for a in x
                       for y in (0.1, 20.3, 40.7)])
    triangles = [[3 * i + j, 3 * i + j + 3, 3 * i + j + 1] for i in range(6) for j in range(2)]
    triangles += [[3 * i + j + 1, 3 * i + j + 3, 3 * i + j + 4] for i in range(6)
                  for j in range(2)]
    surface = TriangleSurface(points, triangles, sheet_side="-z")
    back = load_surface(write_msh(surface, tmp_path / "strip.msh"), sheet_side="-z", comm=None)
    assert back.content_hash == surface.content_hash


@pytest.mark.slow
def test_a_formed_bundle_is_data_and_compares_to_its_own_run(tmp_path, capsys):
    assert not trusted()
    out = tmp_path / "form"
    assert main(["form", "double_dome", "--cell-mm", "20", "--step-mm", "4", "--out",
                 str(out), "--quiet", "--no-fields", "--lab-lines"]) == 0
    # The 300 × 200 mm blank takes 18.75 mm cells (16 along x) and 187.5 mm of its 200 mm
    # along y: said, and the bundle's grid (the net's nodes) and case carry the true cell.
    summary = json.loads((out / "summary.json").read_text())
    assert summary["cell_mm"] == 18.75 and summary["net"]["area_share"] == 0.9375
    assert "6.25 mm of the blank left out" in summary["net"]["note"]
    assert "25 mm or 16.67 mm keeps the whole blank" in summary["net"]["note"]
    assert "note: the net is fitted to the blank: cell 18.75 mm" in capsys.readouterr().out
    case_folder = out / "bundle" / "case"
    assert sorted(p.name for p in case_folder.iterdir()) == [
        "case.toml", "die.msh", "holder.msh", "punch.msh"]
    # Read as data (no --trust): the bundle's case runs no code.
    bundle = load_bundle(out / "bundle", read_case=case_for_test)
    test = bundle.tests[0]
    assert test.forming_case.origin is not None
    assert test.forming["grid_mm"] == 18.75 and test.forming_case.blank.cell_mm == 18.75
    assert main(["compare", str(out / "bundle"), "--out", str(tmp_path / "cmp"),
                 "--no-fit"]) == 0
    report = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    # The model on the bundle's case forms the part of the run again (the same tools), and
    # reads its grid, its shear lines and its edge as the run wrote them.
    rows = {key.split("/")[-1]: v for key, v in report["per_test"].items()}
    assert sorted(rows) == ["file", "outline", "shear_points"]
    assert rows["file"]["rows"] > 50 and rows["shear_points"]["rows"] > 30
    assert all(v["rmse"] < 1e-9 for v in rows.values())
    capsys.readouterr()


def test_a_stopped_geometry_script_leaves_no_temporary_file(tmp_path, monkeypatch):
    temp = tmp_path / "tmp"
    temp.mkdir()
    monkeypatch.setenv("TMPDIR", str(temp))
    monkeypatch.setenv("DRAPE_SCRIPT_TIMEOUT_S", "3")
    pid_file = tmp_path / "sleeper.pid"
    script = tmp_path / "stuck.py"
    script.write_text(
        "import subprocess, tempfile\n"
        "def build(gmsh):\n"
        "    handle, name = tempfile.mkstemp(suffix='.step')\n"
        "    open(name, 'w').write('half a CAD file')\n"
        "    sleeper = subprocess.Popen(['sleep', '600'])\n"
        f"    open({str(pid_file)!r}, 'w').write(str(sleeper.pid))\n"
        "    while True:\n"
        "        pass\n")
    with pytest.raises(DrapeInputError, match=r"stuck\.py: the geometry script did not "
                                              r"finish in 3 s .*temporary files are removed"):
        load_surface(script, comm=None)
    assert list(temp.iterdir()) == []  # the script's file and the job folder: gone
    # What the script started is stopped with it (gone, or a zombie awaiting its reaper).
    stat = Path(f"/proc/{pid_file.read_text()}/stat")
    for _ in range(50):
        if not stat.exists() or stat.read_text().split(")")[1].split()[0] == "Z":
            break
        time.sleep(0.1)
    assert not stat.exists() or stat.read_text().split(")")[1].split()[0] == "Z"
