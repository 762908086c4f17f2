"""A stack of plies: ply-ply contact and inter-ply friction in the FE solve (fe/plies.py).

Exact answers (ten Thije & Akkerman, Int. J. Mater. Form. 2009: a pull-out under a uniform
pressure): the middle of three plies pulled at constant speed v under a pressure p over the
overlap A needs F = 2 A (τ₀ + μ p + η_f v); below 2 A (τ₀ + μ p) it does not slide. Bonded
plies form as one ply of their summed stiffness; frictionless plies as independent plies.
"""

import numpy as np
import pytest

from fenicsx_drape.fe.grid import TrussGrid
from fenicsx_drape.fe.plies import PlyContact, node_areas, ply_of, stack_plies, stack_sheet
from fenicsx_drape.fe.solver import SolverOptions, TrussProblem
from fenicsx_drape.materials.interply import InterplyLaw
from fenicsx_drape.model import default_model

pytestmark = pytest.mark.skip_in_parallel  # one process (on ranks: test_forming_stack_parallel)

K_N = 2000.0  # N/mm, the gap penalty
TAU0, MU, ETA = 0.005, 0.2, 0.004  # MPa, -, MPa·s/mm


class NodeForce:
    """A constant force (N) on some nodes (a nodal term), ramped over ``ramp_s``."""

    def __init__(self, select, force, ramp_s=0.0):
        self.select, self.force, self.ramp_s = select, np.asarray(force, float), ramp_s

    def bind(self, X, owned, comm):
        self.f = np.zeros((len(X), 3))
        mask = self.select(X)
        self.f[mask] = np.broadcast_to(self.force, (len(X), 3))[mask]

    def forces(self, x, t, dt):
        scale = min(1.0, t / self.ramp_s) if self.ramp_s else 1.0
        return scale * self.f, np.zeros((len(x), 3, 3))

    def commit(self):
        pass

    def revert(self):
        pass


def pull_out(pressure, law, *, speed=None, force=None, travel=1.0, dt=None):
    """Three 40 x 20 mm plies (Δ = 10 mm); the middle one pulled at x = 40 mm.

    The bottom ply is held, the top one held in the plane and pressed down by p.

    Returns the problem, the contact term, the grip mask and the overlap area (mm²).
    """
    grid = TrussGrid(4, 2, 10.0, (0.0, 0.0), False)
    plies = stack_plies([grid] * 3, [0.2] * 3)
    area = node_areas(grid)
    contact = PlyContact(plies, law, K_N)

    squeeze = NodeForce(lambda X: ply_of(plies, X) == 2, 0.0)  # p on the top ply
    terms = [contact, squeeze]
    sheet = stack_sheet(plies)
    problem = TrussProblem(sheet, default_model(), terms, SolverOptions(snes_atol=1e-9))
    X = problem.X
    which = ply_of(plies, X)
    # The pressure's nodal forces: p times each node's area (by its grid position).
    ij = np.rint(X[:, :2] / 10.0).astype(int)
    a_node = area.reshape(3, 5)[ij[:, 1], ij[:, 0]]
    squeeze.f[which == 2, 2] = -pressure * a_node[which == 2]
    problem.fix(which == 0)  # the bottom ply held, the top one pressed onto the middle one
    problem.fix(which == 2, (0, 1))
    middle = which == 1
    problem.fix(middle, (1,))
    grip = middle & (np.abs(X[:, 0] - 40.0) < 1e-9)
    if speed is not None:
        problem.fix(grip, (0,), lambda t: speed * t)
        duration = travel / speed
        dt = dt or 0.05 / speed
    else:
        # The force spread over the middle ply by area: every pair carries its share.
        pull = NodeForce(lambda X: middle, 0.0, ramp_s=1.0)
        pull.bind(X, None, None)
        pull.f[middle, 0] = force * a_node[middle] / area.sum()
        problem.nodal_terms.append(pull)
        duration, dt = 2.0, dt or 0.1
    problem.run(duration, dt)
    return problem, contact, grip, area.sum()


