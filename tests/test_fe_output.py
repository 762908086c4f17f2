"""Outputs: the drawn grid, shear per unit cell and tow strains from node positions."""

import pytest

pytest.importorskip("dolfinx")

from mpi4py import MPI

import numpy as np

from fenicsx_drape.fe import TrussProblem, grid_points, truss_sheet, write_grid_csv
from fenicsx_drape.model import default_model

F = np.array([[1.05, 0.2, 0.0], [0.0, 0.97, 0.0], [0.1, -0.05, 1.0]])  # affine map, 3D


def _deformed(cell_mm, quarter):
    sheet = truss_sheet(120.0, cell_mm, quarter=quarter)
    problem = TrussProblem(sheet, default_model())
    problem.u.interpolate(lambda X: (F - np.eye(3)) @ X)
    return problem.results()


@pytest.mark.parallel
@pytest.mark.parametrize(("cell_mm", "quarter"), [(10.0, True), (60 / 7, False)])
def test_drawn_grid_follows_an_affine_deformation(cell_mm, quarter):
    res = _deformed(cell_mm, quarter)
    cols = grid_points(res, grid_mm=10.0)
    n = 7 if quarter else 13  # drawn lines 0..60 or -60..60 mm every 10 mm
    assert len(cols["i"]) == n * n
    X0 = np.column_stack([cols["x0_mm"], cols["y0_mm"], np.zeros(n * n)])
    np.testing.assert_allclose(X0[:, :2], 10.0 * np.column_stack([cols["i"], cols["j"]]),
                               atol=1e-9)
    x = np.column_stack([cols["x_mm"], cols["y_mm"], cols["z_mm"]])
    np.testing.assert_allclose(x, X0 @ F.T, atol=1e-9)  # bilinear is exact for affine maps


@pytest.mark.parallel
def test_shear_and_tow_strains_of_a_homogeneous_state():
    res = _deformed(10.0, True)
    warp, weft = F[:, 0], F[:, 1]
    shear = 90.0 - np.degrees(np.arccos(warp @ weft / np.linalg.norm(warp) / np.linalg.norm(weft)))
    np.testing.assert_allclose(res.shear_deg, shear, atol=1e-9)
    np.testing.assert_allclose(res.warp_strain, 0.5 * (warp @ warp - 1), atol=1e-12)
    np.testing.assert_allclose(res.weft_strain, 0.5 * (weft @ weft - 1), atol=1e-12)
    assert res.weft_strain.max() < 0  # the weft is shortened: wrinkling on every weft bar
    # Σ w L ε⁻ / Σ w L: warp and weft have the same total weight, the warp is stretched.
    assert res.total_wrinkling_strain == pytest.approx(0.5 * 0.5 * (weft @ weft - 1))


@pytest.mark.parallel
def test_grid_csv(tmp_path_factory):
    comm = MPI.COMM_WORLD
    folder = comm.bcast(str(tmp_path_factory.mktemp("csv")) if comm.rank == 0 else None)
    res = _deformed(10.0, True)
    path = write_grid_csv(res, f"{folder}/grid.csv")
    comm.Barrier()
    table = np.genfromtxt(path, delimiter=",", names=True)
    assert table.dtype.names == ("i", "j", "x0_mm", "y0_mm", "x_mm", "y_mm", "z_mm")
    np.testing.assert_allclose(table["z_mm"], 0.1 * table["x0_mm"] - 0.05 * table["y0_mm"],
                               atol=2e-6)
