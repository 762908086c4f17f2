"""Meshed tools: build time, memory and evaluation cost of the distance field, and its accuracy
against the closed-form hemisphere tools (the geometric half of the tool-mesh convergence study).

    ./drape exec python3 benchmarks/bench_contact.py                  # timing: punch and die
    ./drape exec python3 benchmarks/bench_contact.py --accuracy       # mesh sizes × orders
    ./drape exec python3 benchmarks/bench_contact.py --accuracy --mesh-mm 4 2 --order 1 2

The tools are ``meshes/hemisphere/{punch,die,holder}.geo`` with HemisphereTools' numbers. The
distance fields are built without the cache (``--cache`` to use it). Accuracy is measured at
random points near the surface (−0.3 mm < φ < 3 mm: the side the sheet is on, and the depth
a node can penetrate) where the sheet can be, by region: the punch's cap and fillet
(r < 80 mm), its shoulder (80-82 mm) and the edge (82-84 mm: the shoulder's end and the 1 mm
edge round, which a grid of h ≳ 1 mm cannot resolve); the die's cap and lip (r < 80 mm) and
its face (80-85 mm); the holder under its plate (90-170 mm). Columns: ``mesh`` = the exact
distance to the triangles minus the exact distance to the closed form (the facets' error),
``field`` = the spline's φ minus the closed form (what the contact sees), both max |·| in mm,
and the largest angle between ∇φ and the exact normal.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc
from pathlib import Path

import numpy as np

from fenicsx_drape.forming.tools.distance import build_field, default_spacing
from fenicsx_drape.forming.tools.motion import RigidMotion
from fenicsx_drape.forming.tools.shapes import HemisphereTools, MeshedTool
from fenicsx_drape.forming.tools.surfaces import load_surface

FOLDER = Path(__file__).resolve().parent.parent / "meshes" / "hemisphere"
TOOLS = HemisphereTools()


def closed_form(name: str):
    """The exact tool at the time its .geo file shows it (the punch at t = 0)."""
    if name == "punch":
        return TOOLS.punch(40.0), 0.0
    if name == "die":
        return TOOLS.die(), 0.0
    return None, 0.0


def near_points(name: str, n: int, rng) -> dict[str, np.ndarray]:
    """Random points near each tool where the sheet can be, by region.

    Points on the exact profile (uniform in its area), moved along the normal by
    −0.3 … 3 mm and turned about the axis by a random angle.
    """
    if name == "holder":
        r = np.sqrt(rng.uniform(90.0**2, 170.0**2, n))
        a = rng.uniform(0, 2 * np.pi, n)
        z = rng.uniform(-0.3, 3.0, n)
        return {"plate": np.column_stack([r * np.cos(a), r * np.sin(a), z])}
    tool, t = closed_form(name)
    regions = ({"cap+fillet": (0.0, 80.0), "shoulder": (80.0, 82.0), "edge": (82.0, 84.0)}
               if name == "punch" else {"cap+lip": (0.0, 80.0), "face": (80.0, 85.0)})
    # The profile sampled densely in the meridian plane: (r, h) points and their normals.
    pts = []
    for piece in tool.profile:
        if hasattr(piece, "radius"):
            a = np.linspace(piece.start, piece.end, 20001)
            p = np.asarray(piece.centre) + piece.radius * np.column_stack([np.cos(a), np.sin(a)])
        else:
            s = np.linspace(0.0, 1.0, 20001)[:, None]
            p = np.asarray(piece.a) + s * (np.asarray(piece.b) - np.asarray(piece.a))
        pts.append(p[(p[:, 0] < 90.0) & (p[:, 1] > -20.0)])
    p = np.concatenate(pts)
    z0 = tool.z_offset(t)
    out = {}
    for region, (lo, hi) in regions.items():
        q = p[(p[:, 0] >= lo) & (p[:, 0] < hi)]
        k = rng.choice(len(q), n, p=q[:, 0] / q[:, 0].sum())  # area ∝ r
        a = rng.uniform(0, 2 * np.pi, n)
        x = np.column_stack([q[k, 0] * np.cos(a), q[k, 0] * np.sin(a), q[k, 1] + z0])
        g = tool.gap(x, t)
        out[region] = x + rng.uniform(-0.3, 3.0, n)[:, None] * g.normal
    return out


def accuracy(name: str, mesh_mm: float, order: int, spacing_mm: float | None, rng):
    side = {"punch": "+z", "die": "-z", "holder": "+z"}[name]
    start = time.perf_counter()
    surface = load_surface(FOLDER / f"{name}.geo", mesh_size_mm=mesh_mm, order=order,
                           sheet_side=side, comm=None)
    load_s = time.perf_counter() - start
    h = spacing_mm or default_spacing(surface)
    band = 3.0 + 2.0 * h
    tracemalloc.start()
    start = time.perf_counter()
    field = build_field(surface, h, band)
    build_s = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rows = []
    tool, t = closed_form(name)
    for region, x in near_points(name, 20000, rng).items():
        exact_phi = x[:, 2] if tool is None else tool.gap(x, t).phi
        exact_n = np.tile([0, 0, 1.0], (len(x), 1)) if tool is None else tool.gap(x, t).normal
        mesh_phi = surface.signed_distance(x)
        phi, grad, _ = field.evaluate(x)
        cos = np.einsum("ij,ij->i", grad, exact_n) / np.linalg.norm(grad, axis=1)
        angle = np.degrees(np.arccos(np.minimum(cos, 1.0))).max()
        rows.append((region, np.abs(mesh_phi - exact_phi).max(), np.abs(phi - exact_phi).max(),
                     np.abs(phi - exact_phi).mean(), angle))
    return surface, h, field, load_s, build_s, peak, rows


def sheet_nodes(n_side: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """The 240 mm sheet's nodes: flat (t = 0) and on the formed part (t = 40 s, 0-0.3 mm off)."""
    c = np.linspace(-120.0, 120.0, n_side)
    X, Y = np.meshgrid(c, c)
    flat = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    g = TOOLS.formed_part().gap(flat, 0.0)
    formed = flat - (g.phi - rng.uniform(-0.02, 0.3, len(flat)))[:, None] * g.normal
    return flat, formed


