"""A lab's forming bundle through ``drape diagnose`` exactly as the README prints it.

``./drape diagnose BUNDLE --model MODEL.toml --json REPORT.json``, default options: the set-up
stage, the resolution check and every candidate effect run. The bundles are made the way a
lab's would be, independently of the runs the diagnosis makes:

- the part is the small octagonal blank of ``test_forming_case_diagnosis`` (half model) over a
  hemisphere punch, die and holder; the "truth" is formed on the closed-form tools with
  10 mm cells and 1 mm steps;
- the bundle's own case is the lab's copy: the same tools as STL files, meshed by Gmsh here
  from ``meshes/hemisphere/*.geo`` with the octagon's numbers, and its own 20 mm cells and
  2 mm steps (what the diagnosis forms);
- the measurements are read off the truth with lab noise
  (:func:`~fenicsx_drape.diagnosis.lab_synthetic.lab_tables`), their noise declared as the
  spec's keys and columns.
"""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from test_forming_case_diagnosis import OCTAGON, TOOLS

from fenicsx_drape.cli import main

pytestmark = [pytest.mark.slow, pytest.mark.skip_in_parallel]

ROOT = Path(__file__).resolve().parents[1]
GEO = ROOT / "meshes" / "hemisphere"
TRUTH_CELL_MM, TRUTH_STEP_MM = 10.0, 1.0
# The octagon's builtin tools' numbers, as the .geo sources name them.
NUMBERS = dict(punch_radius_mm=40.0, fillet_radius_mm=15.0, shoulder_radius_mm=58.0,
               holder_opening_mm=120.0, travel_mm=55.0, ply_thickness_mm=0.3,
               sheet_mm=190.0)
GEO_PARAMETERS = {"punch": ("punch_radius_mm", "fillet_radius_mm", "shoulder_radius_mm"),
                  "die": ("punch_radius_mm", "fillet_radius_mm", "ply_thickness_mm",
                          "travel_mm", "holder_opening_mm"),
                  "holder": ("holder_opening_mm", "sheet_mm")}


def write_stl(surface, path: Path) -> None:
    """An ASCII STL of a triangle surface (a lab's copy of a tool)."""
    lines = [f"solid {path.stem}"]
    for a, b, c in surface.points[surface.triangles]:
        n = np.cross(b - a, c - a)
        n = n / np.linalg.norm(n)
        lines += [f" facet normal {n[0]:.6e} {n[1]:.6e} {n[2]:.6e}", "  outer loop",
                  *(f"   vertex {p[0]:.6e} {p[1]:.6e} {p[2]:.6e}" for p in (a, b, c)),
                  "  endloop", " endfacet"]
    lines.append(f"endsolid {path.stem}")
    path.write_text("\n".join(lines) + "\n")


def stl_case(folder: Path) -> Path:
    """The octagon's case with its tools as STL files (meshed here), 20 mm cells, 2 mm steps."""
    from fenicsx_drape.forming.tools.surfaces import load_surface

    folder.mkdir(parents=True, exist_ok=True)
    for name, keys in GEO_PARAMETERS.items():
        surface = load_surface(GEO / f"{name}.geo", {k: NUMBERS[k] for k in keys},
                               mesh_size_mm=2.0 if name != "holder" else 4.0, comm=None)
        write_stl(surface, folder / f"{name}.stl")
    text = OCTAGON
    for name in GEO_PARAMETERS:
        text = text.replace(f'name = "{name}"\nrole = "{name}"\ngeometry = "builtin:hemisphere"\n'
                            f"parameters = {{ {TOOLS} }}",
                            f'name = "{name}"\nrole = "{name}"\ngeometry = "{name}.stl"')
    assert text.count(".stl") == 3 and "builtin:" not in text
    # The punch's travel as the builtin tools' (travel_mm): a motion table on the STL punch.
    text = text.replace('geometry = "punch.stl"', 'geometry = "punch.stl"\n'
                        '[tool.motion]\ntime_s = [0.0, 20.0]\nz_mm = [0.0, 55.0]')
    (folder / "case.toml").write_text(text)
    return folder / "case.toml"


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """The truth's runs and the lab's STL case (module doc)."""
    pytest.importorskip("dolfinx")
    from fenicsx_drape.diagnosis import forming_runs as runs
    from fenicsx_drape.forming.case.format import load_case, with_overrides

    root = tmp_path_factory.mktemp("lab")
    (root / "truth").mkdir()
    (root / "truth" / "case.toml").write_text(OCTAGON)
    truth_case = with_overrides(load_case(root / "truth" / "case.toml"),
                                cell_mm=TRUTH_CELL_MM, step_mm=TRUTH_STEP_MM)
    lab_case = load_case(stl_case(root / "stl"))
    return {"root": root, "truth": truth_case, "case": lab_case, "runs": runs}


