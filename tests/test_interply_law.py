"""The inter-ply friction law τ = τ₀ + μ p + η_f v (materials/interply.py)."""

import numpy as np
import pytest

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.materials.interply import InterplyLaw

LAW = InterplyLaw(tau0_MPa=0.01, mu_ply=0.25, eta_f_MPa_s_per_mm=0.004, slip_mm=0.1)


def test_steady_sliding_is_tack_coulomb_film():
    """Pulled at constant speed v under p, the traction settles at τ₀ + μp + η_f v."""
    for p, v in ((0.05, 1.0), (0.2, 1.0), (0.05, 5.0), (0.2, 5.0)):
        law = InterplyLaw(**{**LAW.parameters, "pressure_MPa": p})
        dt, state = 0.01, law.initial_state(1)
        for k in range(1, 200):
            τ, _, state = law.update(np.array([v * dt * k]), dt, state)
        assert τ[0] == pytest.approx(0.01 + 0.25 * p + 0.004 * v, rel=1e-12)
        assert state[0, 0] > 0.0  # it slid


def test_no_slip_below_threshold():
    """Held below τ₀ + μp the interface stays elastic: slip within ε, no plastic slip."""
    law = InterplyLaw(**{**LAW.parameters, "eta_f_MPa_s_per_mm": 0.0, "pressure_MPa": 0.1})
    τ_y = law.yield_traction(0.1)
    state = law.initial_state(1)
    for s in np.linspace(0.0, 0.09, 10):
        τ, _, state = law.update(np.array([s]), 0.1, state)
    assert τ[0] == pytest.approx(0.9 * τ_y)
    assert state[0, 0] == 0.0


def test_tangent_is_a_finite_difference():
    """∂τ/∂s and ∂τ/∂p of the vector law against central differences, stick and slide."""
    rng = np.random.default_rng(3)
    n = 40
    s = rng.normal(scale=0.15, size=(n, 2))
    p = rng.uniform(0.01, 0.3, n)
    state = np.concatenate([rng.normal(scale=0.05, size=(n, 2)),
                            s - rng.normal(scale=0.02, size=(n, 2))], axis=1)
    out = LAW.traction(s, p, 0.1, state)
    k = np.linalg.norm(s - state[:, :2], axis=1) * LAW.yield_traction(p) / LAW.slip_mm
    assert (k > LAW.yield_traction(p)).any() and (k < LAW.yield_traction(p)).any()
    h = 1e-7
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        fd = (LAW.traction(s + e, p, 0.1, state).tau
              - LAW.traction(s - e, p, 0.1, state).tau) / (2 * h)
        assert np.allclose(out.dtau_ds[:, :, j], fd, rtol=1e-5, atol=1e-7)
    fd = (LAW.traction(s, p + h, 0.1, state).tau - LAW.traction(s, p - h, 0.1, state).tau) / (2 * h)
    assert np.allclose(out.dtau_dp, fd, rtol=1e-5, atol=1e-7)


def test_sliding_traction_is_along_the_slip():
    """Sliding from rest in any direction: |τ_Coulomb| = τ₀ + μp along the slip."""
    law = InterplyLaw(**{**LAW.parameters, "eta_f_MPa_s_per_mm": 0.0})
    φ = np.linspace(0, 2 * np.pi, 7)
    s = 2.0 * np.column_stack([np.cos(φ), np.sin(φ)])
    out = law.traction(s, np.full(7, 0.1), 0.1, law.initial_state(7, 2))
    assert np.allclose(out.tau, law.yield_traction(0.1) * s / 2.0)
    assert np.allclose(out.state[:, :2], s * (1 - 0.1 / 2.0))


def test_bonded_and_frictionless_limits():
    bonded = InterplyLaw(interply_friction=False, bond_MPa_per_mm=50.0)
    τ, C, state = bonded.update(np.array([0.3, 3.0]), 0.1, bonded.initial_state(2))
    assert np.allclose(τ, [15.0, 150.0]) and np.allclose(C, 50.0) and (state[:, 0] == 0).all()
    free = InterplyLaw(tau0_MPa=0.0, mu_ply=0.0, eta_f_MPa_s_per_mm=0.0, pressure_MPa=1.0)
    τ, C, _ = free.update(np.array([0.3, 3.0]), 0.1, free.initial_state(2))
    assert (τ == 0).all() and (C == 0).all()


def test_bad_parameters_are_named():
    with pytest.raises(ParameterError, match="mu_ply"):
        InterplyLaw(mu_ply=-0.1)
    with pytest.raises(ParameterError, match="slip_mm"):
        InterplyLaw(slip_mm=0.0)
    with pytest.raises(ParameterError, match="eta_f_MPa_s_per_mm"):
        InterplyLaw(eta_f_MPa_s_per_mm=float("nan"))
    with pytest.raises(ParameterError, match="pressure_MPa"):
        InterplyLaw(pressure_MPa=-1.0)
    with pytest.raises(ValueError, match="negative pressure"):
        LAW.traction(np.zeros((1, 2)), np.array([-1.0]), 0.1, LAW.initial_state(1, 2))
