"""Tool surfaces from every source Gmsh reads; orientation, closest points, errors, MPI."""

import math

import numpy as np
import pytest

pytest.importorskip("gmsh")

import gmsh

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.tools.surfaces import (
    TriangleSurface,
    closest_on_triangles,
    load_surface,
)

R = 10.0  # mm, the test sphere
RNG = np.random.default_rng(5)

SPHERE_GEO = """// a sphere; its radius from outside
DefineConstant[ radius_mm = 10.0 ];
SetFactory("OpenCASCADE");
Sphere(1) = {0, 0, 0, radius_mm};
"""

SPHERE_PY = """
def build(gmsh, radius_mm=10.0):
    gmsh.model.occ.addSphere(0.0, 0.0, 0.0, radius_mm)
    gmsh.model.occ.synchronize()
"""


def area_and_volume(s: TriangleSurface):
    p, t = s.points, s.triangles
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    cross = np.cross(b - a, c - a)
    return 0.5 * np.linalg.norm(cross, axis=1).sum(), np.einsum("ij,ij->i", a, cross).sum() / 6


def write_with_gmsh(path, mesh_mm=None, order=1):
    """Write the sphere as CAD (.step/.brep/.iges) or, meshed, as .stl/.msh."""
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("export")
        gmsh.model.occ.addSphere(0.0, 0.0, 0.0, R)
        gmsh.model.occ.synchronize()
        if mesh_mm is not None:
            gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_mm)
            gmsh.model.mesh.generate(2)
            gmsh.model.mesh.setOrder(order)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    d = tmp_path_factory.mktemp("sources")
    (d / "sphere.geo").write_text(SPHERE_GEO)
    (d / "sphere.py").write_text(SPHERE_PY)
    out = {"geo": d / "sphere.geo", "py": d / "sphere.py"}
    for kind in ("step", "brep", "iges"):
        out[kind] = write_with_gmsh(d / f"sphere.{kind}")
    out["stl"] = write_with_gmsh(d / "sphere.stl", mesh_mm=2.0)
    out["msh"] = write_with_gmsh(d / "sphere.msh", mesh_mm=2.0, order=2)
    return out


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("kind", ["geo", "py", "step", "brep", "iges", "stl", "msh"])
def test_every_source_gives_the_closed_outward_sphere(sources, kind):
    s = load_surface(sources[kind], mesh_size_mm=2.0, comm=None)
    assert s.closed and len(s.triangles) > 500
    area, volume = area_and_volume(s)
    assert area == pytest.approx(4 * math.pi * R**2, rel=0.02)
    assert volume == pytest.approx(4 / 3 * math.pi * R**3, rel=0.03)  # > 0: normals outwards
    d = s.signed_distance(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2 * R], [3.0, 4.0, 0.0]]))
    np.testing.assert_allclose(d, [-R, R, 5.0 - R], atol=0.25)  # faceted: inside the sphere
    assert not gmsh.isInitialized()  # Gmsh finalised again, nothing left behind


@pytest.mark.skip_in_parallel
def test_parameters_reach_the_script_and_do_not_leak(sources):
    for kind in ("geo", "py"):
        big = load_surface(sources[kind], {"radius_mm": 12.0}, mesh_size_mm=3.0, comm=None)
        assert big.bounds[1][2] == pytest.approx(12.0, abs=1e-6)  # the pole is a node
        again = load_surface(sources[kind], mesh_size_mm=3.0, comm=None)  # default radius
        assert again.bounds[1][2] == pytest.approx(R, abs=1e-6)


