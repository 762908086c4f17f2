"""Tool geometry and penalty contact: exact gaps, consistent Jacobians, penetration ∝ 1/k."""

import math

import numpy as np
import pytest

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.forming.terms.contact import PenaltyContact
from fenicsx_drape.forming.tools.shapes import HemisphereTools

TOOLS = HemisphereTools()
RNG = np.random.default_rng(7)


def fd_jacobian(fun, x, h=1e-6):
    """Central differences of a per-node map (n, 3) -> (n, 3): shaped (n, 3, 3)."""
    J = np.empty((len(x), 3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        J[:, :, k] = (fun(x + e) - fun(x - e)) / (2 * h)
    return J


@pytest.mark.parametrize("tool, t", [(TOOLS.punch(40.0), 17.0), (TOOLS.die(), 3.0),
                                     (TOOLS.formed_part(), 0.0)])
def test_gap_normal_and_curvature_are_derivatives(tool, t):
    x = RNG.uniform([-95, -95, -85], [95, 95, 85], size=(3000, 3))
    g = tool.gap(x, t)
    grad = fd_jacobian(lambda y: np.repeat(tool.gap(y, t).phi[:, None], 3, 1), x)[:, 0, :]
    np.testing.assert_allclose(g.normal, grad, atol=1e-7)
    near = np.abs(g.phi) < 10.0  # the Hessian matters near the surface
    hess = fd_jacobian(lambda y: tool.gap(y, t).normal, x)
    np.testing.assert_allclose(g.hessian[near], hess[near], atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(g.normal, axis=1), 1.0, atol=1e-12)


def test_punch_profile_points():
    """Apex, equator, fillet foot and shoulder are on the punch surface; depth is exact."""
    punch = TOOLS.punch(duration_s=40.0)
    assert punch.speed_mm_per_s == pytest.approx(2.0)
    t = 10.0  # travel 20 mm: the base plane at z = -60
    c = 1 / math.sqrt(2)
    on = np.array([[0, 0, 20], [60 * c, 60 * c, -40], [80, 0, -60], [0, 83, -60],
                   [80 - 20 * c, 0, -40 - 20 * c]])
    np.testing.assert_allclose(punch.gap(on, t).phi, 0.0, atol=1e-12)
    np.testing.assert_allclose(punch.gap(np.array([[0, 0, 15.0], [0, 0, 27.0]]), t).phi,
                               [-5.0, 7.0], atol=1e-12)
    # Above the cap the normal is radial from the sphere's centre (0, 0, -40).
    g = punch.gap(np.array([[30.0, 40.0, 10.0]]), t)
    d = np.array([30.0, 40.0, 50.0])
    np.testing.assert_allclose(g.normal[0], d / np.linalg.norm(d), atol=1e-12)
    np.testing.assert_allclose(g.phi[0], np.linalg.norm(d) - 60.0, atol=1e-12)


def test_die_is_the_final_punch_offset_by_the_ply():
    final = TOOLS.punch(40.0)
    die = TOOLS.die()
    x = RNG.uniform([-80, -80, -2], [80, 80, 82], size=(2000, 3))
    φ_p = final.gap(x, 40.0).phi
    φ_d = die.gap(x, 0.0).phi
    near = (np.abs(φ_p) < 5.0) & (np.hypot(x[:, 0], x[:, 1]) < 80.0)
    np.testing.assert_allclose(φ_d[near], TOOLS.ply_thickness_mm - φ_p[near], atol=1e-9)


@pytest.mark.parametrize("friction", [0.0, 0.3])
def test_contact_jacobian_is_consistent(friction):
    punch = TOOLS.punch(40.0)
    term = PenaltyContact(punch, 2.4e3, friction=friction)
    X = RNG.uniform([-85, -85, 0], [85, 85, 0], size=(400, 3))
    term.bind(X, np.ones(len(X), bool), None)
    g = punch.gap(X, 12.0)
    x = X - (g.phi + RNG.uniform(-0.4, 0.3, len(X)))[:, None] * g.normal
    f, K = term.forces(x, 12.0, 0.5)
    assert (np.abs(f).sum(1) > 0).sum() > 100  # many nodes in contact
    K_fd = fd_jacobian(lambda y: -term.forces(y, 12.0, 0.5)[0], x)
    np.testing.assert_allclose(K, K_fd, atol=1e-6 * np.abs(K).max())


def test_contact_force_is_normal_and_projection_removes_penetration():
    punch = TOOLS.punch(40.0)
    term = PenaltyContact(punch, 1e3)
    X = np.column_stack([RNG.uniform(-50, 50, (200, 2)), np.zeros(200)])
    term.bind(X, np.ones(200, bool), None)
    x = X.copy()
    x[:, 2] = 5.0  # the apex is at z = 10 at t = 5 s: most nodes penetrate
    f, _ = term.forces(x, 5.0, 5.0)
    g = punch.gap(x, 5.0)
    depth = np.maximum(-g.phi, 0.0)
    δ = term.δ
    p = np.where(depth < δ, 0.5e3 / δ * depth**2, 1e3 * (depth - 0.5 * δ))
    np.testing.assert_allclose(f, p[:, None] * g.normal)
    assert (depth > δ).any() and ((depth > 0) & (depth < δ)).any()  # both regimes
    y = term.project(x, 5.0)
    assert np.abs(np.minimum(punch.gap(y, 5.0).phi, 0)).max() < 1e-9
    assert term.penetration(y, 5.0).max() < 1e-9


def test_penetration_falls_as_one_over_the_penalty():
    """A node pushed onto the apex by a load F settles at penetration F / k, and the contact
    reaction equals the load (the net patch version is in test_forming_hemisphere.py)."""
    punch = TOOLS.punch(40.0)
    F = -0.8  # N along z, towards the punch
    depth = []
    for k in (1e2, 1e3, 1e4):
        term = PenaltyContact(punch, k)
        x = np.array([[0.0, 0.0, -1e-3]])  # start in contact
        term.bind(x, np.ones(1, bool), None)
        for _ in range(30):  # Newton on f_z + F = 0 along the axis
            f, K = term.forces(x, 0.0, 1.0)
            x[0, 2] += (f[0, 2] + F) / K[0, 2, 2]
        f, _ = term.forces(x, 0.0, 1.0)
        np.testing.assert_allclose(f[0], [0.0, 0.0, -F], atol=1e-12)  # reaction = load
        depth.append(term.penetration(x, 0.0)[0])
    # Below the smoothing force f_s / 2 the law is quadratic: depth = √(2 f_s F) / k.
    np.testing.assert_allclose(depth, np.sqrt(2 * 100.0 * 0.8) / np.array([1e2, 1e3, 1e4]),
                               rtol=1e-9)
    # A load above f_s / 2 is in the linear regime: depth = (F + f_s / 2) / k.
    term = PenaltyContact(punch, 1e3)
    x = np.array([[0.0, 0.0, -1e-3]])
    term.bind(x, np.ones(1, bool), None)
    for _ in range(30):
        f, K = term.forces(x, 0.0, 1.0)
        x[0, 2] += (f[0, 2] - 80.0) / K[0, 2, 2]
    assert term.penetration(x, 0.0)[0] == pytest.approx((80.0 + 50.0) / 1e3, rel=1e-12)


def test_bad_parameters_are_named():
    with pytest.raises(ParameterError, match="penalty stiffness"):
        PenaltyContact(TOOLS.die(), 0.0)
    with pytest.raises(ParameterError, match="shoulder_radius_mm"):
        HemisphereTools(shoulder_radius_mm=90.0)
    with pytest.raises(ParameterError, match="fillet_radius_mm"):
        HemisphereTools(fillet_radius_mm=-1.0)
