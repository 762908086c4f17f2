"""Unit-cell solutions of the tensile and bias-extension tests (eqs. 15-23)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fenicsx_drape import unitcell as uc
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.materials import build_law
from fenicsx_drape.model import Model, default_model

L0, W0 = 210.0, 70.0


def bias_ramp(speed_mm_per_min, strain_end=0.45, rows=200):
    u_end = (L0 - W0) * (math.sqrt(1.0 + 2.0 * strain_end) - 1.0)
    t = np.linspace(0.0, u_end / (speed_mm_per_min / 60.0), rows)
    return t, t * speed_mm_per_min / 60.0


def test_effective_strain_rates_eq23():
    rates = [uc.effective_strain_rate(v, L0, W0) for v in (10.0, 40.0, 160.0)]
    np.testing.assert_allclose(rates, [0.001375, 0.005502, 0.022006], atol=5e-7)
    # The paper prints them truncated to two significant digits.
    printed = [math.floor(r / 10 ** math.floor(math.log10(r) - 1)) * 10 ** math.floor(
        math.log10(r) - 1) for r in rates]
    np.testing.assert_allclose(printed, [0.0013, 0.0055, 0.022], rtol=1e-12)
    assert uc.EFFECTIVE_RATE_FACTOR == pytest.approx(1.1553, abs=1e-4)


def test_eq23_is_the_least_squares_slope_over_time():
    # Fit ε̄ = k t to eq. 21 over time up to the pin-jointed limit ε = 0.5 (NOTES.md).
    e_max = math.sqrt(2.0) - 1.0
    e = np.linspace(0.0, e_max, 200001)
    eps = uc.bias_diagonal_strain(e * (L0 - W0), L0, W0)
    slope = np.sum(e * eps) / np.sum(e * e)
    assert slope == pytest.approx(uc.EFFECTIVE_RATE_FACTOR, rel=1e-6)


def test_bias_kinematics():
    model = default_model()
    t, u = bias_ramp(40.0)
    curve = uc.bias_extension(model, t, u, length_mm=L0, width_mm=W0)
    e = u / (L0 - W0)
    np.testing.assert_allclose(curve.diagonal_strain, e + e**2 / 2, rtol=1e-14)
    εd1, εt = curve.diagonal_strain, curve.tow_strain
    np.testing.assert_allclose(curve.shear_deg,
                               np.degrees(np.arcsin(2 * (εd1 - εt) / (1 + 2 * εt))), rtol=1e-12)
    # Nearly inextensible tows: γ ≈ arcsin(2 ε_d1), ε_d2 ≈ −ε_d1.
    np.testing.assert_allclose(curve.shear_deg, np.degrees(np.arcsin(2 * εd1)), atol=0.2)
    assert np.max(np.abs(curve.tow_strain)) < 1e-3
    np.testing.assert_allclose(curve.transverse_strain, 2 * curve.tow_strain
                               - curve.diagonal_strain, atol=1e-15)


def test_bias_curves_table2_rise_plateau_lockup_ordered_by_rate():
    model = default_model()
    grid = np.linspace(0.02, 0.45, 44)
    forces = []
    for speed in (10.0, 40.0, 160.0):
        t, u = bias_ramp(speed, rows=250)
        c = uc.bias_extension(model, t, u, length_mm=L0, width_mm=W0)
        f = np.interp(grid, c.diagonal_strain, c.force_per_tow_N)
        assert np.all(np.diff(c.force_per_tow_N) > 0)  # rises all the way
        slope = np.gradient(f, grid)
        initial = (c.force_per_tow_N[3] - c.force_per_tow_N[0]) / c.diagonal_strain[3]
        plateau = slope[(grid > 0.1) & (grid < 0.2)].mean()
        lockup = slope[grid > 0.4].mean()
        assert plateau < 0.3 * initial  # the first rise gives way to a plateau
        assert lockup > 8.0 * plateau  # and stiffens steeply towards 0.4-0.5
        forces.append(f)
    assert np.all(forces[0] < forces[1]) and np.all(forces[1] < forces[2])


def test_tensile_slopes_and_buckled_transverse_tows():
    model = default_model()
    u = np.linspace(0.0, 0.5, 201)
    c = uc.tensile(model, u / (2.0 / 60.0), u, gauge_length_mm=100.0)
    e = u / 100.0
    np.testing.assert_allclose(c.tow_strain, e + e**2 / 2, rtol=1e-14)
    slope = np.gradient(c.force_per_tow_N, c.tow_strain)
    assert slope[2] == pytest.approx(3410.0, rel=0.01)  # E_o at small strain
    assert slope[-2] == pytest.approx(29100.0, rel=0.01)  # E_∞ at large strain
    # Buckled transverse tows carry nothing, so the diagonals carry (almost) nothing.
    assert np.all(c.transverse_strain <= 0.0)
    assert np.max(np.abs(c.diagonal_stress_N)) < 1e-6


def _energy(law, strains):
    """Stored energy Φ(ε) = ∫σ/λ dε (σ the bar force per tow) of an elastic law, by quadrature."""
    out = []
    for ε in np.atleast_1d(strains):
        grid = np.linspace(0.0, ε, 4001)
        σ, _, _ = law.update(grid, 0.0, law.initial_state(grid.size))
        w = σ / np.sqrt(1.0 + 2.0 * grid)
        out.append(np.sum(0.5 * (w[1:] + w[:-1]) * np.diff(grid)))
    return np.array(out)


def elastic_model():
    """Path-independent laws (no rate, no plasticity), soft tows to test their terms."""
    return default_model().without_effects("rate_dependence", "tow_buckling").with_parameters(
        sigma_o=1e6, E_p=0.4, E_o=2.0, E_inf=6.0, eps_bar=0.05, alpha=60.0)


def test_bias_force_does_the_work_of_the_stored_energy():
    # ∫ f du = √2 (L_o − W_o) [2Φ_t(ε_t) + √2 (Φ_d(ε_d1) + Φ_d(ε_d2))] per tow (module doc).
    model = elastic_model()
    laws = model.laws()
    t, u = bias_ramp(40.0, strain_end=0.42, rows=3001)
    c = uc.bias_extension(model, t, u, length_mm=L0, width_mm=W0)
    work = np.sum(0.5 * (c.force_per_tow_N[1:] + c.force_per_tow_N[:-1]) * np.diff(u))
    i = -1
    stored = math.sqrt(2.0) * (L0 - W0) * (
        2.0 * _energy(laws["tow"], c.tow_strain[i])[0]
        + math.sqrt(2.0) * _energy(laws["shear"], [c.diagonal_strain[i],
                                                   c.transverse_strain[i]]).sum())
    assert abs(c.tow_strain[i]) > 1e-3  # the tow terms matter in this check
    assert work == pytest.approx(stored, rel=2e-4)


def test_tensile_force_does_the_work_of_the_stored_energy():
    # ∫ f du = L_g [Φ_t(ε_1) + Φ_t(ε_2) + 2√2 Φ_d(ε_d)] per loaded tow (module doc).
    model = elastic_model().with_parameters(E_o=50.0, E_inf=50.0, E_p=20.0)
    laws = model.laws()
    u = np.linspace(0.0, 3.0, 3001)
    c = uc.tensile(model, u, u, gauge_length_mm=100.0)
    work = np.sum(0.5 * (c.force_per_tow_N[1:] + c.force_per_tow_N[:-1]) * np.diff(u))
    stored = 100.0 * (_energy(laws["tow"], [c.tow_strain[-1], c.transverse_strain[-1]]).sum()
                      + 2.0 * math.sqrt(2.0) * _energy(laws["shear"], c.diagonal_strain[-1])[0])
    assert abs(c.transverse_strain[-1]) > 0.05 * c.tow_strain[-1]
    assert work == pytest.approx(stored, rel=2e-4)


def test_relaxation_hold_and_unloading_follow_the_history():
    model = default_model()
    t1, u1 = bias_ramp(40.0, strain_end=0.3, rows=100)
    t = np.concatenate([t1, t1[-1] + np.linspace(1, 120, 60), t1[-1] + 120 + t1[1:]])
    u = np.concatenate([u1, np.full(60, u1[-1]), u1[-1] - u1[1:] * 0.5])
    c = uc.bias_extension(model, t, u, length_mm=L0, width_mm=W0)
    hold = c.force_per_tow_N[99:160]
    assert np.all(np.diff(hold) <= 1e-9) and hold[-1] < 0.7 * hold[0]
    assert c.force_per_tow_N[-1] < hold[-1]


def test_vectorised_parameter_sets_equal_separate_runs():
    model = default_model()
    etas, eps_bar = np.array([0.8, 1.37, 2.5]), np.array([0.0012, 0.00144, 0.002])
    many = model.with_parameters(eta_o=etas, eps_bar=eps_bar)
    t, u = bias_ramp(40.0, rows=80)
    c = uc.bias_extension(many, t, u, length_mm=L0, width_mm=W0)
    ct = uc.tensile(many, t, u / 100.0, gauge_length_mm=100.0)
    assert c.force_per_tow_N.shape == (80, 3) and ct.force_per_tow_N.shape == (80, 3)
    for j in range(3):
        one = model.with_parameters(eta_o=etas[j], eps_bar=eps_bar[j])
        cj = uc.bias_extension(one, t, u, length_mm=L0, width_mm=W0)
        np.testing.assert_allclose(c.force_per_tow_N[:, j], cj.force_per_tow_N, rtol=1e-10)
        ctj = uc.tensile(one, t, u / 100.0, gauge_length_mm=100.0)
        np.testing.assert_allclose(ct.force_per_tow_N[:, j], ctj.force_per_tow_N, rtol=1e-10)


def test_tests_side_by_side_equal_each_test_alone():
    """Tests of one kind solved together (rows of unequal number and pace, a hold, other
    geometries and temperatures, several parameter sets) give each test's own curves."""
    model = default_model().with_effects("temperature_dependence", "shear_tension_coupling")
    many = model.with_parameters(eta_o=np.array([0.8, 1.37, 2.5]))
    t1, u1 = bias_ramp(10.0, rows=90)
    t2, u2 = bias_ramp(160.0, strain_end=0.3, rows=40)
    t2, u2 = np.r_[t2, t2[-1] + np.linspace(1.0, 30.0, 15)], np.r_[u2, np.full(15, u2[-1])]
    hot, warm = {"temperature_C": 50.0}, {"temperature_C": 30.0}
    runs = {
        "bias_extension": [dict(time_s=t1, displacement_mm=u1, length_mm=L0, width_mm=W0,
                                conditions=hot),
                           dict(time_s=t2, displacement_mm=0.8 * u2, length_mm=150.0,
                                width_mm=50.0, conditions=warm),
                           dict(time_s=t2, displacement_mm=u2, length_mm=L0, width_mm=W0)],
        "tensile": [dict(time_s=t1, displacement_mm=u1 / 100.0, gauge_length_mm=100.0,
                         conditions=hot),
                    dict(time_s=t2, displacement_mm=u2 / 50.0, gauge_length_mm=80.0,
                         conditions=warm)],
        "picture_frame": [dict(time_s=t1, displacement_mm=0.3 * u1, frame_side_mm=200.0,
                               fabric_side_mm=150.0, conditions=hot),
                          dict(time_s=t2, displacement_mm=0.3 * u2, frame_side_mm=145.0,
                               fabric_side_mm=145.0, conditions=warm)],
    }
    alone = {"bias_extension": uc.bias_extension, "tensile": uc.tensile,
             "picture_frame": uc.picture_frame}
    for m in (model, many):
        for kind, of_kind in runs.items():
            together = uc.curves(m, kind, of_kind)
            for run, curve in zip(of_kind, together):
                one = alone[kind](m, **run)
                assert curve.force_per_tow_N.shape == one.force_per_tow_N.shape
                for name in ("force_per_tow_N", "tow_strain", "shear_deg",
                             "transverse_strain", "diagonal_stress_N"):
                    np.testing.assert_allclose(getattr(curve, name), getattr(one, name),
                                               rtol=1e-9, atol=1e-12, err_msg=f"{kind} {name}")
                np.testing.assert_array_equal(curve.time_s, run["time_s"])


