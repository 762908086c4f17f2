"""What a lab measures, taken from a formed sheet (fenicsx_drape.forming.running.measure): closest
points, shear within the cell, the blank's edge and draw-in, on sheets with known answers."""

import math

import numpy as np
import pytest

from fenicsx_drape.forming.running import measure
from fenicsx_drape.forming.running.post import FormedGrid


def sheet(shear_deg: float = 0.0, lift_mm: float = 0.0, cell_mm: float = 10.0,
          half_mm: float = 50.0, shrink: float = 1.0) -> FormedGrid:
    """A whole square blank deformed affinely: simple shear, lifted, shrunk in plane."""
    s = np.arange(-half_mm, half_mm + 1e-9, cell_mm)
    X = np.stack([*np.meshgrid(s, s, indexing="ij"), np.zeros((s.size, s.size))], axis=-1)
    t = math.tan(math.radians(shear_deg))
    x = X.copy()
    x[..., 0] = shrink * (X[..., 0] + t * X[..., 1])
    x[..., 1] = shrink * X[..., 1]
    x[..., 2] = lift_mm
    return FormedGrid(X, x, False)


def test_closest_points_of_a_lifted_flat_sheet_are_straight_below():
    mesh = measure.SheetMesh.of(sheet(lift_mm=5.0))
    rng = np.random.default_rng(0)
    P = np.column_stack([rng.uniform(-45, 45, (500, 2)), rng.uniform(0, 10, 500)])
    near = measure.closest_points(mesh, P)
    assert np.allclose(near.signed, P[:, 2] - 5.0, atol=1e-9)
    assert np.allclose(near.flat[:, :2], P[:, :2], atol=1e-9)
    # Beyond the edge the closest point is on the edge.
    far = measure.closest_points(mesh, np.array([[60.0, 0.0, 5.0], [60.0, 60.0, 5.0]]))
    assert np.allclose(far.distance, [10.0, 10.0 * math.sqrt(2)])


def test_shear_is_interpolated_within_the_cell_not_taken_at_the_nearest_node():
    grid = sheet(shear_deg=20.0)  # uniform simple shear: the angle is 20° everywhere
    P = np.array([[3.0, 4.0], [-17.0, 22.0]])
    assert np.allclose(measure.shear_at_flat(grid, P), 20.0, atol=1e-9)
    # A field varying within a cell: shear only in the cells x > 0 (a kink at x = 0).
    g = sheet()
    x = g.x.copy()
    right = g.X[..., 0] > 0
    x[..., 0] = np.where(right, g.X[..., 0] + math.tan(math.radians(10)) * g.X[..., 1],
                         g.X[..., 0])
    kinked = FormedGrid(g.X, x, False)
    nodal = kinked.shear_nodes()
    at = np.array([[2.5, 1.0], [7.5, 1.0]])  # a quarter and three quarters into one cell
    i0 = 5  # node x = 0
    expected = nodal[i0, 5] + np.array([0.25, 0.75]) * (nodal[i0 + 1, 5] - nodal[i0, 5])
    got = measure.shear_at_flat(kinked, at)
    assert np.allclose(got, expected, atol=0.1 * abs(expected[1] - expected[0]))
    assert got[1] - got[0] > 1.0  # differs within the cell


def test_the_edge_and_draw_in_of_a_shrunk_blank():
    grid = sheet(shrink=0.9)  # every edge point drawn in by 10 %
    mesh = measure.SheetMesh.of(grid)
    edge = measure.closest_on_edge(mesh, np.array([[45.0, 0.0], [48.0, 10.0], [40.0, 0.0]]))
    assert np.allclose(edge["signed"], [0.0, 3.0, -5.0], atol=1e-9)
    # Radial draw-in of the edge's material point: (50, y0) formed at (45, 0.9 y0).
    y0 = 10.0 / 0.9
    assert np.allclose(edge["draw_in"], [5.0, math.hypot(50.0, y0) - math.hypot(45.0, 10.0),
                                         5.0], atol=1e-9)
    e, outward = measure.edge_segments(mesh)
    assert len(e) == 40 and np.allclose(np.abs(outward).sum(axis=1), 1.0)


def test_coverage_of_a_scan_of_a_third_of_the_sheet():
    mesh = measure.SheetMesh.of(sheet())
    s = np.arange(-50.0, 50.0 + 1e-9, 1.0)
    P = np.stack(np.meshgrid(s, s, indexing="ij"), -1).reshape(-1, 2)
    third = P[P[:, 0] < -50.0 + 100.0 / 3.0]
    cover = measure.coverage(mesh, np.column_stack([third, np.zeros(len(third))]))
    assert cover == pytest.approx(0.4, abs=0.07)


