"""The kinematic drape on surfaces whose net is known: planes, a cylinder, a sphere, a cone."""

import math
import warnings

import numpy as np
import pytest

from fenicsx_drape.errors import DrapeInputError, ParameterError
from fenicsx_drape.forming.running.kinematic import (
    GENERATORS,
    HeightField,
    Plane,
    UnionSurface,
    drape,
    inside_outline,
    kinematic_drape,
    rectangle,
)
from fenicsx_drape.forming.tools.shapes import Arc, HemisphereTools, RevolvedTool, Segment

R_MM = 50.0
SPHERE = RevolvedTool("sphere", (Arc((0.0, 0.0), R_MM, math.pi / 2, 0.0),))  # the cap z ≥ 0


def cylinder(radius_mm: float = R_MM) -> HeightField:
    """The cylinder z = √(R² − y²) along x, as a height field (it ends at |y| = R)."""
    def height(x, y):
        with np.errstate(invalid="ignore"):
            return np.sqrt(radius_mm**2 - y**2)

    return HeightField(height, name="cylinder")


def assert_chords(net, cell_mm: float) -> None:
    """Every placed bar of the net is a chord of length Δ (to 1e-8 mm)."""
    for axis in (0, 1):
        length = np.linalg.norm(np.diff(net.x, axis=axis), axis=-1)
        np.testing.assert_allclose(length[np.isfinite(length)], cell_mm, rtol=0, atol=1e-8)


def indices(net):
    """The tow indices (i, j) of the grid's nodes, zero at the start node."""
    ci, cj = net.start_index
    n_i, n_j = net.X.shape[:2]
    return np.meshgrid(np.arange(n_i) - ci, np.arange(n_j) - cj, indexing="ij")


def test_a_plane_is_draped_without_shear():
    """A tilted plane, an off-centre start, a ply angle and another direction: the net is
    the flat net moved rigidly (distances of the flat sheet kept, no shear)."""
    plane = Plane((0.0, 0.0, 5.0), (0.3, -0.2, 1.0))
    net = kinematic_drape(plane, 7.0, outline=rectangle((100.0, 80.0), (10.0, -5.0)),
                          start_mm=(13.0, -7.0), ply_angle_deg=20.0, direction_deg=-15.0)
    assert np.nanmax(np.abs(net.shear_deg())) < 1e-9
    assert_chords(net, 7.0)
    ok = net.present
    x, X = net.x[ok], net.X[ok]
    np.testing.assert_allclose(np.linalg.norm(x[:, None] - x[None], axis=-1),
                               np.linalg.norm(X[:, None] - X[None], axis=-1), atol=1e-8)
    assert np.abs(plane.gap(x).phi).max() < 1e-9
    assert net.unplaced_count == 0 and ok.sum() == inside_outline(
        net.X[ok][:, :2], rectangle((100.0, 80.0), (10.0, -5.0))).sum()


def test_a_cylinder_along_its_axis_is_draped_exactly():
    """Warp along the axis, weft around it: node (i, j) at (iΔ, R sin jβ, R cos jβ) with
    2R sin(β/2) = Δ: the developable surface takes the net without shear."""
    net = kinematic_drape(cylinder(), 5.0, outline=rectangle((200.0, 120.0)))
    i, j = indices(net)
    β = 2 * math.asin(2.5 / R_MM)
    exact = np.stack([5.0 * i, R_MM * np.sin(j * β), R_MM * np.cos(j * β)], axis=-1)
    np.testing.assert_allclose(net.x, exact, atol=1e-9)
    assert np.abs(net.shear_deg()).max() < 1e-9
    assert_chords(net, 5.0)


@pytest.mark.parametrize("generator", GENERATORS)
def test_generators_on_a_sphere_are_great_circles(generator):
    """From any start in any direction both generator kinds follow great circles (the
    plane of each step holds the normal, through the centre)."""
    net = kinematic_drape(SPHERE, 5.0, outline=rectangle((60.0, 60.0), (20.0, 10.0)),
                          start_mm=(20.0, 10.0), direction_deg=35.0, generator=generator)
    ci, cj = net.start_index
    s = net.x[ci, cj]
    # the warp's tangent at the start: in the vertical plane at 35° to x
    d = np.array([math.cos(math.radians(35.0)), math.sin(math.radians(35.0)), 0.0])
    t0 = d - (d @ s) / s[2] * np.array([0.0, 0.0, 1.0])
    for k, tow in enumerate((net.x[:, cj], net.x[ci, :])):
        tow = tow[np.isfinite(tow[:, 0])]
        normal = np.cross(tow[1] - tow[0], tow[-1] - tow[0])
        normal /= np.linalg.norm(normal)
        assert np.abs(tow @ normal).max() < 1e-9  # a plane through the centre
        assert len(tow) == 13
        # the warp's plane holds t0, the weft's is normal to it
        assert abs(t0 @ normal) / np.linalg.norm(t0) == pytest.approx(k, abs=1e-9)
    assert_chords(net, 5.0)


