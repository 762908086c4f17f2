"""Forming cases as files: case.toml errors, overrides, blanks of any outline."""

import dataclasses
import itertools
import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.fe.grid import BORDER, SYMMETRY_X, SYMMETRY_Y, outline_grid, sheet_grid
from fenicsx_drape.forming.case.format import CaseError, load_case, with_overrides, write_case

HEMISPHERE = Path(__file__).parents[1] / "meshes" / "hemisphere" / "case.toml"

GOOD = """
[case]
name = "plate"
duration_s = 10.0

[blank]
outline = "polygon"
points_mm = [[-50.0, -40.0], [50.0, -40.0], [60.0, 40.0], [-60.0, 40.0]]
cell_mm = 10.0

[holder]
tool = "clamp"
holder_force_N = 100.0

[[tool]]
name = "punch"
role = "punch"
geometry = "punch.stl"
[tool.motion]
time_s = [0.0, 10.0]
z_mm = [0.0, 20.0]

[[tool]]
name = "clamp"
role = "holder"
geometry = "clamp.stl"
"""


def write(folder: Path, text: str, name: str = "case.toml") -> Path:
    """A case file with empty geometry files next to it (the loader checks they exist)."""
    for geometry in ("punch.stl", "clamp.stl"):
        (folder / geometry).write_text("solid empty\nendsolid empty\n")
    path = folder / name
    path.write_text(textwrap.dedent(text))
    return path


def test_the_good_case_loads_with_its_paths_relative_to_the_file(tmp_path):
    case = load_case(write(tmp_path, GOOD))
    assert case.name == "plate" and case.duration_s == 10.0
    assert case.tool("punch").path == (tmp_path / "punch.stl").resolve()
    assert case.tool("punch").motion.z_mm == (0.0, 20.0)
    assert case.tool("clamp").motion is None and case.holder.force_share == "symmetric_part"
    assert case.max_speed_mm_per_s == pytest.approx(2.0)
    assert case.total_travel_mm == pytest.approx(20.0)
    assert case.blank.area_mm2 == pytest.approx(0.5 * (100 + 120) * 80)


# Each malformed file: the replacement made in GOOD, and what the message must say.
MALFORMED = [
    ('geometry = "punch.stl"', 'geometry = "punch.stp"',
     "[[tool]] 1 'geometry': no such file 'punch.stp'"),
    ('geometry = "clamp.stl"', 'geometry = "clamp.xyz"', "[[tool]] 2 'geometry'"),
    ('duration_s = 10.0', 'duration_s = -10.0', "[case] 'duration_s': -10.0 must be > 0"),
    ('duration_s = 10.0', 'duration_s = "ten"', "[case] 'duration_s': 'ten' is not a number"),
    ('duration_s = 10.0', 'duration_s = 10.0\ncolour = "red"', "[case]: unknown key 'colour'"),
    ('cell_mm = 10.0', 'cell_mm = 0.0', "[blank] 'cell_mm': 0.0 must be > 0"),
    ('outline = "polygon"', 'outline = "circle"', "[blank] 'outline'"),
    ('points_mm = [[-50.0, -40.0], [50.0, -40.0], [60.0, 40.0], [-60.0, 40.0]]',
     'points_mm = [[0.0, 0.0], [1.0, 1.0]]', "[blank] 'points_mm'"),
    ('outline = "polygon"', 'outline = "polygon"\nsize_mm = [10.0, 10.0]',
     "[blank] 'size_mm': does not apply to outline = 'polygon'"),
    ('cell_mm = 10.0', 'cell_mm = 10.0\nsymmetry = ["z"]', "[blank] 'symmetry'"),
    ('role = "punch"', 'role = "anvil"', "[[tool]] 1 'role': 'anvil' is not one of"),
    ('role = "punch"', 'role = "punch"\nmesh_mm = -2.0', "[[tool]] 1 'mesh_mm'"),
    ('role = "punch"', 'role = "punch"\nsheet_side = "up"', "[[tool]] 1 'sheet_side'"),
    ('tool = "clamp"', 'tool = "plates"', "[holder] 'tool': no tool named 'plates'"),
    ('tool = "clamp"', 'tool = "punch"', "[holder] 'tool': tool 'punch' has role 'punch'"),
    ('holder_force_N = 100.0', 'holder_force_N = -1.0',
     "[holder] 'holder_force_N': -1.0 must be >= 0"),
    ('holder_force_N = 100.0', 'holder_force_N = 100.0\nholder_force_share = "half"',
     "[holder] 'holder_force_share'"),
    ('holder_force_N = 100.0', 'holder_force_N = 100.0\nforce_N = 90.0',
     "'force_N' and 'holder_force_N' name one value: give 'holder_force_N' only"),
    ('z_mm = [0.0, 20.0]', 'z_mm = [0.0, 20.0, 30.0]',
     "[[tool]] 1 [tool.motion] 'z_mm': 3 values for 2 times"),
    ('time_s = [0.0, 10.0]', 'time_s = [0.0, 12.0]', "past [case] duration_s = 10"),
    ('time_s = [0.0, 10.0]', 'time_s = [1.0, 10.0]', "'time_s': must start at 0"),
    ('time_s = [0.0, 10.0]\nz_mm = [0.0, 20.0]', 'time_s = [0.0, 10.0]',
     "needs at least one of x_mm"),
    ('[[tool]]\nname = "clamp"', '[[tool]]\nname = "punch"', "'name': 'punch' is used"),
    ('[case]', '[casing]\nx = 1\n[case]', "unknown key 'casing'"),
]


