"""``drape probe``: the model's values at a lab's points, by the definitions ``compare`` uses.

On sheets with known answers (a homogeneous deformation: every value in closed form), and
the lab page's commands as printed on the double dome, whose values ``compare`` reads back
exactly from a bundle made of them.
"""

import math
import re
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.cli import main
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.running import measure
from fenicsx_drape.forming.running.post import FormedGrid

ROOT = Path(__file__).resolve().parents[1]


def affine(shear_deg=20.0, shrink=0.9, lift_mm=4.0, quarter=False, cell_mm=10.0):
    """A square blank of side 100 mm (or its quarter) under x ↦ shrink (X + tan γ Y, Y)."""
    s = np.arange(0.0 if quarter else -50.0, 50.0 + 1e-9, cell_mm)
    X = np.stack([*np.meshgrid(s, s, indexing="ij"), np.zeros((s.size, s.size))], axis=-1)
    x = X.copy()
    t = math.tan(math.radians(shear_deg))
    x[..., 0] = shrink * (X[..., 0] + t * X[..., 1])
    x[..., 1] = shrink * X[..., 1]
    x[..., 2] = lift_mm
    return FormedGrid(X, x, quarter)


def test_the_formed_sheet_is_written_and_read_back_exactly(tmp_path):
    quarter = affine(shear_deg=0.0, quarter=True)
    back = measure.read_sheet(measure.write_sheet(quarter, tmp_path / "q.csv"), ("x", "y"))
    assert back.planes == ("x", "y") and np.array_equal(back.x, quarter.x)
    # A stack: every ply, the last the one away from the punch; a clipped net's absent nodes.
    a, b = affine(), affine(shear_deg=5.0, lift_mm=4.3)
    X, x = b.X.copy(), b.x.copy()
    X[0, 0], x[0, 0] = np.nan, np.nan
    b = FormedGrid(X, x, False)
    import dataclasses

    stack = dataclasses.replace(b, plies=(a, b))
    back = measure.read_sheet(measure.write_sheet(stack, tmp_path / "s.csv"))
    assert len(back.plies) == 2 and np.array_equal(back.ply(1).x, a.x)
    assert np.array_equal(back.x, b.x, equal_nan=True) and not back.present[0, 0]
    (tmp_path / "bad.csv").write_text("ply,i,j\n1,0,0\n")
    with pytest.raises(DrapeInputError, match=r"bad\.csv:1: not a formed sheet"):
        measure.read_sheet(tmp_path / "bad.csv")


