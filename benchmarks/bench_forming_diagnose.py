"""Time of a forming ``diagnose`` with three candidates at Δ = 10 mm.

Quarter-hemisphere grids (10 mm) "measured" with 0.3 mm noise per coordinate, formed and
diagnosed on 10 mm cells, candidates ``tow_buckling``, ``tool_friction`` and
``shear_tension_coupling``:

- hidden ``tow_buckling`` (the paper's model; the baseline lacks it),
- hidden ``tool_friction`` at μ_tool = 0.8 (the baseline is the paper's model, so
  ``tow_buckling`` is not a candidate: two candidates).

Printed per case: the wall time of the whole diagnosis (target: under 5 minutes on two
cores), the forming runs it made, the verdict and the errors.

    ./drape exec python3 benchmarks/bench_forming_diagnose.py
"""

import time

from fenicsx_drape import runs
from fenicsx_drape.diagnosis import diagnose
from fenicsx_drape.diagnosis.synthetic import synthetic_forming_test
from fenicsx_drape.measurements.bundle import Bundle
from fenicsx_drape.model import default_model

CANDIDATES = ["tow_buckling", "tool_friction", "shear_tension_coupling"]


def main() -> None:
    paper = default_model()
    cases = {
        "tow_buckling": (paper, paper.without_effects("tow_buckling")),
        "tool_friction": (paper.with_effects("tool_friction").with_parameters(mu_tool=0.8),
                          paper),
    }
    print(f"forming workers: {runs.default_workers()}; cells {runs.FULL_CELL_MM:g} mm", flush=True)
    for hidden, (truth, baseline) in cases.items():
        test = synthetic_forming_test(truth, sd_mm=0.3, seed=7)
        runs.current().forget()
        start = time.perf_counter()
        report = diagnose(Bundle(name=f"hidden-{hidden}", tests=(test,)), baseline,
                          candidates=[c for c in CANDIDATES if c not in baseline.effects])
        seconds = time.perf_counter() - start
        best = report["candidates"][0]
        m = report["metrics"]
        print(f"hidden {hidden}: {seconds:.1f} s, {runs.current().in_memory()} forming runs, "
              f"missing_effect = {report['missing_effect']}, normalised "
              f"{report['baseline']['error']['normalised']:.2f} → "
              f"{best['error_after']['normalised']:.2f} (evidence {best['evidence']:.2f}), "
              f"mean distance {m['baseline']['hemisphere']['mean_distance_mm']:.2f} → "
              f"{m[best['effect']]['hemisphere']['mean_distance_mm']:.2f} mm", flush=True)


if __name__ == "__main__":
    main()