@pytest.mark.parametrize(("old", "new", "message"), MALFORMED,
                         ids=[m[2].split(":")[0][:40] for m in MALFORMED])
def test_a_malformed_case_file_names_the_file_and_the_key(tmp_path, old, new, message):
    assert old in GOOD
    path = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(CaseError) as err:
        load_case(path)
    text = str(err.value)
    assert str(path) in text
    assert message in text, text
    assert isinstance(err.value, DrapeInputError)  # the CLI's bad-input error (exit 2)


def test_every_problem_of_a_file_is_reported_at_once(tmp_path):
    text = GOOD.replace('duration_s = 10.0', 'duration_s = -1.0').replace(
        'geometry = "punch.stl"', 'geometry = "missing.stl"')
    with pytest.raises(CaseError) as err:
        load_case(write(tmp_path, text))
    assert len(err.value.problems) >= 2
    assert "'duration_s'" in str(err.value) and "missing.stl" in str(err.value)


def test_not_toml_and_missing_file(tmp_path):
    with pytest.raises(CaseError, match="no such case file"):
        load_case(tmp_path / "nothing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[case\nname = 1\n")
    with pytest.raises(CaseError, match="not valid TOML"):
        load_case(bad)


def test_builtin_tools_are_checked(tmp_path):
    text = HEMISPHERE.read_text()
    for old, new, message in [
        ("punch_radius_mm = 60.0", "punch_radius_mm = 60.0, nose_mm = 3.0",
         "[[tool]] 1 'parameters' 'nose_mm': not a parameter of 'builtin:hemisphere'"),
        ('role = "die"', 'role = "surface"',
         "[[tool]] 2 'role': 'builtin:hemisphere' gives the hemisphere's punch, die or holder"),
        ('geometry = "builtin:hemisphere"', 'geometry = "builtin:cone"',
         "[[tool]] 1 'geometry': 'builtin:cone': the builtin geometry is"),
        ("shoulder_radius_mm = 84.0", "shoulder_radius_mm = 95.0",
         "[[tool]] 1 'parameters': HemisphereTools: shoulder_radius_mm"),
    ]:
        path = tmp_path / "case.toml"
        path.write_text(text.replace(old, new, 1))
        with pytest.raises(CaseError) as err:
            load_case(path)
        assert f"{path}: {message}" in str(err.value), str(err.value)


def test_the_hemisphere_case_file_is_the_hemisphere_case():
    from fenicsx_drape.forming import load_case

    case = load_case(HEMISPHERE)
    reference = load_case("hemisphere")
    for key in ("blank", "holder", "duration_s", "step_mm", "penalty_factor",
                "stabilisation_N_per_mm"):
        assert getattr(case, key) == getattr(reference, key)
    assert case.blank.grid() == sheet_grid(240.0, 10.0, quarter=True)
    assert [t.role for t in case.tools] == ["punch", "die", "holder"]
    assert case.max_speed_mm_per_s == reference.max_speed_mm_per_s == 2.0


