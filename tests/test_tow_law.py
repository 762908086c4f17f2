"""The tow law, eqs. 2-4: slopes, buckling, mirroring, overflow safety, tangent, bad input."""

import numpy as np
import pytest

from fenicsx_drape.errors import DrapeInputError, ParameterError
from fenicsx_drape.materials import TowLaw, build_law
from fenicsx_drape.model import default_parameters

TABLE2 = default_parameters()


def tow(*effects, **changes):
    return build_law("paper_tow", {**TABLE2, **changes}, effects)


def fd(law, strain, h):
    state = law.initial_state(strain.size)
    plus, _, _ = law.update(strain + h, 0.0, state)
    minus, _, _ = law.update(strain - h, 0.0, state)
    return (plus - minus) / (2.0 * h)


@pytest.mark.parametrize("effects", [(), ("decrimping",), ("tow_buckling",),
                                     ("decrimping", "tow_buckling")])
def test_tangent_is_central_difference(effects):
    law = tow(*effects)
    # Small, transition, large strain; compression (buckled or mirrored).
    strain = np.array([1e-4, 1.2e-3, 1.44e-3, 1.7e-3, 5e-3, 2e-2, -3e-4, -1.44e-3, -1e-2])
    _, tangent, _ = law.update(strain, 0.0, law.initial_state(strain.size))
    np.testing.assert_allclose(tangent, fd(law, strain, 1e-9), rtol=1e-6, atol=1e-6)


def test_slopes_E_o_small_and_E_inf_large():
    law = tow("decrimping", "tow_buckling")
    strain = np.array([0.0, 1e-5, 0.05])
    _, tangent, _ = law.update(strain, 0.0, law.initial_state(3))
    # αε̄ = 19 for Table 2: G'(0) = E_o to 1e-8; well above ε̄ the slope is E_∞.
    np.testing.assert_allclose(tangent, [TABLE2["E_o"], TABLE2["E_o"], TABLE2["E_inf"]],
                               rtol=1e-6)
    σ, _, _ = law.update(np.array([0.05]), 0.0, law.initial_state(1))
    # The asymptote: G(ε) → E_∞ ε − (E_∞ − E_o) ε̄ for ε ≫ ε̄.
    asymptote = TABLE2["E_inf"] * 0.05 - (TABLE2["E_inf"] - TABLE2["E_o"]) * TABLE2["eps_bar"]
    assert σ[0] == pytest.approx(asymptote, rel=1e-6)


def test_buckling_gives_zero_compression_and_mirror_without_it():
    strain = np.array([-0.02, -1e-3, -1e-8, 1e-3])
    buckled, t_b, _ = tow("decrimping", "tow_buckling").update(strain, 0.0, np.empty((4, 0)))
    mirrored, _, _ = tow("decrimping").update(strain, 0.0, np.empty((4, 0)))
    tension, _, _ = tow("decrimping").update(-strain, 0.0, np.empty((4, 0)))
    np.testing.assert_array_equal(buckled[:3], 0.0)
    np.testing.assert_array_equal(t_b[:3], 0.0)
    assert buckled[3] > 0
    np.testing.assert_allclose(mirrored, -tension, rtol=1e-14)


def test_linear_without_decrimping():
    strain = np.array([1e-4, 1e-2])
    σ, t, _ = tow().update(strain, 0.0, np.empty((2, 0)))
    np.testing.assert_allclose(σ, TABLE2["E_inf"] * strain, rtol=1e-14)
    np.testing.assert_allclose(t, TABLE2["E_inf"], rtol=1e-14)
    assert TowLaw.active_parameters(()) == ("E_inf",)
    assert set(TowLaw.active_parameters(("decrimping",))) == {"E_o", "E_inf", "eps_bar", "alpha"}


def test_no_overflow_for_large_alpha_strain():
    law = tow("decrimping", alpha=1e9)
    strain = np.array([-10.0, -1.0, 0.0, 1.0, 10.0])
    σ, t, _ = law.update(strain, 0.0, np.empty((5, 0)))
    assert np.isfinite(σ).all() and np.isfinite(t).all()
    assert σ[-1] == pytest.approx(TABLE2["E_inf"] * 10.0 - (TABLE2["E_inf"] - TABLE2["E_o"])
                                  * TABLE2["eps_bar"], rel=1e-9)


def test_bad_input_named():
    with pytest.raises(ParameterError, match="E_o"):
        tow(E_o=-1.0)
    with pytest.raises(ParameterError, match="alpha"):
        tow(alpha=float("nan"))
    with pytest.raises(ParameterError, match="missing parameter eps_bar"):
        build_law("paper_tow", {"E_o": 1.0, "E_inf": 2.0, "alpha": 3.0})
    with pytest.raises(ValueError, match="not finite"):
        tow().update(np.array([0.0, np.nan]), 0.0, np.empty((2, 0)))
    with pytest.raises(DrapeInputError, match="unknown law"):
        build_law("no_such_law", TABLE2)
