"""What a lab measures, taken from a formed sheet (fenicsx_drape.forming.running.measure):
closest points, shear by the lab's definition (each cell's own angle at its centre), the
blank's edge and draw-in, on sheets with known answers."""

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


def turned_net(θ_deg: float, F: np.ndarray, cell_mm: float = 10.0, half_mm: float = 60.0,
               clip_mm: float | None = 45.0) -> FormedGrid:
    """A net with its tows at θ to x, mapped by the plane affine map F, clipped to a square
    (absent nodes NaN, as a turned ply's net)."""
    θ = math.radians(θ_deg)
    R = np.array([[math.cos(θ), -math.sin(θ)], [math.sin(θ), math.cos(θ)]])
    s = np.arange(-half_mm, half_mm + 1e-9, cell_mm)
    ij = np.stack(np.meshgrid(s, s, indexing="ij"), axis=-1)
    X2 = ij @ R.T
    X = np.concatenate([X2, np.zeros((*X2.shape[:2], 1))], axis=-1)
    x = np.concatenate([X2 @ F.T, np.full((*X2.shape[:2], 1), 3.0)], axis=-1)
    if clip_mm is not None:
        cells = np.all(np.abs(X2) <= clip_mm, axis=-1)
        keep = np.zeros(cells.shape, bool)  # the nodes of cells with four corners inside
        whole = cells[:-1, :-1] & cells[1:, :-1] & cells[:-1, 1:] & cells[1:, 1:]
        for di in (0, 1):
            for dj in (0, 1):
                keep[di:di + whole.shape[0], dj:dj + whole.shape[1]] |= whole
        X[~keep], x[~keep] = np.nan, np.nan
    return FormedGrid(X, x, False)


def formed(quarter: bool = False, cell_mm: float = 10.0) -> FormedGrid:
    """A non-affine formed sheet: a dome with a twist (each cell its own shear)."""
    s = np.arange(0.0 if quarter else -60.0, 60.0 + 1e-9, cell_mm)
    X = np.stack([*np.meshgrid(s, s, indexing="ij"), np.zeros((s.size, s.size))], axis=-1)
    r2 = X[..., 0] ** 2 + X[..., 1] ** 2
    x = X.copy()
    # Odd in x and in y (symmetric in both planes), so a quarter is a part of it.
    x[..., 0] += 4e-3 * X[..., 0] * X[..., 1] ** 2 / 10.0
    x[..., 1] += 2e-3 * X[..., 1] * X[..., 0] ** 2 / 10.0
    x[..., 2] = 30.0 * np.exp(-r2 / 2000.0)
    return FormedGrid(X, x, quarter)


def centres(grid: FormedGrid) -> np.ndarray:
    """The flat positions of the cell centres (n_i − 1, n_j − 1, 2)."""
    X = grid.X[..., :2]
    return 0.25 * (X[:-1, :-1] + X[1:, :-1] + X[:-1, 1:] + X[1:, 1:])


def test_every_definition_gives_the_exact_angle_on_a_homogeneously_sheared_sheet():
    """Simple shear of 20°, and a turned, clipped net under a general plane map: each
    cell's own angle, the node means and the value anywhere on the blank are the angle
    between the mapped tows, 90° − ∠(F a, F b)."""
    grid = sheet(shear_deg=20.0)
    rng = np.random.default_rng(1)
    P = rng.uniform(-50.0, 50.0, (300, 2))
    assert np.allclose(measure.shear_at_flat(grid, P), 20.0, atol=1e-9)
    assert np.allclose(grid.shear_deg(), 20.0, atol=1e-9)
    assert np.allclose(grid.shear_nodes(), 20.0, atol=1e-9)
    F = np.array([[1.1, 0.35], [-0.05, 0.9]])
    for θ in (0.0, 30.0):
        net = turned_net(θ, F)
        t = math.radians(θ)
        a, b = F @ [math.cos(t), math.sin(t)], F @ [-math.sin(t), math.cos(t)]
        exact = 90.0 - math.degrees(math.acos(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))
        Q = rng.uniform(-45.0, 45.0, (400, 2))
        got = measure.shear_at_flat(net, Q)
        on = np.isfinite(got)
        assert on.mean() > 0.5  # the square's corners beyond the turned net's cells are off
        assert np.allclose(got[on], exact, atol=1e-9)
        assert np.allclose(net.shear_deg()[np.isfinite(net.shear_deg())], exact, atol=1e-9)
        assert np.allclose(net.shear_nodes()[net.present], exact, atol=1e-9)
        assert np.isnan(measure.shear_at_flat(net, np.array([[80.0, 0.0]]))).all()