def test_overrides_are_a_measured_tests_keys(tmp_path):
    case = load_case(HEMISPHERE, duration_s=8.0, holder_force_N=500.0, cell_mm=20.0,
                     punch_radius_mm=50.0, holder_force_share="model", travel_mm=60.0)
    assert case.duration_s == 8.0 and case.blank.cell_mm == 20.0
    assert case.holder.force_N == 500.0 and case.holder.force_share == "model"
    assert case.tool("punch").params["punch_radius_mm"] == 50.0
    assert case.max_speed_mm_per_s == pytest.approx(60.0 / 8.0)
    with pytest.raises(CaseError, match="override 'colour'"):
        load_case(HEMISPHERE, colour=1.0)
    # A motion table is stretched to the new duration and scaled to the new travel.
    plate = load_case(write(tmp_path, GOOD))
    slow = with_overrides(plate, duration_s=40.0, travel_mm=30.0)
    assert slow.tool("punch").motion.time_s == (0.0, 40.0)
    assert slow.tool("punch").motion.z_mm == pytest.approx((0.0, 30.0))
    assert slow.max_speed_mm_per_s == pytest.approx(30.0 / 40.0)



def test_the_holders_force_has_one_name_and_the_earlier_keys_still_read(tmp_path):
    """``holder_force_N`` and ``holder_force_share``: the case's [holder] keys, a test's keys
    (overrides), drape form's options, the set-up candidate, the case as written; the earlier
    [holder] keys ``force_N`` and ``force_share`` are read as them, with a note naming each."""
    from fenicsx_drape.cli import command_parser
    from fenicsx_drape.diagnosis.setup_parameters import SETUP_PARAMETERS
    from fenicsx_drape.forming.case import case_dict
    from fenicsx_drape.forming.case.format import OVERRIDES

    assert {"holder_force_N", "holder_force_share"} <= set(OVERRIDES)
    assert "holder_force_N" in SETUP_PARAMETERS
    assert {"--holder-force-N", "--holder-force-share"} <= set(
        command_parser("form")[1]._option_string_actions)
    new = load_case(write(tmp_path, GOOD.replace(
        "holder_force_N = 100.0", 'holder_force_N = 100.0\nholder_force_share = "model"')))
    assert case_dict(new)["holder"] == {"tool": "clamp", "holder_force_N": 100.0,
                                        "holder_force_share": "model"}
    old_text = GOOD.replace("holder_force_N = 100.0", 'force_N = 100.0\nforce_share = "model"')
    with pytest.warns(FutureWarning) as notes:
        old = load_case(write(tmp_path, old_text, "old.toml"))
    assert old == dataclasses.replace(new, path=old.path)
    said = [str(n.message) for n in notes]
    for key in ("force_N", "force_share"):
        assert any(f"old.toml: [holder] '{key}' is now called 'holder_{key}'" in m
                   for m in said), said


def test_the_holders_friction_coefficient_has_one_name(tmp_path):
    """``mu``: the case's [holder] key, the override, drape form's option, the set-up
    candidate of the spec; the earlier override ``holder_mu`` is read as it, with a warning."""
    from fenicsx_drape.cli import command_parser
    from fenicsx_drape.diagnosis.setup_parameters import SETUP_PARAMETERS
    from fenicsx_drape.forming.case.format import OVERRIDES, case_for_test, case_value

    assert "mu" in OVERRIDES and "mu" in SETUP_PARAMETERS and "holder_mu" not in OVERRIDES
    assert "--mu" in command_parser("form")[1]._option_string_actions
    plate = load_case(write(tmp_path, GOOD))
    assert plate.holder.mu is None and case_value(plate, "mu") is None
    rough = with_overrides(plate, mu=0.45)
    assert rough.holder.mu == 0.45 and case_value(rough, "mu") == 0.45
    with pytest.warns(FutureWarning, match="holder_mu is now called mu"):
        assert with_overrides(plate, holder_mu=0.45) == rough
    # A bundle's test key: the same, and the warning names the case file.
    with pytest.warns(FutureWarning, match="case.toml: test key: holder_mu"):
        case, used = case_for_test(tmp_path / "case.toml", {"holder_mu": 0.45})
    assert case.holder.mu == 0.45 and used == {"holder_mu": 0.45}
    no_holder = write(tmp_path, GOOD.replace('[holder]\ntool = "clamp"\nholder_force_N = 100.0\n',
                                             ""), "bare.toml")
    with pytest.raises(CaseError, match="no \\[holder\\]"):
        with_overrides(load_case(no_holder), mu=0.2)


