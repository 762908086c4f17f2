"""The blank-holder friction bars, eq. 1."""

import numpy as np
import pytest

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.materials import build_law


def friction(on=True, **conditions):
    return build_law("paper_friction", {"mu": 0.3, "holder_slip_mm": 0.1},
                     ("holder_friction",) if on else (),
                     {"holder_force_N": 133.0, "holder_nodes": 50.0, **conditions})


def drive(law, slips):
    state = law.initial_state(1)
    out = []
    for s in slips:
        f, t, state = law.update(np.array([s]), 0.1, state)
        out.append((f[0], t[0], state.copy()))
    return out


def test_yield_force_is_eq1():
    law = friction()
    assert law.yield_force_N == pytest.approx(0.3 * 133.0 / 50.0)
    path = drive(law, [0.05, 0.5, 2.0, 1.9, 0.0, -3.0])
    F_y = law.yield_force_N
    assert path[0][0] == pytest.approx(F_y * 0.5)  # elastic: stiffness F_y / 0.1 mm
    assert path[1][0] == pytest.approx(F_y) and path[2][0] == pytest.approx(F_y)
    assert path[3][0] == pytest.approx(F_y - F_y / 0.1 * 0.1)  # elastic unloading
    assert path[4][0] == pytest.approx(-F_y) and path[5][0] == pytest.approx(-F_y)
    assert path[2][2][0, 0] == pytest.approx(2.0 - 0.1)  # sliding slip


def test_tangent_is_central_difference():
    law = friction()
    for state in (np.array([[0.0]]), np.array([[1.0]])):
        for s in (0.03, 0.5, 1.05, 0.95, 0.8):
            _, t, _ = law.update(np.array([s]), 0.1, state)
            h = 1e-7
            fp, _, _ = law.update(np.array([s + h]), 0.1, state)
            fm, _, _ = law.update(np.array([s - h]), 0.1, state)
            assert t[0] == pytest.approx((fp[0] - fm[0]) / (2 * h), rel=1e-6, abs=1e-9)


def test_off_without_effect_and_bad_conditions():
    assert all(f == 0.0 for f, _, _ in drive(friction(on=False), [0.1, 1.0]))
    with pytest.raises(ParameterError, match="holder_nodes"):
        friction(holder_nodes=0.0)
    with pytest.raises(ParameterError, match="mu"):
        build_law("paper_friction", {"mu": -0.1, "holder_slip_mm": 0.1})
