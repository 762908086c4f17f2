"""Data of another part handed under a case's name: the data check names it (spec version 4).

The bundles are written here as a lab writes them, by hand, from shapes drawn with NumPy (no
forming run, none of the project's writers): the paper's hemisphere case (builtin tools, the
sheet formed on the punch's cap of radius 60 mm and its concave fillet of radius 20 mm, the
blank 240 mm square), one trial with a grid drawn on the blank at 20 mm (position noise
0.3 mm) and shear points along a bias and a weft line at flat positions (noise 1°). Each
formed position follows the sheet's meridian without stretching it (a flat point at radius ρ
lies at arc length ρ along the formed profile), and the shear of that map is what a lab
would measure on it: 90° minus the angle between the images of the warp (x) and the weft (y).

- the hemisphere's own grid and shear lines: nothing suspect;
- a shallow cup's grid (a flat top 24 mm high out to 50 mm, a wall of two 12 mm arcs) under
  the hemisphere's case: its top lies inside the hemisphere's punch, up to 56 mm deep, while
  every flat position lies on the blank and most formed ones within a cell of a tool;
- a shallow dome's shear lines (a 24 mm cap of radius 200 mm) with the hemisphere's grid:
  their shear does not follow the grid's.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.diagnosis.data_check import data_check
from fenicsx_drape.forming.case.format import case_for_test
from fenicsx_drape.measurements.bundle import load_bundle

pytestmark = pytest.mark.skip_in_parallel

CASE = """# the hemisphere of the paper, as the lab states it

[case]
name = "hemisphere"
duration_s = 40.0
step_mm = 4.0

[blank]
outline = "rectangle"
size_mm = [240.0, 240.0]
cell_mm = 20.0
symmetry = ["x", "y"]

[holder]
tool = "holder"
holder_force_N = 400.0
mu = 0.3
"""
TOOL = """
[[tool]]
name = "{0}"
role = "{0}"
geometry = "builtin:hemisphere"
parameters = {{ punch_radius_mm = 60.0, fillet_radius_mm = 20.0, shoulder_radius_mm = 84.0, \
edge_radius_mm = 1.0, holder_opening_mm = 170.0, travel_mm = 80.0, ply_thickness_mm = 0.3 }}
"""
BUNDLE = """# one forming trial of the hemisphere, measured by hand
[bundle]
name = "hemisphere-lab"