def test_write_case_copies_the_geometry_and_reads_back(tmp_path):
    case = load_case(write(tmp_path, GOOD), duration_s=20.0)
    out = write_case(case, tmp_path / "copy")
    assert (tmp_path / "copy" / "punch.stl").read_text().startswith("solid")
    again = load_case(out)
    assert again.tool("punch").path == (tmp_path / "copy" / "punch.stl").resolve()
    strip = dict(path=None)
    for a, b in zip(case.tools, again.tools):
        assert dataclasses.replace(a, **strip) == dataclasses.replace(b, **strip)
    assert again.blank == case.blank and again.holder == case.holder
    assert again.duration_s == 20.0
    hemisphere = load_case(write_case(load_case(HEMISPHERE), tmp_path / "h"))
    assert hemisphere.tools == load_case(HEMISPHERE).tools


# -- blanks of any outline -------------------------------------------------------------------


def brute_force_cells(polygon, cell_mm, angle_deg=0.0, origin=(0.0, 0.0)):
    """Cells of the net (as rounded centres) with four corners inside a convex polygon."""
    P = np.asarray(polygon, float)
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))

    def inside(x, y):  # convex, counter-clockwise: left of every edge
        e = np.roll(P, -1, axis=0) - P
        return bool(np.all(e[:, 0] * (y - P[:, 1]) - e[:, 1] * (x - P[:, 0]) >= -1e-9))

    def node(i, j):
        return origin[0] + cell_mm * (c * i - s * j), origin[1] + cell_mm * (s * i + c * j)

    m = int(np.abs(P).max() / cell_mm) + 3
    cells = set()
    for i, j in itertools.product(range(-m, m), repeat=2):
        corners = [node(i + a, j + b) for a, b in ((0, 0), (1, 0), (0, 1), (1, 1))]
        if all(inside(*p) for p in corners):
            x, y = np.mean(corners, axis=0)
            cells.add((round(x, 6), round(y, 6)))
    return cells


def grid_cells(grid):
    """Centres (rounded) of the cells of a TrussGrid."""
    i, j = np.nonzero(grid.cells)
    ij = np.column_stack([i + 0.5, j + 0.5]) * grid.cell_mm + grid.origin_mm
    c, s = math.cos(math.radians(grid.rotation_deg)), math.sin(math.radians(grid.rotation_deg))
    xy = ij @ np.array([[c, -s], [s, c]]).T
    return {(round(x, 6), round(y, 6)) for x, y in xy}


OCTAGON = [(110 * math.cos(a), 110 * math.sin(a)) for a in np.radians(np.arange(0, 360, 45) + 22.5)]


@pytest.mark.parametrize(("angle", "cell_mm", "origin"),
                         [(0.0, 10.0, (0.0, 0.0)), (0.0, 20.0, (5.0, -3.0)),
                          (15.0, 10.0, (0.0, 0.0)), (-30.0, 20.0, (2.0, 2.0))])
def test_a_polygon_blank_keeps_the_whole_cells_inside(angle, cell_mm, origin):
    grid = outline_grid(OCTAGON, cell_mm, origin_mm=origin, ply_angle_deg=angle)
    expected = brute_force_cells(OCTAGON, cell_mm, angle, origin)
    assert grid_cells(grid) == expected
    area = grid.cells.sum() * cell_mm**2
    octagon_area = 2 * math.sqrt(2) * 110**2
    assert 0.75 * octagon_area < area < octagon_area
    assert np.abs(grid.nodes[:, :2]).max() <= 110.0 + 1e-9
    # The net has a node at origin_mm and the warp at the ply angle.
    assert np.min(np.linalg.norm(grid.nodes[:, :2] - origin, axis=1)) < 1e-9
    bars, kinds = grid.bars
    d = grid.nodes[bars[kinds == 1, 1]] - grid.nodes[bars[kinds == 1, 0]]
    np.testing.assert_allclose(np.degrees(np.arctan2(d[:, 1], d[:, 0])), angle, atol=1e-9)


def test_the_square_outline_is_todays_grid_at_any_angle():
    square = [(-120, -120), (120, -120), (120, 120), (-120, 120)]
    assert outline_grid(square, 10.0) == sheet_grid(240.0, 10.0)
    assert outline_grid(square, 10.0, symmetry=("x", "y")) == sheet_grid(240.0, 10.0, True)
    for θ in (5.0, 30.0):
        a, b = sheet_grid(240.0, 20.0, ply_angle_deg=θ), outline_grid(square, 20.0,
                                                                       ply_angle_deg=θ)
        np.testing.assert_allclose(a.nodes, b.nodes, atol=1e-9)
        np.testing.assert_array_equal(a.bars[0], b.bars[0])
        np.testing.assert_array_equal(a.node_flags, b.node_flags)