@pytest.mark.skip_in_parallel
def test_a_surface_is_read_once_until_its_folder_changes(tmp_path, monkeypatch):
    from fenicsx_drape.forming.tools import surfaces

    path = tmp_path / "sphere.geo"
    path.write_text(SPHERE_GEO)
    reads = []
    read = surfaces._read
    monkeypatch.setattr(surfaces, "_read", lambda *a: reads.append(a) or read(*a))
    first = load_surface(path, mesh_size_mm=3.0, comm=None)
    assert load_surface(path, mesh_size_mm=3.0, comm=None) is first and len(reads) == 1
    # Other arguments, the file's bytes or a file it may include: read again.
    load_surface(path, {"radius_mm": 12.0}, mesh_size_mm=3.0, comm=None)
    path.write_text(SPHERE_GEO.replace("10.0", "11.0"))
    bigger = load_surface(path, mesh_size_mm=3.0, comm=None)
    assert bigger.bounds[1][2] == pytest.approx(11.0, abs=1e-6)
    (tmp_path / "included.geo").write_text("// a file the script might include\n")
    assert load_surface(path, mesh_size_mm=3.0, comm=None) is not bigger
    assert len(reads) == 4


@pytest.mark.skip_in_parallel
def test_onelab_parameters_by_their_name(tmp_path):
    path = tmp_path / "onelab.geo"
    path.write_text('DefineConstant[ r = {10, Name "Parameters/radius"} ];\n'
                    'SetFactory("OpenCASCADE");\nSphere(1) = {0, 0, 0, r};\n')
    s = load_surface(path, {"Parameters/radius": 6.0}, mesh_size_mm=2.0, comm=None)
    assert s.bounds[1][2] == pytest.approx(6.0)


@pytest.mark.skip_in_parallel
def test_second_order_triangles_are_split_through_their_mid_side_nodes(sources):
    one = load_surface(sources["geo"], mesh_size_mm=3.0, order=1, comm=None)
    two = load_surface(sources["geo"], mesh_size_mm=3.0, order=2, comm=None)
    assert len(two.triangles) == 4 * len(one.triangles)
    # Mid-side nodes lie on the sphere: the faceted area converges faster.
    exact = 4 * math.pi * R**2
    err1 = exact - area_and_volume(one)[0]
    err2 = exact - area_and_volume(two)[0]
    assert 0 < err2 < 0.3 * err1
    np.testing.assert_allclose(np.linalg.norm(two.points, axis=1), R, rtol=1e-6)
    # A second-order .msh is split alike.
    msh = load_surface(sources["msh"], comm=None)
    assert msh.closed and np.allclose(np.linalg.norm(msh.points, axis=1), R, rtol=1e-6)
    assert msh.mesh_size_mm < 1.5  # half of Gmsh's 2 mm: the flat triangles


@pytest.mark.skip_in_parallel
def test_gmsh_session_of_the_caller_is_left_alone(sources):
    gmsh.initialize(interruptible=False)
    try:
        gmsh.model.add("mine")
        gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", 123.0)
        models = sorted(gmsh.model.list())
        load_surface(sources["geo"], mesh_size_mm=3.0, comm=None)
        # A build() that makes a model of its own: read from it, removed afterwards.
        own = sources["py"].with_name("own_model.py")
        own.write_text("def build(gmsh):\n    gmsh.model.add('extra')\n"
                       "    gmsh.model.occ.addSphere(0, 0, 0, 4.0)\n"
                       "    gmsh.model.occ.synchronize()\n")
        s = load_surface(own, mesh_size_mm=2.0, comm=None)
        assert s.bounds[1][2] == pytest.approx(4.0)
        assert gmsh.isInitialized()
        assert sorted(gmsh.model.list()) == models  # none added, none lost
        assert gmsh.option.getNumber("Mesh.MeshSizeMax") == 123.0  # options put back
    finally:
        gmsh.finalize()


def disc_surface(flip_some=False, side="+z"):
    """An annulus 2 < r < 10 in z = 0, triangulated by hand (open, two boundaries)."""
    r = np.array([2.0, 4.0, 6.0, 8.0, 10.0])
    n = 24
    θ = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = np.array([[ri * np.cos(a), ri * np.sin(a), 0.0] for ri in r for a in θ])
    tris = []
    for i in range(len(r) - 1):
        for j in range(n):
            a, b = i * n + j, i * n + (j + 1) % n
            c, d = a + n, b + n
            tris += [[a, b, d], [a, d, c]]
    tris = np.array(tris)
    if flip_some:
        flip = RNG.random(len(tris)) < 0.5
        tris[flip] = tris[flip][:, [0, 2, 1]]
    return TriangleSurface(pts, tris, sheet_side=side, source="annulus")