def test_the_tool_forces_are_written_as_a_table_a_picture_and_peaks(tmp_path):
    from types import SimpleNamespace

    from fenicsx_drape.forming.running.outputs import write_tool_forces

    rows = [{"time_s": t, "travel_mm": 2.0 * t, "punch": 3.0 * t, "die": -4.0 * t}
            for t in (1.0, 2.0, 3.0)]
    run = SimpleNamespace(tool_forces=rows)
    peaks = write_tool_forces(run, tmp_path, "part")
    assert peaks == {"max_tool_force_N": {"punch": 9.0, "die": -12.0},
                     "tool_forces_file": "tool_forces.csv"}
    table = np.loadtxt(tmp_path / "tool_forces.csv", delimiter=",", skiprows=1)
    assert (tmp_path / "tool_forces.csv").read_text().startswith("time_s,travel_mm,punch,die")
    assert np.allclose(table[:, 3], [-4.0, -8.0, -12.0])
    assert (tmp_path / "tool_forces.png").stat().st_size > 1000


def test_a_step_whose_force_stands_out_of_its_neighbours_is_noted(tmp_path):
    """A one-step spike (the holder's −94 N among −37 N) is listed and the peak without it
    given; a steep but steady rise (a die closing) and the ends of the curve are not."""
    from types import SimpleNamespace

    from fenicsx_drape.forming.running.outputs import outliers, write_tool_forces

    travel = np.arange(0.0, 20.0, 1.0)
    holder = -37.0 - 0.1 * travel
    holder[12] = -94.0
    punch = np.where(travel < 10.0, 2.0 * travel, 20.0 + 40.0 * (travel - 10.0))  # a kink
    punch[-1] += 200.0  # the last step has one neighbour: never listed
    assert list(outliers(travel, holder)) == [12]
    assert list(outliers(travel, punch)) == []
    # The neighbours' line is in travel: a step at an uneven spacing is not a spike.
    assert list(outliers(np.array([0.0, 0.1, 10.0]), np.array([0.0, 1.0, 100.0]))) == []
    rows = [{"time_s": s, "travel_mm": s, "punch": p, "holder": h}
            for s, p, h in zip(travel, punch, holder)]
    result = write_tool_forces(SimpleNamespace(tool_forces=rows), tmp_path, "part")
    assert result["max_tool_force_N"]["holder"] == -94.0  # every converged step counts ...
    (spike,) = result["tool_force_outliers"]  # ... and the spike is said
    assert spike == {"tool": "holder", "step": 13, "travel_mm": 12.0, "force_N": -94.0,
                     "neighbours_N": [pytest.approx(-38.1), pytest.approx(-38.3)]}
    notes = "\n".join(result["tool_force_notes"])
    assert "step 13" in notes and "-38.9 N without the steps" in notes


def test_a_partial_kinematic_drape_says_how_much_it_placed(tmp_path, monkeypatch):
    """The square box's 240 mm blank on 20 mm cells: 13 × 13 nodes, not all on the tools."""
    import warnings
    from types import SimpleNamespace

    from fenicsx_drape.forming.case.format import load_case
    from fenicsx_drape.forming.running import outputs

    titles = []
    monkeypatch.setattr(outputs, "plot_shear", lambda grid, path, title: titles.append(title))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # said in the summary, not as a Python warning
        net, numbers = outputs._kinematic_beside(load_case("square_box", cell_mm=20.0),
                                                 SimpleNamespace(tools=None), tmp_path)
    placed = int(net.present.sum())
    assert numbers["kinematic_blank_nodes"] == 13 * 13
    assert numbers["kinematic_placed_nodes"] == placed < 13 * 13
    assert numbers["kinematic_unplaced_nodes"] == 13 * 13 - placed
    assert numbers["kinematic_complete"] is False
    assert numbers["kinematic_max_shear_deg"] == pytest.approx(
        np.nanmax(np.abs(net.shear_deg())))
    text = outputs.kinematic_text(numbers)
    assert f"PARTIAL: {placed} of 169 nodes" in text and "on them only" in text
    assert titles and text in titles[0]
    complete = {"kinematic_max_shear_deg": 27.7, "kinematic_complete": True}
    assert outputs.kinematic_text(complete) == "max shear 27.7°"
