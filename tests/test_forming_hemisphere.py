"""Forming on the FE core: a contact patch, and the hemisphere on a coarse mesh."""

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from mpi4py import MPI

from fenicsx_drape.fe.mesh import truss_sheet
from fenicsx_drape.fe.solver import SolverOptions, TrussProblem
from fenicsx_drape.forming import load_case, run_case
from fenicsx_drape.forming.terms.contact import PenaltyContact
from fenicsx_drape.forming.terms.stabilisation import ExtrapolationSpring
from fenicsx_drape.forming.tools.shapes import RevolvedTool, Segment
from fenicsx_drape.model import default_model

# A coarse case: 20 mm cells, 8 s of forming; coarser still for the parallel comparison.
COARSE = {"cell_mm": 20.0, "duration_s": 8.0}
COARSER = {"cell_mm": 30.0, "duration_s": 8.0}


class DeadLoad:
    """A constant force on every node (a nodal term)."""

    def __init__(self, force_N):
        self.force = np.asarray(force_N, dtype=float)

    def bind(self, X, owned, comm):
        self.n = len(X)

    def forces(self, x, t, dt):
        return np.broadcast_to(self.force, (self.n, 3)), np.zeros((self.n, 3, 3))

    def commit(self):
        pass

    def revert(self):
        pass


def plate_patch(k: float, load_N: float, comm=MPI.COMM_WORLD):
    """A 60 mm net pinned on its border and pressed onto a flat rigid plate by a load."""
    plate = RevolvedTool("plate", (Segment((0.0, 0.0), (1e4, 0.0)),))
    contact = PenaltyContact(plate, k)
    spring = ExtrapolationSpring(1.0)
    sheet = truss_sheet(60.0, 10.0, comm=comm)
    terms = [contact, DeadLoad([0.0, 0.0, -load_N]), spring]
    problem = TrussProblem(sheet, default_model(), terms,
                           SolverOptions(snes_atol=1e-10, tow_bending_EI_Nmm2=0.0))
    problem.fix("border")
    problem.run(3.0, 1.0)
    spring.c = 0.0  # at rest on the plate the net needs no stabilisation: drop its force
    problem.run(1.0, 1.0)
    return problem, contact


@pytest.mark.parallel
def test_contact_patch_reaction_equals_load_and_penetration_falls_as_1_over_k():
    load, depth = 0.5, []
    for k in (2.4e2, 2.4e3, 2.4e4):
        problem, contact = plate_patch(k, load)
        x = problem.positions()
        f = contact.forces(x, problem.t, 1.0)[0]
        interior = problem.owned & ~problem.nodes("border")
        n = problem.comm.allreduce(np.count_nonzero(interior))
        push = problem.comm.allreduce(f[interior].sum(axis=0), op=MPI.SUM)
        # The plate carries the load of the free nodes; the border the (tiny) rest.
        np.testing.assert_allclose(push, [0.0, 0.0, n * load], rtol=1e-3, atol=1e-9)
        reaction = problem.reaction_force("border")
        np.testing.assert_allclose(reaction + push, [0.0, 0.0, n * load], atol=1e-7)
        local = contact.penetration(x, problem.t)[interior]
        depth.append(problem.comm.allreduce(local.max(initial=0.0), op=MPI.MAX))
    # Below the smoothing force the law is quadratic: depth = √(2 f_s p) / k ∝ 1/k.
    np.testing.assert_allclose(depth, np.sqrt(2 * 100.0 * load) / np.array([2.4e2, 2.4e3, 2.4e4]),
                               rtol=1e-3)


@pytest.fixture(scope="module")
def quarter():
    return run_case(load_case("hemisphere", **COARSE), comm=MPI.COMM_SELF)


