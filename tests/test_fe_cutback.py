"""Step cut-back: a too-large step fails, is reverted, halved and recovered from."""

import pytest

pytest.importorskip("dolfinx")

from pathlib import Path

import numpy as np

from fenicsx_drape.errors import SolverError
from fenicsx_drape.fe import SolverOptions, TrussProblem, truss_sheet
from fenicsx_drape.model import default_model

SIZE, D = 40.0, 40.0 * np.sqrt(2.0)


def _bias_patch(max_it):
    """A patch in bias with the paper's rate-dependent, path-dependent shear law."""
    sheet = truss_sheet(SIZE, 10.0, rotation_deg=45.0)
    problem = TrussProblem(sheet, default_model(), options=SolverOptions(snes_max_it=max_it))
    problem.fix("all", (2,))
    problem.fix("border", (0,), lambda t, X: 0.006 * t * X[:, [0]])
    problem.fix(lambda X: np.isclose(np.abs(X[:, 0]), D / 2), (1,))
    return problem


@pytest.mark.parallel
def test_too_large_step_is_cut_back_and_recovered():
    problem = _bias_patch(max_it=4)
    report = problem.run(40.0, 40.0, growth=2.0)
    assert report.cutbacks >= 1  # the 40 s step cannot be done in 4 Newton iterations
    assert problem.t == pytest.approx(40.0)
    accepted = [s.time_s for s in report.accepted]
    failed = [s for s in report.steps if not s.converged]
    assert all(s.reason.startswith("DIVERGED") for s in failed)

    # The same accepted steps without failures give the same state: failed attempts left
    # no trace in the laws' history.
    reference = _bias_patch(max_it=25)
    for t in accepted:
        assert reference.step(t).converged
    a, b = problem.results(), reference.results()
    np.testing.assert_allclose(a.x, b.x, atol=1e-9)
    np.testing.assert_allclose(problem.reaction_force("border"),
                               reference.reaction_force("border"), atol=1e-8)
    assert a.max_shear_deg > 10.0


@pytest.mark.parallel
def test_step_floor_raises_and_saves_the_last_state(tmp_path_factory):
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    folder = comm.bcast(str(tmp_path_factory.mktemp("failed")) if comm.rank == 0 else None)
    problem = _bias_patch(max_it=1)
    with pytest.raises(SolverError, match="cannot be cut below") as err:
        problem.run(40.0, 20.0, dt_min_s=5.0, failure_dir=folder)
    assert str(Path(folder) / "state.npz") in str(err.value)
    saved = np.load(Path(folder) / "state.npz")
    assert float(saved["time_s"]) == problem.t
    np.testing.assert_allclose(saved["x"], problem.results().x)