def grip_force(problem, contact, grip):
    """The force the grip exerts (N): the tows' pull plus the friction on the grip nodes."""
    return problem.reaction_force(grip)[0] - contact.f[grip, 0].sum()


@pytest.mark.parametrize("pressure", [0.05, 0.2])
@pytest.mark.parametrize("speed", [0.5, 2.0])
def test_pull_out_steady_force(pressure, speed):
    """F = 2 A (τ₀ + μ p + η_f v) within 2 % once the middle ply slides steadily."""
    law = InterplyLaw(tau0_MPa=TAU0, mu_ply=MU, eta_f_MPa_s_per_mm=ETA, slip_mm=0.05)
    problem, contact, grip, A = pull_out(pressure, law, speed=speed, travel=1.0)
    exact = 2 * A * (TAU0 + MU * pressure + ETA * speed)
    assert grip_force(problem, contact, grip) == pytest.approx(exact, rel=0.02)
    # The pairs follow the sliding ply (node to surface): the pressure over the area in
    # contact carries the load p A on each interface.
    for k in (0, 1):
        on = contact.interface == k
        load = np.sum(contact.pressure_MPa[on] * contact.area[on] * contact.overlap[on])
        assert load == pytest.approx(pressure * A, rel=5e-3)
    assert (np.linalg.norm(contact.sliding_mm, axis=1) > 0.5).all()  # every pair slid


def test_no_slip_below_threshold_and_creep_speed_above():
    """Pulled by 0.9 of 2 A (τ₀ + μp): no pair slides; by 1.2 of it, it creeps at the speed
    the film's drag takes the excess at, over the area in contact.

    The pull is spread over the middle ply by area (a rigid ply's load), so the threshold
    holds pair by pair; pulled at one edge, a flexible ply slides there first (shear lag).
    """
    p = 0.1
    law = InterplyLaw(tau0_MPa=TAU0, mu_ply=MU, eta_f_MPa_s_per_mm=ETA, slip_mm=0.05)
    A = 800.0
    threshold = 2 * A * (TAU0 + MU * p)
    problem, contact, _, _ = pull_out(p, law, force=0.9 * threshold)
    assert np.abs(contact.sliding_mm).max() < 1e-12
    assert np.abs(problem.u.x.array.reshape(-1, 3)[:, 0]).max() < law.slip_mm
    problem, contact, _, _ = pull_out(p, law, force=1.2 * threshold, dt=0.05)
    u0 = problem.u.x.array.reshape(-1, 3)[:, 0].copy()

    def in_contact():  # (mm²) the creeping ply leaves the plates' edges: less area in contact
        return np.sum(contact.area * contact.overlap)

    before = in_contact()
    problem.run(0.5, 0.05)
    v = (problem.u.x.array.reshape(-1, 3)[:, 0] - u0)[contact.a[:15]] / 0.5  # middle ply
    # The load less the Coulomb part (the whole load p A on each interface), over the film's
    # and the tack's areas.
    A_c = 0.5 * (before + in_contact())
    assert A_c < 2 * A  # the overlap shrank as it crept (about 2 mm)
    assert v == pytest.approx((1.2 * threshold - 2 * MU * p * A - TAU0 * A_c) / (ETA * A_c),
                              rel=0.02)