def test_clairauts_relation_on_a_cone():
    """On a surface of revolution a geodesic keeps r sin ψ (ψ: angle to the meridian).
    The discrete geodesic generator does to O(Δ²); the normal section does not."""
    cone = RevolvedTool("cone", (Segment((0.0, 100.0), (1e4, 100.0 - 1e4 * math.tan(0.5))),))
    error = {}
    for generator in GENERATORS:
        for cell in (10.0, 5.0):
            net = kinematic_drape(cone, cell, outline=rectangle((200.0, 200.0), (60.0, 0.0)),
                                  start_mm=(60.0, 0.0), direction_deg=60.0,
                                  generator=generator)
            assert_chords(net, cell)
            tow = net.x[:, net.start_index[1]]
            t = np.diff(tow, axis=0) / cell
            m = 0.5 * (tow[1:] + tow[:-1])
            hoop = np.column_stack([-m[:, 1], m[:, 0], np.zeros(len(m))])  # r e_θ
            c = np.einsum("ni,ni->n", t, hoop)  # r sin ψ
            error[generator, cell] = np.abs(c / c[len(c) // 2] - 1).max()
    assert error["geodesic", 10.0] < 2e-3
    assert error["geodesic", 10.0] / error["geodesic", 5.0] == pytest.approx(4.0, rel=0.1)
    assert error["normal_section", 5.0] > 10 * error["geodesic", 10.0]


def test_a_crease_between_united_planes():
    """A V-shaped valley z = 0.3 |x| (two planes united, a concave crease along y): with the
    warp along the crease each cell lies in one plane and the net is not sheared."""
    valley = UnionSurface((Plane(normal=(-0.3, 0.0, 1.0)), Plane(normal=(0.3, 0.0, 1.0))))
    g = valley.gap(np.array([[0.0, 3.0, 0.0], [2.0, 0.0, 0.6]]))
    np.testing.assert_allclose(g.phi, 0.0, atol=1e-15)
    np.testing.assert_allclose(g.normal[0], [0.0, 0.0, 1.0])  # the bisector
    np.testing.assert_allclose(g.normal[1], np.array([-0.3, 0.0, 1.0]) / math.sqrt(1.09))
    net = kinematic_drape(valley, 5.0, outline=rectangle((100.0, 100.0)), direction_deg=90.0)
    assert np.abs(net.shear_deg()).max() < 1e-9
    assert_chords(net, 5.0)
    assert np.abs(net.x[..., 2] - 0.3 * np.abs(net.x[..., 0])).max() < 1e-9
    assert net.unplaced_count == 0


def test_nodes_beyond_the_end_of_the_surface_are_absent():
    """The sphere's cap ends at its equator: the nodes beyond are counted, NaN, warned of."""
    with pytest.warns(UserWarning, match="460 of 625 nodes"):
        net = kinematic_drape(SPHERE, 10.0, outline=rectangle((240.0, 240.0)))
    assert net.unplaced_count == 460
    assert np.isnan(net.x[net.unplaced]).all() and np.isnan(net.X[net.unplaced]).all()
    assert net.present.sum() == 165 and np.isfinite(net.x[net.present]).all()
    assert np.abs(SPHERE.gap(net.x[net.present], 0.0).phi).max() < 1e-8
    assert_chords(net, 10.0)
    assert net.summary()["unplaced_nodes"] == 460
    # a height field that ends (NaN beyond |y| = R) as well
    with pytest.warns(UserWarning, match="could not be placed"):
        net = kinematic_drape(cylinder(), 10.0, outline=rectangle((100.0, 200.0)))
    assert net.unplaced_count > 0
    assert_chords(net, 10.0)


def test_a_start_off_the_surface_is_a_clear_error():
    with pytest.raises(DrapeInputError, match=r"start point \(x, y\) = \(70, 0\) mm is off "
                                              r"the surface 'sphere'"):
        kinematic_drape(SPHERE, 5.0, outline=rectangle((60.0, 60.0)), start_mm=(70.0, 0.0))
    with pytest.raises(DrapeInputError, match=r"\(0, 0, 55\) mm is off the surface 'sphere' "
                                              r"\(signed distance 5 mm"):
        kinematic_drape(SPHERE, 5.0, outline=rectangle((60.0, 60.0)), start_mm=(0, 0, 55.0))
    # a 3D start on the surface is used as given
    net = kinematic_drape(SPHERE, 5.0, outline=rectangle((60.0, 60.0)), start_mm=(0, 0, 50.0))
    np.testing.assert_allclose(net.start_mm, [0.0, 0.0, 50.0])


def test_bad_options_are_named():
    with pytest.raises(ParameterError, match="outline"):
        kinematic_drape(SPHERE, 5.0)
    with pytest.raises(ParameterError, match="cell_mm"):
        drape(SPHERE, -1.0, outline=rectangle((60.0, 60.0)))
    with pytest.raises(ParameterError, match="generator"):
        drape(SPHERE, 5.0, outline=rectangle((60.0, 60.0)), generator="spline")
    with pytest.raises(ParameterError, match="outline"):
        drape(SPHERE, 5.0, outline=[[0.0, 0.0], [1.0, 1.0]])


def test_a_polygon_blank():
    """An L-shaped blank (a square without its quadrant x, y > 0) on the hemisphere, the
    start in a corner of it: the nodes inside, no others (the ones they hang on outside are
    built and dropped); they are the nodes of the whole square's net."""
    L = np.array([[-60.0, -60.0], [60.0, -60.0], [60.0, 0.0], [0.0, 0.0], [0.0, 60.0],
                  [-60.0, 60.0]])
    tools = HemisphereTools()
    net = kinematic_drape(tools, 10.0, outline=L, start_mm=(-60.0, 60.0))
    X = net.X[net.present][:, :2]
    assert not ((X[:, 0] > 1e-9) & (X[:, 1] > 1e-9)).any()
    assert len(X) == 13 * 13 - 6 * 6 and net.unplaced_count == 0
    assert_chords(net, 10.0)
    square = kinematic_drape(tools, 10.0, outline=rectangle((120.0, 120.0)),
                             start_mm=(-60.0, 60.0))
    np.testing.assert_allclose(net.x[net.present], square.x[net.present], atol=1e-9)


def test_height_field_derivatives():
    """∇φ of a height field against central differences of φ; ∇∇φ on the surface against
    those of ∇φ (with and without the derivatives given)."""
    F = lambda x, y: 10 * np.sin(x / 20) * np.cos(y / 30)  # noqa: E731
    given = HeightField(F, gradient=lambda x, y: (0.5 * np.cos(x / 20) * np.cos(y / 30),
                                                  -np.sin(x / 20) * np.sin(y / 30) / 3))
    rng = np.random.default_rng(3)
    xy = rng.uniform(-40, 40, (5, 2))
    on = np.column_stack([xy, F(xy[:, 0], xy[:, 1])])
    off = on + np.array([0.0, 0.0, 0.7])
    h = 1e-5
    for surface in (given, HeightField(F)):
        for x in (on, off):
            g = surface.gap(x)
            fd = np.stack([(surface.gap(x + h * e).phi - surface.gap(x - h * e).phi) / (2 * h)
                           for e in np.eye(3)], axis=1)
            np.testing.assert_allclose(g.normal, fd, atol=1e-6)
        g = surface.gap(on)
        np.testing.assert_allclose(np.linalg.norm(g.normal, axis=1), 1.0, atol=1e-12)
        fd = np.stack([(surface.gap(on + h * e).normal - surface.gap(on - h * e).normal)
                       / (2 * h) for e in np.eye(3)], axis=2)
        np.testing.assert_allclose(g.hessian, fd, atol=1e-5)


def test_no_warning_when_all_nodes_are_placed():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        net = kinematic_drape(SPHERE, 10.0, outline=rectangle((60.0, 60.0)))
    assert net.unplaced_count == 0
    s = net.summary()
    assert s["nodes"] == 49 and s["max_shear_deg"] > 0 and s["generator"] == "geodesic"


def bumps(turn_deg: float = 0.0) -> HeightField:
    """A Gaussian dome with a sine ripple (no symmetry), turned by ``turn_deg`` about z."""
    c, s = math.cos(math.radians(turn_deg)), math.sin(math.radians(turn_deg))

    def height(x, y):
        u, v = c * x + s * y, -s * x + c * y  # the point in the unturned frame
        return 40 * np.exp(-(u * u + v * v) / 4000) + 6 * np.sin(u / 11) * np.cos(v / 14)

    return HeightField(height, name="bumps")


def test_the_net_turns_with_the_surface():
    """No hidden frame: the surface, blank, start, ply angle and direction all turned by
    50° about z give the same net turned by 50° (on a surface without any symmetry)."""
    β = 50.0
    c, s = math.cos(math.radians(β)), math.sin(math.radians(β))
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    blank = rectangle((160.0, 120.0), (5.0, -8.0))
    start = np.array([12.0, -6.0])
    a = kinematic_drape(bumps(), 5.0, outline=blank, start_mm=start, ply_angle_deg=10.0,
                        direction_deg=25.0)
    b = kinematic_drape(bumps(β), 5.0, outline=blank @ turn[:2, :2].T,
                        start_mm=turn[:2, :2] @ start, ply_angle_deg=10.0 + β,
                        direction_deg=25.0 + β)
    assert a.present.sum() > 700 and a.unplaced_count == 0
    np.testing.assert_array_equal(a.present, b.present)
    # to the differences of the central-difference normals in the two frames (3e-9 mm)
    np.testing.assert_allclose(b.x[b.present], a.x[a.present] @ turn.T, atol=1e-8)
    np.testing.assert_allclose(b.shear_deg(), a.shear_deg(), atol=1e-7)
    assert_chords(a, 5.0)
    assert np.abs(bumps().gap(a.x[a.present]).phi).max() < 1e-9
    warp, weft = a.tow_strains()
    assert min(np.nanmin(warp), np.nanmin(weft)) > -1e-12  # chords: the net never shortens


def slot_tools():
    """A flat-topped post (r ≤ 41) and a plate (r ≥ 42), both with 1 mm rounded edges (G1):
    a 1 mm slot between them at depth, widening to 3 mm at the top."""
    post = RevolvedTool("post", (Segment((0.0, 0.0), (40.0, 0.0)),
                                 Arc((40.0, -1.0), 1.0, math.pi / 2, 0.0),
                                 Segment((41.0, -1.0), (41.0, -1e4))))
    plate = RevolvedTool("plate", (Segment((42.0, -1e4), (42.0, -1.0)),
                                   Arc((43.0, -1.0), 1.0, math.pi, math.pi / 2),
                                   Segment((43.0, 0.0), (1e4, 0.0))))
    return post, plate


def test_bridging_a_slot():
    """The net's nodes fall into the slot of the plain union (4.7 mm deep, 77° of shear);
    a smooth minimum of width 3 mm bridges it: the net stays within 0.1 mm of the plane."""
    post, plate = slot_tools()
    blank = rectangle((120.0, 120.0))
    plain = kinematic_drape(UnionSurface((post, plate)), 5.0, outline=blank)
    assert np.nanmin(plain.x[..., 2]) < -4.0 and np.nanmax(np.abs(plain.shear_deg())) > 70.0
    bridged = kinematic_drape(UnionSurface((post, plate), bridge_mm=3.0), 5.0, outline=blank)
    assert np.nanmax(np.abs(bridged.x[..., 2])) < 0.1
    assert np.nanmax(np.abs(bridged.shear_deg())) < 0.2
    assert bridged.unplaced_count == 0
    assert_chords(bridged, 5.0)


def test_smooth_minimum_derivatives():
    """The bridged union's ∇φ and ∇∇φ against central differences, in the blend zone."""
    post, plate = slot_tools()
    union = UnionSurface((post, plate, Plane((0.0, 0.0, -0.5))), bridge_mm=3.0)
    x = np.array([[40.2, 0.3, 0.1], [41.4, -0.6, -0.3], [30.0, 29.8, 0.4], [42.5, 1.0, 0.7]])
    g = union.gap(x)
    φ = np.sort(np.stack([p.gap(x, 0.0).phi for p in union.parts]), axis=0)
    assert (φ[1] - φ[0] < 3.0).all()  # every point is in a blend zone
    h = 1e-6
    grad = np.stack([(union.gap(x + h * e).phi - union.gap(x - h * e).phi) / (2 * h)
                     for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(g.normal, grad, atol=1e-7)
    h = 1e-5
    hess = np.stack([(union.gap(x + h * e).normal - union.gap(x - h * e).normal) / (2 * h)
                     for e in np.eye(3)], axis=2)
    np.testing.assert_allclose(g.hessian, hess, atol=1e-5)
