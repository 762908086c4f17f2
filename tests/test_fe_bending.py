"""The tow bending term: its energy on a curved sheet, and consistency of its Jacobian."""

import dataclasses

import pytest

pytest.importorskip("dolfinx")

import dolfinx.fem.petsc as fem_petsc
import numpy as np

from fenicsx_drape.fe import SolverOptions, TrussProblem, truss_sheet
from fenicsx_drape.materials.base import MaterialLaw, parameter

EI = 3.0  # N·mm² per tow


@dataclasses.dataclass
class Linear(MaterialLaw):
    """σ = E ε: smooth, so finite differences test the bending term alone."""

    role = "tow"
    E: float = parameter(unit="N/tow")

    def _update(self, strain, dt, state):
        return self.E * strain, np.full_like(strain, self.E), state


LAWS = {"tow": Linear(3000.0), "shear": Linear(1.0)}


def _problem(quarter, EI=EI, sheet=None, mode="full"):
    sheet = sheet or truss_sheet(80.0, 10.0, quarter=quarter)
    return TrussProblem(sheet, LAWS, options=SolverOptions(tow_bending_EI_Nmm2=EI,
                                                           bending_jacobian=mode))


def _jacobians_at_a_curved_state(*problems):
    """Each problem's Jacobian at one curved displacement of a quarter; that displacement."""
    x = None
    for problem in problems:
        problem.symmetry()
        problem.u.interpolate(lambda X: np.vstack([1e-4 * X[0] * X[1], 2e-4 * X[0] * X[1],
                                                   1e-3 * (X[0] ** 2 + X[1] ** 2)]))
        x = problem.u.x.petsc_vec.copy() if x is None else x
        problem._jacobian(x)
    return x


@pytest.mark.parallel
@pytest.mark.parametrize("quarter", [False, True])
def test_energy_of_a_doubly_curved_sheet(quarter):
    """u_z = a x² + b y²: every triplet of a warp line has second difference 2aΔ², weft 2bΔ²."""
    problem = _problem(quarter)
    a, b = 1e-3, -3e-3
    problem.u.interpolate(lambda X: np.vstack([0 * X[0], 0 * X[0], a * X[0] ** 2 + b * X[1] ** 2]))
    energy = problem._bending.energy(problem.u.x.petsc_vec)
    grid = problem.sheet.grid
    Δ, n = grid.cell_mm, grid.nx
    k = 0.71 * Δ * EI / Δ**3
    strips = (n - 1) + 2 * 0.5  # per direction: n + 1 lines, the two edge ones are half
    expected = 0.5 * k * (n - 1) * strips * ((2 * a * Δ**2) ** 2 + (2 * b * Δ**2) ** 2)
    assert energy == pytest.approx(expected, rel=1e-12)


@pytest.mark.parallel
def test_bending_adds_a_consistent_stiffness():
    """Residual differences along a random direction equal the Jacobian's product with it."""
    problem = _problem(quarter=True)
    problem.symmetry()
    # A state on the symmetry constraints (u_x = 0 on x = 0, u_y = 0 on y = 0).
    problem.u.interpolate(lambda X: np.vstack([1e-4 * X[0] * X[1], 2e-4 * X[0] * X[1],
                                               1e-3 * (X[0] ** 2 + X[1] ** 2)]))
    rng = np.random.default_rng(0)
    direction = problem.u.x.petsc_vec.duplicate()
    direction.array_w[:] = rng.standard_normal(direction.getLocalSize())
    for bc in problem.constraints.bcs:  # stay on the constraints
        bc.set(direction.array_w, alpha=0.0)
    x = problem.u.x.petsc_vec.copy()

    def residual(s):
        y = x.copy()
        y.axpy(s, direction)
        b = fem_petsc.create_vector(problem.V)
        problem._residual(y, b)
        return b

    h = 1e-6
    fd = residual(h)
    fd.axpy(-1.0, residual(-h))
    fd.scale(1 / (2 * h))
    problem._jacobian(x)
    Jd = fd.duplicate()
    problem._A.mult(direction, Jd)
    Jd.axpy(-1.0, fd)
    assert Jd.norm() <= 1e-7 * fd.norm()
    # Without the bending term the product differs: the test can fail.
    plain = _problem(True, EI=0.0, sheet=problem.sheet)
    plain.symmetry()
    plain._jacobian(x)
    Jd_plain = fd.duplicate()
    plain._A.mult(direction, Jd_plain)
    Jd_plain.axpy(-1.0, fd)
    assert Jd_plain.norm() > 1e-5 * fd.norm()


@pytest.mark.parallel
def test_a_diagonal_bending_jacobian_keeps_a_plain_nets_pattern_and_the_full_residual():
    """``bending_jacobian = "diagonal"``: K's diagonal alone, in the pattern of a net without
    bending (Newton's matrix factors as a plain net's); the residual keeps the whole term."""
    full = _problem(quarter=True)
    diagonal = _problem(True, sheet=full.sheet, mode="diagonal")
    plain = _problem(True, EI=0.0, sheet=full.sheet)
    x = _jacobians_at_a_curved_state(full, diagonal, plain)
    nonzeros = {name: p._A.getInfo()["nz_used"]
                for name, p in (("full", full), ("diagonal", diagonal), ("plain", plain))}
    assert nonzeros["diagonal"] == nonzeros["plain"] < nonzeros["full"]
    np.testing.assert_allclose(diagonal._A.getDiagonal().array, full._A.getDiagonal().array,
                               rtol=1e-12)
    assert not np.allclose(plain._A.getDiagonal().array, full._A.getDiagonal().array)
    b_full, b_diagonal = (fem_petsc.create_vector(full.V) for _ in range(2))
    full._residual(x, b_full)
    diagonal._residual(x, b_diagonal)
    np.testing.assert_allclose(b_diagonal.array, b_full.array, rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="bending_jacobian"):
        SolverOptions(bending_jacobian="lumped")


