"""`drape form hemisphere` end to end on a coarse case, and the Gmsh tool meshes."""

import json

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from fenicsx_drape.cli import main
from fenicsx_drape.forming.case.format import case_for_test
from fenicsx_drape.forming.tools.shapes import HemisphereTools
from fenicsx_drape.measurements.bundle import load_bundle


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_form_command_writes_summary_bundle_fields_and_pictures(tmp_path):
    out = tmp_path / "hemi"
    rc = main(["form", "hemisphere", "--out", str(out), "--cell-mm", "30", "--duration-s", "8",
               "--mu", "0.25", "--quiet"])
    assert rc == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in ("max_shear_deg", "total_wrinkling_strain", "min_wrinkling_strain", "draw_in_mm",
                "nodes", "steps", "snes_iterations", "wall_time_s", "kinematic_max_shear_deg"):
        assert key in summary
    assert summary["nodes"] == 25 and summary["total_wrinkling_strain"] < 0.0
    assert 0.0 < summary["max_shear_deg"] < 90.0
    bundle = load_bundle(out / "bundle", read_case=case_for_test)
    (test,) = bundle.tests
    # The bundle names a copy of the case file (the hemisphere's tools are builtin).
    assert test.kind == "forming" and test.case == "case/case.toml"
    assert test.forming_case.blank.symmetry == ("x", "y")
    assert test.conditions["mu"] == 0.25  # the holder's μ: its one name
    assert test.forming["holder_force_N"] == 133.0 and test.forming["duration_s"] == 8.0
    # The drawn grid of the quarter: 10 mm is no whole number of 30 mm cells, so the net's
    # own nodes (5 × 5, with their shear), the apex on the punch's top.
    assert test.forming["grid_mm"] == 30.0 and len(test.columns["i"]) == 25
    assert "shear_deg" in test.columns
    apex = (test.columns["i"] == 0) & (test.columns["j"] == 0)
    assert test.columns["z_mm"][apex][0] == pytest.approx(80.0, abs=0.05)
    for name in ("shear.png", "wrinkling.png", "fields.xdmf", "provenance.json",
                 "tools/punch.vtk", "tools/die.vtk", "tools/holder.vtk", "formed_sheet.csv"):
        assert (out / name).stat().st_size > 0
    # 30 mm cells, 8 s and μ = 0.25 are not the paper's conditions: not compared, no paths.
    assert summary["paper_conditions"] is False and not (out / "paths.png").exists()
    assert summary["paper_differences"] == ["cell 30 mm", "8 s", "mu 0.25"]


def test_bad_options_are_input_errors(tmp_path, capsys):
    assert main(["form", "hemisphere", "--out", str(tmp_path), "--cell-mm", "-1"]) == 2
    assert "cell_mm" in capsys.readouterr().err
    assert main(["form", "hemisphere", "--out", str(tmp_path), "--with", "no_such_effect"]) == 2


@pytest.mark.skip_in_parallel
def test_tool_meshes_lie_on_the_exact_surfaces(tmp_path):
    meshio = pytest.importorskip("meshio")
    from fenicsx_drape.forming.tools.drawing import write_tool_meshes

    tools = HemisphereTools()
    files = write_tool_meshes(tools, tmp_path, travel_mm=30.0, size_mm=6.0)

    def nodes(path):
        mesh = meshio.read(path)
        triangles = mesh.cells_dict["triangle"]
        assert len(triangles) > 100
        return mesh.points[np.unique(triangles)]

    # The punch drawn at 30 mm of travel: its nodes are on the exact surface at t = 15 s.
    assert np.abs(tools.punch(40.0).gap(nodes(files[0]), 15.0).phi).max() < 1e-6
    assert np.abs(tools.die().gap(nodes(files[1]), 0.0).phi).max() < 1e-6
