"""Speed of the meshed hemisphere against the closed form, and contact's share.

Forms the quarter of ``meshes/hemisphere/case.toml`` (closed-form tools) and of
``case_meshed.toml`` (tools meshed from Gmsh) at each Δ, with the tools built beforehand (the
distance fields read from the warm cache: a cold cache builds them on the first run), the
fastest of ``--repeat`` runs (the machine may be shared), and prints per run: wall time,
steps, cut-backs, Newton iterations, time per iteration, and two shares of the wall time: in
the tools' ``gap`` and ``covers`` (contact search and evaluation, for every caller: contact,
holder, predictor, the stabilisation's normals) and in the nodal contact and holder terms
(``PenaltyContact.forces``/``project``, ``BlankHolder.forces``/``commit``: gap, forces,
Jacobians, friction bars). Prints, no assertions::

    ./drape exec python3 benchmarks/bench_meshed_forming.py [--cells 10 5]
    ./drape exec python3 benchmarks/bench_meshed_forming.py --cells 2.5 --full --repeat 1
"""

import argparse
import functools
import time
from pathlib import Path

import numpy as np

from fenicsx_drape.forming import load_case, run_case
from fenicsx_drape.forming.case.format import build_tools
from fenicsx_drape.forming.terms.contact import PenaltyContact
from fenicsx_drape.forming.terms.holder import BlankHolder

HERE = Path(__file__).resolve().parent.parent / "meshes" / "hemisphere"

clock = {"tools": 0.0, "terms": 0.0}
depth = {"terms": 0}


def timed(fun, key):
    """Wrap ``fun`` so that its time adds to ``clock[key]`` (outermost call only)."""

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        nested = depth.get(key, 0)
        depth[key] = nested + 1
        start = time.perf_counter()
        try:
            return fun(*args, **kwargs)
        finally:
            depth[key] = nested
            if not nested:
                clock[key] += time.perf_counter() - start

    return wrapper


# The nodal terms, at class level (run_case makes them).
for cls, names in ((PenaltyContact, ("forces", "project")), (BlankHolder, ("forces", "commit"))):
    for name in names:
        setattr(cls, name, timed(getattr(cls, name), "terms"))


def form(name: str, cell_mm: float, full: bool = False):
    """One run with its tools' gap/covers timed; (run, seconds in tools, seconds in terms)."""
    case = load_case(HERE / name, cell_mm=cell_mm, **({"symmetry": []} if full else {}))
    tools = build_tools(case)
    for tool in tools.values():
        for method in ("gap", "covers"):
            if hasattr(tool, method):
                object.__setattr__(tool, method, timed(getattr(tool, method), "tools"))
    clock.update(tools=0.0, terms=0.0)
    run = run_case(case, tools=tools)
    return run, clock["tools"], clock["terms"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cells", type=float, nargs="+", default=[10.0, 5.0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per case; the fastest")
    parser.add_argument("--full", action="store_true", help="the whole sheet (else a quarter)")
    args = parser.parse_args()
    print("case            Δ (mm)  wall (s)  steps  cut  Newton  ms/iter  gap+covers  "
          "contact terms  max shear")
    for cell in args.cells:
        walls = {}
        for name in ("case.toml", "case_meshed.toml"):
            # The fastest of a few runs: the machine is shared, the slower runs are noise.
            run, t_tools, t_terms = min((form(name, cell, args.full) for _ in range(args.repeat)),
                                        key=lambda r: r[0].wall_time_s)
            walls[name] = run.wall_time_s
            shear = float(np.nanmax(np.abs(run.grid.shear_deg())))
            print(f"{name:16s}{cell:6.1f}  {run.wall_time_s:8.2f}  {run.steps:5d}  "
                  f"{run.cutbacks:3d}  {run.iterations:6d}  "
                  f"{1e3 * run.wall_time_s / run.iterations:7.2f}  "
                  f"{100 * t_tools / run.wall_time_s:9.1f} %  "
                  f"{100 * t_terms / run.wall_time_s:12.1f} %  {shear:8.3f}°", flush=True)
        print(f"  meshed / closed form at Δ = {cell:g} mm: "
              f"{walls['case_meshed.toml'] / walls['case.toml']:.2f} × the wall time")


if __name__ == "__main__":
    main()