def timing(args) -> None:
    rng = np.random.default_rng(1)
    tools = {}
    for name, side, motion in (("punch", "+z", RigidMotion(time_s=[0.0, 40.0],
                                                              z_mm=[0.0, 80.0])),
                               ("die", "-z", None)):
        surface = load_surface(FOLDER / f"{name}.geo", mesh_size_mm=args.tool_mm,
                               order=args.tool_order, sheet_side=side, comm=None)
        tracemalloc.start()
        start = time.perf_counter()
        tool = MeshedTool(name, surface, motion, spacing_mm=args.spacing_mm, cache=args.cache,
                          comm=None)
        took = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        f = tool.field
        print(f"{name}: {len(surface.triangles)} triangles ({args.tool_mm:g} mm, order "
              f"{args.tool_order}), h = {f.h:g} mm, band {f.band_mm:g} mm, grid "
              f"{tuple(f.coefficients.shape)} = {f.nbytes / 1e6:.1f} MB; "
              f"{'read or built' if args.cache else 'built'} in {took:.1f} s, peak "
              f"{peak / 1e6:.0f} MB")
        tools[name] = tool
    exact = {"punch": TOOLS.punch(40.0), "die": TOOLS.die()}
    print("gap of punch + die (best of", args.repeat, "calls):")
    for n_side in (33, 65, 97):  # 1089, 4225, 9409 nodes (Δ = 7.5, 3.75, 2.5 mm)
        flat, formed = sheet_nodes(n_side, rng)
        for label, x, t in (("flat, t = 0", flat, 0.0), ("formed, t = 40 s", formed, 40.0)):
            best = {}
            for kind, set_ in (("meshed", tools), ("closed form", exact)):
                b = np.inf
                for _ in range(args.repeat):
                    s = time.perf_counter()
                    for tool in set_.values():
                        tool.gap(x, t)
                    b = min(b, time.perf_counter() - s)
                best[kind] = b
            n = len(x)
            print(f"  {n:5d} nodes, {label:17s} meshed {best['meshed'] * 1e3:6.1f} ms "
                  f"({best['meshed'] / n * 1e6:.2f} µs/node), closed form "
                  f"{best['closed form'] * 1e3:6.1f} ms; meshed = "
                  f"{best['meshed'] / 0.15 * 100:.1f} % of a 0.15 s Newton iteration")
    holder = MeshedTool("holder", load_surface(FOLDER / "holder.geo", mesh_size_mm=args.tool_mm,
                                               order=args.tool_order, comm=None),
                        spacing_mm=args.spacing_mm, cache=args.cache, comm=None)
    for label, x in (("flat", flat), ("formed", formed)):
        start = time.perf_counter()
        under = holder.covers(x, 40.0)
        print(f"holder.covers (exact closest points) of {len(x)} {label} nodes "
              f"({under.sum()} under it): {(time.perf_counter() - start) * 1e3:.0f} ms")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--accuracy", action="store_true", help="the convergence table")
    ap.add_argument("--mesh-mm", type=float, nargs="+", default=[4.0, 2.0, 1.0])
    ap.add_argument("--order", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--tools", nargs="+", default=["punch", "die", "holder"])
    ap.add_argument("--spacing-mm", type=float, default=None, help="grid h (default: mesh)")
    ap.add_argument("--tool-mm", type=float, default=2.0, help="timing: tool mesh size")
    ap.add_argument("--tool-order", type=int, default=2, help="timing: tool mesh order")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--cache", action="store_true", help="use the on-disk cache (timing)")
    args = ap.parse_args()
    if not args.accuracy:
        timing(args)
        return
    rng = np.random.default_rng(2)
    print("tool    mesh order  triangles  h    load s  build s  peak MB  grid MB | region: "
          "mesh err, field err max/mean (mm), normal (deg)")
    for name in args.tools:
        for mesh_mm in args.mesh_mm:
            for order in args.order:
                s, h, f, load_s, build_s, peak, rows = accuracy(name, mesh_mm, order,
                                                               args.spacing_mm, rng)
                cells = "; ".join(f"{r}: {m:.4f}, {a:.4f}/{b:.4f}, {d:.2f}"
                                  for r, m, a, b, d in rows)
                print(f"{name:7s} {mesh_mm:4.1f} {order:5d} {len(s.triangles):10d} {h:5.2f} "
                      f"{load_s:6.1f} {build_s:8.1f} {peak / 1e6:8.0f} {f.nbytes / 1e6:8.1f} | "
                      f"{cells}", flush=True)


if __name__ == "__main__":
    main()
