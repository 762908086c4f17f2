"""DOLFINx smoke test: a branching truss distributes and assembles correctly on any number of ranks.

The woven sheet is a net of bars (interval cells in 3D) with eight bars meeting at every interior
node: warp, weft and both diagonals of each unit cell, the diagonals crossing without a node.
DOLFINx before 0.10 duplicated the nodes of such a mesh on partition boundaries, so a parallel
run solved a torn structure; these checks fail if that comes back.
"""

import numpy as np
import pytest

dolfinx = pytest.importorskip("dolfinx")

from mpi4py import MPI  # noqa: E402

import basix.ufl  # noqa: E402
import ufl  # noqa: E402
from dolfinx import fem  # noqa: E402

BARS_PER_NODE = 8  # warp, weft and two diagonals on each side of an interior node


def woven_net(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and bars of an n×n grid of unit cells with warp, weft and both diagonals.

    The sheet is bent slightly out of its plane (z up to 0.1) so that the bars are honest 3D
    segments. Node ``(i, j)`` at ``x = i, y = j`` has index ``j*(n + 1) + i``.

    Returns:
        The node coordinates, shape ``(n_nodes, 3)``, and the bars as node pairs, shape
        ``(n_bars, 2)``.
    """
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    x, y = i.ravel().astype(float), j.ravel().astype(float)
    z = 0.1 * np.sin(np.pi * x / n) * np.sin(np.pi * y / n) + 0.02 * x * y / n**2
    node = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)  # node[j, i]
    bars = np.vstack(
        [
            np.column_stack([node[:, :-1].ravel(), node[:, 1:].ravel()]),  # warp
            np.column_stack([node[:-1, :].ravel(), node[1:, :].ravel()]),  # weft
            np.column_stack([node[:-1, :-1].ravel(), node[1:, 1:].ravel()]),  # diagonal
            np.column_stack([node[:-1, 1:].ravel(), node[1:, :-1].ravel()]),  # antidiagonal
        ]
    )
    return np.column_stack([x, y, z]), bars


def truss_mesh(comm: MPI.Comm, n: int) -> tuple[dolfinx.mesh.Mesh, np.ndarray, np.ndarray]:
    """The woven net as a DOLFINx mesh of interval cells; rank 0 holds the input.

    Returns:
        The mesh, and the input nodes and bars (on every rank, for reference values).
    """
    points, bars = woven_net(n)
    element = basix.ufl.element("Lagrange", "interval", 1, shape=(3,))
    mine = comm.rank == 0
    mesh = dolfinx.mesh.create_mesh(
        comm,
        bars if mine else np.empty((0, 2), dtype=np.int64),
        element,
        points if mine else np.empty((0, 3)),
        max_facet_to_cell_links=BARS_PER_NODE,
    )
    return mesh, points, bars


@pytest.mark.parallel
@pytest.mark.parametrize("n", [1, 4, 12])
def test_branching_truss_is_one_structure(n):
    comm = MPI.COMM_WORLD
    mesh, points, bars = truss_mesh(comm, n)

    assert mesh.topology.dim == 1 and mesh.geometry.dim == 3
    assert mesh.topology.index_map(0).size_global == (n + 1) ** 2
    assert mesh.topology.index_map(1).size_global == len(bars) == 2 * n * (n + 1) + 2 * n**2

    length = np.linalg.norm(points[bars[:, 1]] - points[bars[:, 0]], axis=1)
    total = comm.allreduce(fem.assemble_scalar(fem.form(1.0 * ufl.dx(domain=mesh))), op=MPI.SUM)
    assert total == pytest.approx(length.sum(), rel=1e-12)


@pytest.mark.parallel
def test_interior_nodes_join_eight_bars():
    """Each node's share of ∫v dx is half the length of the bars meeting there.

    A node duplicated on a partition boundary would hold only part of that sum.
    """
    comm, n = MPI.COMM_WORLD, 6
    mesh, points, bars = truss_mesh(comm, n)
    V = fem.functionspace(mesh, ("Lagrange", 1))
    assert V.dofmap.index_map.size_global == (n + 1) ** 2

    length = np.linalg.norm(points[bars[:, 1]] - points[bars[:, 0]], axis=1)
    expected = 0.5 * (np.bincount(bars[:, 0], length, len(points))
                      + np.bincount(bars[:, 1], length, len(points)))
    assert np.bincount(bars.ravel()).max() == BARS_PER_NODE

    b = fem.assemble_vector(fem.form(ufl.TestFunction(V) * ufl.dx))
    b.scatter_reverse(dolfinx.la.InsertMode.add)
    owned = V.dofmap.index_map.size_local
    xy = V.tabulate_dof_coordinates()[:owned, :2]
    node = np.rint(xy[:, 1]).astype(int) * (n + 1) + np.rint(xy[:, 0]).astype(int)
    np.testing.assert_allclose(b.array[:owned], expected[node], rtol=1e-12)
    assert comm.allreduce(owned, op=MPI.SUM) == (n + 1) ** 2
