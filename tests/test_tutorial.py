"""The tutorial that builds a part from nothing runs as a script, and its rules hold."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dolfinx")

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_the_tutorial_forms_its_own_part(tmp_path):
    from fenicsx_drape.forming.tools.surfaces import load_surface

    run = subprocess.run([sys.executable, str(ROOT / "demos" / "tutorial_own_part.py"),
                          str(tmp_path)], capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    part, formed = tmp_path / "part", tmp_path / "formed"
    # The binary STL: 84 bytes of header and count, 50 a triangle; read back by Gmsh.
    punch = load_surface(part / "punch.stl")
    assert (part / "punch.stl").stat().st_size == 84 + 50 * len(punch.triangles)
    # Placed as the rules say: the punch's top 0.5 mm below the sheet, the die at its end
    # lifted by clearance and ply, the holder in z = 0 past the 200 mm blank.
    die = load_surface(part / "die.stl", sheet_side="-z")
    assert np.max(punch.points[:, 2]) == pytest.approx(-0.5, abs=1e-4)
    assert np.max(die.points[:, 2]) == pytest.approx(-0.5 + 25.0 + 0.8, abs=1e-4)
    holder = load_surface(part / "holder.geo", mesh_size_mm=10.0)
    assert np.allclose(holder.points[:, 2], 0.0) and np.max(holder.points[:, 0]) > 100.0
    # The case's mesh_mm (10 mm) replaces the script's own 20 mm: finer triangles.
    assert len(holder.triangles) > 2 * len(load_surface(part / "holder.geo").triangles)
    summary = json.loads((formed / "summary.json").read_text())
    assert summary["travel_mm"] == pytest.approx(25.0)
    assert summary["kinematic_complete"] and 0.0 < summary["max_shear_deg"] < 45.0
    assert summary["max_tool_force_N"]["punch"] > 0.0 > summary["max_tool_force_N"]["die"]
    assert f"max shear {summary['max_shear_deg']:.1f}°" in run.stdout
    for name in ("shear.png", "tool_forces.png", "provenance.json", "bundle/bundle.toml"):
        assert (formed / name).stat().st_size > 0
