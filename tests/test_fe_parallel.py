"""The same problem on 1, 2 and 3 ranks gives the same nodes and global quantities.

Run serially and under ``mpirun -n 2`` / ``-n 3``: each run compares the distributed solve on
``COMM_WORLD`` with a serial reference solved on ``COMM_SELF`` inside the same test.
"""

import pytest

pytest.importorskip("dolfinx")

from mpi4py import MPI

import numpy as np

from fenicsx_drape.fe import SolverOptions, TrussProblem, truss_sheet
from fenicsx_drape.model import default_model


class SoftPunch:
    """A nodal term: nodes within 15 mm of the axis are pushed up by springs to z = 5t mm."""

    k = 50.0  # N/mm

    def bind(self, X, owned, comm):
        self.under = np.hypot(X[:, 0], X[:, 1]) <= 15.0 + 1e-9
        self.commits = 0

    def forces(self, x, t, dt):
        f = np.zeros_like(x)
        K = np.zeros((len(x), 3, 3))
        f[self.under, 2] = self.k * (5.0 * t - x[self.under, 2])
        K[self.under, 2, 2] = self.k
        return f, K

    def commit(self):
        self.commits += 1

    def revert(self):
        pass


def _solve(comm):
    sheet = truss_sheet(120.0, 10.0, quarter=True, comm=comm)
    punch = SoftPunch()
    # The drag regularises the flat start (free nodes carry no out-of-plane stiffness yet).
    problem = TrussProblem(sheet, default_model(), nodal_terms=[punch],
                           options=SolverOptions(drag_N_per_mm=1.0))
    problem.symmetry()
    problem.fix("border", (0, 1), lambda t, X: 0.01 * t * X[:, :2])
    problem.fix("border", (2,))
    report = problem.run(1.0, 0.25)
    assert punch.commits == len(report.accepted)
    res = problem.results()
    return res, problem.reaction_force("border"), report, sheet.num_nodes_global


@pytest.mark.parallel
def test_same_result_on_any_number_of_ranks():
    res, force, report, nodes = _solve(MPI.COMM_WORLD)
    ref, ref_force, ref_report, ref_nodes = _solve(MPI.COMM_SELF)
    assert nodes == ref_nodes == 49
    assert res.x[..., 2].max() > 3.0  # really lifted out of plane
    # SNES stops at |residual| < 1e-8 N; the softest stiffness is ~1 N/mm (the drag).
    np.testing.assert_allclose(res.x, ref.x, atol=1e-6)
    np.testing.assert_allclose(force, ref_force, atol=1e-6, rtol=1e-8)
    for key, value in res.summary().items():
        assert value == pytest.approx(ref.summary()[key], rel=1e-7, abs=1e-9), key
    assert [s.iterations for s in report.steps] == [s.iterations for s in ref_report.steps]
