"""Model, MODEL.toml, Table 2 defaults, the effect catalogue, parameter information."""

import numpy as np
import pytest

from fenicsx_drape import default_model, load_model
from fenicsx_drape.effects import EFFECTS, describe_effect, effect_names
from fenicsx_drape.errors import DrapeInputError, ParameterError
from fenicsx_drape.materials import FrictionLaw, ShearLaw, TowLaw
from fenicsx_drape.model import Model, default_parameters, parameter_info

SPEC_EFFECTS = ("rate_dependence", "strain_dependent_viscosity", "decrimping", "tow_buckling",
                "holder_friction", "tool_friction", "temperature_dependence",
                "shear_tension_coupling")
TABLE2 = {"sigma_o": 2.62e-2, "eta_o": 1.37, "s_o": 7.48, "s_inf": 5.39e3, "alpha_v": 19.0,
          "eps_v_bar": 0.512, "E_v": 7.89, "E_p": 0.39, "E_o": 3.41e3, "E_inf": 2.91e4,
          "eps_bar": 1.44e-3, "alpha": 1.33e4}


@pytest.fixture(autouse=True)
def _isolated_registry(monkeypatch):
    """Laws registered by a test (plugins) are forgotten after it."""
    from fenicsx_drape import model
    from fenicsx_drape.materials import base

    monkeypatch.setattr(base, "_REGISTRY", dict(base._REGISTRY))
    monkeypatch.setattr(model, "_PLUGINS", dict(model._PLUGINS))


def test_default_parameters_are_table2():
    values = default_parameters()
    for name, value in TABLE2.items():
        assert values[name] == value
    assert parameter_info("eta_o").unit == "N·s/tow"
    assert parameter_info("E_inf").unit == "N/tow"
    assert parameter_info("k_st").unit == "tow/N"
    with pytest.raises(ParameterError, match="unknown parameter 'nope'"):
        parameter_info("nope")


def test_default_model_and_laws():
    model = default_model()
    assert model.effects == ("rate_dependence", "strain_dependent_viscosity", "decrimping",
                             "tow_buckling", "holder_friction")
    laws = model.laws({"temperature_C": 30.0, "speed_mm_per_min": 10.0})
    assert isinstance(laws["tow"], TowLaw) and isinstance(laws["shear"], ShearLaw)
    assert isinstance(laws["friction"], FrictionLaw)
    assert laws["shear"].temperature_C == 30.0
    assert laws["tow"].effects == {"decrimping", "tow_buckling"}


def test_catalogue_covers_the_spec():
    assert set(SPEC_EFFECTS) <= set(EFFECTS)
    for effect in EFFECTS.values():
        assert effect.acts_on in ("tow", "shear", "friction", "contact")
        assert effect.physics and effect.test_kinds
        assert set(effect.prerequisites) <= set(EFFECTS)
        for p in effect.parameters:
            assert parameter_info(p).unit
    assert EFFECTS["temperature_dependence"].prerequisites == ("rate_dependence",)
    assert EFFECTS["strain_dependent_viscosity"].prerequisites == ()
    assert set(SPEC_EFFECTS) <= set(effect_names())


def test_active_parameters():
    model = default_model()
    assert model.active_parameters(("tensile", "bias_extension")) == (
        "E_o", "E_inf", "eps_bar", "alpha", "sigma_o", "E_p", "eta_o", "E_v", "s_o", "s_inf",
        "alpha_v", "eps_v_bar")
    assert "mu" in model.active_parameters()
    linear = model.without_effects("decrimping", "rate_dependence", "holder_friction")
    assert linear.active_parameters() == ("E_inf", "sigma_o", "E_p", "s_o", "s_inf", "alpha_v",
                                          "eps_v_bar")
    fixed = Model(model.effects, {}, fixed=("E_p", "E_v"))
    assert "E_p" not in fixed.active_parameters() and "E_v" not in fixed.active_parameters()
    assert "k_st" in model.with_effects("shear_tension_coupling").active_parameters()
    assert "mu_tool" not in model.with_effects("tool_friction").active_parameters(["tensile"])
    hot = model.with_effects("temperature_dependence")
    assert "Ea_kJ_per_mol" in hot.active_parameters()
    nothing_viscous = hot.without_effects("rate_dependence", "strain_dependent_viscosity")
    assert "Ea_kJ_per_mol" not in nothing_viscous.active_parameters()


