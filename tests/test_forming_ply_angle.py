"""The initial ply angle: a tow net turned by θ inside the square sheet.

The net is clipped to the square cell by cell; these tests check the clipped grid against an
independent count, its use by the bending stencils and the post-processing, and hemisphere
runs: θ = 0 and a quarter turn give today's results, a small θ breaks the mirror symmetry.
"""

import dataclasses
import itertools
import math

import numpy as np
import pytest

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.fe.grid import (
    BORDER,
    DIAGONAL_MINUS,
    DIAGONAL_PLUS,
    WARP,
    WEFT,
    TrussGrid,
    sheet_grid,
)

SIZE = 240.0
COARSE = {"cell_mm": 20.0, "duration_s": 8.0, "symmetry": []}


def same_grid(a: TrussGrid, b: TrussGrid) -> bool:
    """Bit-identical nodes, bars, kinds and flags."""
    return (np.array_equal(a.nodes, b.nodes) and np.array_equal(a.bars[0], b.bars[0])
            and np.array_equal(a.bars[1], b.bars[1])
            and np.array_equal(a.node_flags, b.node_flags))


def formed(grid: TrussGrid, deform):
    """The FormedGrid of a (clipped) grid, NaN at absent nodes, formed by ``deform``."""
    from fenicsx_drape.forming.running.post import FormedGrid

    X = np.full((grid.nx + 1, grid.ny + 1, 3), np.nan)
    i, j = grid.ij.T
    X[i, j] = grid.nodes
    return FormedGrid(X, deform(X), False)


@pytest.mark.parametrize("cell_mm", [10.0, 30.0, 7.0])
def test_clipped_net_at_zero_angle_is_todays_grid(cell_mm):
    today = sheet_grid(SIZE, cell_mm)
    assert same_grid(sheet_grid(SIZE, cell_mm, ply_angle_deg=0.0), today)
    # The clipping path itself, at θ = 0, keeps every cell and changes nothing.
    clipped = dataclasses.replace(today, clip_half_mm=SIZE / 2)
    assert clipped.cells.all()
    assert same_grid(clipped, today)


def independent_net(θ_deg: float, cell_mm: float) -> tuple[set, int]:
    """Nodes (as rounded positions) and the number of cells of the clipped net, by brute force."""
    Δ = SIZE / 2 / round(SIZE / 2 / cell_mm)
    c, s = math.cos(math.radians(θ_deg)), math.sin(math.radians(θ_deg))
    m = int(SIZE / Δ) + 2
    a = SIZE / 2 * (1 + 1e-12)

    def inside(i, j):
        x, y = Δ * (c * i - s * j), Δ * (s * i + c * j)
        return abs(x) <= a and abs(y) <= a

    nodes, cells = set(), 0
    for i, j in itertools.product(range(-m, m), repeat=2):
        corners = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)]
        if all(inside(*k) for k in corners):
            cells += 1
            nodes |= {(round(Δ * (c * p - s * q), 6), round(Δ * (s * p + c * q), 6))
                      for p, q in corners}
    return nodes, cells


