"""Rigid tool motion: the table, interpolation, inverse, displacement, errors naming the key."""

import math

import numpy as np
import pytest

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.forming.tools.motion import RigidMotion, rotation_matrix

RNG = np.random.default_rng(11)


def test_translation_is_piecewise_linear_and_constant_beyond_the_table():
    m = RigidMotion(time_s=[0.0, 10.0, 40.0], z_mm=[0.0, 20.0, 80.0], x_mm=[0.0, 5.0, 5.0])
    for t, T in ((-3.0, [0, 0, 0]), (0.0, [0, 0, 0]), (5.0, [2.5, 0, 10]),
                 (25.0, [5, 0, 50]), (40.0, [5, 0, 80]), (99.0, [5, 0, 80])):
        R, got = m.at(t)
        np.testing.assert_allclose(got, T, atol=1e-12)
        np.testing.assert_array_equal(R, np.eye(3))
    X = RNG.uniform(-50, 50, (20, 3))
    np.testing.assert_allclose(m.apply(X, 25.0), X + np.array([5.0, 0.0, 50.0]))
    np.testing.assert_allclose(m.displacement(X, 5.0, 25.0), np.tile([2.5, 0, 40], (20, 1)))
    assert RigidMotion.fixed().is_fixed and not m.is_fixed
    # The translations kept for the times asked are not the caller's to change.
    m.at(25.0)[1][:] = 0.0
    np.testing.assert_allclose(m.at(25.0)[1], [5, 0, 50], atol=1e-12)
    np.testing.assert_allclose(m.apply(X, 25.0), X + np.array([5.0, 0.0, 50.0]))
    assert m == RigidMotion(time_s=[0.0, 10.0, 40.0], z_mm=[0.0, 20.0, 80.0],
                            x_mm=[0.0, 5.0, 5.0])


def test_rotation_about_an_axis_through_a_centre():
    c = np.array([10.0, -5.0, 3.0])
    axis = np.array([1.0, 2.0, 2.0])
    m = RigidMotion(time_s=[0.0, 2.0], rotation_deg=[0.0, 90.0], axis=axis, centre_mm=c,
                    y_mm=[0.0, 4.0])
    R, T = m.at(1.0)
    np.testing.assert_allclose(R, rotation_matrix(axis, 45.0))
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(R @ (axis / 3), axis / 3, atol=1e-14)  # the axis stays
    X = RNG.uniform(-50, 50, (30, 3))
    x = m.apply(X, 1.0)
    np.testing.assert_allclose(x, (X - c) @ R.T + c + T, atol=1e-12)
    np.testing.assert_allclose(m.inverse(x, 1.0), X, atol=1e-12)  # inverse-apply
    np.testing.assert_allclose(m.apply(c[None], 1.0)[0], c + T, atol=1e-12)  # centre moves by T
    # The displacement of the tool's point now at x since t0 = 0.3 s.
    d = m.displacement(x, 0.3, 1.0)
    np.testing.assert_allclose(x - d, m.apply(X, 0.3), atol=1e-12)
    # A quarter turn about z of the point (1, 0, 0) gives (0, 1, 0).
    q = RigidMotion(time_s=[0.0, 1.0], rotation_deg=[0.0, 90.0])
    np.testing.assert_allclose(q.apply([[1.0, 0.0, 0.0]], 1.0), [[0.0, 1.0, 0.0]], atol=1e-15)
    assert math.isclose(q.angle_deg(0.5), 45.0)


@pytest.mark.parametrize("table, message", [
    ({"time_s": [0.0, 1.0, 1.0], "z_mm": [0, 1, 2]}, "'time_s' must increase strictly"),
    ({"time_s": [0.0, 1.0], "z_mm": [0.0, 1.0, 2.0]}, "'z_mm' has 3 values, 'time_s' has 2"),
    ({"time_s": [0.0, float("nan")]}, "'time_s' has a value that is not a finite"),
    ({"time_s": [0.0, 1.0], "x_mm": [0.0, "a"]}, "'x_mm' must be a list of numbers"),
    ({"time_s": [0.0, 1.0], "rotation_deg": [0, 1], "axis": [0, 0, 0]}, "'axis'"),
    ({"time_s": [0.0, 1.0], "centre_mm": [0, 0]}, "'centre_mm' needs 3 numbers"),
    ({"time_s": [0.0, 1.0], "speed": [0, 0]}, "unknown key"),
    ({"z_mm": [0.0, 1.0]}, "'time_s' is missing"),
    ({"time_s": []}, "'time_s' is empty"),
])
def test_bad_tables_name_the_key(table, message):
    with pytest.raises(ParameterError, match=message) as err:
        RigidMotion.from_table(table, where="case.toml: [[tool]] 2 [tool.motion]")
    assert str(err.value).startswith("case.toml: [[tool]] 2 [tool.motion]")


def test_a_case_files_motion_is_the_one_motion_class(tmp_path):
    """One class from the file to the tool: the case's [tool.motion] is a RigidMotion, and the
    travel and speed the load steps use are its own (20 mm in 10 s, then 10 mm in 20 s)."""
    from pathlib import Path

    from fenicsx_drape.forming.case.format import load_case, with_overrides

    case = load_case(Path(__file__).parents[1] / "meshes" / "double_dome" / "case.toml")
    punch = case.tool("punch").motion
    assert type(punch) is RigidMotion
    assert case.total_travel_mm == pytest.approx(punch.travel_mm(case.duration_s))
    moved = RigidMotion(time_s=[0.0, 10.0, 30.0], z_mm=[0.0, 20.0, 30.0])
    assert moved.max_speed_mm_per_s() == pytest.approx(2.0)
    assert moved.travel_mm(20.0) == pytest.approx(25.0)
    slow = moved.scaled(time=2.0, travel=0.5)
    assert slow.time_s == (0.0, 20.0, 60.0) and slow.z_mm == (0.0, 10.0, 15.0)
    assert type(with_overrides(case, duration_s=2 * case.duration_s).tool("punch").motion) \
        is RigidMotion