def test_a_cell_hanging_by_a_corner_is_left_out():
    # Two squares touching at a corner node: only the larger keeps its cells.
    bow = [(0, 0), (40, 0), (40, 40), (0, 40), (0, 0), (-20, 0), (-20, -20), (0, -20)]
    grid = outline_grid(bow, 10.0)
    assert grid.cells.sum() == 16
    assert np.all(grid.nodes[:, :2] >= -1e-9)


def test_half_and_quarter_models_of_a_symmetric_outline():
    full = outline_grid(OCTAGON, 10.0)
    half = outline_grid(OCTAGON, 10.0, symmetry=("x",))
    quarter = outline_grid(OCTAGON, 10.0, symmetry=("x", "y"))
    assert half.planes == ("x",) and quarter.planes == ("x", "y") and full.planes == ()
    assert 2 * half.cells.sum() == full.cells.sum() == 4 * quarter.cells.sum()
    X = half.nodes
    flags = half.node_flags
    on_plane = np.abs(X[:, 0]) < 1e-9
    np.testing.assert_array_equal((flags & SYMMETRY_X) > 0, on_plane)
    assert not (flags & SYMMETRY_Y).any()
    # Nodes on the plane are not free border nodes unless they end the plane's line.
    assert ((flags & BORDER) > 0)[on_plane].sum() == 2
    with pytest.raises(DrapeInputError, match="not symmetric"):
        outline_grid([(-50, -50), (80, -50), (80, 50), (-50, 50)], 10.0, symmetry=("x",))
    with pytest.raises(DrapeInputError, match="no nodes on the plane"):
        outline_grid(OCTAGON, 10.0, origin_mm=(5.0, 0.0), symmetry=("x",))
    with pytest.raises(DrapeInputError, match="breaks the symmetry"):
        outline_grid(OCTAGON, 10.0, ply_angle_deg=3.0, symmetry=("y",))


@pytest.mark.parallel
@pytest.mark.parametrize("symmetry", [(), ("x",)])
def test_edge_tows_of_a_polygon_net_are_half_strips(symmetry):
    """Each cell owns half of each of its four sides: Σ n_t = 2 l_t Δ × cells."""
    pytest.importorskip("dolfinx")
    from mpi4py import MPI

    from fenicsx_drape.fe import TrussProblem
    from fenicsx_drape.fe.grid import WARP, WEFT
    from fenicsx_drape.fe.mesh import grid_to_sheet
    from fenicsx_drape.model import default_model

    grid = outline_grid(OCTAGON, 20.0, ply_angle_deg=0.0 if symmetry else 10.0,
                        symmetry=symmetry)
    sheet = grid_to_sheet(grid)
    assert sheet.num_nodes_global == len(grid.nodes)
    problem = TrussProblem(sheet, default_model())
    kinds, tows = problem._bars()
    total = MPI.COMM_WORLD.allreduce(tows[(kinds == WARP) | (kinds == WEFT)].sum())
    l_t = problem.options.tows_per_mm
    assert total == pytest.approx(2 * l_t * grid.cell_mm * grid.cells.sum(), rel=1e-12)


GEO = """
SetFactory("OpenCASCADE");
Circle(1) = {10, 0, 0, 100, 0, 2*Pi};
"""
GEO_RECT = """
Point(1) = {-60, -40, 0}; Point(2) = {60, -40, 0}; Point(3) = {60, 40, 0};
Point(4) = {-60, 40, 0};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 1};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
"""


def test_an_outline_from_a_gmsh_curve(tmp_path):
    pytest.importorskip("gmsh")
    (tmp_path / "disc.geo").write_text(GEO)
    (tmp_path / "rect.geo").write_text(GEO_RECT)
    polygon = 'points_mm = [[-50.0, -40.0], [50.0, -40.0], [60.0, 40.0], [-60.0, 40.0]]'
    base = GOOD.replace(f'outline = "polygon"\n{polygon}', 'outline = "disc.geo"')
    case = load_case(write(tmp_path, base))
    P = np.asarray(case.blank.points_mm)
    np.testing.assert_allclose(np.hypot(P[:, 0] - 10, P[:, 1]), 100.0, atol=1e-6)
    assert case.blank.area_mm2 == pytest.approx(math.pi * 100**2, rel=2e-3)
    grid = case.blank.grid()
    assert grid_cells(grid) == brute_force_cells(P[::-1] if _clockwise(P) else P, 10.0)
    rect = load_case(write(tmp_path, base.replace("disc.geo", "rect.geo"), "rect.toml"))
    assert rect.blank.area_mm2 == pytest.approx(120 * 80)
    assert rect.blank.grid().cells.all() and rect.blank.grid().cells.shape == (12, 8)
    (tmp_path / "open.geo").write_text("Point(1) = {0,0,0}; Point(2) = {10,0,0}; "
                                       "Line(1) = {1,2};\n")
    with pytest.raises(CaseError, match=r"'outline': open\.geo: the curves are not one closed"):
        load_case(write(tmp_path, base.replace("disc.geo", "open.geo"), "open.toml"))


