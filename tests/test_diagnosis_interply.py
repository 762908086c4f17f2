"""Inter-ply friction tests compared and diagnosed (diagnosis/kinds/interply_friction.py).

The bundle is written here from the pull-out's closed form: a ply pulled at constant speed v
between two others under a pressure p carries F = 2A (τ₀ + μ p) min(d/ε, 1) + 2A η_f v (the
steady F = 2A (τ₀ + μp + η_f v) of ten Thije & Akkerman 2009 once the slip d passes the
law's regularisation ε; the film term from the first step on), with Gaussian noise.
"""

import json

import numpy as np
import pytest

from fenicsx_drape.cli import main
from fenicsx_drape.diagnosis import compare, diagnose
from fenicsx_drape.diagnosis.kinds import INTERPLY_FRICTION, KINDS, kind_of
from fenicsx_drape.diagnosis.kinds.interply_friction import table_problems
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.measurements.bundle import BundleError, load_bundle
from fenicsx_drape.model import Model

AREA_MM2 = 100.0 * 50.0  # the overlap
EPS_MM = 0.1  # the law's regularisation slip (InterplyLaw.slip_mm's default)
TRUE = {"tau0_MPa": 0.004, "mu_ply": 0.22, "eta_f_MPa_s_per_mm": 0.003}
NOISE_N = 0.5  # one standard deviation of the force (N)
# Fitted within: about 7 standard errors of each over the noise (seeds 1, 2, 3, 7 give at
# most 0.3 %, 0.02 %, 0.2 %): τ₀ adds 40 N to forces of 150-530 N, μ 110-440 N, η_f 5-50 N.
TOLERANCE = {"tau0_MPa": 0.02, "mu_ply": 0.002, "eta_f_MPa_s_per_mm": 0.01}
BONDED, SLIDING = Model(effects=()), Model(effects=("interply_friction",))


def pull_out_force(t, p_kPa, v_mm_per_min, values=TRUE):
    """The pull-out's force (N) at times ``t`` (module doc)."""
    d = v_mm_per_min / 60.0 * t
    coulomb = values["tau0_MPa"] + values["mu_ply"] * p_kPa / 1000.0
    film = values["eta_f_MPa_s_per_mm"] * v_mm_per_min / 60.0
    return 2 * AREA_MM2 * (coulomb * np.minimum(d / EPS_MM, 1.0) + film * (t > 0))


