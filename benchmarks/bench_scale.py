"""The forming runs of a diagnosis at scale: workers, a warm cache, the executor's cost.

The bundle is a whole grid of the small octagon case of ``tests/test_forming_case_diagnosis.py``
(20 mm cells, under a second a run), formed with the paper's model and 0.3 mm noise; the
baseline lacks ``tow_buckling``. Printed:

- the wall time of ``diagnose`` as a user runs it (every candidate and the set-up stage; only
  ``--candidates`` with no set-up stage, when given), without disk cache, on 1 worker, 2 and
  all the machine's cores, with the runs it formed;
- the README's loop (compare the baseline, diagnose, compare the model with the effect back,
  history) twice with one cache folder: each pass's time, runs formed and runs read back,
  and the share of the second pass's runs that were reused;
- the executor's cost per run: the round trip of a job (a run's case and model out, a
  run's result back) through a warm one-process pool, without the forming.

    ./drape exec python3 benchmarks/bench_scale.py
"""

import argparse
import json
import multiprocessing
import operator
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_forming_case_diagnosis import write_case

from fenicsx_drape import runs
from fenicsx_drape.cli import main as drape
from fenicsx_drape.diagnosis import diagnose
from fenicsx_drape.diagnosis.synthetic import synthetic_case_test, write_case_bundle
from fenicsx_drape.forming.case.format import case_for_test, load_case
from fenicsx_drape.measurements.bundle import load_bundle
from fenicsx_drape.model import default_model
from fenicsx_drape.runs import pools, store


def quiet(*args: str) -> None:
    """Run a drape command with its printing silenced; fail loudly on a bad status."""
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        status = drape(list(args))
    if status != 0:
        raise SystemExit(f"drape {' '.join(args)}: exit status {status}")


def counted(action) -> tuple[float, int, int]:
    """Wall time (s) of ``action()``, and the runs formed and read from disk it returns."""
    start = time.perf_counter()
    formed, read = action()
    return time.perf_counter() - start, formed, read


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--candidates", nargs="+", default=None,
                        help="only these effects, no set-up stage (default: diagnose's own)")
    parser.add_argument("--overhead-runs", type=int, default=20)
    parser.add_argument("--parts", nargs="+", choices=("workers", "loop", "overhead"),
                        default=("workers", "loop", "overhead"))
    args = parser.parse_args()
    paper = default_model()
    baseline = paper.without_effects("tow_buckling")
    scratch = tempfile.TemporaryDirectory(prefix="bench_scale_")  # removed when it goes
    tmp = Path(scratch.name)
    case = load_case(write_case(tmp / "part"))
    test = synthetic_case_test(paper, case, sd_mm=0.3, seed=3, full=True)
    write_case_bundle("octagon", [test], tmp / "bundle")
    bundle = load_bundle(tmp / "bundle", read_case=case_for_test)
    (tmp / "baseline.toml").write_text(
        "effects = [" + ", ".join(f'"{e}"' for e in baseline.effects) + "]\n")
    (tmp / "with.toml").write_text(
        "effects = [" + ", ".join(f'"{e}"' for e in paper.effects) + "]\n")
    cores = runs.default_workers()
    tried = ", ".join(args.candidates) if args.candidates else "all, with the set-up stage"
    print(f"octagon, {case.blank.cell_mm:g} mm cells; candidates {tried}; {cores} cores",
          flush=True)

    if "workers" in args.parts:
        print("\ndiagnose against workers (no disk cache)")
        print(f"{'workers':>8} {'wall s':>8} {'runs':>5} {'s/run':>6}")
        seen = set()
        for workers in (1, 2, cores):
            if workers in seen:
                continue
            seen.add(workers)
            with runs.execution(workers=workers) as made:  # nothing in memory at its start

                def diagnosed(made=made):
                    diagnose(bundle, baseline, candidates=args.candidates)
                    return made.counts["formed"], 0

                seconds, formed, _ = counted(diagnosed)
            print(f"{workers:>8} {seconds:>8.1f} {formed:>5} {seconds / max(formed, 1):>6.2f}",
                  flush=True)

    if "loop" in args.parts:
        print("\nthe README's loop (compare, diagnose, compare, history), twice, one cache folder")
        print(f"{'pass':>5} {'wall s':>8} {'formed':>7} {'reused':>7}")
        cache = tmp / "runs"
        totals = []
        for k in (1, 2):

            def loop(k=k):  # each command its own Runs: nothing in memory at its start
                out = tmp / f"pass{k}"
                quiet("compare", str(tmp / "bundle"), "--model", str(tmp / "baseline.toml"),
                      "--out", str(out / "v1"), "--cache", str(cache))
                with runs.execution(cache=cache) as made:
                    diagnose(bundle, baseline, candidates=args.candidates)
                quiet("compare", str(tmp / "bundle"), "--model", str(tmp / "with.toml"),
                      "--out", str(out / "v2"), "--cache", str(cache))
                quiet("history", str(out / "v1"), str(out / "v2"), "--out", str(out / "history"))
                made = [made.record()["runs"]] + [json.loads(
                    (out / v / "provenance.json").read_text())["forming_runs"]["runs"]
                    for v in ("v1", "v2")]
                return sum(r["formed"] for r in made), sum(r["from_disk"] for r in made)

            seconds, formed, read = counted(loop)
            totals.append(seconds)
            print(f"{k:>5} {seconds:>8.1f} {formed:>7} {read:>7}", flush=True)
        print(f"second pass: {100 * totals[1] / totals[0]:.0f} % of the first's time, "
              f"{100 * read / max(read + formed, 1):.0f} % of its runs reused")

    if "overhead" in args.parts:
        print(f"\nexecutor cost per run: a job that sends a run's case and model and gets its "
              f"result back, without forming ({args.overhead_runs} jobs, warm one-process pool)")
        job = (case, paper)
        pools.form(*job)  # this process warm: DOLFINx imported, forms compiled
        start = time.perf_counter()
        grid, stopped, curves = pools.form(*job)
        here = time.perf_counter() - start
        data = store.encode(grid, stopped, curves)
        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            start = time.perf_counter()
            with pools.fresh_workers():  # a new worker's first run: it imports DOLFINx
                pool.submit(pools.run_job, *job, False, runs.solver_options()).result()
            first = time.perf_counter() - start
            times = []
            for _ in range(args.overhead_runs):
                start = time.perf_counter()
                with pools.fresh_workers():
                    future = pool.submit(operator.itemgetter(1), (job, data))
                back = store.decode(future.result())
                times.append(time.perf_counter() - start)
        assert np.array_equal(back[0].x, grid.x, equal_nan=True)
        print(f"median {1e3 * np.median(times):.1f} ms, max {1e3 * max(times):.1f} ms per run "
              f"({grid.x.size // 3} nodes); a worker's start: its first run "
              f"{first:.1f} s against {here:.1f} s in a warm process")


if __name__ == "__main__":
    main()