def test_with_and_without():
    model = default_model()
    assert model.with_parameters(eta_o=2.0).parameters["eta_o"] == 2.0
    assert model.parameters["eta_o"] == 1.37  # frozen: unchanged
    assert "tool_friction" in model.with_effects("tool_friction").effects
    assert "tow_buckling" not in model.without_effects("tow_buckling").effects
    with pytest.raises(DrapeInputError, match="unknown effect 'wrinkles'"):
        model.with_effects("wrinkles")
    with pytest.raises(ParameterError, match="unknown parameter 'Eo'"):
        model.with_parameters(Eo=1.0)
    with pytest.raises(ParameterError, match="E_p"):
        model.with_parameters(E_p=-0.1)
    with pytest.raises(ParameterError, match="k_st"):
        model.with_parameters(k_st=-1.0)


def test_toml_round_trip(tmp_path):
    model = Model(("rate_dependence", "decrimping"), {"sigma_o": 0.03, "E_p": 0.5},
                  fixed=("E_p",))
    path = tmp_path / "MODEL.toml"
    path.write_text(model.to_toml())
    again = load_model(path)
    assert again == model
    assert again.active_parameters() == model.active_parameters()
    arrays = model.with_parameters(eta_o=np.array([1.0, 2.0]))
    assert arrays.n_sets == 2
    with pytest.raises(ValueError, match="arrays"):
        arrays.to_toml()
    with pytest.raises(ParameterError, match="shapes"):
        arrays.with_parameters(E_v=np.ones(3))


@pytest.mark.parametrize(("text", "message"), [
    ('effects = ["decrimping", "wrinkles"]\n', r"MODEL.toml:1: unknown effect 'wrinkles'"),
    ('effects = []\n[parameters]\nsigma_o = 0.1\nEo = 3\n',
     r"MODEL.toml:4: unknown parameter 'Eo'"),
    ('effects = []\n[parameters]\nE_p = -1.0\n', r"MODEL.toml:3: .*E_p = -1"),
    ('effects = []\n[parameters]\nE_p = "soft"\n', r"MODEL.toml:3: .*E_p"),
    ('effects = []\n[fit]\nfixed = ["E_q"]\n', r"MODEL.toml:3: unknown parameter 'E_q'"),
    ('effects = []\nplugins = ["missing.py"]\n', r"MODEL.toml:2: plugin 'missing.py' not found"),
    ('effect = []\n', r"MODEL.toml:1: unknown key 'effect'"),
    ('effects = "decrimping"\n', r"MODEL.toml:1: effects must be a list"),
    ('effects = [\n', r"MODEL.toml: not valid TOML"),
])
def test_load_model_errors_name_file_line_and_key(tmp_path, text, message):
    path = tmp_path / "MODEL.toml"
    path.write_text(text)
    with pytest.raises(DrapeInputError, match=message):
        load_model(path)


def test_plugins_relative_to_the_file(tmp_path):
    (tmp_path / "laws").mkdir()
    (tmp_path / "laws" / "stiff_tow.py").write_text('''
from dataclasses import dataclass
import numpy as np
from fenicsx_drape.materials import MaterialLaw, parameter, register_law

@register_law("test_plugin_tow")
@dataclass
class StiffTow(MaterialLaw):
    """A linear tow with its own modulus."""
    role = "tow"
    E_plugin: float = parameter(123.0, unit="N/tow")

    def _update(self, strain, dt, state):
        return self.E_plugin * strain, self.E_plugin + 0 * strain, state
''')
    path = tmp_path / "MODEL.toml"
    path.write_text('effects = ["test_plugin_tow", "rate_dependence"]\n'
                    'plugins = ["laws/stiff_tow.py"]\n[parameters]\nE_plugin = 7.0\n')
    model = load_model(path)
    assert model.laws()["tow"].E_plugin == 7.0
    assert "test_plugin_tow" in effect_names()
    assert describe_effect("test_plugin_tow").acts_on == "tow"
    assert parameter_info("E_plugin").default == 123.0
    assert load_model(path) == model  # loading twice registers once
    text = model.to_toml(relative_to=tmp_path)
    assert 'plugins = ["laws/stiff_tow.py"]' in text
    (tmp_path / "copy.toml").write_text(text)
    assert load_model(tmp_path / "copy.toml") == model


def test_two_laws_of_one_role_is_an_error(tmp_path):
    (tmp_path / "two.py").write_text('''
from dataclasses import dataclass
from fenicsx_drape.materials import MaterialLaw, register_law

@dataclass
class _Tow(MaterialLaw):
    role = "tow"

    def _update(self, strain, dt, state):
        return strain, strain * 0 + 1, state

register_law("test_tow_a")(dataclass(type("TowA", (_Tow,), {})))
register_law("test_tow_b")(dataclass(type("TowB", (_Tow,), {})))
''')
    with pytest.raises(DrapeInputError, match="both tow laws"):
        Model(("test_tow_a", "test_tow_b"), plugins=(tmp_path / "two.py",))