@pytest.mark.parametrize("θ", [3.0, 5.0, -12.0, 30.0, 45.0])
@pytest.mark.parametrize("cell_mm", [10.0, 30.0])
def test_turned_net_is_clipped_to_the_square_with_whole_cells(θ, cell_mm):
    grid = sheet_grid(SIZE, cell_mm, ply_angle_deg=θ)
    x = grid.nodes
    bars, kinds = grid.bars
    Δ = grid.cell_mm
    assert np.abs(x[:, :2]).max() <= SIZE / 2 + 1e-9  # every node inside the square
    assert np.abs(x[:, 2]).max() == 0.0
    assert np.any(np.all(x == 0.0, axis=1))  # a node on the punch axis
    d = x[bars[:, 1]] - x[bars[:, 0]]
    length = np.linalg.norm(d, axis=1)
    tow = (kinds == WARP) | (kinds == WEFT)
    np.testing.assert_allclose(length[tow], Δ, rtol=1e-12)
    np.testing.assert_allclose(length[~tow], Δ * math.sqrt(2), rtol=1e-12)
    angle = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    np.testing.assert_allclose((angle[kinds == WARP] - θ + 90) % 180 - 90, 0, atol=1e-9)
    np.testing.assert_allclose((angle[kinds == WEFT] - θ) % 180 - 90, 0, atol=1e-9)
    # Whole cells: two diagonals per cell, four tow sides each; the counts of an independent
    # brute-force clipping.
    nodes, n_cells = independent_net(θ, cell_mm)
    assert (kinds == DIAGONAL_PLUS).sum() == (kinds == DIAGONAL_MINUS).sum() == n_cells
    assert grid.cells.sum() == n_cells
    assert {(round(p, 6), round(q, 6)) for p, q in x[:, :2]} == nodes
    assert len(x) == len(nodes)
    sides = np.zeros(len(x), int)
    np.add.at(sides, bars[tow].ravel(), 1)
    diagonals = np.zeros(len(x), int)
    np.add.at(diagonals, bars[~tow].ravel(), 1)
    assert diagonals.min() >= 1 and sides.min() >= 2  # no dangling node or bar
    # Border nodes: those with a missing cell around them, i.e. fewer than four diagonals.
    np.testing.assert_array_equal(grid.node_flags == BORDER, diagonals < 4)
    assert set(np.unique(grid.node_flags)) == {0, BORDER}


def test_a_ply_angle_needs_the_full_sheet():
    from fenicsx_drape.forming import load_case

    assert load_case("hemisphere", ply_angle_deg=3.0).planes == ()  # the planes it breaks go
    with pytest.raises(DrapeInputError, match="symmetry"):
        load_case("hemisphere", ply_angle_deg=3.0, symmetry=["x", "y"])
    with pytest.raises(DrapeInputError, match="ply_angle_deg"):
        load_case("hemisphere", symmetry=[], ply_angle_deg=float("nan"))
    with pytest.raises(DrapeInputError, match="full sheet"):
        sheet_grid(SIZE, 10.0, quarter=True, ply_angle_deg=3.0)
    full = load_case("hemisphere", symmetry=[])
    assert load_case("hemisphere", symmetry=[], ply_angle_deg=0.0) == full


