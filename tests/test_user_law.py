"""A user law registered by name works like a built-in one (demo: power-law viscosity)."""

from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape import unitcell as uc
from fenicsx_drape.effects import describe_effect, effect_names
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.model import Model, default_model, load_model

DEMO = Path(__file__).parents[1] / "demos" / "user_laws" / "power_law_viscosity.py"
L0, W0 = 210.0, 70.0


@pytest.fixture(autouse=True)
def _isolated_registry(monkeypatch):
    """Laws registered by a test (plugins) are forgotten after it."""
    from fenicsx_drape import model
    from fenicsx_drape.materials import base

    monkeypatch.setattr(base, "_REGISTRY", dict(base._REGISTRY))
    monkeypatch.setattr(model, "_PLUGINS", dict(model._PLUGINS))


def power_law_model(n_power):
    base = default_model()
    return Model(("power_law_viscosity", "decrimping", "tow_buckling"),
                 {**base.parameters, "n_power": n_power}, plugins=(DEMO,))


def bias(model, speed, strain_end=0.42, rows=120):
    u_end = (L0 - W0) * (np.sqrt(1 + 2 * strain_end) - 1)
    t = np.linspace(0.0, u_end / (speed / 60.0), rows)
    return uc.bias_extension(model, t, t * speed / 60.0, length_mm=L0, width_mm=W0)


def test_picked_by_name_and_catalogued():
    model = power_law_model(0.5)
    assert type(model.laws()["shear"]).__name__ == "PowerLawViscosityShear"
    assert "power_law_viscosity" in effect_names()
    assert describe_effect("power_law_viscosity").acts_on == "shear"
    assert "n_power" in model.active_parameters()
    assert "rate_ref_per_s" not in model.active_parameters()


def test_with_n_1_it_is_the_builtin_law():
    for speed in (10.0, 160.0):
        user = bias(power_law_model(1.0), speed).force_per_tow_N
        builtin = bias(default_model(), speed).force_per_tow_N
        np.testing.assert_allclose(user, builtin, rtol=1e-8, atol=1e-12)


def test_shear_thinning_flattens_the_rate_dependence():
    def spread(model):
        f = [np.interp(0.15, c.diagonal_strain, c.force_per_tow_N)
             for c in (bias(model, 10.0), bias(model, 160.0))]
        return f[1] / f[0]

    assert spread(power_law_model(0.4)) < spread(power_law_model(1.0)) - 0.2


def test_tangent_is_central_difference():
    law = power_law_model(0.5).laws()["shear"]
    state = law.initial_state(1)
    for i in range(1, 40):
        _, _, state = law.update(np.array([0.01 * i]), 1.0, state)
    for strain, dt in ((0.3951, 1.0), (0.3823, 0.5), (0.21, 2.0), (0.3899, 30.0), (0.4, 0.0)):
        _, tangent, _ = law.update(np.array([strain]), dt, state)
        h = 1e-7
        plus, _, _ = law.update(np.array([strain + h]), dt, state)
        minus, _, _ = law.update(np.array([strain - h]), dt, state)
        assert tangent[0] == pytest.approx((plus[0] - minus[0]) / (2 * h), rel=1e-6)


def test_a_second_file_cannot_take_a_registered_name(tmp_path):
    copy = tmp_path / "copy.py"
    copy.write_text(DEMO.read_text())
    power_law_model(0.5)
    with pytest.raises(DrapeInputError, match="already registered"):
        Model(("power_law_viscosity",), plugins=(copy,))


def test_model_toml_with_the_plugin(tmp_path):
    path = tmp_path / "MODEL.toml"
    path.write_text(f'effects = ["power_law_viscosity", "decrimping"]\nplugins = ["{DEMO}"]\n'
                    '[parameters]\nn_power = 0.7\n')
    model = load_model(path)
    assert model.parameters["n_power"] == 0.7
    path.write_text(f'effects = ["power_law_viscosity"]\nplugins = ["{DEMO}"]\n'
                    '[parameters]\nn_power = 1.5\n')
    with pytest.raises(DrapeInputError, match=r"MODEL.toml:4: .*n_power"):
        load_model(path)
