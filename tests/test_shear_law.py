"""The shear-diagonal law, eqs. 5-9: tangent, rate, relaxation, unloading, convergence."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.materials import ShearLaw, build_law
from fenicsx_drape.model import default_parameters

TABLE2 = default_parameters()
PAPER = ("rate_dependence", "strain_dependent_viscosity")
RATE = 0.0055  # 1/s, the middle effective rate of the paper's bias tests


def shear(effects=PAPER, conditions=None, **changes):
    return build_law("paper_shear", {**TABLE2, **changes}, effects, conditions)


def drive(law, time_s, strain, n=1):
    """Stress and states along a strain history (states after each row)."""
    state = law.initial_state(n)
    stress, states = [], []
    for i in range(len(time_s)):
        dt = time_s[i] - time_s[i - 1] if i else 0.0
        σ, _, state = law.update(np.full(n, strain[i]), dt, state)
        stress.append(σ.copy())
        states.append(state.copy())
    return np.array(stress)[:, 0] if n == 1 else np.array(stress), states


def ramp(strain_end, rate=RATE, rows=200, start=0.0, t0=0.0):
    t = t0 + np.linspace(0.0, abs(strain_end - start) / rate, rows)
    return t, np.linspace(start, strain_end, rows)


def history():
    """Loading to 0.42, holding 60 s, unloading to -0.3 (rows are (time, strain))."""
    t1, e1 = ramp(0.42)
    t2 = t1[-1] + np.linspace(0.0, 60.0, 30)[1:]
    t3, e3 = ramp(-0.3, start=0.42, t0=t2[-1])
    return np.concatenate([t1, t2, t3[1:]]), np.concatenate([e1, np.full(29, 0.42), e3[1:]])


REGIMES = {  # (row of the history whose state starts the step, strain increment, dt)
    "elastic loading": (2, 0.004, 1.0),
    "plastic viscous loading": (60, 0.01, 1.7),
    "lock-up": (198, 0.004, 0.7),
    "relaxation": (210, 1e-6, 5.0),
    "reversal (dashpot still loading)": (229, -0.002, 0.3),
    "unloading (eta_o branch)": (260, -0.01, 1.0),
    "compressive yield, loading in compression": (400, -0.01, 1.0),
    "zero step": (100, 0.001, 0.0),
}


@pytest.mark.parametrize("effects", [PAPER, ("rate_dependence",), ("strain_dependent_viscosity",),
                                     (), (*PAPER, "temperature_dependence")])
@pytest.mark.parametrize("regime", REGIMES)
def test_tangent_is_central_difference(effects, regime):
    law = shear(effects, {"temperature_C": 35.0})
    t, e = history()
    row, dε, dt = REGIMES[regime]
    _, states = drive(law, t, e)
    state = states[row]
    ε = np.array([e[row] + dε])
    _, tangent, _ = law.update(ε, dt, state)
    h = 1e-7
    plus, _, _ = law.update(ε + h, dt, state)
    minus, _, _ = law.update(ε - h, dt, state)
    assert tangent[0] == pytest.approx((plus[0] - minus[0]) / (2 * h), rel=1e-6, abs=1e-7)


def test_regimes_are_what_they_say():
    law = shear()
    t, e = history()
    _, states = drive(law, t, e)
    E_p, σ_o = TABLE2["E_p"], TABLE2["sigma_o"]
    ep = lambda row: E_p * (e[row] - states[row][0, 0])  # noqa: E731
    assert abs(ep(2)) < σ_o and ep(60) == pytest.approx(σ_o)
    assert ep(400) == pytest.approx(-σ_o)  # compressive yield reached on unloading
    assert states[260][0, 1] < states[250][0, 1]  # the dashpot moves back


def test_higher_rate_gives_higher_stress():
    law = shear()
    at = []
    for rate in (0.0013, 0.0055, 0.022):
        t, e = ramp(0.4, rate, rows=400)
        σ, _ = drive(law, t, e)
        at.append(np.interp([0.05, 0.2, 0.35, 0.4], e, σ))
    assert np.all(at[0] < at[1]) and np.all(at[1] < at[2])


def test_stress_relaxes_at_constant_strain_and_recovers_on_reloading():
    law = shear()
    t1, e1 = ramp(0.3)
    t_hold = t1[-1] + np.linspace(0.0, 200.0, 101)[1:]
    t3, e3 = ramp(0.35, start=0.3, t0=t_hold[-1])
    t = np.concatenate([t1, t_hold, t3[1:]])
    e = np.concatenate([e1, np.full(100, 0.3), e3[1:]])
    σ, _ = drive(law, t, e)
    hold = σ[len(t1) - 1:len(t1) + 100]
    assert np.all(np.diff(hold[:6]) < 0) and np.all(np.diff(hold) <= 1e-15)  # decays
    assert hold[-1] < 0.6 * hold[0]
    assert hold[-1] == pytest.approx(TABLE2["sigma_o"], rel=1e-6)  # to the plastic level
    # Reloading: the stress rises at once (stiff Maxwell spring) back above the hold's start.
    assert σ[-1] > hold[0]


def test_unloading_reaches_compressive_yield():
    law = shear()
    t, e = ramp(0.4)
    t2, e2 = ramp(0.0, start=0.4, t0=t[-1])
    σ, _ = drive(law, np.concatenate([t, t2[1:]]), np.concatenate([e, e2[1:]]))
    # The stress falls quickly to the compressive yield stress of the elastic-plastic branch
    # (minus the small viscous stress η_o ε̇ of the unloading dashpot) and then flows.
    assert σ[-1] < -TABLE2["sigma_o"]
    assert σ[-1] > -TABLE2["sigma_o"] - 2.0 * TABLE2["eta_o"] * RATE
    drop = np.argmax(σ[len(t):] < 0.0)
    assert 0 < drop < 0.2 * len(t2)


def test_integration_converges_first_order():
    law = shear()
    t_ref, e_ref = ramp(0.45, rows=6401)
    σ_ref, _ = drive(law, t_ref, e_ref)
    errors = []
    for rows in (51, 101, 201, 401):
        t, e = ramp(0.45, rows=rows)
        σ, _ = drive(law, t, e)
        # After the first 10 s: the start-up transient of the Maxwell branch (time constant
        # η/E_v = 0.17 s) is not resolved by any of these steps, by design of the test rates.
        error = np.abs(σ - np.interp(t, t_ref, σ_ref))[t > 10.0]
        errors.append(error.max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all(ratios > 1.7) and np.all(ratios < 2.5), (errors, ratios)  # first order
    assert errors[-1] < 2e-3 * σ_ref.max()


def test_stable_for_huge_steps():
    law = shear()
    for dt in (1e-3, 1.0, 1e3, 1e6):
        σ, tangent, state = law.update(np.array([0.3, -0.45]), dt, law.initial_state(2))
        assert np.isfinite(σ).all() and np.all(tangent > 0)
        assert np.all(np.abs(state[:, 1]) <= np.array([0.3, 0.45]) + 1e-15)


def test_rate_independent_limit():
    law = shear(("strain_dependent_viscosity",))
    σ_slow, _ = drive(law, *ramp(0.45, 0.0013))
    σ_fast, _ = drive(law, *ramp(0.45, 0.022))
    np.testing.assert_allclose(σ_slow, σ_fast, rtol=1e-12)
    # Lock-up term η_o ε̇_ref (f(|ε|) − 1) sign ε; without the effect: elastic-plastic only.
    f = 1 + 7.48 * 0.45 + (5390 - 7.48) / 19 * (np.log1p(np.exp(19 * (0.45 - 0.512)))
                                               - np.log1p(np.exp(-19 * 0.512)))
    assert σ_slow[-1] == pytest.approx(TABLE2["sigma_o"] + 1.37 * 0.0055 * (f - 1), rel=1e-9)
    σ_ep, _ = drive(shear(()), *ramp(0.45))
    assert σ_ep[-1] == pytest.approx(TABLE2["sigma_o"])
    assert ShearLaw.active_parameters(()) == ("sigma_o", "E_p")


def test_temperature_lowers_the_viscous_stress():
    t, e = ramp(0.3)
    effects = (*PAPER, "temperature_dependence")
    σ20, _ = drive(shear(effects, {"temperature_C": 20.0}), t, e)
    σ60, _ = drive(shear(effects, {"temperature_C": 60.0}), t, e)
    σ_off, _ = drive(shear(PAPER, {"temperature_C": 60.0}), t, e)
    np.testing.assert_allclose(σ20, σ_off, rtol=1e-13)  # T_ref = 20 °C
    assert np.all(σ60[5:] < σ20[5:])


def test_array_parameters_equal_scalar_runs():
    etas = np.array([0.5, 1.37, 3.0])
    law = shear(eta_o=etas, s_inf=np.array([2000.0, 5390.0, 8000.0]))
    t, e = ramp(0.45, rows=100)
    σ, _ = drive(law, t, e, n=3)
    for j, (eta, s_inf) in enumerate(zip(etas, (2000.0, 5390.0, 8000.0))):
        σ_j, _ = drive(shear(eta_o=eta, s_inf=s_inf), t, e)
        np.testing.assert_allclose(σ[:, j], σ_j, rtol=1e-12)


def test_bad_input_named():
    with pytest.raises(ParameterError, match="eta_o"):
        shear(eta_o=-1.0)
    with pytest.raises(ParameterError, match="s_inf"):
        shear(s_inf=float("inf"))
    with pytest.raises(ParameterError, match="temperature_C"):
        shear(conditions={"temperature_C": -300.0})
    law = shear()
    with pytest.raises(ValueError, match="not finite"):
        law.update(np.array([np.nan]), 1.0, law.initial_state(1))
    with pytest.raises(ValueError, match="dt"):
        law.update(np.array([0.1]), -1.0, law.initial_state(1))


def test_bad_condition_is_named():
    with pytest.raises(ParameterError, match="temperature_C"):
        shear(conditions={"temperature_C": "hot"})


@pytest.mark.parametrize("regime", ["plastic viscous loading", "lock-up", "relaxation"])
def test_tangent_with_a_softening_viscosity(regime):
    # s_∞ < s_o: f is concave and the dashpot iteration runs bracketed.
    law = shear(s_o=60.0, s_inf=2.0, eps_v_bar=0.2, alpha_v=30.0)
    t, e = history()
    row, dε, dt = REGIMES[regime]
    _, states = drive(law, t, e)
    ε = np.array([e[row] + dε])
    _, tangent, _ = law.update(ε, dt, states[row])
    h = 1e-7
    plus, _, _ = law.update(ε + h, dt, states[row])
    minus, _, _ = law.update(ε - h, dt, states[row])
    assert tangent[0] == pytest.approx((plus[0] - minus[0]) / (2 * h), rel=1e-6)


@settings(max_examples=40, deadline=None)
@given(steps=st.lists(st.tuples(st.floats(-0.49, 0.49), st.floats(0.0, 1e3)), min_size=1,
                      max_size=12),
       effects=st.sets(st.sampled_from((*PAPER, "temperature_dependence"))),
       temperature=st.floats(-50.0, 200.0))
def test_any_history_gives_finite_bounded_output(steps, effects, temperature):
    law = shear(tuple(effects), {"temperature_C": temperature})
    state = law.initial_state(1)
    for strain, dt in steps:
        σ, tangent, state = law.update(np.array([strain]), dt, state)
        assert np.isfinite(σ).all() and np.isfinite(tangent).all() and np.all(tangent >= 0)
        # The elastic-plastic branch never exceeds the yield stress; the dashpot strain lies
        # between its old value and the total strain.
        assert abs(TABLE2["E_p"] * (strain - state[0, 0])) <= TABLE2["sigma_o"] * (1 + 1e-12)
        assert abs(state[0, 1]) <= max(0.49, abs(strain)) + 1e-12