def truth_tables(lab, model, seed, **overrides):
    """Lab measurements of the truth formed by ``model`` (with set-up ``overrides``)."""
    from fenicsx_drape.diagnosis.lab_synthetic import lab_tables
    from fenicsx_drape.forming.case.format import with_overrides

    case = with_overrides(lab["truth"], **overrides) if overrides else lab["truth"]
    (grid,) = lab["runs"].form_many([(case, model)])
    return lab_tables(grid, lab["runs"].tool_forces(case, model), seed=seed,
                      points_per_line=20, scan_points=600, holes=[(20.0, 20.0, 10.0)],
                      edge_points=40)


def diagnose_as_the_readme(lab, name, tables, model, measurements=None, keys=()):
    """Write the bundle and the model, run the README's command line; the report."""
    from fenicsx_drape.diagnosis.lab_synthetic import write_lab_bundle

    folder = lab["root"] / name
    write_lab_bundle(folder / "bundle", lab["case"], tables, measurements=measurements,
                     keys=dict(keys))
    (folder / "model.toml").write_text(model.to_toml())
    status = main(["diagnose", str(folder / "bundle"), "--model", str(folder / "model.toml"),
                   "--json", str(folder / "REPORT.json")])
    assert status == 0
    return json.loads((folder / "REPORT.json").read_text())


def test_the_lab_copy_of_the_tools_is_read_as_stl(lab):
    assert [t.path.suffix for t in lab["case"].tools] == [".stl"] * 3
    assert lab["case"].blank.cell_mm == 20.0


def test_a_hidden_effect_is_named_from_every_kind_together(lab):
    from fenicsx_drape.model import default_model

    truth = default_model()
    report = diagnose_as_the_readme(lab, "hidden", truth_tables(lab, truth, seed=3),
                                    truth.without_effects("tow_buckling"))
    assert report["missing_effect"] == "tow_buckling"
    assert report["setup_error"] is None
    assert report["candidates"][0]["error_after"]["normalised"] <= 1.5
    # Each kind's noise is its own declared sd: the key, or the outline's column.
    assert report["noise_floor"]["sources"] == {
        "part/shear_points": "shear_sd_deg key", "part/surface": "position_sd_mm key",
        "part/outline": "position_sd_mm", "part/punch_force": "force_sd_N key"}
    assert report["noise_floor"]["per_test"]["part/shear_points"] == 1.0
    assert isinstance(report["resolution"], list)


@pytest.mark.parametrize("kind", ["shear_points", "surface", "outline", "punch_force"])
def test_each_kind_alone_from_the_model_that_formed_it_names_nothing(lab, kind):
    from fenicsx_drape.model import default_model

    truth = default_model()
    report = diagnose_as_the_readme(lab, f"null-{kind}", truth_tables(lab, truth, seed=7),
                                    truth, measurements=[kind])
    assert report["missing_effect"] is None
    assert report["setup_error"] is None
    assert list(report["baseline"]["error"]["per_test"]) == [f"part/{kind}"]


def test_a_holder_force_is_read_from_the_force_curve_and_the_edge(lab):
    from fenicsx_drape.model import default_model

    truth = default_model()
    tables = truth_tables(lab, truth, seed=5, holder_force_N=300.0)
    report = diagnose_as_the_readme(lab, "force", tables, truth,
                                    measurements=["outline", "punch_force"])
    assert report["setup_error"] in ("holder_force_N", "mu")
    (entry,) = [s for s in report["setup"] if s["parameter"] == "holder_force_N"]
    assert entry["stated"] == 100.0
    assert abs(entry["fitted"] - 300.0) <= 2.0 * entry["sd"] + 0.1 * 300.0
    assert report["missing_effect"] is None


def test_shear_read_off_a_finer_net_is_the_nets_not_physics(lab):
    """A sound lab estimate on a 5 mm net against the model's 20 mm cells (resolution)."""
    from fenicsx_drape.forming.case.format import with_overrides
    from fenicsx_drape.model import default_model

    truth = default_model()
    fine = {"root": lab["root"], "case": lab["case"], "runs": lab["runs"],
            "truth": with_overrides(lab["truth"], cell_mm=5.0)}
    report = diagnose_as_the_readme(lab, "fine", truth_tables(fine, truth, seed=9), truth,
                                    measurements=["shear_points"])
    assert report["missing_effect"] is None
    (entry,) = report["resolution"]
    assert entry["measurement"] == "part/shear_points" and entry["explains"]
    assert entry["cell_mm"] == 20.0 and entry["suggested_cell_mm"] < 20.0
    assert "Resolution" in report["conclusion"]
    assert "not in the catalogue" not in report["conclusion"]


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
