"""The square box (meshes/square_box): a deep-drawn box formed to full travel."""

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dolfinx")
from mpi4py import MPI

from fenicsx_drape.forming.case.format import load_case
from fenicsx_drape.forming.running.run import run_case

SQUARE_BOX = Path(__file__).resolve().parents[1] / "meshes" / "square_box" / "case.toml"
COARSE = {"cell_mm": 20.0}
# The case's numbers (case.toml): punch half side, radii, depth = travel, end of the punch top.
A, R_CORNER, R_FILLET, DEPTH = 50.0, 20.0, 15.0, 25.0
END = 25.0  # s: the end of the punch's motion
TOP_END = DEPTH - 0.5  # the punch's top after full travel (it starts 0.5 mm below the blank)
DIE_OFFSET = 0.8  # 0.5 mm clearance + the 0.3 mm ply


@pytest.fixture(scope="module")
def quarter():
    return run_case(load_case(SQUARE_BOX, **COARSE), comm=MPI.COMM_SELF)


def test_the_case_file_builds_the_box_tools_from_gmsh():
    from fenicsx_drape.forming.case.format import build_tools
    from fenicsx_drape.forming.tools.shapes import MeshedTool

    tools = build_tools(load_case(SQUARE_BOX))
    assert all(isinstance(t, MeshedTool) for t in tools.values())
    punch, die, holder = tools["punch"], tools["die"], tools["holder"]
    # The punch's top starts 0.5 mm under the blank and moves rigidly by the depth.
    centre = np.array([[0.0, 0.0, 0.0], [20.0, 10.0, 0.0]])
    np.testing.assert_allclose(punch.gap(centre, 0.0).phi, 0.5, atol=1e-6)
    lifted = centre + np.array([0.0, 0.0, DEPTH])
    np.testing.assert_allclose(punch.gap(lifted, END).phi, 0.5, atol=1e-6)
    # At the end, 5 mm off the straight wall (x = a) and off the rounded vertical edge (radius
    # r_c about (a − r_c, a − r_c)), halfway up the straight wall (z = 4.5 to 9.5 mm between
    # the foot radius and the bottom fillet): faceting of a 3 mm mesh < 0.1 mm. The exact
    # distance: these points are near the medial axis of the concave foot, where the gridded
    # field that contact uses is smoothed (4.8 mm there).
    c = A - R_CORNER + (R_CORNER + 5.0) / np.sqrt(2.0)
    walls = np.array([[A + 5.0, 0.0, 7.0], [0.0, A + 5.0, 7.0], [c, c, 7.0]])
    np.testing.assert_allclose(punch.signed_distance(walls, END), 5.0, atol=0.1)
    # The die is the punch's end surface offset by clearance + ply: on top, wall and corner
    # (measured 0.70 mm there: the chords of a 3 mm mesh on the die's concave 20.8 mm radius
    # and the distance field's interpolation on its grid).
    on_punch = np.array([[0.0, 0.0, TOP_END], [A, 0.0, 7.0],
                         [A - R_CORNER * (1 - 1 / np.sqrt(2))] * 2 + [7.0]])
    np.testing.assert_allclose(die.gap(on_punch, END).phi, DIE_OFFSET, atol=0.15)
    # The holder clamps the flange, not the opening (140 mm square, 40 mm corners about
    # (30, 30)): 5 mm either side of the rounded corner of the opening.
    o = 30.0 + np.array([35.0, 45.0]) / np.sqrt(2.0)
    flange = np.array([[100.0, 0.0, 0.0], [0.0, 110.0, 0.0], [o[1], o[1], 0.0]])
    opening = np.array([[60.0, 0.0, 0.0], [0.0, 0.0, 0.0], [o[0], o[0], 0.0]])
    assert holder.covers(flange, 0.0).all()
    assert not holder.covers(opening, 0.0).any()


@pytest.mark.skip_in_parallel
def test_the_square_box_is_formed_to_full_travel(quarter):
    assert quarter.stopped is None and quarter.travel_mm == pytest.approx(DEPTH)
    assert quarter.max_penetration_mm < 0.1 * quarter.case.blank.cell_mm
    x = quarter.grid.x
    # The box bottom (the punch's flat top, |x|, |y| < a − r_b) holds the sheet between the
    # punch and the die: within the penetration below the punch, at most the die offset above.
    bottom = (np.abs(x[..., 0]) < A - R_FILLET) & (np.abs(x[..., 1]) < A - R_FILLET)
    assert bottom.sum() >= 4
    z = x[..., 2][bottom]
    assert np.all(z > TOP_END - quarter.max_penetration_mm - 1e-6)
    assert np.all(z < TOP_END + DIE_OFFSET)
    # The flange's far corner stays clamped on the holder's plane.
    assert abs(x[-1, -1, 2]) < 0.5
    # Draw-in: the tows along x and y carry the depth into the flange (they hardly stretch),
    # so the middle of a side is drawn in most; the corner shears on the bias instead.
    d = quarter.draw_in_mm
    assert d["mid_side_mm"] > 5.0
    assert 0.0 < d["corner_mm"] < 0.5 * d["mid_side_mm"]
    # The tow on the symmetry plane y = 0 keeps its length (tow strains are small).
    tow = np.sum(np.linalg.norm(np.diff(x[:, 0], axis=0), axis=-1))
    flat = np.sum(np.linalg.norm(np.diff(quarter.grid.X[:, 0], axis=0), axis=-1))
    assert tow == pytest.approx(flat, rel=0.01)


@pytest.mark.skip_in_parallel
def test_the_square_box_is_symmetric_about_the_diagonal(quarter):
    """Box, blank and holder are square with the tows along x and y: x ↔ y maps the quarter
    onto itself (warp onto weft). The tool meshes are not symmetric, hence the tolerances."""
    x = quarter.grid.x
    mirrored = np.transpose(x, (1, 0, 2))[..., [1, 0, 2]]
    np.testing.assert_allclose(x, mirrored, atol=0.1)  # mm; measured 0.01 at Δ = 20 mm
    γ = quarter.grid.shear_deg()
    np.testing.assert_allclose(γ, γ.T, atol=0.5)  # degrees; measured 0.02 at Δ = 20 mm
    # The shear is at the rounded vertical edge, on the bias: the largest |γ| lies in a cell
    # on or next to the diagonal, and the cells along the axes stay nearly unsheared.
    i, j = np.unravel_index(np.nanargmax(np.abs(γ)), γ.shape)
    assert abs(i - j) <= 1
    assert np.nanmax(np.abs(γ)) > 20.0
    assert np.nanmax(np.abs(γ[0, :])) < 5.0 and np.nanmax(np.abs(γ[:, 0])) < 5.0


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_drape_form_says_the_kinematic_drape_is_partial(tmp_path, capsys):
    """On 20 mm cells the kinematic net leaves the box's tools before it covers the blank:
    the command, the summary and the picture say how much it placed."""
    import json

    from fenicsx_drape.cli import main

    out = tmp_path / "box"
    assert main(["form", "square_box", "--out", str(out), "--cell-mm", "20", "--no-fields",
                 "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    placed, total = summary["kinematic_placed_nodes"], summary["kinematic_blank_nodes"]
    assert total == 13 * 13 and 0 < placed < total and not summary["kinematic_complete"]
    assert summary["kinematic_unplaced_nodes"] == total - placed
    printed = capsys.readouterr().out
    assert f"PARTIAL: {placed} of {total} nodes" in printed
    assert f"max shear {summary['kinematic_max_shear_deg']:.1f}° on them only" in printed
    assert (out / "kinematic_shear.png").stat().st_size > 0
