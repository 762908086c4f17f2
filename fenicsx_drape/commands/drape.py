"""``drape drape hemisphere``: the kinematic (pin-jointed net) drape, with its pictures.

Example::

    ./drape drape hemisphere --out results/kinematic
    ./drape drape hemisphere --out out --cell-mm 5 --start-mm 30 20 --direction-deg 10
    ./drape drape hemisphere --out out --ply-angle-deg 30 --generator normal_section

It writes into ``--out``: ``summary.json`` (max shear, nodes, unplaced nodes, the options),
``shear.png`` (the net coloured by shear angle), ``bundle/`` (the net on the drawn grid as a
forming bundle, so it compares like a measured part) and ``provenance.json``. The same in
Python: :func:`~fenicsx_drape.forming.kinematic.kinematic_drape` and
:func:`~fenicsx_drape.forming.kinematic.write_drape`.

A forming case file (``drape drape CASE.toml``) comes with the case files of issue 13.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from fenicsx_drape.errors import DrapeInputError

CASES = ("hemisphere",)


def configure(parser: argparse.ArgumentParser) -> None:
    """Options of ``drape drape``."""
    from fenicsx_drape.forming.kinematic import GENERATORS

    parser.add_argument("case", choices=CASES, help="the forming case")
    parser.add_argument("--out", required=True, type=Path, help="output folder")
    parser.add_argument("--cell-mm", type=float, default=10.0, help="cell size Δ (mm)")
    parser.add_argument("--start-mm", type=float, nargs=2, default=(0.0, 0.0),
                        metavar=("X", "Y"), help="start node on the flat sheet (mm), placed on "
                        "the highest surface point above it (default: the axis)")
    parser.add_argument("--direction-deg", type=float, default=None, metavar="ALPHA",
                        help="the warp's initial direction on the surface: its projection at "
                        "ALPHA to x (default: the ply angle)")
    parser.add_argument("--ply-angle-deg", type=float, default=0.0, metavar="THETA",
                        help="the tows at THETA to the blank's edges (degrees)")
    parser.add_argument("--generator", choices=GENERATORS, default="geodesic",
                        help="the generator tows through the start (default: geodesic)")
    parser.add_argument("--locking-angle-deg", type=float, default=None, metavar="GAMMA",
                        help="cells sheared beyond GAMMA lock: their last node is left out "
                        "(default: no limit)")
    parser.add_argument("--grid-mm", type=float, default=10.0,
                        help="spacing of the drawn grid written to the bundle (mm)")
    parser.add_argument("--no-pictures", action="store_true", help="skip shear.png")


def run(args: argparse.Namespace) -> int:
    """Run ``drape drape``."""
    from fenicsx_drape.forming.hemisphere import HemisphereCase
    from fenicsx_drape.forming.kinematic import kinematic_drape, write_drape
    from fenicsx_drape.forming.tools import HemisphereTools

    if not args.grid_mm > 0:
        raise DrapeInputError(f"--grid-mm {args.grid_mm}: must be positive")
    tools = HemisphereTools()
    net = kinematic_drape(tools, args.cell_mm, start_mm=tuple(args.start_mm),
                          direction_deg=args.direction_deg, ply_angle_deg=args.ply_angle_deg,
                          generator=args.generator, locking_angle_deg=args.locking_angle_deg,
                          warn=False)
    nominal = HemisphereCase()
    setup = {"geometry": "hemisphere", "punch_radius_mm": tools.punch_radius_mm,
             "fillet_radius_mm": tools.fillet_radius_mm,
             "holder_opening_mm": tools.holder_opening_mm, "sheet_mm": tools.sheet_mm,
             "travel_mm": tools.travel_mm, "duration_s": nominal.duration_s,
             "holder_force_N": nominal.holder_force_N}
    summary = write_drape(args.out, net, grid_mm=args.grid_mm, setup=setup,
                          pictures=not args.no_pictures,
                          case={"name": "hemisphere", "tools": dataclasses.asdict(tools)})
    print(f"kinematic drape: max shear {summary['max_shear_deg']:.1f}°, {summary['nodes']} "
          f"nodes" + (f", {summary['unplaced_nodes']} could not be placed (absent)"
                      if summary["unplaced_nodes"] else ""))
    print(f"summary: {args.out / 'summary.json'}"
          + ("" if args.no_pictures else f"; picture: {args.out / 'shear.png'}"))
    return 0
