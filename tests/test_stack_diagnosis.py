"""Measurements on a stack of plies in compare and diagnose (spec version 4).

A forming measurement names the ply it was taken on (a ``<measurement>_ply`` key or a ``ply``
column) and is compared with that ply's sheet; ``interply_friction`` is an effect the
diagnosis names (a model whose plies are bonded against data formed with plies that slid);
``ply_angle_deg/<k>`` is a set-up candidate (a ply laid at the wrong angle within the stack).

The part: the hemisphere's [0/90, ±45] stack (``meshes/hemisphere/stack_0_45.toml``) on
30 mm cells, the 80 mm stroke in 8 s (a few seconds a run), the holder's μ stated in the case
so that the forming fit has nothing to fit (the runs are the candidates' own).
"""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape import runs
from fenicsx_drape.diagnosis import diagnose, setup_parameters
from fenicsx_drape.diagnosis.comparison import compare_tests, prepare, simulate
from fenicsx_drape.diagnosis.decision import setup_rules
from fenicsx_drape.diagnosis.kinds import kind_of
from fenicsx_drape.diagnosis.kinds.forming import fit_forming, forming_case_of, forming_parameters
from fenicsx_drape.diagnosis.setup_stage import fit_setup
from fenicsx_drape.diagnosis.synthetic import synthetic_case_test, write_case_bundle
from fenicsx_drape.forming.case.format import PlySpec, case_for_test, load_case
from fenicsx_drape.measurements.bundle import Bundle, BundleError, Test, load_bundle, write_bundle
from fenicsx_drape.model import default_model

pytestmark = pytest.mark.skip_in_parallel  # serial runs (on ranks: test_forming_stack_parallel)
STACK = Path(__file__).parents[1] / "meshes" / "hemisphere" / "stack_0_45.toml"
SLIDING = default_model().with_effects("interply_friction")
BONDED = default_model()  # a model of the paper's effects: its plies move together


def stack_case(angles=(0.0, 45.0)):
    case = load_case(STACK, cell_mm=30.0, duration_s=8.0, mu=0.3)
    return dataclasses.replace(case, plies=tuple(PlySpec(a, 0.3) for a in angles))


def write(folder, model, case, plies=(None,), seed=0):
    """A bundle of grids "measured" on the given plies (None: no ply named), 0.3 mm noise."""
    tests = [synthetic_case_test(model, case, test_id=f"ply{k or 'n'}", ply=k,
                                    seed=seed + i) for i, k in enumerate(plies)]
    return write_case_bundle("stack", tests, folder)


def load(folder):
    return load_bundle(folder, read_case=case_for_test)


def test_a_run_keeps_every_ply_and_a_single_ply_ignores_interply_friction():
    (sheet,) = runs.form_many([(stack_case(), SLIDING)])
    assert len(sheet.plies) == 2 and sheet.ply(None) is sheet and sheet.ply(2) is sheet.plies[1]
    # The plies differ: the 45° ply shears more (measured 25.8° against 22.6°).
    assert np.nanmax(np.abs(sheet.ply(2).shear_deg())) > np.nanmax(
        np.abs(sheet.ply(1).shear_deg())) + 2.0
    with pytest.raises(Exception, match="ply 3"):
        sheet.ply(3)
    # On one ply the effect changes nothing: its runs are the model's without it.
    single = load_case("hemisphere", cell_mm=30.0)
    assert runs.key_of(single, SLIDING) == runs.key_of(single, BONDED)
    assert runs.key_of(stack_case(), SLIDING) != runs.key_of(stack_case(), BONDED)


def without_film(case):
    """The stack's case without [interply]'s η_f: the model's acts (interply_friction's)."""
    return dataclasses.replace(case, interply=tuple(
        (k, v) for k, v in case.interply if k != "eta_f_MPa_s_per_mm"))


