"""A candidate's refit reaches the truth when the truth is the candidate (forming tests only).

Two trials of the paper's hemisphere at different speeds, formed with the paper's model on the
coarse 20 mm net and "measured" on it: the forming fit, handed ``rate_dependence``'s own
parameters, moves a wrong η_o back to the truth's; and the diagnosis's steps for that
candidate, from the paper's model less the effect (μ fitted as a baseline is), reach the
truth's own error.
"""

import pytest

from fenicsx_drape import runs
from fenicsx_drape.measurements.bundle import Bundle

DURATIONS_S = (2.0, 240.0)  # a fast and a slow trial: the viscous branch tells them apart


@pytest.fixture(scope="module")
def trials():
    """The two trials, formed by the paper's model, with and without noise."""
    pytest.importorskip("dolfinx")  # the forming runs need DOLFINx
    from fenicsx_drape.diagnosis.synthetic import synthetic_forming_test
    from fenicsx_drape.model import default_model

    truth = default_model()
    with runs.resolution(runs.SCREEN_CELL_MM):
        exact = [synthetic_forming_test(truth, test_id=f"dome-{d:g}s", duration_s=d,
                                        sd_mm=1e-3, seed=i, cell_mm=runs.SCREEN_CELL_MM)
                 for i, d in enumerate(DURATIONS_S)]
        noisy = [synthetic_forming_test(truth, test_id=f"dome-{d:g}s", duration_s=d,
                                        sd_mm=0.3, seed=10 + i, cell_mm=runs.SCREEN_CELL_MM)
                 for i, d in enumerate(DURATIONS_S)]
    return truth, Bundle(name="exact", tests=tuple(exact)), Bundle(name="noisy",
                                                                    tests=tuple(noisy))


@pytest.mark.bench  # 80 CPU-s: make bench
def test_forming_fit_moves_a_candidates_own_parameter_back_to_the_truth(trials):
    from fenicsx_drape.diagnosis.refits import fit

    truth, exact, _ = trials
    wrong = truth.with_parameters(eta_o=3.0 * truth.parameters["eta_o"])
    with runs.resolution(runs.SCREEN_CELL_MM):
        held = fit(exact, wrong, parameters=("eta_o",), max_iterations=40)
        moved = fit(exact, wrong, parameters=("eta_o",), own=("eta_o",), max_iterations=40)
    assert held.parameters["eta_o"] == wrong.parameters["eta_o"]  # the friction only
    # Noise-free data of the same net: the truth is the fit's minimum (to the solver's
    # tolerance); from 3 × the truth, within 5 %.
    assert moved.parameters["eta_o"] == pytest.approx(truth.parameters["eta_o"], rel=0.05)
    assert moved.parameters["mu"] == pytest.approx(truth.parameters["mu"], abs=0.02)


@pytest.mark.bench  # 86 CPU-s: make bench
def test_candidates_refit_reaches_the_truths_own_error(trials):
    """The diagnosis's steps for rate_dependence, from the model less it (μ fitted)."""
    from fenicsx_drape.calibration.coupons import declare_noise
    from fenicsx_drape.diagnosis.comparison import normalised_error, simulate
    from fenicsx_drape.diagnosis.decision import BASELINE_ITERATIONS
    from fenicsx_drape.diagnosis.pipeline import prepare_tests
    from fenicsx_drape.diagnosis.refits import (
        REFIT_ITERATIONS,
        best_start,
        fit,
        no_worse,
        refit_parameters,
    )

    truth, _, noisy = trials
    given = truth.without_effects("rate_dependence")
    data = prepare_tests(declare_noise(noisy, given.noise))

    def error(model):
        return normalised_error(data.compare(simulate(data.tests, model)))

    with runs.resolution(runs.SCREEN_CELL_MM):
        target = error(fit(noisy, truth, max_iterations=BASELINE_ITERATIONS,
                           from_features=True))
        base = fit(noisy, given, max_iterations=BASELINE_ITERATIONS, from_features=True)
        assert error(base) > 1.5 * target  # the effect shows: the test is not vacuous
        start_model = base.with_effects("rate_dependence")
        names = refit_parameters(start_model, "rate_dependence")  # the shear law's too
        own = ("eta_o", "E_v")
        start = best_start(data, start_model, own, names, stated=given)
        refit = no_worse(data, fit(noisy, start, parameters=names, own=own,
                                   max_iterations=REFIT_ITERATIONS), start)
        assert error(refit) <= 1.1 * target
