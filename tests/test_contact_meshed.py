"""Contact with meshed tools: gap and Jacobian of moving meshed tools, tool friction through
``tool.displacement``, and FE patches on a meshed plate (flat and tilted)."""

import math

import numpy as np
import pytest

from fenicsx_drape.forming.terms.contact import PenaltyContact
from fenicsx_drape.forming.tools.motion import RigidMotion
from fenicsx_drape.forming.tools.shapes import HemisphereTools, MeshedTool
from fenicsx_drape.forming.tools.surfaces import TriangleSurface, load_surface

RNG = np.random.default_rng(23)


def fd_jacobian(fun, x, h=1e-6):
    """Central differences of a per-node map (n, 3) -> (n, 3): shaped (n, 3, 3)."""
    J = np.empty((len(x), 3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        J[:, :, k] = (fun(x + e) - fun(x - e)) / (2 * h)
    return J


def meshed_plate(half=100.0, n=11, side="+z", normal=(0.0, 0.0, 1.0), offset_mm=0.0):
    """A square plate (irregular Delaunay triangles) through the origin, normal ``normal``."""
    from scipy.spatial import Delaunay

    c = np.linspace(-half, half, n)
    X, Y = np.meshgrid(c, c)
    xy = np.column_stack([X.ravel(), Y.ravel()])
    inner = (np.abs(xy) < half - 1e-9).all(axis=1)
    xy[inner] += RNG.uniform(-0.3, 0.3, (inner.sum(), 2)) * (c[1] - c[0])
    tri = Delaunay(xy).simplices
    n_ = np.asarray(normal, float) / np.linalg.norm(normal)
    # Turn the plane z = 0 onto the plane of normal n (about the x axis for a tilted one).
    e2 = np.cross(n_, [1.0, 0.0, 0.0])
    e2 /= np.linalg.norm(e2)
    e1 = np.cross(e2, n_)
    pts = xy[:, :1] * e1 + xy[:, 1:] * e2 + offset_mm * n_
    return TriangleSurface(pts, tri, sheet_side=side, source="plate")


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    path = tmp_path_factory.mktemp("ball") / "ball.geo"
    path.write_text('SetFactory("OpenCASCADE");\nSphere(1) = {0, 0, 0, 20};\n')
    return load_surface(path, mesh_size_mm=2.0, order=2, comm=None)


def moving(surface, rotation=True):
    motion = RigidMotion(time_s=[0.0, 10.0], x_mm=[0.0, 3.0], z_mm=[0.0, 20.0],
                         rotation_deg=[0.0, 30.0] if rotation else None, axis=(1.0, 1.0, 0.0),
                         centre_mm=(5.0, 0.0, 0.0))
    return MeshedTool("ball", surface, motion, spacing_mm=1.0, cache=False, comm=None)


def test_gap_of_a_moving_meshed_tool_is_its_field_carried_along(ball):
    tool = moving(ball)
    t = 6.0
    X = RNG.normal(size=(400, 3))
    X = X / np.linalg.norm(X, axis=1)[:, None] * RNG.uniform(18, 23, (400, 1))
    x = tool.motion.apply(X, t)
    g = tool.gap(x, t)
    phi, grad, _ = tool.field.evaluate(X)
    R, _ = tool.motion.at(t)
    np.testing.assert_allclose(g.phi, phi, atol=1e-12)
    np.testing.assert_allclose(g.normal, grad @ R.T, atol=1e-12)
    np.testing.assert_allclose(g.phi, np.linalg.norm(X, axis=1) - 20.0, atol=0.03)
    # Normal and curvature are the derivatives of the gap (the Jacobian's consistency).
    grad_fd = fd_jacobian(lambda y: np.repeat(tool.gap(y, t).phi[:, None], 3, 1), x)[:, 0, :]
    np.testing.assert_allclose(g.normal, grad_fd, atol=1e-7)
    hess_fd = fd_jacobian(lambda y: tool.gap(y, t).normal, x)
    np.testing.assert_allclose(g.hessian, hess_fd, atol=1e-6)
    # displacement: where the tool's point now at x was at t0.
    d = tool.displacement(x, 2.0, t)
    np.testing.assert_allclose(x - d, tool.motion.apply(X, 2.0), atol=1e-12)


@pytest.mark.parametrize("friction", [0.0, 0.3])
@pytest.mark.parametrize("rotation", [False, True])
def test_contact_jacobian_with_a_meshed_tool_is_consistent(ball, friction, rotation):
    tool = moving(ball, rotation)
    term = PenaltyContact(tool, 2.4e3, friction=friction)
    t0, t = 4.0, 6.0
    X = RNG.normal(size=(300, 3))
    X = X / np.linalg.norm(X, axis=1)[:, None] * 20.0
    x_n = tool.motion.apply(X + RNG.normal(size=X.shape) * 0.5, t0)
    term.bind(x_n, np.ones(len(X), bool), None)
    term.forces(x_n, t0, t0)
    term.commit()  # the last converged step ended at t0, at x_n
    x = tool.motion.apply(X * (1 - RNG.uniform(-0.1, 0.3, (300, 1)) / 20), t)
    f, K = term.forces(x, t, t - t0)
    assert (np.abs(f).sum(1) > 0).sum() > 100  # many nodes in contact
    K_fd = fd_jacobian(lambda y: -term.forces(y, t, t - t0)[0], x)
    np.testing.assert_allclose(K, K_fd, atol=1e-6 * np.abs(K).max())
    if friction == 0.0:  # the gradient of a potential: symmetric
        np.testing.assert_allclose(K, K.transpose(0, 2, 1), atol=1e-9 * np.abs(K).max())


class ZOffsetContact(PenaltyContact):
    """The contact term as it was before ``tool.displacement``: the slip corrected by the
    tool's z offset (the friction method of main at 4c390df, verbatim but for the nodes'
    last positions ``x_n``, now an argument: the contact evaluates only the nodes near it)."""

    def _friction(self, x, x_n, t, g, f_N, dp, active):
        def _outer(a, b):
            return np.einsum("ni,nj->nij", a, b)

        n, H = g.normal, g.hessian
        d = x - x_n
        d[:, 2] -= self.tool.z_offset(t) - self.tool.z_offset(self._t_n)
        dn = np.einsum("ni,ni->n", d, n)
        s = d - dn[:, None] * n
        w = np.sqrt(np.einsum("ni,ni->n", s, s) + self.s_ε**2)
        m = s / w[:, None]
        f = -self.μ * f_N[:, None] * m
        P = np.eye(3) - _outer(n, n)
        ds = P - dn[:, None, None] * H - _outer(n, np.einsum("nij,nj->ni", H, d))
        dm = (np.eye(3) - _outer(m, m)) / w[:, None, None]
        K = self.μ * (f_N[:, None, None] * dm @ ds + dp[:, None, None] * _outer(m, n))
        on = active[:, None]
        return np.where(on, f, 0.0), np.where(on[:, :, None], K, 0.0)


@pytest.mark.parametrize("tool", ["punch", "die"])
def test_tool_friction_of_the_closed_form_tools_is_unchanged(tool):
    """The slip is x − x_n − tool.displacement: for the hemisphere's punch and die the old
    z-offset rule, bit for bit (so the closed-form hemisphere's results are unchanged)."""
    tools = HemisphereTools()
    rigid = tools.punch(40.0) if tool == "punch" else tools.die()
    np.testing.assert_array_equal(tools.punch(40.0).displacement(np.zeros((2, 3)), 3.0, 5.5),
                                  [[0, 0, 5.0], [0, 0, 5.0]])
    X = np.column_stack([RNG.uniform(-70, 70, (400, 2)), np.zeros(400)])
    t0, t = 10.0, 12.0
    g0 = rigid.gap(X, t0)
    x_n = X - (g0.phi + RNG.uniform(-0.3, 0.1, 400))[:, None] * g0.normal
    g = rigid.gap(x_n, t)
    x = x_n - (g.phi + RNG.uniform(-0.3, 0.1, 400))[:, None] * g.normal
    x[:, :2] += RNG.uniform(-0.5, 0.5, (400, 2))
    out = []
    for cls in (PenaltyContact, ZOffsetContact):
        term = cls(rigid, 2.4e3, friction=0.3)
        term.bind(X, np.ones(400, bool), None)
        term.forces(x_n, t0, t0)
        term.commit()
        out.append(term.forces(x, t, t - t0))
    assert (np.abs(out[0][0]).sum(1) > 0).sum() > 100
    np.testing.assert_array_equal(out[0][0], out[1][0])
    np.testing.assert_array_equal(out[0][1], out[1][1])


def test_covers_tells_the_nodes_under_a_clamping_surface(tmp_path):
    path = tmp_path / "ring.geo"
    path.write_text('SetFactory("OpenCASCADE");\nDisk(1) = {0, 0, 0, 60};\n'
                    'Disk(2) = {0, 0, 0, 30};\n'
                    'BooleanDifference{ Surface{1}; Delete; }{ Surface{2}; Delete; }\n')
    ring = load_surface(path, mesh_size_mm=3.0, order=2, comm=None)
    holder = MeshedTool("holder", ring, spacing_mm=2.0, cache=False, comm=None)
    x = np.column_stack([RNG.uniform(-70, 70, (3000, 2)), RNG.uniform(-0.5, 0.5, 3000)])
    r = np.hypot(x[:, 0], x[:, 1])
    covered = holder.covers(x, 0.0)
    clear = (np.abs(r - 30) > 0.2) & (np.abs(r - 60) > 0.2)  # the rims are polygons
    np.testing.assert_array_equal(covered[clear], ((r > 30) & (r < 60))[clear])
    # Far above the plate a node is not under it (unless asked to look that far).
    far = np.array([[45.0, 0.0, 20.0]])
    assert not holder.covers(far, 0.0)[0] and holder.covers(far, 0.0, reach_mm=30.0)[0]
    # Its gap under the plate (away from the rims) is the height, its normal +z.
    inner = (r > 30 + holder.field.band_mm + 4) & (r < 60 - holder.field.band_mm - 4)
    g = holder.gap(x[inner], 0.0)
    np.testing.assert_allclose(g.phi, x[inner, 2], atol=1e-6)
    np.testing.assert_allclose(g.normal, np.tile([0, 0, 1.0], (inner.sum(), 1)), atol=1e-6)


# -- the FE patches -----------------------------------------------------------------------------


class DeadLoad:
    """A constant force on every node (a nodal term)."""

    def __init__(self, force_N):
        self.force = np.asarray(force_N, dtype=float)

    def bind(self, X, owned, comm):
        self.n = len(X)

    def forces(self, x, t, dt):
        return np.broadcast_to(self.force, (self.n, 3)).copy(), np.zeros((self.n, 3, 3))

    def commit(self):
        pass

    def revert(self):
        pass


def _fe():
    pytest.importorskip("dolfinx")
    from mpi4py import MPI

    from fenicsx_drape.fe.mesh import truss_mesh, truss_sheet
    from fenicsx_drape.fe.solver import SolverOptions, TrussProblem
    from fenicsx_drape.forming.terms.stabilisation import ExtrapolationSpring
    from fenicsx_drape.model import default_model

    return (MPI, truss_mesh, truss_sheet, SolverOptions, TrussProblem, ExtrapolationSpring,
            default_model)


@pytest.mark.parallel
def test_meshed_plate_patch_reaction_equals_load_and_penetration_falls_as_1_over_k():
    """A 60 mm net pressed onto a meshed plate by a load on every node: the plate carries
    the whole load, and every node sinks by the penalty law's depth, ∝ 1/k."""
    MPI, _, truss_sheet, SolverOptions, TrussProblem, ExtrapolationSpring, default_model = _fe()
    comm = MPI.COMM_WORLD
    plate = MeshedTool("plate", meshed_plate(), spacing_mm=2.0, cache=False, comm=comm)
    load, depth = 0.5, []
    for k in (2.4e2, 2.4e3, 2.4e4):
        contact = PenaltyContact(plate, k)
        spring = ExtrapolationSpring(1.0)  # holds the flat net until the plate pushes back
        problem = TrussProblem(truss_sheet(60.0, 10.0, comm=comm), default_model(),
                               [contact, DeadLoad([0.0, 0.0, -load]), spring],
                               SolverOptions(snes_atol=1e-10, tow_bending_EI_Nmm2=0.0,
                                             predictor=False))
        # No predictor: it would project the resting nodes onto the plate, where the
        # penalty's stiffness starts from zero, and the net (z free) would have none.
        # The border held in the plane, stretched by 0.1 %: tows in tension, off the kink of
        # the tow law at ε = 0.
        problem.fix("border", (0, 1), lambda t, X: 1e-3 * X[:, :2])
        problem.run(3.0, 1.0)
        spring.c = 0.0  # at rest on the plate: no stabilisation force left
        problem.run(1.0, 1.0)
        x = problem.positions()
        f = contact.forces(x, problem.t, 1.0)[0]
        owned = problem.owned
        n = comm.allreduce(np.count_nonzero(owned))
        push = comm.allreduce(f[owned].sum(axis=0), op=MPI.SUM)
        np.testing.assert_allclose(push, [0.0, 0.0, n * load], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(problem.reaction_force("border"), 0.0, atol=1e-8)
        local = contact.penetration(x, problem.t)[owned]
        depth.append(comm.allreduce(local.max(initial=0.0), op=MPI.MAX))
        lowest = comm.allreduce(local.min(initial=np.inf), op=MPI.MIN)
        assert lowest == pytest.approx(depth[-1], rel=1e-6)  # the flat net sinks evenly
    # Quadratic regime of the penalty (load < f_s / 2): depth = √(2 f_s p) / k ∝ 1/k.
    np.testing.assert_allclose(depth, np.sqrt(2 * 100.0 * load) / np.array([2.4e2, 2.4e3, 2.4e4]),
                               rtol=1e-6)


@pytest.mark.parametrize("tool_moves", [False, True])
def test_tilted_meshed_plane_normals_and_friction_oppose_the_slip(tool_moves):
    """A net lying on a plane tilted 30° about x, pressed onto it and slid along x (the
    nodes pulled, or the plane moved under them): contact normals are the plane's normal,
    friction opposes the slip relative to the plane with magnitude μ N."""
    MPI, truss_mesh, _, SolverOptions, TrussProblem, ExtrapolationSpring, default_model = _fe()
    from fenicsx_drape.fe.grid import sheet_grid

    comm = MPI.COMM_SELF
    α = math.radians(30.0)
    n = np.array([0.0, -math.sin(α), math.cos(α)])  # the plane's normal
    t2 = np.array([0.0, math.cos(α), math.sin(α)])  # in the plane, across the slip
    grid = sheet_grid(40.0, 10.0)
    bars, kinds = grid.bars
    X = grid.nodes[:, :1] * [1.0, 0, 0] + grid.nodes[:, 1:2] * t2  # the net on the plane
    sheet = truss_mesh(X, bars, kinds, 10.0, comm=comm)
    # The plane 0.01 mm above the net (so the nodes start in contact), fixed or moving +x.
    motion = RigidMotion(time_s=[0.0, 3.0], x_mm=[0.0, 3.0]) if tool_moves else None
    plane = MeshedTool("plane", meshed_plate(normal=n, offset_mm=0.01), motion,
                       spacing_mm=2.0, cache=False, comm=comm)
    μ, F = 0.3, 0.8  # N per node, along −n
    contact = PenaltyContact(plane, 2.4e3, friction=μ, slip_regularisation_mm=0.01)
    spring = ExtrapolationSpring(1.0, lambda x, t: np.tile(t2, (len(x), 1)))  # no mechanism
    problem = TrussProblem(sheet, default_model(), [contact, DeadLoad(-F * n), spring],
                           SolverOptions(snes_atol=1e-10, tow_bending_EI_Nmm2=0.0))
    problem.fix("all", (0,), (lambda t: 0.0) if tool_moves else (lambda t: t))  # 1 mm/s
    for t in (1.0, 2.0, 3.0):
        x_n = problem.positions()
        assert problem.step(t).converged
    x = problem.positions()
    g = plane.gap(x, problem.t)
    np.testing.assert_allclose(g.normal, np.tile(n, (len(x), 1)), atol=1e-9)
    # The contact force of the last step (slip from x_n at 2 s), by a fresh term.
    last = PenaltyContact(plane, 2.4e3, friction=μ, slip_regularisation_mm=0.01)
    last.bind(x_n, np.ones(len(x), bool), None)
    last.forces(x_n, 2.0, 1.0)
    last.commit()
    f = last.forces(x, 3.0, 1.0)[0]
    N = f @ n
    np.testing.assert_allclose(N, F, rtol=1e-6)  # the normal force carries the load
    f_t = f - N[:, None] * n
    slip_dir = np.array([1.0, 0, 0]) * (-1.0 if tool_moves else 1.0)  # relative to the plane
    s = 1.0  # mm of slip per step, ≫ the regularising 0.01 mm
    np.testing.assert_allclose(f_t, np.tile(-μ * F * s / math.hypot(s, 0.01) * slip_dir,
                                            (len(x), 1)), atol=1e-6)


@pytest.mark.parallel
def test_a_meshed_tool_gives_the_same_gap_on_every_rank_as_on_one(tmp_path_factory):
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    folder = comm.bcast(str(tmp_path_factory.mktemp("tool")) if comm.rank == 0 else None)
    if comm.rank == 0:
        with open(f"{folder}/ball.geo", "w") as f:
            f.write('SetFactory("OpenCASCADE");\nSphere(1) = {0, 0, 0, 12};\n')
    comm.Barrier()
    motion = RigidMotion(time_s=[0.0, 1.0], z_mm=[0.0, 5.0])
    shared = MeshedTool("ball", load_surface(f"{folder}/ball.geo", mesh_size_mm=3.0),
                        motion, cache=False)  # read and built on rank 0, broadcast
    alone = MeshedTool("ball", load_surface(f"{folder}/ball.geo", mesh_size_mm=3.0,
                                            comm=None), motion, cache=False, comm=None)
    x = np.random.default_rng(3).uniform(-15, 15, (500, 3))
    a, b = shared.gap(x, 0.4), alone.gap(x, 0.4)
    np.testing.assert_array_equal(a.phi, b.phi)
    np.testing.assert_array_equal(a.hessian, b.hessian)
    assert len(set(comm.allgather(a.phi.tobytes()))) == 1