def test_bending_stencils_follow_the_tows_of_the_clipped_net():
    pytest.importorskip("petsc4py")
    from fenicsx_drape.fe.bending import stencils

    today = sheet_grid(SIZE, 20.0)
    for a, b in zip(stencils(today, 0.5),
                    stencils(dataclasses.replace(today, clip_half_mm=SIZE / 2), 0.5)):
        np.testing.assert_array_equal(a, b)
    grid = sheet_grid(SIZE, 20.0, ply_angle_deg=5.0)
    triplets, shares = stencils(grid, 0.5)
    present = grid.present.T.ravel()  # lattice order
    assert present[triplets].all()
    # Straight lines of three nodes Δ apart, on the flat sheet.
    index = np.cumsum(present) - 1
    x = grid.nodes[index[triplets]]
    np.testing.assert_allclose(x[:, 0] - 2 * x[:, 1] + x[:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(x[:, 1] - x[:, 0], axis=1), grid.cell_mm)
    # Edge strips (half a strip) are the lines through a node of the ragged border.
    border = (grid.node_flags & BORDER) > 0
    np.testing.assert_array_equal(shares == 0.5, border[index[triplets[:, 1]]])


def test_post_processing_of_a_turned_net():
    from fenicsx_drape.forming.running.run import draw_in

    grid = sheet_grid(SIZE, 10.0, ply_angle_deg=3.0)
    turn = np.radians(20.0)
    rigid = np.array([[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0],
                      [0, 0, 1]])
    g = formed(grid, lambda X: X @ rigid.T + [1.0, 2.0, 3.0])
    γ = g.shear_deg()
    np.testing.assert_array_equal(np.isfinite(γ), grid.cells)
    assert np.nanmax(np.abs(γ)) < 1e-9
    assert abs(g.total_wrinkling_strain()) < 1e-12
    assert g.cell_mm == pytest.approx(grid.cell_mm, rel=1e-12)
    # A uniform shrink by 10 %: every tow has ε = (0.9² − 1) / 2.
    g = formed(grid, lambda X: 0.9 * X)
    ε = 0.5 * (0.81 - 1.0)
    assert g.total_wrinkling_strain() == pytest.approx(ε, rel=1e-12)
    w = g.wrinkle_strain_nodes()
    np.testing.assert_allclose(w[grid.present], ε, rtol=1e-12)
    assert np.isnan(w[~grid.present]).all()
    assert np.isnan(g.shear_nodes()[~grid.present]).all()
    # The drawn grid follows the tows, inside the sheet, and samples the shrink exactly.
    t = g.drawn_grid(10.0)
    P = np.column_stack([t["x0_mm"], t["y0_mm"]])
    assert np.abs(P).max() <= SIZE / 2 + 1e-9
    c, s = np.cos(np.radians(3.0)), np.sin(np.radians(3.0))
    np.testing.assert_allclose(P, 10.0 * np.column_stack([c * t["i"] - s * t["j"],
                                                          s * t["i"] + c * t["j"]]), atol=1e-9)
    np.testing.assert_allclose(np.column_stack([t["x_mm"], t["y_mm"]]), 0.9 * P, atol=1e-9)
    np.testing.assert_allclose(t["wrinkle_strain"], ε, rtol=1e-12)
    assert len(t["i"]) == grid.present.sum()  # Δ = grid: one drawn point per node
    # Paths in the tow frame: the apex outwards, Δ√2 and Δ apart.
    s_diag, γ_diag = g.diagonal_path()
    np.testing.assert_allclose(np.diff(s_diag), grid.cell_mm * np.sqrt(2), rtol=1e-9)
    assert len(γ_diag) == len(s_diag) > 10 and np.abs(γ_diag).max() < 1e-9
    s_norm, w_norm = g.normal_path()
    np.testing.assert_allclose(s_norm, grid.cell_mm * np.arange(len(s_norm)), atol=1e-9)
    assert s_norm[-1] > SIZE / 2 - 2 * grid.cell_mm  # out to the edge of the sheet
    np.testing.assert_allclose(w_norm, ε, rtol=1e-12)
    # Draw-in of the shrink: 10 % of the distance to the node nearest a side, a corner.
    d = draw_in(g)
    assert 0.1 * (SIZE / 2 - grid.cell_mm) < d["mid_side_mm"] < 0.1 * SIZE / 2 + 1e-9
    assert d["corner_mm"] > d["mid_side_mm"]


@pytest.mark.parallel
def test_bending_energy_of_a_curved_turned_net():
    """u_z = a x² + b y²: a tow line along e has the second difference 2Δ²(a e_x² + b e_y²)."""
    pytest.importorskip("dolfinx")
    from fenicsx_drape.fe import SolverOptions, TrussProblem, truss_sheet
    from fenicsx_drape.fe.bending import stencils
    from fenicsx_drape.model import default_model

    θ, EI = 5.0, 3.0
    sheet = truss_sheet(SIZE, 30.0, ply_angle_deg=θ)
    grid = sheet.grid
    assert sheet.num_nodes_global == len(grid.nodes)  # no node lost or doubled over ranks
    problem = TrussProblem(sheet, default_model(), options=SolverOptions(tow_bending_EI_Nmm2=EI))
    a, b = 1e-3, -3e-3
    problem.u.interpolate(lambda X: np.vstack([0 * X[0], 0 * X[0], a * X[0] ** 2 + b * X[1] ** 2]))
    energy = problem._bending.energy(problem.u.x.petsc_vec)
    triplets, shares = stencils(grid, problem.options.edge_tow_factor)
    Δ = grid.cell_mm
    k = shares * problem.options.tows_per_mm * Δ * EI / Δ**3
    c, s = np.cos(np.radians(θ)), np.sin(np.radians(θ))
    warp = (triplets[:, 2] - triplets[:, 1]) == 1  # lattice neighbours along i
    second = np.where(warp, 2 * Δ**2 * (a * c**2 + b * s**2), 2 * Δ**2 * (a * s**2 + b * c**2))
    assert energy == pytest.approx(0.5 * np.sum(k * second**2), rel=1e-10)


@pytest.mark.parallel
@pytest.mark.parametrize("θ", [0.0, 7.0])
def test_tows_of_the_clipped_net_add_up_to_its_area(θ):
    """Each cell owns half of each of its four sides: Σ n_t = 2 l_t Δ × cells (edge halves)."""
    pytest.importorskip("dolfinx")
    from mpi4py import MPI

    from fenicsx_drape.fe import TrussProblem, truss_sheet
    from fenicsx_drape.model import default_model

    sheet = truss_sheet(SIZE, 20.0, ply_angle_deg=θ)
    problem = TrussProblem(sheet, default_model())
    kinds, tows = problem._bars()
    total = MPI.COMM_WORLD.allreduce(tows[(kinds == WARP) | (kinds == WEFT)].sum())
    n_cells = int(sheet.grid.cells.sum())
    l_t = problem.options.tows_per_mm
    assert total == pytest.approx(2 * l_t * sheet.grid.cell_mm * n_cells, rel=1e-12)
    if θ:
        assert n_cells < 144  # the ragged edge has lost cells: its bars are edge bars


# -- hemisphere runs (coarse: Δ = 20 mm, 8 s) ---------------------------------------------


def mirror_asymmetry_deg(g) -> float:
    """Largest change of |shear| (deg) at the nodes under the mirror x → −x of the sheet.

    The node field is interpolated bilinearly in the tow frame at the mirrored points (exact
    at θ = 0, where they are nodes); points outside the net are left out.
    """
    γ = np.abs(g.shear_nodes())
    origin, Δ, R = g.tow_frame()
    P = g.X[g.present][:, :2] * [-1.0, 1.0]
    s = ((P - origin) @ R) / Δ
    k = np.floor(s + 1e-9).astype(int)
    k = np.minimum(k, np.array(γ.shape) - 2)
    keep = (k >= 0).all(axis=1)
    k, s, own = k[keep], s[keep], γ[g.present][keep]
    a, b = (s - k).T
    v = ((1 - a) * (1 - b) * γ[k[:, 0], k[:, 1]] + a * (1 - b) * γ[k[:, 0] + 1, k[:, 1]]
         + (1 - a) * b * γ[k[:, 0], k[:, 1] + 1] + a * b * γ[k[:, 0] + 1, k[:, 1] + 1])
    return float(np.nanmax(np.abs(v - own)))


@pytest.fixture(scope="module")
def runs():
    from mpi4py import MPI

    from fenicsx_drape.forming import load_case, run_case

    return {θ: run_case(load_case("hemisphere", **COARSE, ply_angle_deg=θ), comm=MPI.COMM_SELF)
            for θ in (0.0, 90.0, 5.0, 10.0)}


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_zero_angle_and_a_quarter_turn_give_todays_run(runs):
    g0, g90 = runs[0.0].grid, runs[90.0].grid
    today = sheet_grid(SIZE, COARSE["cell_mm"])
    assert g0.present.all() and g0.X.shape[:2] == (today.nx + 1, today.ny + 1)
    # A quarter turn goes through the clipping (all cells kept), swaps warp and weft: the
    # same run turned by 90°.
    max0 = np.abs(g0.shear_deg()).max()
    assert np.nanmax(np.abs(g90.shear_deg())) == pytest.approx(max0, abs=1e-8)
    assert g90.total_wrinkling_strain() == pytest.approx(g0.total_wrinkling_strain(), abs=1e-10)
    assert mirror_asymmetry_deg(g0) < 1e-6
    assert mirror_asymmetry_deg(g90) < 1e-6
    assert g0.mirror_asymmetry_deg() < 1e-6


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_a_small_ply_angle_breaks_the_mirror_symmetry(runs):
    run = runs[5.0]
    g = run.grid
    γ = np.abs(g.shear_deg())
    assert np.isfinite(γ).sum() == sheet_grid(SIZE, 20.0, ply_angle_deg=5.0).cells.sum()
    # Measured 10.5° on this mesh (the shear lobes turn with the tows, by 2θ under the mirror);
    # at θ = 0 below 1e-6° (previous test).
    assert mirror_asymmetry_deg(g) > 5.0
    assert g.mirror_asymmetry_deg() == pytest.approx(mirror_asymmetry_deg(g), rel=1e-9)
    # The formed sheet is still a hemisphere with a sheared net: apex on the punch, shear of
    # the order of θ = 0's (26.4° here; 40.8° measured at θ = 5°, the whole sheet pressed as
    # the quarter is, its most sheared cells on the turned net's ragged edge).
    np.testing.assert_allclose(g.x[g.X.shape[0] // 2, g.X.shape[1] // 2], [0, 0, 80], atol=0.05)
    assert 15.0 < np.nanmax(γ) < 50.0
    assert run.max_penetration_mm < 1.0


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_the_formed_net_turns_with_the_tows(runs):
    """Tools and holder are axisymmetric: θ enters only through the cells the square keeps.

    At Δ = 20 mm, θ = 5° and 10° keep the same cells of the lattice, so the second run is
    the first turned by 5°.
    """
    a, b = runs[5.0].grid, runs[10.0].grid
    np.testing.assert_array_equal(a.present, b.present)
    c, s = np.cos(np.radians(5.0)), np.sin(np.radians(5.0))
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(b.X[b.present], a.X[a.present] @ turn.T, atol=1e-9)
    np.testing.assert_allclose(b.x[b.present], a.x[a.present] @ turn.T, atol=1e-6)
    assert np.nanmax(np.abs(b.shear_deg())) == pytest.approx(np.nanmax(np.abs(a.shear_deg())),
                                                             abs=1e-8)


@pytest.mark.skip_in_parallel
@pytest.mark.slow
def test_summary_pictures_and_bundle_of_a_turned_ply(runs, tmp_path):
    from fenicsx_drape.forming.running.outputs import case_bundle, case_summary
    from fenicsx_drape.forming.running.plots import plot_paths, plot_shear, plot_wrinkling

    run = runs[5.0]
    out = case_summary(run)
    assert out["ply_angle_deg"] == 5.0 and out["case"]["blank"]["ply_angle_deg"] == 5.0
    assert out["mirror_asymmetry_deg"] > 5.0
    assert out["nodes"] == len(sheet_grid(SIZE, 20.0, ply_angle_deg=5.0).nodes)
    for key in ("max_shear_deg", "total_wrinkling_strain", "min_wrinkling_strain"):
        assert np.isfinite(out[key])
    assert case_summary(runs[0.0])["ply_angle_deg"] == 0.0
    for plot in (plot_shear, plot_wrinkling):
        assert plot(run.grid, tmp_path / f"{plot.__name__}.png").stat().st_size > 1000
    assert plot_paths({"θ = 5°": run.grid}, tmp_path / "paths.png").exists()
    columns = case_bundle(run, 0.3).tests[0].columns
    assert all(np.isfinite(v).all() for v in columns.values())
    assert np.abs(np.column_stack([columns["x0_mm"], columns["y0_mm"]])).max() <= SIZE / 2 + 1e-9


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_cli_forms_a_ply_angle_on_the_full_sheet_unasked(tmp_path, capsys):
    pytest.importorskip("dolfinx")
    import json

    from fenicsx_drape.cli import main

    out = tmp_path / "q"
    assert main(["form", "hemisphere", "--out", str(out), "--ply-angle-deg", "3",
                 "--cell-mm", "20", "--duration-s", "8", "--no-fields", "--quiet"]) == 0
    assert "breaks the symmetry plane(s) x = 0 and y = 0" in capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["symmetry"] == [] and summary["case"]["blank"]["symmetry"] == []


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_cli_forms_a_turned_ply(tmp_path):
    pytest.importorskip("dolfinx")
    import json

    from fenicsx_drape.cli import main

    out = tmp_path / "ply"
    assert main(["form", "hemisphere", "--out", str(out), "--full", "--ply-angle-deg", "5",
                 "--cell-mm", "20", "--duration-s", "8", "--no-fields", "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    provenance = json.loads((out / "provenance.json").read_text())
    assert summary["ply_angle_deg"] == 5.0
    assert provenance["case"]["blank"]["ply_angle_deg"] == 5.0
    assert summary["nodes"] == len(sheet_grid(SIZE, 20.0, ply_angle_deg=5.0).nodes)
    assert summary["mirror_asymmetry_deg"] > 5.0
    assert (out / "shear.png").exists() and (out / "bundle" / "bundle.toml").exists()
