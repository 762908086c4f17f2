"""Inter-ply friction tests in a bundle (spec version 4) and their fit (calibration/interply.py)."""

import numpy as np
import pytest

from fenicsx_drape.calibration.interply import fit_interply, simulate_interply
from fenicsx_drape.cli import main
from fenicsx_drape.materials.interply import InterplyLaw
from fenicsx_drape.measurements.bundle import BundleError, load_bundle

TRUE = InterplyLaw(tau0_MPa=0.004, mu_ply=0.22, eta_f_MPa_s_per_mm=0.003, slip_mm=0.1)
TESTS = [(p, v) for p in (50.0, 200.0) for v in (10.0, 100.0)]  # kPa, mm/min


class _History:
    """The parts of a test that the simulation reads."""

    def __init__(self, t, d, p):
        self.time_s, self.displacement_mm = t, d
        self.interply = {"contact_length_mm": 100.0, "contact_width_mm": 50.0,
                         "interfaces": 2, "pressure_kPa": p}

    def column(self, name):
        return None


def write_bundle(folder, law=TRUE, noise=0.0):
    """Pull-out tests at two pressures and two speeds, simulated with ``law`` (+ noise, N)."""
    folder.mkdir(exist_ok=True)
    rng = np.random.default_rng(7)
    lines = ['[bundle]\nname = "ipf"\n']
    for p, v in TESTS:
        name = f"ipf_{p:g}kPa_{v:g}"
        t = np.linspace(0.0, 3.0 * 60.0 / v, 61)  # 3 mm of pulling
        d = v / 60.0 * t
        lines.append(f'[[test]]\nid = "{name}"\nkind = "interply_friction"\nfile = "{name}.csv"\n'
                     f"contact_length_mm = 100.0\ncontact_width_mm = 50.0\ninterfaces = 2\n"
                     f"pressure_kPa = {p}\nspeed_mm_per_min = {v}\n"
                     + (f"force_sd_N = {noise}\n" if noise else "")
                     + "ply_angles_deg = [0.0, 45.0]\n[test.conditions]\ntemperature_C = 60.0\n")
        f = simulate_interply(_History(t, d, p), law) + noise * rng.standard_normal(len(t))
        rows = "\n".join(f"{a:.9g},{b:.9g},{c:.9g}" for a, b, c in zip(t, d, f))
        (folder / f"{name}.csv").write_text("time_s,displacement_mm,force_N\n" + rows + "\n")
    (folder / "bundle.toml").write_text("\n".join(lines))
    return folder


def test_the_steady_force_is_the_pull_out_answer(tmp_path):
    """The simulated test settles at F = 2 A (τ₀ + μ p + η_f v) (ten Thije & Akkerman 2009)."""
    bundle = load_bundle(write_bundle(tmp_path / "b"))
    for test in bundle.tests:
        p, v = test.interply["pressure_kPa"] / 1000.0, test.speed_mm_per_min / 60.0
        exact = 2 * 5000.0 * (0.004 + 0.22 * p + 0.003 * v)
        assert test.force_N[-1] == pytest.approx(exact, rel=1e-6)
        assert test.interply["ply_angles_deg"] == [0.0, 45.0]
        assert test.conditions == {"temperature_C": 60.0}


def test_the_fit_finds_the_law_that_made_the_curves(tmp_path):
    bundle = load_bundle(write_bundle(tmp_path / "b", noise=0.5))
    result = fit_interply(bundle.tests)
    assert result.law.tau0_MPa == pytest.approx(0.004, rel=0.02)
    assert result.law.mu_ply == pytest.approx(0.22, rel=0.01)
    assert result.law.eta_f_MPa_s_per_mm == pytest.approx(0.003, rel=0.02)
    assert result.held == {}
    assert 0.8 < result.normalised < 1.2  # the residuals are the declared noise


def test_one_pressure_holds_the_tack(tmp_path):
    bundle = load_bundle(write_bundle(tmp_path / "b"))
    one = [t for t in bundle.tests if t.interply["pressure_kPa"] == 200.0]
    result = fit_interply(one)
    assert "tau0_MPa" in result.held
    assert result.law.eta_f_MPa_s_per_mm == pytest.approx(0.003, rel=0.02)


@pytest.mark.parametrize("old, new, message", [
    ("interfaces = 2", "interfaces = 3", "interfaces = 3 must be 2"),
    ("contact_width_mm = 50.0\n", "", "needs contact_width_mm"),
    ("pressure_kPa = 50.0", "pressure_MPa = 0.05", "pressure_MPa"),
    ("ply_angles_deg = [0.0, 45.0]", 'ply_angles_deg = "0/45"', "ply_angles_deg"),
])
def test_a_bad_interply_test_names_the_key(tmp_path, old, new, message):
    folder = write_bundle(tmp_path / "b")
    text = (folder / "bundle.toml").read_text()
    (folder / "bundle.toml").write_text(text.replace(old, new, 1))
    with pytest.raises(BundleError, match=message):
        load_bundle(folder)


def test_drape_fit_fits_interply_tests(tmp_path, capsys):
    write_bundle(tmp_path / "b", noise=0.5)
    assert main(["fit", str(tmp_path / "b"), "--out", str(tmp_path / "fit")]) == 0
    text = (tmp_path / "fit" / "interply.toml").read_text()
    assert "[interply]" in text and "mu_ply = 0.2" in text
    assert (tmp_path / "fit" / "interply.json").stat().st_size > 0
    printed = capsys.readouterr().out
    assert "inter-ply friction" in printed
    # The printout names each value as interply.toml (and a case's [interply]) does.
    for key in ("tau0_MPa", "mu_ply", "eta_f_MPa_s_per_mm"):
        assert f"{key} = " in text and f"{key} = " in printed, key