def write_bundle(folder, seed=7, rows=41):
    """Two pressures × two speeds, 3 mm of pulling each, with the noise in ``force_sd_N``."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    toml = ['[bundle]\nname = "pull-outs"\n']
    for p in (50.0, 200.0):
        for v in (10.0, 100.0):
            name = f"ipf_{p:g}kPa_{v:g}"
            t = np.linspace(0.0, 3.0 * 60.0 / v, rows)
            f = pull_out_force(t, p, v) + NOISE_N * rng.standard_normal(t.size)
            toml.append(f'[[test]]\nid = "{name}"\nkind = "interply_friction"\n'
                        f'file = "{name}.csv"\ncontact_length_mm = 100.0\n'
                        f"contact_width_mm = 50.0\ninterfaces = 2\npressure_kPa = {p}\n"
                        f"speed_mm_per_min = {v}\n")
            table = "\n".join(f"{a:.9g},{v / 60.0 * a:.9g},{b:.9g},{NOISE_N}"
                              for a, b in zip(t, f))
            (folder / f"{name}.csv").write_text(
                "time_s,displacement_mm,force_N,force_sd_N\n" + table + "\n")
    (folder / "bundle.toml").write_text("\n".join(toml))
    return folder


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    return load_bundle(write_bundle(tmp_path_factory.mktemp("pull-outs")))


def test_the_kind_is_registered_and_simulates_the_closed_form(bundle):
    assert INTERPLY_FRICTION in KINDS and "interply_friction" in {k.test_kind for k in KINDS}
    model = SLIDING.with_parameters(**TRUE)
    for test in bundle.tests:
        assert kind_of(test) is INTERPLY_FRICTION
        p, v = test.interply["pressure_kPa"], test.speed_mm_per_min
        exact = pull_out_force(test.time_s, p, v)
        assert INTERPLY_FRICTION.simulate(test, model) == pytest.approx(exact, rel=1e-9,
                                                                         abs=1e-9)
        assert INTERPLY_FRICTION.noise(test) == (pytest.approx(NOISE_N), "force_sd_N")
        # two parameter sets at once (a candidate's starts): each its own force
        both = INTERPLY_FRICTION.simulate(test, model.with_parameters(
            mu_ply=np.array([0.22, 0.0])))
        assert both.shape == (2, test.n_rows)
        assert both[0] == pytest.approx(exact)
        assert both[1] == pytest.approx(pull_out_force(test.time_s, p, v,
                                                       {**TRUE, "mu_ply": 0.0}))


def test_a_bonded_model_pulls_with_the_bond_force(bundle):
    """Bonded plies cannot slide: the force is the bond's, n A k_b d (the module's choice)."""
    test = bundle.tests[0]
    force = INTERPLY_FRICTION.simulate(test, BONDED)
    assert force == pytest.approx(2 * AREA_MM2 * 1e4 * test.displacement_mm)
    assert force[-1] > 1e5 * test.force_N[-1]


def test_compare_fits_the_inter_ply_law(bundle):
    """The fit finds τ₀, μ and η_f that made the curves, within TOLERANCE, at the noise."""
    result = compare(bundle, SLIDING)
    for name, value in TRUE.items():
        assert result.model.parameters[name] == pytest.approx(value, rel=TOLERANCE[name])
    # 4 × 41 rows of noise 0.5 N, 3 parameters fitted: the residual is the noise
    assert 0.8 < result.normalised < 1.2
    sliding = result.metrics["ipf_200kPa_100"]
    steady = 2 * AREA_MM2 * (0.004 + 0.22 * 0.2 + 0.003 * 100 / 60)
    assert sliding["model_sliding_shear_stress_MPa"] == pytest.approx(
        steady / (2 * AREA_MM2), rel=1e-3)
    assert [r.says for r in INTERPLY_FRICTION.regions(bundle.tests[0])] == [
        "onset (sticking, friction building up)", "sliding (friction plateau)"]


def test_diagnose_names_interply_friction_for_a_bonded_model(bundle):
    report = diagnose(bundle, BONDED)
    assert report["missing_effect"] == "interply_friction"
    best = report["candidates"][0]
    assert best["effect"] == "interply_friction" and best["significant"]
    assert best["error_after"]["normalised"] < 1.2
    for name, value in TRUE.items():
        assert best["parameters"][name] == pytest.approx(value, rel=TOLERANCE[name])
    # no other effect changes a pull-out
    assert {u["effect"] for u in report["untestable"]} >= {"rate_dependence", "tool_friction"}


def test_diagnose_names_nothing_for_the_right_model(bundle):
    report = diagnose(bundle, SLIDING)
    assert report["missing_effect"] is None
    assert report["candidates"] == []
    assert report["baseline"]["error"]["normalised"] < 1.2


def test_the_cli_diagnoses_a_bundle_of_pull_outs(tmp_path):
    folder = write_bundle(tmp_path / "b")
    (tmp_path / "bonded.toml").write_text("effects = []\n")
    out = tmp_path / "report.json"
    assert main(["diagnose", str(folder), "--model", str(tmp_path / "bonded.toml"),
                 "--json", str(out)]) == 0
    assert json.loads(out.read_text())["missing_effect"] == "interply_friction"


def _without_force(header, rows):
    return header.replace("force_N,", ""), [r[:2] + r[3:] for r in rows]


def _nan_force(header, rows):
    rows[4][2] = "nan"  # row 5: line 6
    return header, rows


def _negative_pressure(header, rows):
    return header + ",pressure_kPa", [[*r, "-5" if i == 6 else "50"]
                                      for i, r in enumerate(rows)]


@pytest.mark.parametrize(("change", "line", "says"), [
    (_without_force, 1, "missing column(s) force_N"),
    (_nan_force, 6, "column force_N: 'nan' is not a finite number"),
    (_negative_pressure, 8, "column pressure_kPa: -5 kPa is negative"),
], ids=["missing column", "NaN", "negative pressure"])
def test_a_malformed_table_is_refused_naming_its_file(tmp_path, capsys, change, line, says):
    """The file, its line and the column, when read and from the command line (exit 2)."""
    folder = write_bundle(tmp_path / "b")
    csv = folder / "ipf_50kPa_10.csv"
    header, *rows = csv.read_text().splitlines()
    header, rows = change(header, [r.split(",") for r in rows])
    csv.write_text("\n".join([header, *(",".join(r) for r in rows)]) + "\n")
    with pytest.raises(BundleError) as err:
        load_bundle(folder)
    assert f"{csv}:{line}:" in str(err.value) and says in str(err.value)
    (tmp_path / "m.toml").write_text('effects = ["interply_friction"]\n')
    assert main(["compare", str(folder), "--model", str(tmp_path / "m.toml"),
                 "--out", str(tmp_path / "cmp")]) == 2
    assert f"{csv}:{line}:" in capsys.readouterr().err


def test_the_kind_refuses_a_table_made_in_code(bundle):
    """A test built without the reader: its table checked by the kind, named by file and row."""
    import dataclasses

    test = bundle.tests[0]
    force = np.array(test.force_N)
    force[3] = np.nan
    time = np.array(test.time_s)
    time[7] = time[6]
    bad = dataclasses.replace(test, columns={**test.columns, "force_N": force})
    assert table_problems(bad) == [f"{test.file}: test {test.id!r}: row 4, column force_N: "
                                   "nan is not a finite number (1 such row(s))"]
    late = dataclasses.replace(test, columns={**test.columns, "time_s": time})
    (problem,) = table_problems(late)
    assert problem.startswith(f"{test.file}: test {test.id!r}: row 8, column time_s")
    with pytest.raises(DrapeInputError, match="row 4, column force_N"):
        INTERPLY_FRICTION.simulate(bad, SLIDING)


def test_the_docs_commands_on_the_demo_bundle(tmp_path):
    """docs/laminates.md's two commands on demos/bundles/pull-outs (its stated numbers)."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    folder = root / "demos" / "bundles" / "pull-outs"
    assert main(["compare", str(folder), "--model",
                 str(root / "demos" / "models" / "with_interply_friction.toml"),
                 "--out", str(tmp_path / "cmp")]) == 0
    compared = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert compared["error"]["normalised"] == pytest.approx(1.05, abs=0.005)
    assert {n: compared["model"]["parameters"][n] for n in TRUE} == pytest.approx(
        {"mu_ply": 0.2200, "eta_f_MPa_s_per_mm": 0.003002, "tau0_MPa": 0.004003}, rel=5e-4)
    out = tmp_path / "report.json"
    assert main(["diagnose", str(folder), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["missing_effect"] == "interply_friction"
    best = report["candidates"][0]
    assert best["error_after"]["normalised"] == pytest.approx(1.05, abs=0.005)
    assert best["heldout_normalised"] == pytest.approx(1.11, abs=0.005)
    assert best["parameters"] == pytest.approx(
        {"mu_ply": 0.2200, "eta_f_MPa_s_per_mm": 0.003002, "tau0_MPa": 0.004003}, rel=5e-4)