@pytest.mark.parametrize("side, sign", [("+z", 1.0), ("-z", -1.0), ((0.1, 0.0, 1.0), 1.0)])
def test_open_surface_is_oriented_consistently_towards_the_sheet(side, sign):
    s = disc_surface(flip_some=True, side=side)
    np.testing.assert_allclose(s.face_normals[:, 2], sign)
    assert not s.closed and len(s.boundary_edges) == 48


def test_closest_points_are_exact_and_the_boundary_is_flagged():
    s = disc_surface()
    x = np.column_stack([RNG.uniform(-12, 12, (2000, 2)), RNG.uniform(-3, 3, 2000)])
    q, d, on_boundary = s.closest(x)
    # Brute force over all triangles.
    p, t = s.points, s.triangles
    for i in range(0, 2000, 97):
        qq, _ = closest_on_triangles(np.repeat(x[i:i + 1], len(t), 0), p[t[:, 0]], p[t[:, 1]],
                                     p[t[:, 2]])
        assert d[i] == pytest.approx(np.linalg.norm(qq - x[i], axis=1).min(), abs=1e-12)
    np.testing.assert_allclose(np.linalg.norm(q - x, axis=1), d, atol=1e-12)
    r = np.hypot(x[:, 0], x[:, 1])
    # Under the (polygonal) plate: the foot of the perpendicular, not on the boundary.
    inside = (r > 2.05) & (r < 9.6)
    np.testing.assert_allclose(d[inside], np.abs(x[inside, 2]), atol=1e-12)
    assert not on_boundary[inside].any()
    assert on_boundary[(r < 1.9) | (r > 10.01)].all()  # in the opening or beyond the rim
    # Signed: the sheet's side (+z) is positive; beyond the boundary counts as outside.
    sd = s.signed_distance(x)
    np.testing.assert_allclose(sd[inside], x[inside, 2], atol=1e-12)
    assert (sd[on_boundary] >= 0).all()


def test_few_points_measured_against_every_triangle_are_the_search(monkeypatch):
    """Few points (a holder per step): all point-triangle pairs, the search's answer; a point
    on an edge or a corner inside the surface is on it, whichever triangle wins the tie."""
    import fenicsx_drape.forming.tools.surfaces as surfaces

    s = disc_surface()
    x = np.column_stack([RNG.uniform(-12, 12, (300, 2)), RNG.uniform(-3, 3, 300)])
    chunks = np.array_split(np.arange(len(x)), 10)  # 30 points × 192 triangles a call
    assert 30 * len(s.triangles) <= surfaces._ALL_PAIRS
    pairs = [np.concatenate(c) for c in zip(*(s.closest(x[i]) for i in chunks))]
    monkeypatch.setattr(surfaces, "_ALL_PAIRS", 0)
    searched = [np.concatenate(c) for c in zip(*(s.closest(x[i]) for i in chunks))]
    np.testing.assert_allclose(pairs[0], searched[0], atol=1e-12)
    np.testing.assert_allclose(pairs[1], searched[1], atol=1e-12)
    np.testing.assert_array_equal(pairs[2], searched[2])
    monkeypatch.undo()
    p, t = s.points, s.triangles
    r = np.hypot(p[:, 0], p[:, 1])
    middles = 0.5 * (p[t[:, 0]] + p[t[:, 1]])
    rm = np.hypot(middles[:, 0], middles[:, 1])
    on = np.concatenate([p[(r > 3) & (r < 9)], middles[(rm > 3) & (rm < 9)]])
    for part in np.array_split(on, 8):
        _, d, on_boundary = s.closest(part)
        assert d.max() < 1e-12 and not on_boundary.any()


