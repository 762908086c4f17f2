"""Plies that slide over cells on several ranks: the pairs follow them, and every rank goes on.

A ply pulled 20 mm (2 cells) between a long ply held below and one held above: the pairs
follow it (fe/plies.py), and each new partner adds blocks to the Jacobian's pattern on the
ranks whose rows it touches: here those of the columns the pulled ply lies on, not the
others. Taking a pattern into the Jacobian is collective, so every rank must do it when any
pattern grew (a rank that did it alone waited in the matrix's assembly for ever). Without
pressure the pull-out's force is exact (ten Thije & Akkerman 2009): F = 2 A (τ₀ + η_f v)
with A the pulled ply's area, on any number of ranks, and the nodes are those of one process
within what Newton leaves.
"""

import pytest

pytest.importorskip("dolfinx")
from mpi4py import MPI

import numpy as np

from fenicsx_drape.fe.grid import TrussGrid
from fenicsx_drape.fe.plies import PlyContact, node_areas, ply_of, stack_plies, stack_sheet
from fenicsx_drape.fe.solver import SolverOptions, TrussProblem
from fenicsx_drape.materials.interply import InterplyLaw
from fenicsx_drape.model import default_model

TAU0, ETA = 0.005, 0.004  # MPa, MPa·s/mm (no μ: no pressure is needed)
SPEED, TRAVEL = 5.0, 20.0  # mm/s, mm


def pull(comm):
    """The middle ply pulled along x; its grip's force (N) after each step, and the stack."""
    long = TrussGrid(16, 2, 10.0, (-10.0, 0.0), False)  # the ranks' cuts across it
    pulled = TrussGrid(3, 2, 10.0, (0.0, 0.0), False)  # on one rank's columns
    plies = stack_plies([long, pulled, long], [0.2, 0.2, 0.2])
    law = InterplyLaw(tau0_MPa=TAU0, mu_ply=0.0, eta_f_MPa_s_per_mm=ETA, slip_mm=0.05)
    contact = PlyContact(plies, law, 2000.0, follow=True)
    problem = TrussProblem(stack_sheet(plies, comm), default_model(), [contact],
                           SolverOptions(snes_atol=1e-9))
    X = problem.X
    which = ply_of(plies, X)
    problem.fix(which != 1)  # the outer plies held
    problem.fix(which == 1, (1, 2))
    grip = (which == 1) & (np.abs(X[:, 0] - 30.0) < 1e-9)
    problem.fix(grip, (0,), lambda t: SPEED * t)
    owned = grip[: problem.num_owned]
    forces, versions = [], []

    def record(problem):
        friction = comm.allreduce(contact.f[: problem.num_owned][owned, 0].sum())
        forces.append(problem.reaction_force(grip)[0] - friction)
        versions.append(contact.pattern_version)

    problem.run(TRAVEL / SPEED, 0.2, on_step=record)
    return problem, contact, np.array(forces), versions, node_areas(pulled).sum()


@pytest.mark.parallel
def test_a_ply_pulled_over_cells_on_any_number_of_ranks():
    comm = MPI.COMM_WORLD
    _, contact, forces, versions, A = pull(comm)
    steady = forces[len(forces) // 5:]  # sliding steadily
    assert steady == pytest.approx(2 * A * (TAU0 + ETA * SPEED), rel=0.02)
    # Followed over cells: each partner point 2 cells on from the first (x = 0, 10, ... on
    # the long ply's cell 1, 2, ...: (i + ξ) = 1, 2, ...).
    first = (contact.cell + contact.q)[contact.interface == 0, 0]
    assert first == pytest.approx(np.tile([3.0, 4.0, 5.0, 6.0], 3), abs=1e-3)
    if comm.size > 1:
        # The patterns grew on some rank and not on another: the case that hung.
        every = comm.allgather(versions)
        assert any(v != every[0] for v in every[1:])
        assert max(v[-1] for v in every) > 1


@pytest.mark.parallel
@pytest.mark.compares_ranks
def test_a_ply_pulled_over_cells_as_on_one_process():
    """Every node and the grip's force as on one process (the pairs on every rank alike)."""
    comm = MPI.COMM_WORLD
    problem, _, forces, _, _ = pull(comm)
    one, _, forces_one, _, _ = pull(MPI.COMM_SELF)
    assert [s.iterations for s in problem.steps] == [s.iterations for s in one.steps]
    np.testing.assert_allclose(forces, forces_one, rtol=1e-6, atol=1e-9)
    # Each owned node against the node of one process at the same reference place (mm).
    at = {tuple(np.round(p, 6)): i for i, p in enumerate(one.X)}
    mine = [at[tuple(np.round(p, 6))] for p in problem.X[: problem.num_owned]]
    np.testing.assert_allclose(problem.positions()[: problem.num_owned],
                               one.positions()[mine], rtol=0, atol=1e-6)
