"""Running any forming case: the hemisphere's case file, blanks, holders, ranks."""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from mpi4py import MPI

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case.format import BlankSpec, CaseError, ToolSpec, load_case
from fenicsx_drape.forming.running.run import forming_options, free_edge, run_case
from fenicsx_drape.forming.tools.shapes import HemisphereTools
from fenicsx_drape.model import default_model

HEMISPHERE = Path(__file__).parents[1] / "meshes" / "hemisphere" / "case.toml"
COARSE = {"cell_mm": 30.0, "duration_s": 8.0}
# An octagonal blank (circumradius 115 mm), symmetric in x = 0 and y = 0.
OCTAGON = tuple((115 * math.cos(a), 115 * math.sin(a))
                for a in np.radians(np.arange(0, 360, 45) + 22.5))


class SquareOpening:
    """A clamping surface given in Python: the plane z = 0 outside |x|, |y| <= a."""

    flat = True
    name = "holder"

    def __init__(self, a_mm):
        self.a = a_mm

    def gap(self, x, t):
        from fenicsx_drape.forming.tools.shapes import Gap

        n = np.zeros_like(x)
        n[:, 2] = 1.0
        return Gap(x[:, 2].copy(), n, np.zeros((len(x), 3, 3)))

    def covers(self, x, t):
        return np.maximum(np.abs(x[:, 0]), np.abs(x[:, 1])) > self.a

    def displacement(self, x, t0, t1):
        return np.zeros_like(x)


def octagon(symmetry, cell_mm=20.0):
    """The hemisphere's tools on the octagonal blank, a coarse and fast case."""
    base = load_case(HEMISPHERE, duration_s=8.0)
    blank = BlankSpec("polygon", cell_mm=cell_mm, points_mm=OCTAGON, symmetry=symmetry)
    # F on the whole blank, a half carrying F/2: the half model is then the full one's half.
    holder = dataclasses.replace(base.holder, force_share="symmetric_part")
    return dataclasses.replace(base, blank=blank, holder=holder)


def test_the_named_hemisphere_is_its_case_file():
    """One pipeline: ``"hemisphere"`` names meshes/hemisphere/case.toml, read like any case."""
    from fenicsx_drape.forming.case.format import case_file

    assert case_file("hemisphere") == HEMISPHERE.resolve()
    assert load_case("hemisphere", **COARSE) == load_case(HEMISPHERE, **COARSE)
    assert case_file("my_part/case.toml") == Path("my_part/case.toml")
    with pytest.raises(DrapeInputError, match="named case"):
        case_file("no_such_case")


