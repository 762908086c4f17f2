"""The truss mesh of the woven sheet: counts, tags and lengths on any number of ranks."""

import pytest

pytest.importorskip("dolfinx")

from mpi4py import MPI

import dolfinx
import numpy as np
import ufl

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.fe import load_sheet, read_grid, sheet_grid, truss_sheet, write_grid
from fenicsx_drape.fe.grid import BORDER, SYMMETRY_X, SYMMETRY_Y, WARP, WEFT


def _global_tag_count(tags, value, owned_entities):
    local = np.count_nonzero((tags.values == value) & (tags.indices < owned_entities))
    return MPI.COMM_WORLD.allreduce(local)


@pytest.mark.parallel
@pytest.mark.parametrize("quarter", [False, True])
def test_counts_lengths_and_tags(quarter):
    sheet = truss_sheet(240.0, 20.0, quarter=quarter)
    grid, mesh = sheet.grid, sheet.mesh
    n = grid.nx  # cells per side: 12 full, 6 quarter
    assert n == (6 if quarter else 12)
    assert sheet.num_nodes_global == (n + 1) ** 2  # no node duplicated by the partition
    n_bars = 2 * n * (n + 1) + 2 * n * n
    assert mesh.topology.index_map(1).size_global == n_bars
    length = dolfinx.fem.assemble_scalar(dolfinx.fem.form(1.0 * ufl.dx(domain=mesh)))
    Δ = 20.0
    exact = 2 * n * (n + 1) * Δ + 2 * n * n * Δ * np.sqrt(2)
    assert np.isclose(mesh.comm.allreduce(length), exact, rtol=1e-12)
    owned_cells = mesh.topology.index_map(1).size_local
    for kind in (WARP, WEFT):
        assert _global_tag_count(sheet.bar_tags, kind, owned_cells) == n * (n + 1)
    # Vertex tags: count each flagged node once (owned vertices only).
    owned_vertices = mesh.topology.index_map(0).size_local
    tags = sheet.node_tags

    def count(bit):
        local = np.count_nonzero(((tags.values & bit) != 0) & (tags.indices < owned_vertices))
        return mesh.comm.allreduce(local)

    if quarter:
        assert (count(SYMMETRY_X), count(SYMMETRY_Y), count(BORDER)) == (n + 1, n + 1, 2 * n + 1)
    else:
        assert (count(SYMMETRY_X), count(SYMMETRY_Y), count(BORDER)) == (0, 0, 4 * n)


@pytest.mark.parallel
def test_no_vertex_at_the_diagonal_crossing():
    sheet = truss_sheet(40.0, 20.0, quarter=True)  # one cell
    x = sheet.mesh.geometry.x
    centre = np.isclose(x[:, 0], 10.0) & np.isclose(x[:, 1], 10.0)
    assert not sheet.mesh.comm.allreduce(bool(centre.any()), op=MPI.LOR)
    assert sheet.num_nodes_global == 4


def test_cell_size_fits_the_half_sheet():
    grid = sheet_grid(240.0, 8.6, quarter=True)  # the paper's finest quarter: 225 nodes
    assert grid.nx == 14 and np.isclose(grid.cell_mm, 120.0 / 14)
    assert len(grid.nodes) == 225
    with pytest.raises(DrapeInputError, match="cell_mm"):
        sheet_grid(240.0, 0.0)


@pytest.mark.parallel
@pytest.mark.parametrize("suffix", [".msh", ".xdmf"])
def test_write_and_read_back(tmp_path_factory, suffix):
    comm = MPI.COMM_WORLD
    folder = comm.bcast(str(tmp_path_factory.mktemp("mesh")) if comm.rank == 0 else None)
    path = f"{folder}/sheet{suffix}"
    grid = sheet_grid(240.0, 30.0, quarter=True)
    if comm.rank == 0:
        write_grid(grid, path)
        back = read_grid(path)
        assert back.nx == grid.nx and back.quarter
        assert np.isclose(back.cell_mm, grid.cell_mm)
        np.testing.assert_allclose(back.nodes, grid.nodes)
    comm.Barrier()
    sheet = load_sheet(path)
    assert sheet.num_nodes_global == (grid.nx + 1) ** 2


def test_read_rejects_a_non_truss(tmp_path):
    import meshio

    path = tmp_path / "tri.xdmf"
    meshio.Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]),
                [("triangle", np.array([[0, 1, 2]]))]).write(path, data_format="XML")
    with pytest.raises(DrapeInputError, match="no line cells"):
        read_grid(path)
    with pytest.raises(DrapeInputError, match="no such"):
        read_grid(tmp_path / "missing.msh")


def test_mesh_command_writes_the_papers_quarter(tmp_path):
    """``drape mesh --cell-mm 10 --quarter --out DIR`` gives the 169-node quarter of meshes/."""
    from pathlib import Path

    from fenicsx_drape.cli import main

    assert main(["mesh", "--cell-mm", "10", "--quarter", "--out", str(tmp_path)]) == 0
    stored = read_grid(Path(__file__).parents[1] / "meshes" / "quarter_10mm" / "sheet.msh")
    for suffix in (".msh", ".xdmf"):
        grid = read_grid(tmp_path / f"sheet{suffix}")
        assert len(grid.nodes) == 169 and grid.quarter
        np.testing.assert_allclose(grid.nodes, stored.nodes)
    assert (tmp_path / "provenance.json").exists()
    assert main(["mesh", "--cell-mm", "-1", "--out", str(tmp_path / "bad")]) == 2