def stretch(n_plies, law=None, tows_per_mm=0.71, pull_all=False):
    """Plies of 40 x 40 mm (Δ = 10 mm) whose first ply's border is stretched 1 % and sheared.

    The other plies are free in the plane (held in z only where the first ply is), unless
    ``law`` is None (a single ply). Returns the reaction on the first ply's edge x = 20 mm and the
    in-plane displacement of every ply's nodes (ply, node) in grid order.
    """
    grid = TrussGrid(4, 4, 10.0, (-20.0, -20.0), False)
    plies = stack_plies([grid] * n_plies, [0.2] * n_plies)
    terms = [PlyContact(plies, law, K_N)] if n_plies > 1 else []
    problem = TrussProblem(stack_sheet(plies), default_model(), terms,
                           SolverOptions(tows_per_mm=tows_per_mm, snes_atol=1e-9))
    which = ply_of(plies, problem.X)
    border = problem.nodes("border")
    first = border & (which == 0)
    right = first & (problem.X[:, 0] > 19.0)
    problem.fix(which == 0, (2,))
    problem.fix(first, (0, 1), lambda t, X: t * (0.01 * X[:, :2] + 0.05 * X[:, 1::-1]))
    if n_plies > 1 and law.interply_friction:  # frictionless: hold the others' borders
        problem.fix(border & (which > 0), (0, 1))
        press = NodeForce(lambda X: ply_of(plies, X) > 0, [0.0, 0.0, -1.0])
        press.bind(problem.X, None, None)
        problem.nodal_terms.append(press)  # the upper plies pressed onto the first
    problem.run(1.0, 0.25)
    u = problem.u.x.array.reshape(-1, 3)
    key = np.lexsort((problem.X[:, 0], problem.X[:, 1], which))
    force = problem.reaction_force(right)
    if terms:  # the plies' coupling at the gripped nodes also passes through the grip
        force = force - terms[0].f[right].sum(axis=0)
    return force, u[key].reshape(n_plies, -1, 3)


def test_bonded_plies_form_like_one_ply_of_summed_stiffness():
    """Two bonded plies, one gripped: the force and motion of one ply with twice the tows."""
    F2, u2 = stretch(2, InterplyLaw(interply_friction=False, bond_MPa_per_mm=1e5))
    F1, u1 = stretch(1, tows_per_mm=2 * 0.71)
    assert F2[:2] == pytest.approx(F1[:2], rel=0.01)
    assert np.abs(u2[1, :, :2] - u2[0, :, :2]).max() < 0.01 * np.abs(u1[0, :, :2]).max()


def test_frictionless_plies_form_like_independent_plies():
    """Frictionless: the gripped ply alone carries the load; the other does not move."""
    free = InterplyLaw(tau0_MPa=0.0, mu_ply=0.0, eta_f_MPa_s_per_mm=0.0)
    F2, u2 = stretch(2, free)
    F1, u1 = stretch(1)
    assert F2[:2] == pytest.approx(F1[:2], rel=1e-6)
    assert np.abs(u2[0] - u1[0]).max() < 1e-6
    assert np.abs(u2[1, :, :2]).max() < 1e-9