def test_the_model_gives_the_inter_ply_values_the_case_leaves_out():
    """μ_ply and η_f are interply_friction's parameters: a model has them with the effect, and
    they act where the case's [interply] table does not give them (the table's value wins)."""
    assert "mu_ply" not in BONDED.parameters and SLIDING.parameters["mu_ply"] == 0.2
    assert SLIDING.parameters["eta_f_MPa_s_per_mm"] == 0.002
    thick = SLIDING.with_parameters(mu_ply=0.35, eta_f_MPa_s_per_mm=0.006)
    case, free = stack_case(), without_film(stack_case())
    assert case.interply_law(thick).mu_ply == 0.2  # given by the case
    assert case.interply_law(thick).eta_f_MPa_s_per_mm == 0.002
    assert free.interply_law(thick).eta_f_MPa_s_per_mm == 0.006  # left to the model
    assert free.interply_law(thick).mu_ply == 0.2
    # A run depends on the model's value only where it acts.
    assert runs.key_of(case, thick) == runs.key_of(case, SLIDING)
    assert runs.key_of(free, thick) != runs.key_of(free, SLIDING)
    single = load_case("hemisphere", cell_mm=30.0)
    assert runs.key_of(single, thick) == runs.key_of(single, BONDED)
    assert forming_parameters(SLIDING) == ("mu", "mu_ply", "eta_f_MPa_s_per_mm")
    assert forming_parameters(BONDED) == ("mu",)


@pytest.mark.bench  # 60 CPU-s: make bench
def test_the_forming_fit_fits_the_film_the_case_leaves_to_the_model(tmp_path):
    """Grids on both plies of a stack formed with η_f = 0.006 MPa·s/mm, the case giving μ_ply
    and the holder's μ but not η_f: the forming fit, from the model's 0.002, finds it."""
    case = without_film(stack_case())
    truth = SLIDING.with_parameters(eta_f_MPa_s_per_mm=0.006)
    write(tmp_path, truth, case, plies=(1, 2))
    bundle = load(tmp_path)
    bundle = dataclasses.replace(bundle, tests=tuple(
        dataclasses.replace(t, forming_case=case) for t in bundle.tests))
    # The model's μ_ply does not act (the case gives 0.2): the fitted model carries the case's.
    fitted = fit_forming(bundle, SLIDING.with_parameters(mu_ply=0.35), kind_of=kind_of)
    assert fitted.parameters["mu_ply"] == 0.2
    # Measured: 0.00644 (from the scan's 0.008, cost 3.2, to 1.87; 80 at the model's 0.002).
    assert fitted.parameters["eta_f_MPa_s_per_mm"] == pytest.approx(0.006, rel=0.15)