def test_values_at_points_of_a_homogeneously_deformed_sheet():
    """Flat and formed points and edge points on x ↦ 0.9 (X + tan 20° Y, Y) lifted 4 mm:
    the shear is 20° everywhere, positions and draw-in are the map's."""
    grid = affine()
    F = 0.9 * np.array([[1.0, math.tan(math.radians(20.0))], [0.0, 1.0]])
    flat = np.array([[3.0, 4.0], [-17.0, 22.0], [45.0, -45.0], [80.0, 0.0]])
    got = measure.probe(grid, {"x0_mm": flat[:, 0], "y0_mm": flat[:, 1],
                               "label": ["a", "b", "c", "off"]})
    assert list(got)[:3] == ["x0_mm", "y0_mm", "label"]  # the input first, in its order
    on = slice(0, 3)
    x = flat[on] @ F.T
    assert np.allclose(got["shear_deg"][on], 20.0, atol=1e-9)
    assert np.allclose(np.column_stack([got["x_mm"], got["y_mm"]])[on], x, atol=1e-9)
    assert np.allclose(got["z_mm"][on], 4.0)
    assert np.allclose(got["draw_in_mm"][on], np.linalg.norm(flat[on], axis=1)
                       - np.linalg.norm(x, axis=1), atol=1e-9)
    assert list(got["unmatched"]) == [0, 0, 0, 1] and np.isnan(got["shear_deg"][3])
    # Formed points: 1 mm above the sheet (and one far off), with a measured shear kept.
    P = np.column_stack([x, np.full(3, 5.0)])
    P = np.vstack([P, [0.0, 0.0, 40.0]])
    got = measure.probe(grid, {"x_mm": P[:, 0], "y_mm": P[:, 1], "z_mm": P[:, 2],
                               "shear_deg": [19.0, 21.0, 20.5, 0.0]})
    assert np.allclose(got["x0_mm"][on], flat[on, 0]) and np.allclose(got["y0_mm"][on],
                                                                       flat[on, 1])
    assert np.allclose(got["distance_mm"][on], 1.0)
    assert np.allclose(got["shear_deg"][on], 20.0, atol=1e-9)
    assert list(got["measured_shear_deg"]) == [19.0, 21.0, 20.5, 0.0]
    assert list(got["unmatched"]) == [0, 0, 0, 1]  # 36 mm off: beyond 2 cells
    # Edge points in plan: the edge x0 = 50 is at x = 0.9 (50 + tan 20° y0), y = 0.9 y0.
    y0 = np.array([0.0, 20.0])
    xe = 0.9 * (50.0 + math.tan(math.radians(20.0)) * y0)
    got = measure.probe(grid, {"x_mm": xe + 2.0, "y_mm": 0.9 * y0}, edge=True)
    assert list(got["unmatched"]) == [0, 0]
    # 2 mm along x outside the edge, which is slanted at 20° to y: 2 cos 20° from it,
    # outward (positive), its closest point 2 sin 20° further along it.
    γ = math.radians(20.0)
    assert np.allclose(got["distance_mm"], 2.0 * math.cos(γ))
    y1 = y0 + 2.0 * math.sin(γ) * math.cos(γ) / 0.9
    assert np.allclose(got["x0_mm"], 50.0) and np.allclose(got["y0_mm"], y1, atol=1e-9)
    x1 = 0.9 * (50.0 + math.tan(γ) * y1)
    assert np.allclose(np.column_stack([got["edge_x_mm"], got["edge_y_mm"]]),
                       np.column_stack([x1, 0.9 * y1]), atol=1e-9)
    assert np.allclose(got["draw_in_mm"], np.hypot(50.0, y1) - np.hypot(x1, 0.9 * y1))


def test_a_ply_of_a_stack_and_bad_points_are_named():
    import dataclasses

    a, b = affine(shear_deg=0.0), affine(shear_deg=10.0)
    stack = dataclasses.replace(b, plies=(a, b))
    pts = {"x0_mm": [1.0, 1.0], "y0_mm": [2.0, 2.0]}
    assert np.allclose(measure.probe(stack, pts)["shear_deg"], 10.0)  # the outer ply
    assert np.allclose(measure.probe(stack, pts, ply=1)["shear_deg"], 0.0)
    both = measure.probe(stack, {**pts, "ply": [1, 2]})
    assert np.allclose(both["shear_deg"], [0.0, 10.0]) and list(both["ply"]) == [1, 2]
    with pytest.raises(DrapeInputError, match="points:2: ply 3: the formed sheet has 2"):
        measure.probe(stack, {**pts, "ply": [1, 3]})
    with pytest.raises(DrapeInputError, match=r"x_mm, y_mm, z_mm \(formed\) or x0_mm, y0_mm"):
        measure.probe(stack, {"x_mm": [1.0], "y_mm": [2.0]})


def documented_commands() -> list[list[str]]:
    """The lab page's probe example, as printed (its one code block with drape probe)."""
    text = (ROOT / "docs" / "lab-measurements.md").read_text()
    (block,) = [b for b in re.findall(r"```sh\n(.*?)```", text, flags=re.S)
                if "./drape probe" in b]
    return [shlex.split(line)[1:] for line in block.splitlines() if line.strip()]


