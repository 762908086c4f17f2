"""Lab measurements: the cost of comparing a scan, and of diagnosing lab data.

    ./drape exec nice python3 benchmarks/bench_lab_compare.py            # compare only
    ./drape exec nice python3 benchmarks/bench_lab_compare.py --diagnose # and both diagnoses

The double dome (quarter model, 20 mm cells by default) formed by the paper's model is read
as a lab would (:mod:`fenicsx_drape.diagnosis.lab_synthetic`): a 10 000-point scan, a
100-point outline and 80 shear points on two measuring lines.

1. **Comparing one model run with the scan** (the run cached, so this is the comparison
   alone): matching the 10 000 points to the formed sheet (k-d tree and vectorised
   point-to-triangle projection), its coverage, and ``evaluate`` of the whole bundle
   (matching, noise, regions, measures). Target: under 1 s.
2. With ``--diagnose``: ``diagnose`` (baseline lacking ``tow_buckling``, that one candidate)
   on the scan + outline + shear bundle, and on the same part's drawn grid (whole blank,
   20 mm grid, 0.3 mm noise); target: the lab bundle at most 1.5× the grid's time. Both
   start from an empty cache of forming runs.

Prints the figures (seconds); asserts nothing.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cell-mm", type=float, default=20.0)
    parser.add_argument("--scan-points", type=int, default=10_000)
    parser.add_argument("--diagnose", action="store_true")
    args = parser.parse_args()

    from fenicsx_drape import runs
    from fenicsx_drape.diagnosis import diagnose, evaluate
    from fenicsx_drape.diagnosis.kinds import lab as lab_kind
    from fenicsx_drape.diagnosis.lab_synthetic import lab_tables, write_lab_bundle
    from fenicsx_drape.diagnosis.synthetic import synthetic_case_test, write_case_bundle
    from fenicsx_drape.forming.case.format import case_for_test, load_case, with_overrides
    from fenicsx_drape.forming.running import measure
    from fenicsx_drape.measurements.bundle import load_bundle
    from fenicsx_drape.model import default_model

    case = with_overrides(load_case(ROOT / "meshes/double_dome/case.toml"),
                          cell_mm=args.cell_mm)
    truth = default_model()
    t = time.perf_counter()
    (grid,) = runs.form_many([(case, truth)])
    print(f"forming run ({args.cell_mm:g} mm cells): {time.perf_counter() - t:.2f} s")
    tables = lab_tables(grid, runs.tool_forces(case, truth), seed=1,
                        scan_points=args.scan_points, holes=[(30.0, 20.0, 15.0)])
    with tempfile.TemporaryDirectory() as tmp:
        folder = write_lab_bundle(Path(tmp) / "lab", case, tables,
                                  measurements=["shear_points", "surface", "outline"])
        bundle = load_bundle(folder, read_case=case_for_test)
        scan = next(t for t in bundle.tests if t.id.endswith("/surface"))
        mesh = measure.SheetMesh.of(grid)
        P = lab_kind.points(scan)
        t = time.perf_counter()
        near = measure.closest_points(mesh, P)
        cover = measure.coverage(mesh, P)
        match_s = time.perf_counter() - t
        print(f"scan of {len(P)} points against {len(mesh.triangles)} triangles: "
              f"closest points and coverage {match_s:.3f} s (RMS distance "
              f"{float((near.signed**2).mean()) ** 0.5:.3f} mm, coverage {cover:.2f})")
        t = time.perf_counter()
        evaluate(bundle, truth)
        print(f"evaluate, first (the part's regions of the points: tool distances): "
              f"{time.perf_counter() - t:.3f} s")
        runs.memo("lab.match").clear()  # the model's side again; the regions stay
        t = time.perf_counter()
        result = evaluate(bundle, truth)
        print(f"evaluate of one run (run cached) of the lab bundle "
              f"({', '.join(f'{c.id} {c.residual.size}' for c in result.tests)}): "
              f"{time.perf_counter() - t:.3f} s, normalised {result.normalised:.2f}")
        if not args.diagnose:
            return
        baseline = default_model().without_effects("tow_buckling")
        runs.current().forget()
        t = time.perf_counter()
        report = diagnose(bundle, baseline, candidates=["tow_buckling"])
        lab_s = time.perf_counter() - t
        runs_lab = runs.current().in_memory()
        test = synthetic_case_test(truth, case, sd_mm=0.3, seed=1, full=True)
        write_case_bundle("grid", [test], Path(tmp) / "grid")
        grid_bundle = load_bundle(Path(tmp) / "grid", read_case=case_for_test)
        runs.current().forget()
        t = time.perf_counter()
        grid_report = diagnose(grid_bundle, baseline, candidates=["tow_buckling"])
        grid_s = time.perf_counter() - t
        print(f"diagnose, lab bundle (scan + outline + shear points): {lab_s:.1f} s, "
              f"{runs_lab} forming runs, missing_effect {report['missing_effect']}")
        print(f"diagnose, grid bundle ({grid_bundle.tests[0].n_rows} nodes): {grid_s:.1f} s, "
              f"{runs.current().in_memory()} forming runs, missing_effect "
              f"{grid_report['missing_effect']}")
        print(f"ratio lab / grid: {lab_s / grid_s:.2f} (target <= 1.5)")


if __name__ == "__main__":
    main()