def test_a_measurement_is_compared_with_the_ply_it_names(tmp_path):
    case = stack_case()
    write(tmp_path, SLIDING, case, plies=(1, None))
    bundle = load(tmp_path)
    tests = {t.id: t for t in bundle.tests}
    assert tests["ply1"].ply == 1 and tests["plyn"].ply is None
    assert any("'plyn'" in n and "outermost ply" in n and "ply 2" in n for n in bundle.notes)
    # Each grid against the model it was formed with, on its own ply: at the noise (0.3 mm).
    chosen, notes = prepare(bundle)  # the report's notes say which ply was taken
    assert notes == ["test 'plyn': no ply named; compared with the outermost ply away from the "
                     "punch (ply 2)"]
    values = simulate(chosen, SLIDING)
    for c in compare_tests(chosen, values):
        assert c.normalised == pytest.approx(1.0, abs=0.2), c.id
    # Read on the other ply, the same grid misses by far more than its noise.
    other = dataclasses.replace(tests["plyn"], ply=1)
    (wrong,) = compare_tests([other], simulate([other], SLIDING))
    assert wrong.normalised > 5.0

    # A ply column: rows of both plies in one table, one test per ply.
    (ply1,) = [t for t in bundle.tests if t.id == "ply1"]
    (plyn,) = [t for t in bundle.tests if t.id == "plyn"]
    both = {c: np.concatenate([ply1.columns[c], plyn.columns[c]]) for c in plyn.columns}
    both["ply"] = np.repeat([1.0, 2.0], [ply1.n_rows, plyn.n_rows])
    mixed = dataclasses.replace(plyn, id="mixed", file="mixed.csv", columns=both, ply=None)
    write_bundle(Bundle(name="stack", tests=(mixed,)), tmp_path)
    split = load(tmp_path).tests
    assert [(t.id, t.ply, t.n_rows) for t in split] == [
        ("mixed/file/ply1", 1, ply1.n_rows), ("mixed/file/ply2", 2, plyn.n_rows)]
    for c in compare_tests(split, simulate(split, SLIDING)):
        assert c.normalised == pytest.approx(1.0, abs=0.2), c.id

    # A ply the stack does not have is bad input, with the file and line.
    text = (tmp_path / "mixed.csv").read_text().splitlines()
    header = text.index(next(line for line in text if line.startswith("i,")))
    cells = text[header + 1].split(",")
    cells[text[header].split(",").index("ply")] = "3"
    text[header + 1] = ",".join(cells)
    (tmp_path / "mixed.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(BundleError, match=rf"mixed.csv:{header + 2}: .*ply = 3 must be a ply"):
        load(tmp_path)
    toml = (tmp_path / "bundle.toml").read_text()
    (tmp_path / "bundle.toml").write_text(toml.replace('kind = "forming"',
                                                       'kind = "forming"\nfile_ply = 0'))
    with pytest.raises(BundleError, match="file_ply = 0 must be a ply of the stack, 1"):
        load(tmp_path)


@pytest.mark.slow
def test_a_bonded_model_against_plies_that_slid_names_interply_friction(tmp_path):
    """The data: the stack formed with its plies sliding under the case's [interply] law,
    measured on both plies. The model: the paper's effects, its plies bonded.

    Only interply_friction is tried, and shear_tension_coupling, which a stack cannot take
    (its coupling needs one structured net): it is untestable, not a crash. The others would
    each form the stack again; the default path on the same data is the bench test below.
    """
    write(tmp_path, SLIDING, stack_case(), plies=(1, 2))
    report = diagnose(load(tmp_path), BONDED,
                      candidates=["interply_friction", "shear_tension_coupling"])
    (refused,) = report["untestable"]
    assert refused["effect"] == "shear_tension_coupling"
    assert "cannot be formed" in refused["reason"] and "structured" in refused["reason"]
    assert report["baseline"]["error"]["normalised"] > 5.0
    (candidate,) = report["candidates"]
    assert candidate["effect"] == "interply_friction" and candidate["significant"]
    assert candidate["error_after"]["normalised"] == pytest.approx(1.0, abs=0.2)
    assert report["missing_effect"] == "interply_friction"


@pytest.mark.bench
def test_the_default_diagnosis_of_a_stack_names_interply_friction_and_no_set_up_error(
        tmp_path):
    """The test above on the path a user takes: every candidate of the catalogue and the
    set-up stage with its default parameters (the stack's angle, each ply's, the holder's μ,
    ...). Marked bench: every candidate and set-up scan forms the stack again (minutes)."""
    write(tmp_path, SLIDING, stack_case(), plies=(1, 2))
    report = diagnose(load(tmp_path), BONDED)
    assert report["missing_effect"] == "interply_friction"
    assert report.get("setup_error") is None
    best = max(report["candidates"], key=lambda c: c.get("evidence", -np.inf))
    assert best["effect"] == "interply_friction" and best["significant"]
    assert best["error_after"]["normalised"] == pytest.approx(1.0, abs=0.3)


def turned_ply_bundle(folder):
    """The [0/90, ±45] stack with its second ply laid at 51° (6° off), measured on both plies;
    the bundle states the case's 45°."""
    write(folder, SLIDING, stack_case((0.0, 51.0)), plies=(1, 2))
    bundle = load(folder)
    return dataclasses.replace(bundle, tests=tuple(
        dataclasses.replace(t, forming_case=stack_case()) for t in bundle.tests))


def test_the_set_up_stage_reads_each_plys_angle_of_a_stack():
    """The names the stage adds on a stack, their stated values and the case each one forms.

    The fit itself is the bench test below (it forms the stack 26 times); the stage's fit of a
    turned ply runs in ``make test`` on one ply (test_setup_diagnosis.py).
    """
    # Tests as the turned-ply bundle's (each ply measured, the stated case named), their
    # grids unformed: what is checked here is read off the case, not off a run.
    X0 = np.array([[0.0, 0.0], [30.0, 0.0], [0.0, 30.0]])
    columns = {"i": np.arange(3.0), "j": np.zeros(3), "x0_mm": X0[:, 0], "y0_mm": X0[:, 1],
               "x_mm": X0[:, 0], "y_mm": X0[:, 1], "z_mm": np.zeros(3),
               "position_sd_mm": np.full(3, 0.3)}
    tests = setup_parameters.forming_tests(Bundle("stack", tuple(
        Test(id=f"ply{k}", kind="forming", file=f"ply{k}.csv", columns=columns,
             case="case/case.toml", forming_case=stack_case(), ply=k) for k in (1, 2))))
    assert setup_parameters.setup_names(["ply_angle_deg", "mu"], tests) == [
        "ply_angle_deg", "ply_angle_deg/1", "ply_angle_deg/2", "mu"]
    assert setup_parameters.stated(tests[0], "ply_angle_deg/2", SLIDING) == 45.0
    assert setup_parameters.stated(tests[0], "ply_angle_deg/1", SLIDING) == 0.0
    # A ply's angle is scanned wider than the whole stack's (a ply laid 10° off, or more).
    assert setup_parameters.SCAN["ply_angle_deg/2"] == (-10.0, -4.0, 4.0, 10.0)
    assert setup_parameters.SCAN["ply_angle_deg"] == (-4.0, 4.0)
    assert setup_parameters.STEP["ply_angle_deg/2"] == setup_parameters.STEP["ply_angle_deg"]
    turned, _ = setup_parameters.applied(tests[0], "ply_angle_deg/2", [6.0], SLIDING)
    assert [p.angle_deg for p in forming_case_of(turned).plies] == [0.0, 51.0]
    # The whole stack turned: the blank's angle, the plies' own angles kept within it.
    whole = forming_case_of(setup_parameters.applied(tests[0], "ply_angle_deg", [6.0], SLIDING)[0])
    assert whole.blank.ply_angle_deg == 6.0
    assert [p.angle_deg for p in whole.plies] == [0.0, 45.0]


@pytest.mark.bench
def test_a_ply_turned_within_the_stack_is_named_by_the_set_up_stage(tmp_path):
    """The set-up stage tries each ply's angle on the turned-ply bundle; the stack's own angle
    and the other set-up parameters are left out here (each forms the whole stack again; the
    stage's default path on a stack is the bench test above). Marked ``bench``: 26 runs of the
    stack, 2 min on two cores (with 2 mm steps instead of 1 the scan finds nothing to gain)."""
    stated = turned_ply_bundle(tmp_path)
    stage = fit_setup(stated, SLIDING, setup_rules(),
                         parameters=["ply_angle_deg/1", "ply_angle_deg/2"])
    assert stage.setup_error == "ply_angle_deg/2"
    best = stage.entries[0]
    assert best["parameter"] == "ply_angle_deg/2" and best["significant"]
    # Measured: 50.5 ± 0.7°, normalised 2.5 from the stated 18.1, evidence 7.3 (26 runs).
    assert best["fitted"] == pytest.approx(51.0, abs=max(1.0, 2 * best["sd"]))
    # The turned ply's net is clipped to the blank cell by cell: the fit leaves more than the
    # noise, but most of the stated set-up's error goes.
    assert best["error_after"]["normalised"] < 0.5 * stage.stated_heldout_normalised
    assert stage.entries[1]["heldout_normalised"] > 1.5 * best["heldout_normalised"]