def test_shear_tension_coupling_and_temperature():
    model = default_model()
    t, u = bias_ramp(40.0, rows=80)
    base = uc.bias_extension(model, t, u, length_mm=L0, width_mm=W0).force_per_tow_N
    coupled = uc.bias_extension(model.with_effects("shear_tension_coupling"), t, u,
                                length_mm=L0, width_mm=W0).force_per_tow_N
    assert np.all(coupled[1:] > base[1:])
    hot = uc.bias_extension(model.with_effects("temperature_dependence"), t, u, length_mm=L0,
                            width_mm=W0, conditions={"temperature_C": 50.0}).force_per_tow_N
    assert np.all(hot[5:] < base[5:])


def test_diagonal_response_matches_the_law():
    model = default_model()
    t = np.linspace(0.0, 50.0, 51)
    strain = 0.005 * t
    law = build_law("paper_shear", model.parameters, model.effects)
    state, expected = law.initial_state(1), []
    for i in range(t.size):
        σ, _, state = law.update(np.array([strain[i]]), 1.0 if i else 0.0, state)
        expected.append(σ[0])
    np.testing.assert_allclose(uc.diagonal_response(model, t, strain), expected, rtol=1e-14)


def test_bad_input():
    model = default_model()
    with pytest.raises(DrapeInputError, match="not finite at row 2"):
        uc.bias_extension(model, [0, 1, 2], [0, 1, np.nan], length_mm=L0, width_mm=W0)
    with pytest.raises(DrapeInputError, match="time_s decreases at row 2"):
        uc.tensile(model, [0, 1, 0.5], [0, 0.1, 0.2], gauge_length_mm=100.0)
    with pytest.raises(DrapeInputError, match="length_mm > width_mm"):
        uc.bias_extension(model, [0, 1], [0, 1], length_mm=70.0, width_mm=70.0)
    with pytest.raises(DrapeInputError, match="gauge_length_mm"):
        uc.tensile(model, [0, 1], [0, 1], gauge_length_mm=-1.0)
    assert isinstance(model, Model)


