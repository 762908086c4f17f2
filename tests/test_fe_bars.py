"""A single bar and a two-bar truss against analytic large-stretch solutions."""

import dataclasses

import pytest

pytest.importorskip("dolfinx")

import numpy as np
from scipy.optimize import brentq

from fenicsx_drape.fe.grid import WARP
from fenicsx_drape.fe.mesh import truss_mesh
from fenicsx_drape.fe.solver import TrussProblem
from fenicsx_drape.materials.base import MaterialLaw, parameter

E = 250.0  # N/tow
CELL = 10.0  # mm: each bar stands for n_t = 0.71 · 10 tows
N_T = 0.71 * CELL


@dataclasses.dataclass
class LinearTow(MaterialLaw):
    """σ = E ε: force per tow linear in the Green-Lagrange strain."""

    role = "tow"
    E: float = parameter(E, unit="N/tow")

    def _update(self, strain, dt, state):
        return self.E * strain, np.full_like(strain, self.E), state


LAWS = {"tow": LinearTow(), "shear": LinearTow()}


def at(x0):
    return lambda X: np.linalg.norm(X - np.asarray(x0), axis=1) < 1e-9


@pytest.mark.parallel
@pytest.mark.parametrize("stretch", [1.8, 0.6])
def test_single_bar_stretched_and_rotated(stretch):
    L = 20.0
    sheet = truss_mesh([[0.0, 0, 0], [L, 0, 0]], [[0, 1]], [WARP], CELL)
    problem = TrussProblem(sheet, LAWS)
    direction = np.array([np.cos(0.7) * np.cos(0.3), np.sin(0.7) * np.cos(0.3), np.sin(0.3)])
    end = stretch * L * direction - [L, 0, 0]
    problem.fix(at([0, 0, 0]))
    problem.fix(at([L, 0, 0]), (0, 1, 2), lambda t: t * end)
    report = problem.run(1.0, 0.25)
    assert all(s.converged for s in report.steps)
    ε = (stretch**2 - 1) / 2
    force = problem.reaction_force(at([L, 0, 0]))
    # The bar carries the force n_t σ(ε) along its current direction (eq. 11's convention).
    np.testing.assert_allclose(force, N_T * E * ε * direction, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(problem.reaction_force(at([0, 0, 0])), -force, rtol=1e-10,
                               atol=1e-9)


@pytest.mark.parallel
def test_two_bar_truss_under_large_deflection():
    a, b, w = 10.0, 20.0, 15.0
    sheet = truss_mesh([[-a, 0, 0], [0, 0, 0], [b, 0, 0]], [[0, 1], [1, 2]], [WARP, WARP], CELL)
    problem = TrussProblem(sheet, LAWS)
    problem.fix(at([-a, 0, 0]))
    problem.fix(at([b, 0, 0]))
    problem.fix(at([0, 0, 0]), (2,), lambda t: w * t)  # x, y of the apex are free
    report = problem.run(1.0, 0.2)
    assert all(s.converged for s in report.steps)

    def bars(x):
        l1, l2 = np.hypot(x + a, w), np.hypot(b - x, w)
        N1 = N_T * E * (l1**2 / a**2 - 1) / 2
        N2 = N_T * E * (l2**2 / b**2 - 1) / 2
        return l1, l2, N1, N2

    def balance_x(x):
        l1, l2, N1, N2 = bars(x)
        return -N1 * (x + a) / l1 + N2 * (b - x) / l2

    x_apex = brentq(balance_x, -a + 1e-6, b - 1e-6, xtol=1e-14)
    l1, l2, N1, N2 = bars(x_apex)
    load = N1 * w / l1 + N2 * w / l2
    apex = problem.nodes(at([0, 0, 0]))
    if apex.any():
        np.testing.assert_allclose(problem.positions()[apex][0], [x_apex, 0, w], atol=1e-9)
    force = problem.reaction_force(apex)
    np.testing.assert_allclose(force, [0, 0, load], rtol=1e-9, atol=1e-7)
    assert x_apex < -1.0  # the short bar stretches more: the apex moves towards it
