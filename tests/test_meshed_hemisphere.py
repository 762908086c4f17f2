"""The hemisphere with meshed tools (meshes/hemisphere/case_meshed.toml: punch, die and holder
from Gmsh, 2 mm second-order) against the closed-form tools (case.toml): the FE forming and the
kinematic drape agree within stated tolerances.

Tolerances: max shear within 0.5° and every node within 0.1 mm of the closed-form run (issue
13); the kinematic drape's max shear within 0.5° at the case's Δ = 10 mm (measured 62.537° against
62.547°; at Δ = 20 mm the drape on the meshed punch leaves 76 of 169 nodes unplaced: README).
"""

from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.forming import load_case, run_case
from fenicsx_drape.forming.kinematic import drape_case

HERE = Path(__file__).resolve().parent.parent / "meshes" / "hemisphere"
SHEAR_TOL_DEG = 0.5
NODE_TOL_MM = 0.1


@pytest.fixture(scope="module")
def runs():
    """Both cases formed at Δ = 20 mm to the full 80 mm (about 2 s each, fields cached)."""
    exact = run_case(load_case(HERE / "case.toml", cell_mm=20.0))
    meshed = run_case(load_case(HERE / "case_meshed.toml", cell_mm=20.0))
    return exact, meshed


def test_the_meshed_case_uses_meshed_tools_with_a_flat_holder(runs):
    _, meshed = runs
    from fenicsx_drape.forming.tools import MeshedTool

    assert all(isinstance(t, MeshedTool) for t in meshed.tools.values())
    assert meshed.tools["holder"].flat and not meshed.tools["punch"].flat
    assert meshed.tools["punch"].field.h == pytest.approx(1.0, rel=0.1)


def test_meshed_hemisphere_reaches_full_travel_and_agrees_with_the_closed_form(runs):
    exact, meshed = runs
    assert meshed.stopped is None and meshed.travel_mm == pytest.approx(80.0)
    assert meshed.cutbacks <= exact.cutbacks + 2
    shear = [float(np.nanmax(np.abs(r.grid.shear_deg()))) for r in runs]
    assert shear[0] > 30.0  # a formed part, not a flat sheet
    assert abs(shear[1] - shear[0]) < SHEAR_TOL_DEG
    d = np.linalg.norm(meshed.grid.x - exact.grid.x, axis=-1)
    assert np.nanmax(d) < NODE_TOL_MM
    # Penetration measured with each run's own tools: the same to the spline's bias.
    assert abs(meshed.max_penetration_mm - exact.max_penetration_mm) < 0.05


def test_kinematic_drape_on_the_meshed_tools_agrees_with_the_closed_form():
    nets = [drape_case(load_case(HERE / name)) for name in ("case.toml", "case_meshed.toml")]
    shear = [n.summary()["max_shear_deg"] for n in nets]
    assert shear[0] == pytest.approx(62.5, abs=0.2)  # the paper's 61° (Fig. 11a: 62.5)
    assert abs(shear[1] - shear[0]) < SHEAR_TOL_DEG
    assert not nets[1].unplaced.any()
