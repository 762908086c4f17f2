"""Post-processing of formed grids: shear, tow strains, wrinkling totals, paths, sampling."""

import numpy as np
import pytest

from fenicsx_drape.forming.running.post import FormedGrid, mean_distance


def flat(cell=10.0, half=120.0, quarter=True):
    c = np.arange(0.0 if quarter else -half, half + cell / 2, cell)
    X = np.stack([*np.meshgrid(c, c, indexing="ij"), np.zeros((len(c), len(c)))], axis=-1)
    return X


def mapped(F, cell=10.0, quarter=True):
    """A grid deformed by the affine map x = F X (F 3×3)."""
    X = flat(cell, quarter=quarter)
    return FormedGrid(X, X @ np.asarray(F).T, quarter)


def test_pure_shear_angle_and_no_wrinkling():
    γ = np.radians(30.0)
    # Warp stays along x, weft turns by γ towards it: the angle between them is 90° − γ.
    F = [[1.0, np.sin(γ), 0], [0, np.cos(γ), 0], [0, 0, 1]]
    g = mapped(F)
    np.testing.assert_allclose(g.shear_deg(), 30.0)
    warp, weft = g.tow_strains()
    np.testing.assert_allclose(warp, 0.0, atol=1e-14)
    np.testing.assert_allclose(weft, 0.0, atol=1e-14)  # inextensible tows
    assert g.total_wrinkling_strain() == pytest.approx(0.0, abs=1e-15)


def test_compressed_weft_is_wrinkling_with_edge_weights():
    g = mapped(np.diag([1.0, 0.9, 1.0]))
    warp, weft = g.tow_strains()
    ε = 0.5 * (0.81 - 1.0)
    np.testing.assert_allclose(weft, ε)
    np.testing.assert_allclose(warp, 0.0, atol=1e-14)
    # Σ w ε⁻ / Σ w: only the weft bars are compressed; edge lines weigh ½ (12 + 1 lines).
    n = 12 * 13  # bars per family
    w_lines = np.r_[0.5, np.ones(11), 0.5]
    expected = ε * 12 * w_lines.sum() / (2 * 12 * w_lines.sum())
    assert g.total_wrinkling_strain() == pytest.approx(expected)
    assert n == warp.size
    np.testing.assert_allclose(g.wrinkle_strain_nodes(), ε)
    s, w = g.normal_path()
    np.testing.assert_allclose(s, np.arange(0.0, 121.0, 10.0))
    np.testing.assert_allclose(w, ε)


def test_full_mirror_quadrant_and_paths():
    γ = np.radians(20.0)
    F = [[1.0, np.sin(γ), 0], [0, np.cos(γ), 0], [0, 0, 1]]
    q = mapped(F)
    f = q.full()
    assert f.X.shape == (25, 25, 3) and not f.quarter
    np.testing.assert_allclose(f.quadrant.x, q.x)
    np.testing.assert_allclose(f.x[12:, :12][:, ::-1] * [1, -1, 1], q.x[:, 1:])
    s, γ_path = q.diagonal_path()
    np.testing.assert_allclose(s, np.sqrt(2) * (np.arange(12) + 0.5) * 10.0)
    np.testing.assert_allclose(γ_path, 20.0)


def test_sampling_a_drawn_grid_and_distances():
    F = [[0.9, 0.1, 0], [0.05, 1.1, 0], [0.01, 0.02, 1]]
    fine = mapped(F, cell=120.0 / 14)  # 8.57 mm cells: the 10 mm grid falls inside cells
    table = fine.drawn_grid(10.0)
    P = np.column_stack([table["x0_mm"], table["y0_mm"], np.zeros(len(table["i"]))])
    x = np.column_stack([table["x_mm"], table["y_mm"], table["z_mm"]])
    np.testing.assert_allclose(x, P @ np.asarray(F).T, atol=1e-12)  # bilinear is exact
    assert len(table["i"]) == 169 and "shear_deg" not in table
    coarse = mapped(F, cell=10.0)
    assert "shear_deg" in coarse.drawn_grid(10.0)
    assert mean_distance(fine, coarse) == pytest.approx(0.0, abs=1e-12)
    moved = FormedGrid(coarse.X, coarse.x + np.array([0.0, 0.0, 2.0]), True)
    assert mean_distance(moved, coarse) == pytest.approx(2.0)
    full = mapped(F, quarter=False)
    assert mean_distance(full, coarse) == pytest.approx(0.0, abs=1e-12)  # the common quarter
    assert min(full.drawn_grid(10.0)["i"]) == -12


def test_from_nodes_rejects_scattered_points():
    X = flat(quarter=True).reshape(-1, 3)
    g = FormedGrid.from_nodes(X[::-1], X[::-1] * 2.0, 10.0, True)
    np.testing.assert_allclose(g.x, 2.0 * g.X)
    from fenicsx_drape.errors import DrapeInputError

    with pytest.raises(DrapeInputError, match="not a structured"):
        FormedGrid.from_nodes(X[:-1], X[:-1], 10.0, True)


def test_shear_on_a_quarters_mirror_lines_is_the_whole_parts():
    """A symmetric part's shear is 0 on its symmetry planes, the quarter's nodes there too.

    u_x = c x y², u_y = c x² y is symmetric in both planes; its shear (odd in x and in y) is 0
    on them. The quarter's nodes on a plane see the mirrored cells as the whole part does, not
    only the one cell beside the plane (a drawn grid of a quarter model written by drape form
    would tell a lab measuring along a symmetry line that its part disagrees).
    """
    c = 2e-5
    quarter = flat(half=60.0)
    X, Y = quarter[..., 0], quarter[..., 1]
    x = quarter + np.stack([c * X * Y**2, c * X**2 * Y, 0 * X], axis=-1)
    part = FormedGrid(quarter, x, True)
    γ = part.shear_nodes()
    np.testing.assert_allclose(γ[0, :], 0.0, atol=1e-12)
    np.testing.assert_allclose(γ[:, 0], 0.0, atol=1e-12)
    assert np.abs(part.shear_deg()[0, 1:]).max() > 0.5  # the cell beside the plane is sheared
    whole = part.full().shear_nodes()
    np.testing.assert_allclose(γ, whole[-γ.shape[0]:, -γ.shape[1]:], atol=1e-12)
    table = part.drawn_grid(10.0)
    on_plane = table["x0_mm"] == 0.0
    np.testing.assert_allclose(table["shear_deg"][on_plane], 0.0, atol=1e-12)