@pytest.mark.skip_in_parallel
def test_the_lab_pages_probe_example_runs_as_printed(tmp_path, monkeypatch, capsys):
    """The page's three commands on the double dome; the values it prints; and ``compare``'s
    reading of them: a bundle of the probed values against the run gives 0."""
    pytest.importorskip("dolfinx")
    from fenicsx_drape.cli import load_bundle_reported
    from fenicsx_drape.diagnosis.kinds import GRID, kind_of
    from fenicsx_drape.diagnosis.kinds.lab import match

    shutil.copytree(ROOT / "demos" / "probe", tmp_path / "demos" / "probe")
    monkeypatch.chdir(tmp_path)
    commands = documented_commands()
    assert [c[0] for c in commands] == ["form", "probe", "probe"]
    for args in commands:
        assert main(args) == 0
    err = capsys.readouterr().err
    page = (ROOT / "docs" / "lab-measurements.md").read_text().replace("\n", " ")
    said = re.findall(r"drape probe: (.*?)(?:; written|\n)", err)
    assert len(said) == 2
    for line in said:  # what the command says is what the page prints
        assert line.replace(" ", "") in page.replace("`", "").replace(" ", "")
    dd = tmp_path / "results" / "dd"
    lines = dd / "lines.csv"
    import csv

    rows = list(csv.DictReader(x for x in lines.read_text().splitlines()
                               if not x.startswith("#")))
    table = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    table.update({k: v.astype(float) for k, v in table.items() if k != "line"})
    printed = [row for row in page.split("```") if row.strip().startswith("line,x0_mm")]
    for row in printed[0].split()[1:]:  # the page's rows, to the digits printed
        name, x0, _, *rest = row.split(",")
        (k,) = np.flatnonzero((table["line"] == name) & np.isclose(table["x0_mm"], float(x0)))
        assert np.allclose([table[c][k] for c in ("shear_deg", "draw_in_mm", "z_mm")],
                           [float(rest[4]), float(rest[5]), float(rest[3])], atol=1e-6)
    # compare reads what probe gives: a bundle of the probed shear and edge, 0 residuals.
    api = measure.probe(dd, "demos/probe/lines.csv")
    assert np.array_equal(api["shear_deg"], table["shear_deg"])
    edge = measure.probe(dd, "demos/probe/edge.csv", edge=True)
    bundle = tmp_path / "probed"
    shutil.copytree(dd / "bundle" / "case", bundle / "case")
    measure.write_values({"x0_mm": api["x0_mm"], "y0_mm": api["y0_mm"],
                          "shear_deg": api["shear_deg"]}, bundle / "shear.csv")
    measure.write_values({"x_mm": edge["edge_x_mm"], "y_mm": edge["edge_y_mm"],
                          "draw_in_mm": edge["draw_in_mm"]}, bundle / "edge.csv")
    (bundle / "bundle.toml").write_text(
        '[bundle]\nname = "probed"\n\n[[test]]\nid = "dd"\nkind = "forming"\n'
        'case = "case/case.toml"\nshear_points = "shear.csv"\noutline = "edge.csv"\n'
        "shear_sd_deg = 1.0\nposition_sd_mm = 0.3\n")
    grid = measure.read_formed(dd).grid
    for source in (bundle, dd / "bundle"):  # ... and the bundle drape form wrote
        tests = [t for t in load_bundle_reported(source).tests if kind_of(t) is not GRID]
        assert sorted(kind_of(t).name for t in tests) == ["outline", "shear_points"]
        for test in tests:
            got = match(kind_of(test), test, grid)
            assert not got.unmatched.any()
            assert np.abs(got.values - kind_of(test).measured(test)).max() < 1e-9
    capsys.readouterr()


def test_probe_says_what_is_wrong(tmp_path, capsys):
    assert main(["probe", str(tmp_path), "--points", "x.csv"]) == 2
    assert "not the output folder of 'drape form'" in capsys.readouterr().err
    (tmp_path / "summary.json").write_text("{}")
    assert main(["probe", str(tmp_path), "--points", "x.csv"]) == 2
    assert "no formed_sheet.csv" in capsys.readouterr().err
    measure.write_sheet(affine(), tmp_path / "formed_sheet.csv")
    (tmp_path / "p.csv").write_text("x0_mm,y0_mm\n1,2\nnan,3\n")
    assert main(["probe", str(tmp_path), "--points", str(tmp_path / "p.csv")]) == 2
    assert "p.csv:3: column x0_mm is not a finite number" in capsys.readouterr().err
    (tmp_path / "p.csv").write_text("# a lab's points\nx0_mm,y0_mm,line\n1,2,A\n")
    assert main(["probe", str(tmp_path), "--points", str(tmp_path / "p.csv")]) == 0
    out = capsys.readouterr()
    assert out.out.splitlines()[1] == "x0_mm,y0_mm,line,x_mm,y_mm,z_mm,shear_deg,draw_in_mm," \
                                      "unmatched"
    assert "1 points, shear 20.00° to 20.00°" in out.err
