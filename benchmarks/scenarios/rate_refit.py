"""Why does the rate_dependence refit stop short of the truth? (a study, not a test)

Makes the two-trial double-dome bundle of the scenario generator — the paper's model at
Table 2 formed at 8 s and 240 s on the case's 10 mm net (2 mm steps), the lab's STL copy of
the tools, shear at cell centres along measuring lines (1°) and the blank's edge (0.3 mm),
noise stated by keys, the holder's μ not stated (the baseline fits it) — and follows the
diagnosis's refit of ``rate_dependence`` step by step with the model less that effect: the
baseline's fit, the candidate's starts and their costs, its refit, against the truth's own
error on the same net.

    ./drape exec python3 benchmarks/scenarios/rate_refit.py [--work DIR] [--full]

``--full`` also runs the README's command on the bundle (default options).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))

import generate


def make(work: Path) -> Path:
    folder = work / "dd-rate"
    if not (folder / "truth.json").is_file():
        generate.small(folder, work / "truths", "effect", "rate_dependence", seed=3,
                       part="double_dome", case_cell=10.0, case_step=2.0,
                       kinds=["shear", "edge"], shear_mode="cells",
                       noise={"shear_sd_deg": 1.0, "position_sd_mm": 0.3},
                       trials=[{"duration_s": 8.0}, {"duration_s": 240.0}],
                       stated_mu=None)
    return folder


def follow(folder: Path) -> dict:
    """The diagnosis's own steps for the rate_dependence candidate, each with its numbers."""
    from fenicsx_drape.calibration.coupons import declare_noise
    from fenicsx_drape.diagnosis import refits
    from fenicsx_drape.diagnosis.comparison import normalised_error, simulate
    from fenicsx_drape.diagnosis.decision import BASELINE_ITERATIONS
    from fenicsx_drape.diagnosis.pipeline import prepare_tests
    from fenicsx_drape.forming.case.format import case_for_test
    from fenicsx_drape.measurements.bundle import load_bundle
    from fenicsx_drape.model import default_model, load_model

    bundle = load_bundle(folder / "bundle", read_case=case_for_test)
    given = load_model(folder / "model.toml")
    data = prepare_tests(declare_noise(bundle, given.noise))
    out: dict = {}

    def error(model, label: str) -> float:
        compared = data.compare(simulate(data.tests, model))
        e = normalised_error(compared)
        shown = {k: round(float(model.parameters[k]), 4) for k in
                 ("mu", "eta_o", "E_v", "s_o", "s_inf", "sigma_o", "E_p")
                 if k in model.active_parameters()}
        per = {c.id: round(c.rmse / c.noise, 3) for c in compared}
        print(f"{label}: normalised {e:.3f} {per} at {shown}", flush=True)
        out[label] = {"normalised": e, "per_test": per, "parameters": shown}
        return e

    truth = default_model()
    error(truth, "the truth's model, as formed (mu 0.3)")
    fitted_truth = refits.fit(data.bundle, truth, max_iterations=BASELINE_ITERATIONS,
                           from_features=True)
    error(fitted_truth, "the truth's model, its mu fitted as the baseline is")
    base = refits.fit(data.bundle, given, max_iterations=BASELINE_ITERATIONS,
                   from_features=True)
    error(base, "baseline (less rate_dependence), fitted")
    start_model = base.with_effects("rate_dependence")
    names = refits.refit_parameters(start_model, "rate_dependence")
    own = [n for n in names if n not in set(base.active_parameters())
           and n in ("eta_o", "E_v")]
    print(f"refitted parameters: {names}; own: {own}", flush=True)
    out["refit_parameters"] = list(names)
    weak = {n: refits.WEAK * float(start_model.parameters[n]) for n in own}
    error(start_model, "start 1: the effect at its default on the baseline's fit")
    error(start_model.with_parameters(**weak), "start 2: the effect weak")
    best = refits.best_start(data, start_model, own, names)
    error(best, "the best start (chosen by refits.best_start)")
    refit = refits.fit(data.bundle, best, parameters=names, max_iterations=refits.REFIT_ITERATIONS)
    error(refit, "the refit (fit_bundle from the best start, parameters=names)")
    kept = refits.no_worse(data, refit, best)
    error(kept, "the candidate's refit as the diagnosis keeps it")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=ROOT / "results" / "scenarios" / "study")
    parser.add_argument("--full", action="store_true")
    args = parser.parse_args()
    folder = make(args.work.resolve())
    record = json.loads((folder / "truth.json").read_text())
    print(f"bundle {folder / 'bundle'}: signal {record['signal']:.2f} × noise "
          f"({record['signal_per_measurement']})", flush=True)
    (folder / "follow.json").write_text(json.dumps(follow(folder), indent=1))
    if args.full:
        start = time.perf_counter()
        subprocess.run(["./drape", "diagnose", str(folder / "bundle"), "--model",
                        str(folder / "model.toml"), "--json", str(folder / "REPORT.json")],
                       cwd=ROOT, check=True)
        print(f"README command: {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