def _clockwise(P):
    return np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1]) < 0


def test_a_motion_table_moves_rigidly_and_sets_the_load_steps():
    from fenicsx_drape.forming.tools.motion import RigidMotion

    m = RigidMotion(time_s=(0.0, 10.0, 20.0), x_mm=(0.0, 0.0, 0.0), y_mm=(0.0, 0.0, 0.0),
                    z_mm=(0.0, 30.0, 40.0), rotation_deg=(0.0, 0.0, 90.0),
                    axis=(0.0, 0.0, 1.0))
    # Fastest: the second segment, 1 mm/s of translation plus 90° in 10 s at 50 mm from the axis.
    assert m.max_speed_mm_per_s(50.0) == pytest.approx(1.0 + math.radians(9.0) * 50.0)
    assert m.travel_mm(10.0) == pytest.approx(30.0)
    R, T = m.at(15.0)
    np.testing.assert_allclose(R @ [1.0, 0.0, 0.0], [math.cos(math.pi / 4),
                                                     math.sin(math.pi / 4), 0.0], atol=1e-12)
    np.testing.assert_allclose(T, [0.0, 0.0, 35.0])
    # displacement(x, t0, t1): where the tool's point now at x was at t0, by the motion.
    x = np.array([[50.0, 0.0, 40.0]])
    d = m.displacement(x, 10.0, 20.0)
    np.testing.assert_allclose(x - d, [[0.0, -50.0, 30.0]], atol=1e-9)
    slow = m.scaled(time=2.0, travel=0.5)
    assert slow.time_s == (0.0, 20.0, 40.0) and slow.z_mm == (0.0, 15.0, 20.0)
    assert slow.max_speed_mm_per_s(50.0) == pytest.approx(m.max_speed_mm_per_s(50.0) / 4)


def test_tools_are_built_by_role(tmp_path):
    """Builtin tools are the hemisphere's by role; file tools need the meshed surfaces."""
    from fenicsx_drape.forming.case.format import build_tools
    from fenicsx_drape.forming.terms.holder import FlatHolder
    from fenicsx_drape.forming.tools.shapes import HemisphereTools

    tools = build_tools(load_case(HEMISPHERE, duration_s=20.0))
    reference = HemisphereTools()
    assert tools["punch"] == reference.punch(20.0) and tools["die"] == reference.die()
    assert tools["holder"] == FlatHolder(reference.opening_radius_mm)
    assert set(build_tools(load_case(HEMISPHERE), skip=("die",))) == {"punch", "holder"}
    case = load_case(write(tmp_path, GOOD))
    with pytest.raises(DrapeInputError, match=r"punch\.stl: no surface in it"):
        build_tools(case)  # the empty STL files of write()
    plate = ("solid plate\n" + "".join(
        "facet normal 0 0 1\nouter loop\n" + "".join(f"vertex {x} {y} 0\n" for x, y in tri)
        + "endloop\nendfacet\n"
        for tri in (((-80, -80), (80, -80), (80, 80)), ((-80, -80), (80, 80), (-80, 80))))
        + "endsolid plate\n")
    for name in ("punch.stl", "clamp.stl"):
        (tmp_path / name).write_text(plate)
    tools = build_tools(case)
    x = np.array([[0.0, 0.0, 1.0], [10.0, -20.0, 1.0]])
    assert tools["clamp"].gap(x, 0.0).phi == pytest.approx([1.0, 1.0], abs=1e-6)
    # The punch (sheet on +z by its role's default) rises 20 mm in 10 s: 2 mm at t = 1.
    assert tools["punch"].gap(x, 1.0).phi == pytest.approx([-1.0, -1.0], abs=1e-6)
