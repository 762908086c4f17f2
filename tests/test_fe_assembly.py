"""The quadrature path assembles the residual and Jacobian of an equivalent pure-UFL truss."""

import dataclasses

import pytest

pytest.importorskip("dolfinx")

from petsc4py import PETSc

import dolfinx
import dolfinx.fem.petsc as fem_petsc
import numpy as np
import ufl

from fenicsx_drape.fe import TrussProblem, truss_sheet
from fenicsx_drape.fe.kinematics import green_lagrange, measure, strain_variation
from fenicsx_drape.materials.base import MaterialLaw, parameter


@dataclasses.dataclass
class CubicLaw(MaterialLaw):
    """σ = E ε + K ε³ (a non-linear elastic law with its exact tangent)."""

    role = "tow"
    E: float = parameter(unit="N/tow")
    K: float = parameter(unit="N/tow")

    def _update(self, strain, dt, state):
        return (self.E * strain + self.K * strain**3, self.E + 3 * self.K * strain**2, state)


TOW = CubicLaw(E=300.0, K=5e3)
SHEAR = CubicLaw(E=2.0, K=40.0)


@pytest.mark.parallel
def test_quadrature_path_equals_pure_ufl():
    sheet = truss_sheet(60.0, 10.0, quarter=True)
    problem = TrussProblem(sheet, {"tow": TOW, "shear": SHEAR})
    u = problem.u
    # A smooth, large, fully 3D deformation.
    u.interpolate(lambda X: np.vstack([0.02 * X[1] + 1e-4 * X[0] ** 2,
                                       -0.03 * X[0] + 0.05 * np.sin(X[1] / 9),
                                       0.1 * np.cos(X[0] / 7) * X[1] / 10]))
    problem.state.evaluate(dt=0.1)

    # The same truss written directly in UFL: per-cell n_t and law constants.
    mesh = sheet.mesh
    W = dolfinx.fem.functionspace(mesh, ("DG", 0))
    n_t, E, K = (dolfinx.fem.Function(W) for _ in range(3))
    n_cells = mesh.topology.index_map(1).size_local
    dofs = W.dofmap.list[:n_cells, 0]
    n_t.x.array[dofs] = problem.state.tows
    tow_points = problem.state.groups["tow"][0]
    shear_points = problem.state.groups["shear"][0]
    for f, name in ((E, "E"), (K, "K")):
        f.x.array[dofs[tow_points]] = getattr(TOW, name)
        f.x.array[dofs[shear_points]] = getattr(SHEAR, name)
        f.x.scatter_forward()
    n_t.x.scatter_forward()
    ε = green_lagrange(u)
    σ = E * ε + K * ε**3
    λ = ufl.sqrt(1 + 2 * ε)
    v = ufl.TestFunction(problem.V)
    residual = n_t * σ / λ * strain_variation(u, v) * measure(mesh)
    jacobian = ufl.derivative(residual, u, ufl.TrialFunction(problem.V))

    def vector(form):
        b = fem_petsc.assemble_vector(dolfinx.fem.form(form) if not isinstance(
            form, dolfinx.fem.Form) else form)
        b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        return b

    def matrix(form):
        A = fem_petsc.assemble_matrix(dolfinx.fem.form(form) if not isinstance(
            form, dolfinx.fem.Form) else form)
        A.assemble()
        return A

    b_q, b_u = vector(problem.residual_form), vector(residual)
    A_q, A_u = matrix(problem.jacobian_form), matrix(jacobian)
    assert b_u.norm() > 1.0 and A_u.norm() > 1.0  # a real, loaded state
    b_q.axpy(-1.0, b_u)
    A_q.axpy(-1.0, A_u)
    assert b_q.norm() <= 1e-12 * b_u.norm()
    assert A_q.norm() <= 1e-12 * A_u.norm()
    # The geometric stiffness makes the Jacobian non-symmetric only if a bug does.
    assert A_u.isSymmetric(1e-9 * A_u.norm())


@pytest.mark.parallel
def test_jacobian_is_the_derivative_of_the_residual():
    """Finite differences of the assembled residual reproduce the assembled Jacobian."""
    sheet = truss_sheet(40.0, 10.0, quarter=True)
    problem = TrussProblem(sheet, {"tow": TOW, "shear": SHEAR})
    u = problem.u
    u.interpolate(lambda X: np.vstack([0.03 * X[1], 0.02 * X[0], 0.05 * X[0]]))
    rng = np.random.default_rng(3)
    direction = dolfinx.fem.Function(problem.V)
    direction.x.array[:] = rng.standard_normal(direction.x.array.size)
    direction.x.scatter_forward()

    def residual_at(s):
        u0 = u.x.array.copy()
        u.x.array[:] += s * direction.x.array
        problem.state.evaluate(0.1)
        b = fem_petsc.assemble_vector(problem.residual_form)
        b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        u.x.array[:] = u0
        return b

    h = 1e-6
    fd = residual_at(h)
    fd.axpy(-1.0, residual_at(-h))
    fd.scale(1 / (2 * h))
    problem.state.evaluate(0.1)
    A = fem_petsc.assemble_matrix(problem.jacobian_form)
    A.assemble()
    Jd = A.createVecLeft()
    A.mult(direction.x.petsc_vec, Jd)
    Jd.axpy(-1.0, fd)
    assert Jd.norm() <= 1e-6 * fd.norm()