@pytest.fixture(scope="module")
def full():
    # The case's force share ("model") gives the quarter's own nodes the whole F: the full
    # sheet, pressed as the quarter is, carries 4F (with_overrides doubles it per plane).
    full = load_case("hemisphere", **COARSE, symmetry=[])
    assert full.holder.force_N == 4 * 133.0
    return run_case(full, comm=MPI.COMM_SELF)


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_quarter_and_full_sheet_agree_and_the_full_sheet_is_symmetric(quarter, full):
    g = full.grid
    # Mirror symmetry of the full sheet in x = 0, y = 0 and x = y.
    mirrored = g.x[::-1, :] * [-1, 1, 1]
    np.testing.assert_allclose(g.x, mirrored, atol=0.05)
    np.testing.assert_allclose(g.x, g.x[:, ::-1] * [1, -1, 1], atol=0.05)
    np.testing.assert_allclose(g.x, g.x.transpose(1, 0, 2)[..., [1, 0, 2]], atol=0.05)
    # The full sheet's quadrant is the quarter model (node positions within 0.5 mm).
    q = g.quadrant
    np.testing.assert_allclose(q.X, quarter.grid.X, atol=1e-9)
    assert np.abs(q.x - quarter.grid.x).max() < 0.5
    assert abs(np.abs(q.shear_deg()).max() - np.abs(quarter.grid.shear_deg()).max()) < 1.0


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_formed_quarter_zero_shear_at_apex_and_wrinkling_on_the_tow_axes(quarter):
    g = quarter.grid
    γ = np.abs(g.shear_deg())
    assert γ.max() > 20.0  # the bias regions are sheared, the apex cell (20 mm) hardly
    assert γ[0, 0] < 0.1 * γ.max()
    i, j = np.unravel_index(np.argmax(γ), γ.shape)
    assert abs(i - j) <= 1  # the most sheared cell is on the bias line
    np.testing.assert_allclose(g.x[0, 0], [0.0, 0.0, 80.0], atol=0.05)  # apex on the punch
    # Wrinkling concentrates on the tow axes (Fig. 8): the strongly wrinkled tows (below half
    # the minimum wrinkling strain) lie within 15° of the x or y axis, and the tows within
    # 22.5° of the axes carry at least four times the wrinkling of those around the bias.
    warp, weft = g.tow_strains()
    mids = [0.5 * (g.X[1:, :] + g.X[:-1, :]), 0.5 * (g.X[:, 1:] + g.X[:, :-1])]
    angle = np.concatenate([np.degrees(np.arctan2(m[..., 1], m[..., 0])).ravel() for m in mids])
    ε = np.concatenate([warp.ravel(), weft.ravel()])
    off_axis = np.minimum(angle, 90.0 - angle)
    assert ε.min() < -0.05
    assert off_axis[ε < 0.5 * ε.min()].max() < 15.0
    wrinkling = np.minimum(ε, 0.0)
    assert wrinkling[off_axis < 22.5].sum() < 4.0 * wrinkling[off_axis >= 22.5].sum()
    # ... and none on the cap under the punch's top.
    radius = np.concatenate([np.hypot(m[..., 0], m[..., 1]).ravel() for m in mids])
    assert radius[ε < -0.01].min() > 40.0


@pytest.mark.parallel
@pytest.mark.compares_ranks
@pytest.mark.slow
def test_serial_and_parallel_runs_agree(tight_solver):
    """The coarse quarter on all ranks equals the same run on one process."""
    case = load_case("hemisphere", **COARSER)
    parallel = run_case(case, options=tight_solver, comm=MPI.COMM_WORLD)
    serial = run_case(case, options=tight_solver, comm=MPI.COMM_SELF)
    assert parallel.problem.sheet.num_nodes_global == serial.grid.X[..., 0].size
    np.testing.assert_allclose(parallel.grid.x, serial.grid.x, atol=1e-5)
    assert parallel.max_penetration_mm == pytest.approx(serial.max_penetration_mm, rel=1e-3)


@pytest.mark.skip_in_parallel
def test_a_run_that_cannot_finish_raises_or_returns_how_far_it_got():
    """One Newton iteration per step cannot converge: SolverError, or the last state."""
    from fenicsx_drape.errors import SolverError

    case = load_case("hemisphere", cell_mm=30.0, duration_s=8.0)
    starved = SolverOptions(snes_atol=1e-6, snes_max_it=1)
    with pytest.raises(SolverError, match="cannot be cut"):
        run_case(case, options=starved, comm=MPI.COMM_SELF)
    run = run_case(case, options=starved, comm=MPI.COMM_SELF, allow_incomplete=True)
    assert "cannot be cut" in run.stopped
    assert 0.0 <= run.travel_mm < case.total_travel_mm
    assert run.cutbacks >= 10  # halved down to dt / 1024
    np.testing.assert_allclose(run.grid.x[..., 2].max(), 0.0, atol=1e-6 + run.travel_mm)


@pytest.mark.parametrize("with_tool_friction", [False, True])
def test_the_jacobian_is_symmetric_unless_tool_friction_acts(with_tool_friction):
    """run_hemisphere factors with a symmetric LDLᵀ when the Jacobian is symmetric."""
    model = default_model()
    if with_tool_friction:
        model = model.with_effects("tool_friction")
    run = run_case(load_case("hemisphere", cell_mm=30.0, duration_s=8.0), model)
    A = run.problem._A
    asymmetry = A.copy().transpose()  # in place, on the copy
    asymmetry.axpy(-1.0, A)
    relative = asymmetry.norm() / A.norm()
    pc = run.problem.newton.snes.getKSP().getPC().getType()
    if with_tool_friction:
        assert relative > 1e-6 and pc == "lu"  # the friction tangent is not symmetric
    else:
        assert relative < 1e-12 and pc == "cholesky"
