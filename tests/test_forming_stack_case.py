"""A stack of plies in the case file: ``[[ply]]`` tables and ``[interply]`` (docs/laminates.md)."""

import dataclasses

import pytest

from fenicsx_drape.forming.case.format import (
    CaseError,
    PlySpec,
    load_case,
    with_overrides,
    write_case,
)
from fenicsx_drape.materials.interply import InterplyLaw

STACK = """
[[ply]]
angle_deg = 0.0
thickness_mm = 0.3

[[ply]]
angle_deg = 45.0
thickness_mm = 0.25

[interply]
mu_ply = 0.3
eta_f_MPa_s_per_mm = 0.001
"""


def stack_case(tmp_path, text=STACK, symmetry="[]"):
    base = load_case("hemisphere")
    folder = write_case(base, tmp_path / "base").parent
    body = (folder / "case.toml").read_text().replace('symmetry = ["x", "y"]',
                                                       f"symmetry = {symmetry}")
    # The die's gap: room for the stack (a die closing on one ply's gap refuses it).
    body = body.replace("ply_thickness_mm = 0.3", "ply_thickness_mm = 0.6")
    path = tmp_path / "stack.toml"
    path.write_text(body + text)
    for f in folder.iterdir():
        if f.name != "case.toml":
            (tmp_path / f.name).write_bytes(f.read_bytes())
    return path


def test_a_stack_reads_and_writes_back(tmp_path):
    case = load_case(stack_case(tmp_path))
    assert case.stack and [p.angle_deg for p in case.plies] == [0.0, 45.0]
    assert [p.thickness_mm for p in case.plies] == [0.3, 0.25]
    assert case.interply_law() == InterplyLaw(mu_ply=0.3, eta_f_MPa_s_per_mm=0.001)
    again = load_case(write_case(case, tmp_path / "again"))
    assert again.plies == case.plies and again.interply == case.interply


def test_the_ply_angle_override_turns_the_whole_stack(tmp_path):
    case = with_overrides(load_case(stack_case(tmp_path)), ply_angle_deg=10.0)
    assert [b.ply_angle_deg for b in case.ply_blanks()] == [10.0, 55.0]
    assert [b.grid().rotation_deg for b in case.ply_blanks()] == [10.0, 55.0]


def test_one_ply_is_todays_case(tmp_path):
    one = "[[ply]]\nangle_deg = 30.0\nthickness_mm = 0.3\n"
    case = load_case(stack_case(tmp_path, one))
    today = with_overrides(load_case("hemisphere"), symmetry=[], ply_angle_deg=30.0)
    assert not case.stack and case.plies == ()
    assert case.blank.ply_angle_deg == 30.0
    assert case.blank.grid() == dataclasses.replace(today.blank, hold_origin=False).grid()


@pytest.mark.parametrize("text, message", [
    ("[[ply]]\nangle_deg = 0.0\n", "[[ply]] 1: 'thickness_mm' is required"),
    ("[[ply]]\nangle_deg = 0.0\nthickness_mm = -1.0\n", "[[ply]] 1 'thickness_mm'"),
    ("[[ply]]\nangle_deg = 0.0\nthickness_mm = 0.3\ncolour = 1\n", "unknown key 'colour'"),
    ("[[ply]]\nangle_deg = 0.0\nthickness_mm = 0.3\nmodel = 'none.toml'\n",
     "[[ply]] 1 'model': no such file"),
    (STACK.replace("mu_ply = 0.3", "mu_ply = -0.3"), "[interply] 'mu_ply'"),
    (STACK.replace("mu_ply = 0.3", "slip_mm = 0.0"), "parameter slip_mm"),
    (STACK.replace("mu_ply = 0.3", "mu = 0.3"), "[interply]: unknown key 'mu'"),
])
def test_a_bad_stack_names_the_key(tmp_path, text, message):
    with pytest.raises(CaseError) as err:
        load_case(stack_case(tmp_path, text))
    assert message in str(err.value) and "stack.toml" in str(err.value)


def test_a_turned_ply_in_a_quarter_model_is_refused(tmp_path):
    with pytest.raises(CaseError, match=r"\[\[ply\]\] 2"):
        load_case(stack_case(tmp_path, symmetry='["x", "y"]'))


def test_each_ply_may_name_its_own_model(tmp_path):
    from fenicsx_drape.forming.running.run import case_model, ply_models

    (tmp_path / "a.toml").write_text('effects = ["decrimping"]\n')
    (tmp_path / "b.toml").write_text('effects = ["tow_buckling"]\n')
    text = STACK.replace("thickness_mm = 0.3\n", "thickness_mm = 0.3\nmodel = 'a.toml'\n")
    text = text.replace("thickness_mm = 0.25\n", "thickness_mm = 0.25\nmodel = 'b.toml'\n")
    case = load_case(stack_case(tmp_path, text))
    # No model of the case's own: the paper's for the run (holder, tools, its plies slide),
    # and each ply's tow and shear laws from its own model.
    assert "interply_friction" in case_model(case).effects
    assert [m.effects for m in ply_models(case)] == [("decrimping",), ("tow_buckling",)]
    same = text.replace("model = 'b.toml'", "model = 'a.toml'")
    case = load_case(stack_case(tmp_path, same))  # one model for all: the case's
    assert case_model(case).effects == ("decrimping",) and ply_models(case) is None
    # The loader keeps the plies' models, and a copy of the case names no file of its folder.
    assert "model =" not in write_case(case, tmp_path / "copy").read_text()


def test_the_plies_share_the_cell_size_the_rectangle_fits():
    """A 300 mm side takes 18.75 mm cells for 20 asked; the ply at 45° takes them too."""
    case = load_case("double_dome", symmetry=[], cell_mm=20.0)
    case = dataclasses.replace(case, plies=(PlySpec(0.0, 0.3), PlySpec(45.0, 0.3)))
    assert [b.grid().cell_mm for b in case.ply_blanks()] == [18.75, 18.75]