def test_curves_command_writes_tables_and_pictures(tmp_path, capsys):
    from fenicsx_drape.cli import main

    model_toml = tmp_path / "MODEL.toml"
    model_toml.write_text(default_model().to_toml())
    assert main(["curves", "--model", str(model_toml), "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "0.001375 1/s (the paper prints 0.0013)" in printed
    assert "0.022006 1/s (the paper prints 0.022)" in printed
    for name in ("tensile.csv", "bias_extension.csv", "shear_law.csv", "provenance.json",
                 "fig6_characterisation.png", "fig2b_shear_law.png"):
        assert (tmp_path / "out" / name).stat().st_size > 100
    table = np.genfromtxt(tmp_path / "out" / "bias_extension.csv", delimiter=",", names=True,
                          skip_header=1)
    assert set(table["speed_mm_per_min"]) == {10.0, 40.0, 160.0}
    np.testing.assert_allclose(table["force_N"], table["force_per_tow_N"] * 0.713 * 70
                               / math.sqrt(2), rtol=1e-8)
    assert main(["curves", "--model", str(tmp_path / "nope.toml"), "--out",
                 str(tmp_path / "x")]) == 2


@settings(max_examples=20, deadline=None)
@given(rows=st.lists(st.tuples(st.floats(0.0, 30.0), st.floats(-10.0, 55.0)), min_size=1,
                     max_size=15),
       drop=st.sets(st.sampled_from(("rate_dependence", "strain_dependent_viscosity",
                                     "decrimping", "tow_buckling"))))
def test_any_history_gives_finite_forces(rows, drop):
    model = default_model().without_effects(*drop)
    t = np.cumsum([dt for dt, _ in rows])
    u = np.array([d for _, d in rows])
    c = uc.bias_extension(model, t, u, length_mm=L0, width_mm=W0)
    ct = uc.tensile(model, t, u / 100.0, gauge_length_mm=100.0)
    for curve in (c, ct):
        for column in (curve.force_per_tow_N, curve.tow_strain, curve.transverse_strain,
                       curve.shear_deg):
            assert np.isfinite(column).all()