def test_point_triangle_regions():
    a, b, c = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.0, 1, 0])
    p = np.array([[0.2, 0.2, 1.0], [-1, -1, 0], [2, -0.1, 0], [-0.5, 2, 0], [0.5, -1, 0],
                  [1, 1, 0.5], [-1, 0.5, 0]])
    q, region = closest_on_triangles(p, *(np.tile(v, (len(p), 1)) for v in (a, b, c)))
    np.testing.assert_array_equal(region, [0, 1, 2, 3, 4, 5, 6])  # FACE, A, B, C, AB, BC, CA
    np.testing.assert_allclose(q, [[0.2, 0.2, 0], a, b, c, [0.5, 0, 0], [0.5, 0.5, 0],
                                   [0, 0.5, 0]], atol=1e-15)


def test_bad_sources_are_named(tmp_path, sources):
    with pytest.raises(DrapeInputError, match=r"punch\.stp: no such file"):
        load_surface(tmp_path / "punch.stp", comm=None)
    (tmp_path / "tool.obj").write_text("")
    with pytest.raises(DrapeInputError, match=r"tool\.obj: unknown kind"):
        load_surface(tmp_path / "tool.obj", comm=None)
    (tmp_path / "bad.geo").write_text("Point(1) = {0, 0, 0;\n")
    with pytest.raises(DrapeInputError, match=r"bad.geo: Gmsh: .*syntax error"):
        load_surface(tmp_path / "bad.geo", comm=None)
    (tmp_path / "empty.geo").write_text("Point(1) = {0, 0, 0};\n")
    with pytest.raises(DrapeInputError, match=r"empty\.geo: no surface in it"):
        load_surface(tmp_path / "empty.geo", comm=None)
    (tmp_path / "nobuild.py").write_text("x = 1\n")
    with pytest.raises(DrapeInputError, match=r"nobuild.py: defines no function build"):
        load_surface(tmp_path / "nobuild.py", comm=None)
    (tmp_path / "raises.py").write_text("def build(gmsh):\n    raise ValueError('oops')\n")
    with pytest.raises(DrapeInputError, match=r"raises.py: build\(\) failed: ValueError: oops"):
        load_surface(tmp_path / "raises.py", comm=None)
    with pytest.raises(DrapeInputError, match=r"parameters .* apply to .geo and .py"):
        load_surface(sources["stl"], {"radius_mm": 3.0}, comm=None)
    with pytest.raises(DrapeInputError, match="sheet_side 'up'"):
        load_surface(sources["geo"], sheet_side="up", comm=None)
    with pytest.raises(DrapeInputError, match="no physical surface named 'top'"):
        load_surface(sources["geo"], physical="top", comm=None)
    assert not gmsh.isInitialized()


def test_non_manifold_and_ambiguous_surfaces_are_refused():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.0]])
    with pytest.raises(DrapeInputError, match="non-manifold"):
        TriangleSurface(pts, [[0, 1, 2], [0, 1, 3], [0, 1, 4]], source="fan")
    wall = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1.0]])
    with pytest.raises(DrapeInputError, match="cannot tell which side"):
        TriangleSurface(wall, [[0, 1, 2], [0, 2, 3]], sheet_side="+z", source="wall")


@pytest.mark.parallel
def test_every_rank_gets_the_same_surface(tmp_path_factory):
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    folder = tmp_path_factory.mktemp("mpi") if comm.rank == 0 else None
    folder = comm.bcast(str(folder) if folder else None)
    path = f"{folder}/sphere.geo"
    if comm.rank == 0:
        with open(path, "w") as f:
            f.write(SPHERE_GEO)
    comm.Barrier()
    s = load_surface(path, {"radius_mm": 7.0}, mesh_size_mm=3.0)
    digests = comm.allgather(s.content_hash)
    assert len(set(digests)) == 1 and len(s.triangles) > 100
    with pytest.raises(DrapeInputError, match="no such file"):  # raised on every rank
        load_surface(f"{folder}/missing.geo")
