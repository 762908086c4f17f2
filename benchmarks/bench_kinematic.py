"""Wall time of the kinematic drape (any case under 1 s at Δ = 5 mm on one core).

    ./drape exec python3 benchmarks/bench_kinematic.py
    ./drape exec python3 benchmarks/bench_kinematic.py --cells 10 5 2.5 --repeat 5
    ./drape exec python3 benchmarks/bench_kinematic.py --case meshes/double_dome/case.toml

Cases: the paper's hemisphere on its closed-form formed part and on the punch at its final
position united with the holder plane (240 mm square blank, start at the apex), a bumpy
analytic height field (a Gaussian dome with a superposed sine ripple, the same blank), and the
forming cases of ``meshes/*/case*.toml`` (``--case`` to choose): their whole blank on their
formed surface (:func:`~fenicsx_drape.forming.running.kinematic.drape_case`), meshed tools included.
A case's tools are built first (their distance fields cached on disk) and not timed. Each
time is the best of ``--repeat`` runs; the Newton work is the number of surface evaluations.
"""

import argparse
import time
from pathlib import Path

import numpy as np

from fenicsx_drape.forming.case.format import build_tools, load_case
from fenicsx_drape.forming.running.kinematic import (
    HeightField,
    Plane,
    case_surface,
    formed_surface,
    kinematic_drape,
    rectangle,
)
from fenicsx_drape.forming.tools.shapes import HemisphereTools

parser = argparse.ArgumentParser()
parser.add_argument("--cells", type=float, nargs="*", default=[10.0, 5.0, 2.5],
                    help="cell sizes Δ (mm)")
parser.add_argument("--repeat", type=int, default=3, help="runs per case (the best is shown)")
parser.add_argument("--case", nargs="*", default=None,
                    help="forming case files (default: meshes/*/case*.toml)")
args = parser.parse_args()

A_MM, W_MM, RIPPLE_MM, LX_MM, LY_MM = 40.0, 45.0, 6.0, 70.0, 90.0
kx, ky = 2 * np.pi / LX_MM, 2 * np.pi / LY_MM


def bump(x, y):
    """A Gaussian dome 40 mm high with a 6 mm sine ripple."""
    return (A_MM * np.exp(-(x * x + y * y) / (2 * W_MM**2))
            + RIPPLE_MM * np.sin(kx * x) * np.cos(ky * y))


def bump_gradient(x, y):
    """(∂F/∂x, ∂F/∂y) of :func:`bump`."""
    g = -A_MM * np.exp(-(x * x + y * y) / (2 * W_MM**2)) / W_MM**2
    return (g * x + RIPPLE_MM * kx * np.cos(kx * x) * np.cos(ky * y),
            g * y - RIPPLE_MM * ky * np.sin(kx * x) * np.sin(ky * y))


class Counted:
    """A surface that counts its evaluations."""

    def __init__(self, surface):
        self.surface, self.calls, self.points = surface, 0, 0
        self.name = getattr(surface, "name", "surface")

    def gap(self, x, t=0.0):
        self.calls += 1
        self.points += len(x)
        return self.surface.gap(x, t)


tools = HemisphereTools()
square = rectangle((tools.sheet_mm, tools.sheet_mm))
cases = {
    "hemisphere, closed-form part": (tools.formed_part(), {"outline": square}),
    "hemisphere, punch + holder plane": (formed_surface([tools.punch(40.0), Plane()], 40.0),
                                         {"outline": square}),
    "bumpy height field": (HeightField(bump, bump_gradient, name="bumps"), {"outline": square}),
}
root = Path(__file__).resolve().parent.parent
for path in args.case if args.case is not None else sorted(root.glob("meshes/*/case*.toml")):
    case = load_case(path)
    blank = case.blank
    surface = case_surface(case, build_tools(case))
    cases[f"case {Path(path).parent.name}/{Path(path).name}"] = (
        surface, {"outline": blank.polygon(), "start_mm": blank.origin_mm,
                  "ply_angle_deg": blank.ply_angle_deg})
for cell in args.cells:
    for name, (surface, options) in cases.items():
        counted = Counted(surface)
        net = kinematic_drape(counted, cell, **options)
        best = np.inf
        for _ in range(args.repeat):
            start = time.perf_counter()
            kinematic_drape(surface, cell, **options)
            best = min(best, time.perf_counter() - start)
        γ = np.nanmax(np.abs(net.shear_deg()))
        print(f"Δ = {cell:5.2f} mm  {name:40s} {net.present.sum():6d} nodes "
              f"({net.unplaced_count} unplaced), max shear {γ:6.2f}°, {counted.calls:4d} "
              f"surface calls ({counted.points} points): {best:6.3f} s")
