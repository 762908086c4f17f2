"""A case's geometry checked before the first step, in the user's terms.

The tools are built here: a dome punch (an STL of R = 60 mm) rising 20 mm from 1 mm under the
blank, a flat plate as the holder and another as the die, each moved where a careless case
puts it.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_untrusted_input import dome_stl

from fenicsx_drape.cli import main
from fenicsx_drape.forming.case.format import CaseError, load_case
from fenicsx_drape.forming.running.geometry import geometry_problems
from fenicsx_drape.forming.running.run import run_case

CASE = """\
[case]
name = "placed"
duration_s = 10.0

[blank]
outline = "rectangle"
size_mm = [160.0, 160.0]
centre_mm = {centre}
cell_mm = 20.0

[holder]
tool = "holder"
holder_force_N = 10.0

[[tool]]
name = "punch"
role = "punch"
geometry = "dome.stl"
[tool.motion]
time_s = [0.0, 10.0]
z_mm = [-61.0, -41.0]

[[tool]]
name = "die"
role = "die"
geometry = "plate.stl"
[tool.motion]
time_s = [0.0]
z_mm = [{die_z}]

[[tool]]
name = "holder"
role = "holder"
geometry = "plate.stl"
[tool.motion]
time_s = [0.0]
z_mm = [{holder_z}]
"""


def write_case(folder, *, centre=(0.0, 0.0), die_z=40.0, holder_z=0.0):
    """The case in ``folder``: a 200 mm square plate (die, holder) and the dome punch."""
    dome_stl(folder / "dome.stl", 60.0, 12, 48)
    corners = [(-100, -100), (100, -100), (100, 100), (-100, 100)]
    facets = [(corners[0], corners[1], corners[2]), (corners[0], corners[2], corners[3])]
    (folder / "plate.stl").write_text("solid plate\n" + "".join(
        "facet normal 0 0 1\n outer loop\n" + "".join(f"  vertex {x} {y} 0\n" for x, y in f)
        + " endloop\nendfacet\n" for f in facets) + "endsolid plate\n")
    path = folder / "case.toml"
    path.write_text(CASE.format(centre=list(centre), die_z=die_z, holder_z=holder_z))
    return path


def problems(path):
    from fenicsx_drape.forming.case.format import build_tools

    case = load_case(path)
    return geometry_problems(case, build_tools(case), case.blank.grid().nodes)


def test_a_sound_case_has_no_problem(tmp_path):
    # The die 40 mm up: the dome's top ends at 60 − 41 = 19 mm, 21 mm short of it (> a cell).
    errors, warns = problems(write_case(tmp_path, die_z=19.5))
    assert errors == [] and warns == []


def test_a_blank_no_tool_meets_is_named_with_the_distances(tmp_path, capsys):
    # The blank 400 mm to the side: the dome (foot radius 60 mm) never comes under it.
    path = write_case(tmp_path, centre=(400.0, 0.0))
    with pytest.raises(CaseError) as err:
        run_case(load_case(path))
    text = str(err.value)
    assert "the blank and the tools never meet: over the motion 'punch' comes no nearer " \
           "than " in text
    assert "the holder 'holder' does not reach the blank: its surface covers none of the " \
           "blank's nodes at the start" in text
    # The blank's nearest edge (x = 320 mm) from the dome's foot (r = 60 mm), which ends
    # 41 mm under the blank's plane.
    punch = float(text.split("'punch' comes no nearer than ")[1].split(" mm")[0])
    assert punch == pytest.approx(np.hypot(320.0 - 60.0, 41.0), abs=0.5)
    assert main(["form", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "never meet" in capsys.readouterr().err


def test_a_die_on_the_wrong_side_of_the_sheet_is_named_with_its_depth(tmp_path):
    errors, _ = problems(write_case(tmp_path, die_z=-10.0))
    assert errors == ["tool 'die' (die) starts on the wrong side of the sheet: 81 of the "
                      "blank's 81 nodes start inside it, up to 10 mm deep (the sheet must "
                      "start on its sheet_side '-z')"]


def test_a_holder_that_does_not_reach_the_blank_is_named_with_its_distance(tmp_path):
    errors, _ = problems(write_case(tmp_path, holder_z=15.0))
    assert errors == ["the holder 'holder' does not reach the blank: its surface covers none "
                      "of the blank's nodes at the start (the nearest node is 15 mm from it)"]


def test_a_punch_that_never_reaches_the_die_is_warned_with_the_gap(tmp_path):
    errors, warns = problems(write_case(tmp_path, die_z=80.0))
    # The dome's top at 60 − 41 = 19 mm at the end, the die at 80 mm: 61 mm apart.
    assert errors == [] and warns == ["the punch 'punch' never reaches the die 'die': at the "
                                      "end of the motion they are still 61 mm apart (more "
                                      "than the sheet's cell 20 mm)"]


def test_a_blank_within_the_holders_opening_is_named():
    # The paper's hemisphere with a 110 mm sheet (corners at r = 78 mm): the opening is
    # 170 mm across.
    case = load_case("hemisphere", sheet_mm=110.0, cell_mm=40.0)
    with pytest.raises(CaseError, match=r"the holder 'holder' does not reach the blank: its "
                                        r"surface covers none of the blank's nodes at the "
                                        r"start \(the blank lies within its opening\)"):
        run_case(case)


def test_the_check_is_made_once_per_case_content_and_again_for_a_changed_one(tmp_path,
                                                                              monkeypatch):
    # A diagnosis forms the same part for many models: its geometry is checked once. A case
    # whose content changed (the holder moved 15 mm up) is checked again, and fails.
    from fenicsx_drape.forming.running import run

    calls = []
    monkeypatch.setattr(run, "geometry_problems",
                        lambda *a: calls.append(1) or geometry_problems(*a))
    monkeypatch.setattr(run, "_GEOMETRY", {})
    path = write_case(tmp_path, die_z=19.5)
    first = run_case(load_case(path))
    again = run_case(load_case(path))
    assert len(calls) == 1
    assert np.array_equal(first.grid.x, again.grid.x, equal_nan=True)
    path.write_text(CASE.format(centre=[0.0, 0.0], die_z=19.5, holder_z=15.0))
    for _ in range(2):
        with pytest.raises(CaseError, match="the holder 'holder' does not reach the blank"):
            run_case(load_case(path))
    assert len(calls) == 2
