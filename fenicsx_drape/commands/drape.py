"""``drape drape CASE.toml``: the kinematic (pin-jointed net) drape of a case, with pictures.

Example::

    ./drape drape meshes/hemisphere/case.toml --out results/kinematic
    ./drape drape my_part/case.toml --out out --cell-mm 5 --start-mm 30 20 --direction-deg 10
    ./drape drape hemisphere --out out --ply-angle-deg 30 --generator normal_section

The surface is the case's formed surface: the tools the sheet lies on at the end of their
motion, united (:func:`~fenicsx_drape.forming.running.kinematic.case_surface`); the blank, Δ, ply
angle and start (the net's origin) are the case's unless given. A named case is a case of
the repository: ``hemisphere`` is ``meshes/hemisphere/case.toml``.

It writes into ``--out``: ``summary.json`` (max shear, nodes, unplaced nodes, the options),
``shear.png`` (the net coloured by shear angle), ``bundle/`` (the net on the drawn grid as a
forming bundle, so it compares like a measured part) and ``provenance.json``. The same in
Python: :func:`~fenicsx_drape.forming.running.kinematic.drape_case` (or ``kinematic_drape``) and
:func:`~fenicsx_drape.forming.running.kinematic.write_drape`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from fenicsx_drape.cli import positive_float
from fenicsx_drape.errors import DrapeInputError


def configure(parser: argparse.ArgumentParser) -> None:
    """Options of ``drape drape``."""
    from fenicsx_drape.forming.running.kinematic import GENERATORS

    parser.add_argument("case", metavar="CASE",
                        help="a case file (case.toml) or a named case: hemisphere (the "
                        "paper's), double_dome, square_box")
    parser.add_argument("--out", required=True, type=Path, help="output folder")
    parser.add_argument("--cell-mm", type=float, default=None,
                        help="cell size Δ (mm; default: the case's)")
    parser.add_argument("--start-mm", type=float, nargs=2, default=None,
                        metavar=("X", "Y"), help="start node on the flat sheet (mm), placed on "
                        "the highest surface point above it (default: the net's origin)")
    parser.add_argument("--direction-deg", type=float, default=None, metavar="ALPHA",
                        help="the warp's initial direction on the surface: its projection at "
                        "ALPHA to x (default: the ply angle)")
    parser.add_argument("--ply-angle-deg", type=float, default=None, metavar="THETA",
                        help="the tows at THETA to x on the blank (degrees; default: the "
                        "case's)")
    parser.add_argument("--generator", choices=GENERATORS, default="geodesic",
                        help="the generator tows through the start (default: geodesic)")
    parser.add_argument("--locking-angle-deg", type=float, default=None, metavar="GAMMA",
                        help="cells sheared beyond GAMMA lock: their last node is left out "
                        "(default: no limit)")
    parser.add_argument("--grid-mm", type=positive_float, default=10.0,
                        help="spacing of the drawn grid written to the bundle (mm)")
    parser.add_argument("--no-pictures", action="store_true", help="skip shear.png")


def run(args: argparse.Namespace) -> int:
    """Run ``drape drape``."""
    from fenicsx_drape.forming.running.kinematic import drape_case, write_drape

    if not args.grid_mm > 0:
        raise DrapeInputError(f"--grid-mm {args.grid_mm}: must be positive")
    options = {"start_mm": None if args.start_mm is None else tuple(args.start_mm),
               "direction_deg": args.direction_deg, "ply_angle_deg": args.ply_angle_deg,
               "generator": args.generator, "locking_angle_deg": args.locking_angle_deg,
               "warn": False}
    from fenicsx_drape.forming.case import case_dict, case_file, load_case

    path = case_file(args.case)
    if path.suffix.lower() != ".toml":
        raise DrapeInputError(f"{args.case!r}: not a case file (.toml) nor a named case")
    case = load_case(path)
    net = drape_case(case, cell_mm=args.cell_mm, **options)
    summary = write_drape(args.out, net, grid_mm=args.grid_mm, forming_case=case,
                          pictures=not args.no_pictures,
                          case=case_dict(case, relative_to=path.parent))
    print(f"kinematic drape: max shear {summary['max_shear_deg']:.1f}°, {summary['nodes']} "
          f"nodes" + (f", {summary['unplaced_nodes']} could not be placed (absent)"
                      if summary["unplaced_nodes"] else ""))
    print(f"summary: {args.out / 'summary.json'}"
          + ("" if args.no_pictures else f"; picture: {args.out / 'shear.png'}"))
    return 0
