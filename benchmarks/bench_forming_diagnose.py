"""Time of a forming ``diagnose`` with three candidates at Δ = 10 mm (issue 8).

A quarter-hemisphere grid (10 mm) "measured" with the paper's model, 0.3 mm noise per
coordinate; the baseline lacks ``tow_buckling``; the candidates are ``tow_buckling``,
``tool_friction`` and ``shear_tension_coupling``. Printed: the wall time of the whole
diagnosis (target: under 5 minutes on two cores), the forming runs it made, and the verdict.
A second line gives the screening route: the same at Δ = 20 mm, then the baseline and the
winner confirmed at 10 mm (:func:`fenicsx_drape.forming_compare.confirm`).

    ./drape exec python3 benchmarks/bench_forming_diagnose.py
"""

import time

from fenicsx_drape import forming_compare as fc
from fenicsx_drape.bundle import Bundle
from fenicsx_drape.diagnose import diagnose
from fenicsx_drape.model import default_model

CANDIDATES = ["tow_buckling", "tool_friction", "shear_tension_coupling"]


def main() -> None:
    truth, baseline = default_model(), default_model().without_effects("tow_buckling")
    test = fc.synthetic_forming_test(truth, cell_mm=10.0, sd_mm=0.3, seed=7)
    bundle = Bundle(name="bench-forming", tests=(test,))
    print(f"forming workers: {fc.WORKERS}; measured grid: {test.n_rows} nodes")
    for cell in (10.0, 20.0):
        fc._cache.clear()
        start = time.perf_counter()
        with fc.resolution(cell):
            report = diagnose(bundle, baseline, candidates=CANDIDATES)
        seconds = time.perf_counter() - start
        line = (f"diagnose at Δ = {cell:g} mm: {seconds:.1f} s, {len(fc._cache)} forming runs, "
                f"missing_effect = {report['missing_effect']}, baseline "
                f"{report['baseline']['error']['normalised']:.2f} → "
                f"{report['candidates'][0]['error_after']['normalised']:.2f} × noise")
        if cell != 10.0:
            start = time.perf_counter()
            checked = fc.confirm(bundle, report, 10.0)
            best = report["candidates"][0]["effect"]
            line += (f"; confirmed at 10 mm in {time.perf_counter() - start:.1f} s: baseline "
                     f"{checked['baseline']['error']['normalised']:.2f}, {best} "
                     f"{checked[best]['error']['normalised']:.2f} × noise")
        print(line, flush=True)


if __name__ == "__main__":
    main()