[[test]]
id = "trial"
kind = "forming"
case = "case/case.toml"
duration_s = 40.0
file = "grid.csv"
shear_points = "shear.csv"
grid_mm = 20.0
position_sd_mm = 0.3
shear_sd_deg = 1.0
"""


def hemisphere(r: np.ndarray) -> np.ndarray:
    """The formed sheet's height at radius r: the cap (R 60 mm), the fillet (20 mm), the flange.

    The sheet's mid-plane lies half the ply's 0.3 mm above the punch.
    """
    cap = 20.0 + np.sqrt(np.maximum(3600.0 - r**2, 0.0))
    fillet = 20.0 - np.sqrt(np.maximum(400.0 - (r - 80.0) ** 2, 0.0))
    return np.where(r <= 60.0, cap, np.where(r <= 80.0, fillet, 0.0)) + 0.15


def cup(r: np.ndarray) -> np.ndarray:
    """A shallow cup: a flat top 24 mm high to r = 50 mm, a wall of two 12 mm arcs, a flange."""
    top = np.where(r <= 50.0, 24.0, 0.0)
    upper = 12.0 + np.sqrt(np.maximum(144.0 - (r - 50.0) ** 2, 0.0))
    lower = 12.0 - np.sqrt(np.maximum(144.0 - (r - 74.0) ** 2, 0.0))
    return np.where(r <= 50.0, top, np.where(r <= 62.0, upper, np.where(r <= 74.0, lower, 0.0)))


def shallow_dome(r: np.ndarray) -> np.ndarray:
    """A 24 mm cap of radius 200 mm, out to its rim at r ≈ 94.9 mm, then a flange."""
    return np.maximum(np.sqrt(np.maximum(200.0**2 - r**2, 0.0)) - 176.0, 0.0)


def drape(profile, flat: np.ndarray) -> np.ndarray:
    """Formed positions (n, 3) of flat points (n, 2): the meridian kept at its length."""
    r = np.linspace(0.0, 200.0, 40001)
    z = profile(r)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(r), np.diff(z)))])
    rho = np.hypot(flat[:, 0], flat[:, 1])
    radius = np.interp(rho, s, r)
    scale = np.divide(radius, rho, out=np.ones_like(rho), where=rho > 0)
    return np.column_stack([flat * scale[:, None], profile(radius)])


def shear(profile, flat: np.ndarray, h: float = 0.5) -> np.ndarray:
    """90° minus the angle between the formed images of warp and weft (central differences)."""
    ex, ey = np.array([h, 0.0]), np.array([0.0, h])
    warp = drape(profile, flat + ex) - drape(profile, flat - ex)
    weft = drape(profile, flat + ey) - drape(profile, flat - ey)
    cos = np.einsum("ni,ni->n", warp, weft) / (np.linalg.norm(warp, axis=1)
                                                * np.linalg.norm(weft, axis=1))
    return 90.0 - np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def write_bundle(folder: Path, grid_of=hemisphere, lines_of=hemisphere) -> Path:
    """The lab's bundle: case, grid of ``grid_of``'s part, shear lines of ``lines_of``'s."""
    rng = np.random.default_rng(7)
    (folder / "case").mkdir(parents=True)
    (folder / "case" / "case.toml").write_text(
        CASE + "".join(TOOL.format(name) for name in ("punch", "die", "holder")))
    (folder / "bundle.toml").write_text(BUNDLE)
    i, j = np.meshgrid(np.arange(-6, 7), np.arange(-6, 7), indexing="ij")
    ij = np.column_stack([i.ravel(), j.ravel()])
    flat = 20.0 * ij.astype(float)
    formed = drape(grid_of, flat) + rng.normal(0.0, 0.3, (len(flat), 3))
    rows = ["i,j,x0_mm,y0_mm,x_mm,y_mm,z_mm"] + [
        f"{a},{b},{x0:g},{y0:g},{x:.3f},{y:.3f},{z:.3f}"
        for (a, b), (x0, y0), (x, y, z) in zip(ij, flat, formed, strict=True)]
    (folder / "grid.csv").write_text("# grid drawn at 20 mm, tracked after forming\n"
                                     + "\n".join(rows) + "\n")
    s = np.arange(0.0, 320.0, 20.0)
    bias = np.column_stack([s, s]) / math.sqrt(2.0) - 105.0  # (-105, -105) to (107, 107)
    weft = np.column_stack([np.full(len(s), 30.0), 0.7 * s - 105.0])  # x0 = 30, y0 ±105
    points = np.vstack([bias, weft])
    gamma = shear(lines_of, points) + rng.normal(0.0, 1.0, len(points))
    names = ["bias"] * len(s) + ["weft"] * len(s)
    rows = ["x0_mm,y0_mm,shear_deg,line,s_mm"] + [
        f"{x0:.2f},{y0:.2f},{g:.2f},{n},{d:g}"
        for (x0, y0), g, n, d in zip(points, gamma, names, [*s, *s], strict=True)]
    (folder / "shear.csv").write_text("# shear along two lines, flat positions\n"
                                      + "\n".join(rows) + "\n")
    return folder


def checked(folder: Path) -> dict[str, dict]:
    return {e["measurement"]: e for e in data_check(load_bundle(folder, read_case=case_for_test))}


def test_the_hemispheres_own_grid_and_shear_lines_are_not_suspect(tmp_path):
    entries = checked(write_bundle(tmp_path / "b"))
    assert set(entries) == {"file", "shear_points"}
    assert not any(e["suspect"] for e in entries.values()), entries
    # The drawn shear is the hemisphere's: about 28° on the bias where the sheet meets the
    # fillet, 0 on the axes.
    table = np.genfromtxt(tmp_path / "b" / "shear.csv", delimiter=",", names=True,
                          skip_header=1, dtype=None, encoding="utf-8")
    assert 24.0 < np.abs(table["shear_deg"]).max() < 32.0


def test_a_shallow_cups_grid_under_the_hemisphere_is_another_parts(tmp_path):
    entry = checked(write_bundle(tmp_path / "b", grid_of=cup))["file"]
    assert entry["suspect"], entry
    assert "lie inside it deeper than a cell (20 mm) at the end of its motion" in entry["why"]
    assert entry["why"].endswith("another part's grid?")
    # The deepest point is the cup's top on the axis: 80.15 − 24 mm below the punch's apex.
    depth = float(entry["why"].split("up to ")[1].split(" mm")[0])
    assert depth == pytest.approx(56.15, abs=1.5)
    # Every flat position lies on the blank, so the flat check alone cannot tell.
    assert "of the flat positions lie outside" not in entry["why"]


def test_a_shallow_domes_shear_lines_with_the_hemispheres_grid_are_another_parts(tmp_path):
    entries = checked(write_bundle(tmp_path / "b", lines_of=shallow_dome))
    assert entries["file"]["suspect"] is False
    entry = entries["shear_points"]
    assert entry["suspect"], entry
    assert entry["why"].startswith("the shear points differ from the shear of the test's "
                                   "own grid")
    assert entry["why"].endswith("another part's shear points?")
    # The dome's lines vary by about their noise (1°); they miss the grid's by far more.
    apart = float(entry["why"].split(" by ")[1].split("°")[0])
    spread = float(entry["why"].split("points vary (")[1].split("°")[0])
    assert apart > 10.0 and spread < apart