def test_stiffness_is_the_derivative_of_the_forces():
    """The coupling blocks equal a finite difference of the forces (plies at 0° and 30°)."""
    from fenicsx_drape.fe.grid import sheet_grid

    lower = TrussGrid(6, 6, 10.0, (-30.0, -30.0), False)
    upper = sheet_grid(40.0, 10.0, ply_angle_deg=30.0)
    plies = stack_plies([lower, upper], [0.3, 0.3])
    law = InterplyLaw(tau0_MPa=0.01, mu_ply=0.3, eta_f_MPa_s_per_mm=0.01, slip_mm=0.1)
    term = PlyContact(plies, law, K_N)
    from fenicsx_drape.fe.plies import stack_nodes

    X = stack_nodes(plies)[0]
    term.bind(X, np.ones(len(X), bool), None)
    assert (term.w.max(axis=1) < 0.99).any()  # some nodes sit inside a cell, not on a node
    rng = np.random.default_rng(1)
    x = X + rng.normal(scale=[0.3, 0.3, 0.05], size=X.shape)
    x[ply_of(plies, X) == 1, 2] -= 0.05  # pressed together
    term.state[:, :3] = rng.normal(scale=0.2, size=(len(term.a), 3))
    term.forces(x, 1.0, 0.1)
    indptr, indices = term.pattern
    K = np.zeros((3 * len(X), 3 * len(X)))
    for r in range(len(X)):
        for k in range(indptr[r], indptr[r + 1]):
            c = indices[k]
            K[3 * r:3 * r + 3, 3 * c:3 * c + 3] = term.values[k]
    h = 1e-6
    nodes = np.unique(np.column_stack([term.a, term.J]))
    for node in nodes[:: max(1, len(nodes) // 25)]:
        for i in range(3):
            xp, xm = x.copy(), x.copy()
            xp[node, i] += h
            xm[node, i] -= h
            fd = -(term.forces(xp, 1.0, 0.1)[0] - term.forces(xm, 1.0, 0.1)[0]).ravel() / (2 * h)
            assert np.allclose(K[:, 3 * node + i], fd, rtol=1e-4, atol=1e-6 * np.abs(K).max())


class Spring:
    """A soft spring (N/mm) holding some nodes near their height (a nodal term)."""

    def __init__(self, select, k):
        self.select, self.k = select, k

    def bind(self, X, owned, comm):
        self.X, self.mask = X, self.select(X)

    def forces(self, x, t, dt):
        f, K = np.zeros((len(x), 3)), np.zeros((len(x), 3, 3))
        f[self.mask, 2] = -self.k * (x[self.mask, 2] - self.X[self.mask, 2])
        K[self.mask, 2, 2] = self.k
        return f, K

    def commit(self):
        pass

    def revert(self):
        pass


class Pressure:
    """A pressure p (MPa) on the upper ply of a contact, over each node's area in contact."""

    def __init__(self, contact, p, area):
        self.contact, self.p, self.area = contact, p, area

    def bind(self, X, owned, comm):
        self.n = len(X)

    def forces(self, x, t, dt):
        c = self.contact
        f = np.zeros((self.n, 3))
        on = c.interface == 1
        f[c.a[on], 2] = -self.p * self.area * c.overlap[on]
        return f, np.zeros((self.n, 3, 3))

    def commit(self):
        pass

    def revert(self):
        pass


def test_a_pull_out_over_five_cells_follows_the_plies():
    """A 40 x 20 mm ply pulled 55 mm (5.5 cells) between two 120 mm plies, the top one pressed
    by p where it lies on the pulled one: the pairs follow it, each node's partner is the point
    under it, and F = 2 A (τ₀ + μ p + η_f v) within 2 % all along (the nodes of the top ply
    that the pulled one passes fade in and out of the contact over a cell: the area in
    contact stays A)."""
    long = TrussGrid(12, 2, 10.0, (-10.0, 0.0), False)
    pulled = TrussGrid(4, 2, 10.0, (0.0, 0.0), False)
    plies = stack_plies([long, pulled, long], [0.2, 0.2, 0.2])
    law = InterplyLaw(tau0_MPa=TAU0, mu_ply=MU, eta_f_MPa_s_per_mm=ETA, slip_mm=0.05)
    contact = PlyContact(plies, law, K_N, follow=True)
    p, v = 0.1, 5.0
    top = node_areas(long)
    soft = Spring(lambda X: ply_of(plies, X) == 2, 1e-3)  # the top ply beyond the pulled one
    problem = TrussProblem(stack_sheet(plies), default_model(),
                           [contact, Pressure(contact, p, top), soft],
                           SolverOptions(snes_atol=1e-9))
    X = problem.X
    which = ply_of(plies, X)
    problem.fix(which == 0)
    problem.fix(which == 2, (0, 1))
    problem.fix(which == 1, (1,))
    grip = (which == 1) & (np.abs(X[:, 0] - 40.0) < 1e-9)
    problem.fix(grip, (0,), lambda t: v * t)
    A = node_areas(pulled).sum()
    exact = 2 * A * (TAU0 + MU * p + ETA * v)
    forces = []

    def record(problem):
        if problem.t > 1.0:  # sliding steadily
            forces.append(grip_force(problem, contact, grip))

    problem.run(55.0 / v, 0.2, on_step=record)
    x = problem.positions()
    on = contact.overlap == 1.0  # (a node beyond the edge keeps the edge's point)
    under = x[contact.a[on]] - np.einsum("pj,pji->pi", contact.w[on], x[contact.J[on]])
    assert np.abs(under[:, :2]).max() < 1e-3  # mm: the partner is the point under the node
    assert contact.cell[contact.interface == 0, 0].min() >= 6  # cells along
    assert np.sum((contact.area * contact.overlap)[contact.interface == 1]) == pytest.approx(
        A, rel=1e-3)
    assert np.array(forces) == pytest.approx(exact, rel=0.02)