@pytest.mark.parallel
def test_the_bending_as_preconditioner_applies_the_full_jacobian_and_factors_a_plain_net():
    """``bending_jacobian = "preconditioner"``: the Krylov operator is the full Jacobian (its
    product equals the assembled full one's); the factored matrix has a plain net's pattern
    and, the couplings two nodes apart being lumped on the diagonal, acts on a rigid motion
    as the full Jacobian does."""
    full = _problem(quarter=True)
    split, diagonal = (_problem(True, sheet=full.sheet, mode=mode)
                       for mode in ("preconditioner", "diagonal"))
    x = _jacobians_at_a_curved_state(full, split, diagonal)
    operator, P = split.newton.snes.getKSP().getOperators()
    assert P.handle == split._A.handle and operator.getType() == "python"
    rng = np.random.default_rng(1)
    d = x.duplicate()
    d.array_w[:] = rng.standard_normal(d.getLocalSize())
    Jd, Ad = d.duplicate(), d.duplicate()
    full._A.mult(d, Jd)
    operator.mult(d, Ad)
    assert np.allclose(Ad.array, Jd.array, rtol=1e-12, atol=1e-12 * Jd.norm())
    P.mult(d, Ad)  # the factored matrix alone misses the stencils' couplings
    assert not np.allclose(Ad.array, Jd.array, rtol=1e-6, atol=1e-6 * Jd.norm())
    assert P.getInfo()["nz_used"] == diagonal._A.getInfo()["nz_used"]
    lift = x.duplicate()  # a rigid motion out of the plane (the constraints leave u_z free)
    lift.array_w[:] = np.tile([0.0, 0.0, 1.0], d.getLocalSize() // 3)
    full._A.mult(lift, Jd)
    diagonal._A.mult(lift, Ad)  # K's diagonal alone resists it: by about k per node
    off = Ad.copy()
    off.axpy(-1.0, Jd)
    assert off.norm() > 0.1
    P.mult(lift, Ad)
    Ad.axpy(-1.0, Jd)
    assert Ad.norm() <= 1e-12 * off.norm()


@pytest.mark.parallel
def test_the_default_splits_the_solve_of_a_large_sheet_and_factors_a_small_one_whole():
    """``bending_jacobian = "auto"``: the split solve above SPLIT_FROM_NODES nodes (counted
    over all ranks), the stencils factored whole below."""
    from fenicsx_drape.fe.solver import SPLIT_FROM_NODES

    small, large = (TrussProblem(truss_sheet(80.0 * k, 10.0), LAWS,
                                 options=SolverOptions(tow_bending_EI_Nmm2=EI)) for k in (1, 3))
    sizes = [p.comm.allreduce(p.num_owned) for p in (small, large)]
    assert sizes[0] <= SPLIT_FROM_NODES < sizes[1]
    assert (small.bending_jacobian, large.bending_jacobian) == ("full", "preconditioner")
    assert large.newton.snes.getKSP().getType() == "gmres"
    assert small.newton.snes.getKSP().getType() == "preonly"


def test_forming_with_the_bending_as_preconditioner_gives_the_same_part():
    """The quarter hemisphere on 30 mm cells formed with the stencils factored and with them
    only in GMRES's operator: the same steps, Newton iterations and nodes (within 0.1 mm)."""
    from fenicsx_drape.forming.case.format import load_case
    from fenicsx_drape.forming.running.run import forming_options, run_case
    from fenicsx_drape.model import default_model

    model = default_model()
    case = load_case("hemisphere", cell_mm=30.0, duration_s=8.0)
    runs = {mode: run_case(case, model, forming_options(model, bending_jacobian=mode))
            for mode in ("full", "preconditioner")}
    full, split = runs["full"], runs["preconditioner"]
    assert not full.stopped and not split.stopped
    assert sum(s.krylov_iterations for s in split.problem.steps) > split.iterations
    assert sum(s.krylov_iterations for s in full.problem.steps) == 0
    assert split.steps == full.steps and abs(split.iterations - full.iterations) <= 2
    distance = np.linalg.norm(split.grid.x - full.grid.x, axis=-1)
    assert np.nanmax(distance) < 0.1


@pytest.mark.skip_in_parallel
def test_the_split_solve_gives_the_same_part_to_the_last_digit_run_after_run():
    """The quarter hemisphere on 10 mm cells formed four times with the split solve: the same
    nodes bit for bit (a run must not depend on when it is formed: a diagnosis's report is the
    same whichever worker forms it). With GMRES's classical Gram-Schmidt one run in four
    differed in its last digits."""
    import hashlib

    from fenicsx_drape.forming.case.format import load_case
    from fenicsx_drape.forming.running.run import forming_options, run_case
    from fenicsx_drape.model import default_model

    model = default_model()
    case = load_case("hemisphere", cell_mm=10.0, duration_s=10.0)
    options = forming_options(model, bending_jacobian="preconditioner")
    digests = {hashlib.sha1(np.ascontiguousarray(run_case(case, model, options).grid.x)
                            .tobytes()).hexdigest() for _ in range(4)}
    assert len(digests) == 1
