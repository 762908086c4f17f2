"""Bar kinematics in UFL: Green-Lagrange strain, its variation, residual and Jacobian.

A bar is an interval cell of the reference (flat) sheet. With ``J = ufl.Jacobian(mesh)`` (3×1)
the reference tangent is ``t₀ = dX/dξ = J[:, 0]`` and the current one ``t = t₀ + ∇u t₀``,
so the bar's Green-Lagrange strain (the strain of the paper's laws, eqs. 2-3 and 13-14) is

    ε = ½ (|t|² / |t₀|² − 1),   δε = t · (∇δu t₀) / |t₀|².

One quadrature point per bar is exact: ε is constant along a P1 bar.

Force convention. The laws return the *force per tow* along the bar, σ (N/tow), as the
unit-cell analysis uses it (eq. 11: ``f/n_t = Σ σ r/|r|``). A bar standing for ``n_t`` tows
(section 4: properties times ``n_t/A_e``) therefore carries the axial force ``N = n_t σ``, whose
virtual work over the length change ``δl = L δε / λ`` (stretch ``λ = √(1 + 2ε)``) is

    δW = ∫ S δε dX,   S = n_t σ / λ  (the work-conjugate of ε, a second Piola-Kirchhoff force),

and the consistent tangent is ``dS/dε = n_t (dσ/dε) / λ − n_t σ / λ³``. The forms below are
the standard total-Lagrangian truss in ``S``; :mod:`fenicsx_drape.fe.state` turns the laws' σ
and dσ/dε into ``S`` and ``dS/dε`` at the quadrature points. (Reading σ itself as the second
Piola-Kirchhoff force would make the FE bar differ from the fitted unit cell by the factor λ,
up to 1.4 on a sheared diagonal.)
"""

from __future__ import annotations

import basix.ufl
import dolfinx
import ufl

QUADRATURE_DEGREE = 1  # one Gauss point at the bar's midpoint: exact for P1 bars


def quadrature_space(mesh: dolfinx.mesh.Mesh) -> dolfinx.fem.FunctionSpace:
    """Scalar quadrature space with one point per bar."""
    element = basix.ufl.quadrature_element(mesh.basix_cell(), value_shape=(),
                                           degree=QUADRATURE_DEGREE)
    return dolfinx.fem.functionspace(mesh, element)


def measure(mesh: dolfinx.mesh.Mesh) -> ufl.Measure:
    """The bar measure ``dX`` (reference length, mm) with the quadrature of the state."""
    return ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": QUADRATURE_DEGREE})


def tangents(u: dolfinx.fem.Function) -> tuple[ufl.core.expr.Expr, ufl.core.expr.Expr]:
    """Reference and current bar tangents ``t₀ = dX/dξ`` and ``t = dx/dξ``."""
    t0 = ufl.Jacobian(u.function_space.mesh)[:, 0]
    return t0, t0 + ufl.grad(u) * t0


def green_lagrange(u: dolfinx.fem.Function) -> ufl.core.expr.Expr:
    """The bar's Green-Lagrange strain ε = ½(|t|²/|t₀|² − 1)."""
    t0, t = tangents(u)
    return (ufl.dot(t, t) / ufl.dot(t0, t0) - 1) / 2


def strain_variation(u: dolfinx.fem.Function, w) -> ufl.core.expr.Expr:
    """δε in the direction ``w`` (a test or trial function): t · (∇w t₀) / |t₀|²."""
    t0, t = tangents(u)
    return ufl.dot(t, ufl.grad(w) * t0) / ufl.dot(t0, t0)


def truss_forms(u: dolfinx.fem.Function, S: dolfinx.fem.Function, dS: dolfinx.fem.Function,
                S_geometric: dolfinx.fem.Function | None = None) -> tuple[ufl.Form, ufl.Form]:
    """Residual ``∫ S δε dX`` and its Jacobian, with ``S`` and ``dS = dS/dε`` given.

    The Jacobian is ``∫ dS δε(Δu) δε(v) + S (∇Δu t₀)·(∇v t₀)/|t₀|² dX``: material plus
    geometric stiffness. With ``dS`` the consistent algorithmic tangent it is the exact
    derivative of the residual. ``S_geometric`` (default ``S``) is the force the geometric
    stiffness is taken with (the solver may limit it: the Jacobian is then inexact, the
    residual and its solution are not).
    """
    V = u.function_space
    v, du = ufl.TestFunction(V), ufl.TrialFunction(V)
    dX = measure(V.mesh)
    t0, _ = tangents(u)
    residual = S * strain_variation(u, v) * dX
    geometric = ufl.dot(ufl.grad(du) * t0, ufl.grad(v) * t0) / ufl.dot(t0, t0)
    S_g = S if S_geometric is None else S_geometric
    jacobian = (dS * strain_variation(u, du) * strain_variation(u, v) + S_g * geometric) * dX
    return residual, jacobian
