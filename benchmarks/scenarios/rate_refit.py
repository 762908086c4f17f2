"""Why does the rate_dependence refit stop short of the truth? (a study, not a test)

Makes the two-trial double-dome bundle of the scenario generator — the paper's model at
Table 2 formed at 8 s and 240 s on the case's 10 mm net (2 mm steps), the lab's STL copy of
the tools, shear at cell centres along measuring lines (1°) and the blank's edge (0.3 mm),
noise stated by keys, the holder's μ not stated (the baseline fits it) — and follows the
diagnosis's refit of ``rate_dependence`` step by step with the model less that effect: the
baseline's fit, the candidate's starts and their costs, its refit, against the truth's own
error on the same net.

    ./drape exec python3 benchmarks/scenarios/rate_refit.py [--work DIR] [--cache DIR] [--full]

Prints each step's normalised error, μ, η_o, E_v and forming runs (asked, and formed new),
then the steps as docs/scenarios.md's table. ``--full`` also runs the README's command on
the bundle (default options) and prints its runs and time.
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


SHOWN = ("mu", "eta_o", "E_v")  # the parameters the table shows


def follow(folder: Path) -> dict:
    """The diagnosis's own steps for the rate_dependence candidate, each with its numbers.

    Each step's forming runs are counted (asked, and formed new: the runs of earlier steps
    are remembered); the starts are judged in one vectorised call, as the diagnosis does.
    """
    import numpy as np

    from fenicsx_drape.calibration.coupons import declare_noise
    from fenicsx_drape.diagnosis import refits
    from fenicsx_drape.diagnosis.comparison import normalised_error, simulate
    from fenicsx_drape.diagnosis.decision import BASELINE_ITERATIONS
    from fenicsx_drape.diagnosis.kinds.forming import XTOL
    from fenicsx_drape.diagnosis.pipeline import prepare_tests
    from fenicsx_drape.forming.case import case_for_test
    from fenicsx_drape.measurements.bundle import load_bundle
    from fenicsx_drape.model import default_model, load_model
    from fenicsx_drape.runs import execution_record

    bundle = load_bundle(folder / "bundle", read_case=case_for_test)
    given = load_model(folder / "model.toml")
    data = prepare_tests(declare_noise(bundle, given.noise))
    out: dict = {"steps": []}

    def counted() -> dict[str, int]:
        return dict(execution_record()["runs"])

    def row(model, label: str, since: dict[str, int] | None, error: float | None = None,
            note: str = "") -> float:
        if error is None:
            compared = data.compare(simulate(data.tests, model))
            error = normalised_error(compared)
        shown = {k: float(model.parameters[k]) for k in SHOWN
                 if k in model.active_parameters()}
        now = counted()
        runs = ({k: now[k] - since[k] for k in ("asked", "formed")} if since is not None
                else None)
        print(f"{label}: normalised {error:.3f} at "
              f"{ {k: round(v, 4) for k, v in shown.items()} }"
              + (f"; runs asked {runs['asked']}, formed {runs['formed']}" if runs else "")
              + (f" ({note})" if note else ""), flush=True)
        out["steps"].append({"step": label, "normalised": error, "parameters": shown,
                             "runs": runs, "note": note})
        return error

    since = counted()
    truth = default_model()
    row(truth, "the truth's model, as formed", since)
    since = counted()
    fitted_truth = refits.fit(data.bundle, truth, max_iterations=BASELINE_ITERATIONS,
                              from_features=True)
    target = row(fitted_truth, "the truth's model, μ fitted (as a baseline is)", since)
    since = counted()
    base = refits.fit(data.bundle, given, max_iterations=BASELINE_ITERATIONS,
                      from_features=True)
    row(base, "baseline (less `rate_dependence`), μ fitted", since)
    start_model = base.with_effects("rate_dependence")
    names = refits.refit_parameters(start_model, "rate_dependence")
    own = [n for n in names if n not in set(base.active_parameters()) and n in ("eta_o", "E_v")]
    print(f"refitted parameters: {names}; own: {own}", flush=True)
    out["refit_parameters"], out["own"] = list(names), own

    # The starts, each at the baseline's, the stated and the default μ, in one call.
    since = counted()
    found, moved = refits.starts(data, start_model, own, names, stated=given)
    errors = np.sqrt(refits.costs(data, refits.vectorised(found, moved)))
    chosen = int(np.nanargmin(errors))
    at_base = [i for i, m in enumerate(found)
               if abs(float(m.parameters["mu"]) - float(base.parameters["mu"])) < XTOL]
    before = min(at_base, key=lambda i: errors[i])
    for i, model in enumerate(found):  # the runs of all starts on the first's row
        row(model, f"start {i + 1}", since if i == 0 else None, float(errors[i]),
            "chosen" if i == chosen else "chosen before (judged at the baseline's μ only)"
            if i == before else "")

    # Before: the refit from the start judged at the baseline's μ, the friction only.
    since = counted()
    old = refits.no_worse(data, refits.fit(data.bundle, found[before], parameters=names,
                                           max_iterations=refits.REFIT_ITERATIONS),
                          found[before])
    row(old, "before: its refit, μ only (the forming fit ignored η_o, E_v)", since)
    # Now: the refit from the chosen start, the candidate's own parameters with μ.
    since = counted()
    refit = refits.no_worse(data, refits.fit(data.bundle, found[chosen], parameters=names,
                                             own=own, max_iterations=refits.REFIT_ITERATIONS),
                            found[chosen])
    error = row(refit, "now: its refit, μ with η_o and E_v (their logarithms)", since)
    out["target"], out["refit"] = target, error
    print(f"the refit at {error / target:.3f} × the truth's own normalised error "
          f"({error:.3f} against {target:.3f})", flush=True)
    return out


def table(out: dict) -> str:
    """The steps as a Markdown table (docs/scenarios.md's)."""
    lines = ["| step | μ | η_o (N·s/tow) | E_v (N/tow) | normalised error | forming runs "
             "(asked / formed) |", "| --- | --- | --- | --- | --- | --- |"]
    for s in out["steps"]:
        p = s["parameters"]
        runs = f"{s['runs']['asked']} / {s['runs']['formed']}" if s["runs"] else ""
        lines.append(f"| {s['step']} | {p.get('mu', float('nan')):.3g} | "
                     + " | ".join(f"{p[k]:.3g}" if k in p else "—" for k in ("eta_o", "E_v"))
                     + f" | {s['normalised']:.2f}{': ' + s['note'] if s['note'] else ''} | "
                     f"{runs} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=ROOT / "results" / "scenarios" / "study")
    parser.add_argument("--full", action="store_true")
    parser.add_argument("--cache", type=Path, default=None,
                        help="keep the runs in this folder (default: in memory, all formed)")
    args = parser.parse_args()
    from fenicsx_drape.runs import Runs

    folder = make(args.work.resolve())
    record = json.loads((folder / "truth.json").read_text())
    print(f"bundle {folder / 'bundle'}: signal {record['signal']:.2f} × noise "
          f"({record['signal_per_measurement']})", flush=True)
    with Runs(cache=args.cache):
        out = follow(folder)
    (folder / "follow.json").write_text(json.dumps(out, indent=1))
    print(table(out), flush=True)
    if args.full:
        start = time.perf_counter()
        subprocess.run(["./drape", "diagnose", str(folder / "bundle"), "--model",
                        str(folder / "model.toml"), "--json", str(folder / "REPORT.json")],
                       cwd=ROOT, check=True)
        seconds = time.perf_counter() - start
        report = json.loads((folder / "REPORT.json").read_text())
        best = next((c for c in report.get("candidates", [])
                     if c.get("effect") == "rate_dependence"), {})
        print(f"README command: {seconds:.0f} s; rate_dependence refitted to "
              f"{best.get('error_after', {}).get('normalised')} × the noise, evidence "
              f"{best.get('evidence')}; conclusion: {report.get('conclusion')}", flush=True)


if __name__ == "__main__":
    main()