@pytest.fixture(scope="module")
def octagon_runs():
    return {sym: run_case(octagon(sym), comm=MPI.COMM_SELF) for sym in ((), ("x",))}


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_a_half_model_of_a_polygon_blank_is_half_of_the_full_one(octagon_runs):
    full, half = octagon_runs[()], octagon_runs[("x",)]
    assert full.stopped is None and half.stopped is None
    assert half.grid.planes == ("x",)
    g = half.grid.full()
    # The mirrored half has the full model's nodes, formed alike (within 0.5 mm, like the
    # quarter against the full square sheet).
    np.testing.assert_allclose(g.X, full.grid.X, atol=1e-9)
    assert np.nanmax(np.abs(g.x - full.grid.x)) < 0.5
    γ_full, γ_half = np.nanmax(np.abs(full.grid.shear_deg())), np.nanmax(np.abs(g.shear_deg()))
    assert abs(γ_full - γ_half) < 1.0 and γ_full > 15.0
    # The full octagon is symmetric in x = 0 itself.
    x = full.grid.x
    np.testing.assert_allclose(x, x[::-1] * [-1, 1, 1], atol=0.05)
    # Free edge: the octagon's ragged border (not the symmetry plane), drawn in.
    edge = free_edge(half.grid)
    assert not edge[0, 1:-1].any()  # nodes on x = 0 are on the plane, not free
    assert half.edge_displacement_mm["mean_mm"] > 10.0
    assert half.draw_in_mm is None  # a polygon, not a rectangle


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_a_square_opening_clamps_the_nodes_under_its_plates():
    # The whole sheet with the stated force shared over its own nodes (the force share given:
    # not the quarter's press), as this test was measured.
    case = load_case(HEMISPHERE, **COARSE, symmetry=[], holder_force_share="model")
    holder = ToolSpec("holder", "holder", "python:SquareOpening")  # given in Python below
    case = dataclasses.replace(case, tools=(*case.tools[:2], holder))
    run = run_case(case, tools={"holder": SquareOpening(85.0)}, comm=MPI.COMM_SELF)
    g = run.grid
    X, x = g.X[g.present], g.x[g.present]
    under = np.maximum(np.abs(x[:, 0]), np.abs(x[:, 1])) > 85.0
    assert under.sum() == run.holder.n_s > 0
    # Clamped on the plates: |z| at most the penetration of a 0.1 N node into k = 726 N/mm.
    assert np.abs(x[under, 2]).max() < 1e-3
    # The corners of the square opening beyond the circle r = 85 mm are not clamped: the
    # sheet hangs free there, off the plane. With the paper's circular opening they are.
    corner = ~under & (np.hypot(x[:, 0], x[:, 1]) > 90.0)
    assert corner.any() and np.abs(x[corner, 2]).min() > 0.01
    assert run.stopped is None and np.isfinite(X).all()
    circular = run_case(load_case(HEMISPHERE, **COARSE, symmetry=[],
                                  holder_force_share="model"), comm=MPI.COMM_SELF)
    y = circular.grid.x[circular.grid.present]
    assert np.abs(y[corner, 2]).max() < 1e-3
    assert circular.holder.n_s > run.holder.n_s


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_drape_form_case_toml_end_to_end(tmp_path):
    from fenicsx_drape.cli import main

    out = tmp_path / "case"
    assert main(["form", str(HEMISPHERE), "--out", str(out), "--cell-mm", "30",
                 "--duration-s", "8", "--holder-force-N", "200", "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in ("max_shear_deg", "total_wrinkling_strain", "min_wrinkling_strain",
                "edge_displacement_mm", "draw_in_mm", "nodes", "steps", "cutbacks",
                "snes_iterations", "wall_time_s", "max_penetration_mm", "ranks", "case"):
        assert key in summary
    assert summary["nodes"] == 25 and summary["case"]["holder"]["holder_force_N"] == 200.0
    reference = run_case(load_case("hemisphere", **COARSE, holder_force_N=200.0),
                               comm=MPI.COMM_SELF)
    assert summary["max_shear_deg"] == np.abs(reference.grid.shear_deg()).max()
    assert summary["snes_iterations"] == reference.iterations
    # The kinematic drape beside it, on the same tools: the hemisphere's net at 30 mm.
    from fenicsx_drape.forming.running.kinematic import kinematic_drape

    net = kinematic_drape(HemisphereTools(), 30.0)
    assert summary["kinematic_max_shear_deg"] == pytest.approx(
        np.nanmax(np.abs(net.shear_deg())), abs=0.05)
    for name in ("shear.png", "wrinkling.png", "fields.xdmf", "provenance.json",
                 "kinematic_shear.png", "tools/punch.vtk", "tools/die.vtk", "tools/holder.vtk"):
        assert (out / name).stat().st_size > 0
    # The case file is the paper's hemisphere, but not under the paper's conditions: no
    # paper comparison and no paths (Figs. 10-11), with what differs.
    assert not (out / "paths.png").exists()
    assert summary["paper_differences"] == ["cell 30 mm", "holder_force_N 200", "8 s"]
    provenance = json.loads((out / "provenance.json").read_text())
    assert provenance["case"]["blank"]["cell_mm"] == 30.0
    # The bundle names a copy of the case, which loads and is the case that ran.
    copy = load_case(out / "bundle" / "case" / "case.toml")
    assert copy.blank == load_case(HEMISPHERE, **COARSE).blank
    assert copy.holder.force_N == 200.0 and copy.duration_s == 8.0
    text = (out / "bundle" / "bundle.toml").read_text()
    assert 'case = "case/case.toml"' in text and "holder_force_N = 200.0" in text
    # The drawn grid of the quarter: the 30 mm net's own 5 × 5 nodes (10 mm is no whole
    # number of its cells), the apex on the punch.
    assert "grid_mm = 30.0" in text
    lines = (out / "bundle" / "hemisphere_grid.csv").read_text().splitlines()
    table = np.genfromtxt([r for r in lines if not r.startswith("#")], delimiter=",",
                          names=True)
    assert len(table) == 25
    assert table.dtype.names[:7] == ("i", "j", "x0_mm", "y0_mm", "x_mm", "y_mm", "z_mm")
    apex = table[(table["i"] == 0) & (table["j"] == 0)][0]
    assert apex["z_mm"] == pytest.approx(80.0, abs=0.05)
    # A bad case is a bad-input error (exit 2).
    bad = tmp_path / "bad.toml"
    bad.write_text(HEMISPHERE.read_text().replace('tool = "holder"', 'tool = "plates"'))
    assert main(["form", str(bad), "--out", str(tmp_path / "bad")]) == 2


@pytest.mark.parallel
@pytest.mark.compares_ranks
@pytest.mark.slow
def test_a_case_gives_the_same_sheet_on_any_number_of_ranks(tight_solver):
    case = octagon(("x",), cell_mm=30.0)
    parallel = run_case(case, options=tight_solver, comm=MPI.COMM_WORLD)
    serial = run_case(case, options=tight_solver, comm=MPI.COMM_SELF)
    assert parallel.problem.sheet.num_nodes_global == serial.grid.present.sum()
    np.testing.assert_allclose(parallel.grid.x, serial.grid.x, atol=1e-5)
    assert parallel.holder.n_s == serial.holder.n_s
    assert parallel.max_penetration_mm == pytest.approx(serial.max_penetration_mm, rel=1e-3)


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_a_tool_given_in_python_moves_by_its_motion_table():
    """A spherical punch (not builtin) on a motion table: load steps of 1 mm of its travel,
    the apex node carried to its final height, the sheet clamped by the builtin holder."""
    from fenicsx_drape.forming.tools.motion import RigidMotion
    from fenicsx_drape.forming.tools.shapes import Arc, RevolvedTool, Segment

    R, travel, duration = 60.0, 40.0, 8.0
    sphere = RevolvedTool("punch", (Arc((0.0, 0.0), R, math.pi / 2, 0.0),
                                    Segment((R, 0.0), (R, -1e4))),
                          z0_mm=-R, speed_mm_per_s=travel / duration)
    motion = RigidMotion(time_s=(0.0, duration), x_mm=(0.0, 0.0), y_mm=(0.0, 0.0),
                         z_mm=(0.0, travel))
    base = load_case(HEMISPHERE, cell_mm=20.0, duration_s=duration)
    punch = ToolSpec("punch", "punch", "python:sphere", motion=motion)
    case = dataclasses.replace(base, tools=(punch, base.tool("holder")))
    assert case.max_speed_mm_per_s == pytest.approx(travel / duration)
    run = run_case(case, tools={"punch": sphere}, comm=MPI.COMM_SELF)
    assert run.stopped is None and run.travel_mm == pytest.approx(travel)
    assert run.steps >= travel / case.step_mm
    np.testing.assert_allclose(run.grid.x[0, 0], [0.0, 0.0, travel], atol=0.05)
    assert run.max_penetration_mm < 0.1


@pytest.mark.skip_in_parallel
def test_a_punch_that_never_reaches_the_blank_is_reported():
    """A punch started 100 mm too low passes under the blank: the run says so before it starts
    (it used to run 80 steps and warn), naming the tools and how near they come."""
    from fenicsx_drape.forming.case.format import build_tools

    case = load_case(HEMISPHERE, **COARSE)
    punch = build_tools(case)["punch"]
    low = dataclasses.replace(punch, z0_mm=punch.z0_mm - 100.0)
    steps = []
    with pytest.raises(CaseError, match=r"the blank and the tools never meet: over the motion "
                                        r"'punch' comes no nearer than 20 mm, 'die' comes no "
                                        r"nearer than 0\.3 mm"):
        run_case(case, tools={"punch": low}, comm=MPI.COMM_SELF, on_step=steps.append)
    assert steps == []


@pytest.mark.skip_in_parallel
def test_a_run_that_forms_the_blank_does_not_warn(recwarn):
    run = run_case(load_case(HEMISPHERE, **COARSE), comm=MPI.COMM_SELF)
    assert run.max_penetration_mm > 0.0
    assert not [w for w in recwarn if "touched" in str(w.message)]


def test_petsc_options_given_to_forming_options_add_to_the_factorisation_chosen():
    """LDLᵀ for a symmetric Jacobian, LU with tool friction; a user's options on top of both."""
    extra = {"pc_precision": "single"}
    assert forming_options(default_model(), petsc_options=extra).petsc_options == \
        {"pc_type": "cholesky", "pc_precision": "single"}
    friction = default_model().with_effects("tool_friction")
    assert forming_options(friction, petsc_options=extra).petsc_options == extra
    assert forming_options(default_model(), snes_max_it=7).snes_max_it == 7