def test_the_shear_at_a_cell_centre_is_that_cells_own_angle():
    """On a formed sheet (non-affine: every cell its own angle) the value at each centre
    is the cell's own angle to 1e-9, not a mean of its nodes' means; between two centres it
    is their mean, and at a node the mean of the cells around it (the grid's shear_deg)."""
    grid = formed()
    γ = grid.shear_deg()
    C = centres(grid)
    got = measure.shear_at_flat(grid, C.reshape(-1, 2)).reshape(γ.shape)
    assert np.abs(got - γ).max() < 1e-9
    nodal = grid.shear_nodes()
    old = 0.25 * (nodal[:-1, :-1] + nodal[1:, :-1] + nodal[:-1, 1:] + nodal[1:, 1:])
    assert np.abs(old - γ).max() > 0.1  # the node means' value there is another one
    mid = 0.5 * (C[3, 4] + C[4, 4])
    assert measure.shear_at_flat(grid, mid[None])[0] == pytest.approx(
        0.5 * (γ[3, 4] + γ[4, 4]), abs=1e-9)
    nodes = grid.X[..., :2].reshape(-1, 2)
    assert np.allclose(measure.shear_at_flat(grid, nodes), nodal.ravel(), atol=1e-9)
    # A quarter model: its mirrored cells count, so it is the whole sheet's field, 0 on
    # the symmetry planes.
    quarter = formed(quarter=True)
    Cq = centres(quarter).reshape(-1, 2)
    assert np.allclose(measure.shear_at_flat(quarter, Cq), quarter.shear_deg().ravel(),
                       atol=1e-9)
    assert np.allclose(measure.shear_at_flat(quarter, Cq), measure.shear_at_flat(grid, Cq),
                       atol=1e-9)
    assert np.allclose(measure.shear_at_flat(quarter, [[0.0, 17.0], [23.0, 0.0]]), 0.0,
                       atol=1e-12)
    # A clipped net: at each present cell's centre, its angle; an absent cell is off.
    F = np.array([[1.0, 0.2], [0.0, 1.0]])
    net = turned_net(30.0, F)
    bent = FormedGrid(net.X, net.x + np.stack([0.002 * net.X[..., 1] ** 2,
                                               np.zeros(net.X.shape[:2]),
                                               0.01 * net.X[..., 0] ** 2], -1), False)
    γb, Cb = bent.shear_deg(), centres(bent)
    ok = np.isfinite(γb)
    assert np.abs(measure.shear_at_flat(bent, Cb[ok]) - γb[ok]).max() < 1e-9
    assert np.isnan(measure.shear_at_flat(bent, Cb[~ok & np.isfinite(Cb[..., 0])])).all()


def test_the_shear_at_a_formed_point_is_the_closest_material_points():
    grid = formed()
    mesh = measure.SheetMesh.of(grid)
    C = centres(grid).reshape(-1, 2)
    on_sheet = grid.sample(C)  # formed images of the centres (bilinear within the cell)
    near = measure.closest_points(mesh, on_sheet)
    values, _ = measure.shear_at_formed(grid, on_sheet, mesh)
    assert np.allclose(values, measure.shear_at_flat(grid, near.flat[:, :2]), atol=1e-12)
    # The bilinear image of a centre lies off the triangulated sheet of a curved cell: its
    # closest point's material position is within a tenth of the cell of the centre.
    assert np.abs(near.flat[:, :2] - C).max() < 0.1 * grid.cell_mm


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
        run = SimpleNamespace(tools=None, grid=SimpleNamespace(cell_mm=20.0))
        net, numbers = outputs._kinematic_beside(load_case("square_box", cell_mm=20.0), run,
                                                 tmp_path)
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
