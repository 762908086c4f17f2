"""``drape probe``: the model's values at a lab's points, from the output of ``drape form``.

Example::

    ./drape form double_dome --cell-mm 20 --out results/dd
    ./drape probe results/dd --points demos/probe/points.csv --out results/dd/points.csv
    ./drape probe results/dd --edge demos/probe/edge.csv --out results/dd/edge.csv

``FORMED`` is the output folder of ``drape form`` (its ``formed_sheet.csv`` and
``summary.json``). ``--points``: points of the formed part (``x_mm, y_mm, z_mm``) or of the
flat blank (``x0_mm, y0_mm``), with any of ``label``, ``line``, ``s_mm``, ``ply`` passed
through; ``--edge``: points of the blank's edge after forming (``x_mm, y_mm``, optional
``z_mm``). The values are those ``drape compare`` reads for the same measurement (shear by the
lab's definition, distance to the sheet or the edge, draw-in); the same is one call in
Python: :func:`~fenicsx_drape.forming.running.measure.probe`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fenicsx_drape.cli import positive_int


def configure(parser: argparse.ArgumentParser) -> None:
    """Options of ``drape probe``."""
    parser.add_argument("formed", metavar="FORMED", type=Path,
                        help="the output folder of 'drape form'")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--points", type=Path, metavar="CSV",
                      help="points of the formed part (x_mm, y_mm, z_mm) or of the flat "
                      "blank (x0_mm, y0_mm): the model's shear, positions and draw-in there")
    what.add_argument("--edge", type=Path, metavar="CSV",
                      help="points of the blank's edge after forming (x_mm, y_mm, optional "
                      "z_mm): their distance to the model's edge and its draw-in there")
    parser.add_argument("--ply", type=positive_int, default=None, metavar="K",
                        help="the ply of a stack (1: the punch side; default: the ply away "
                        "from the punch, as a camera sees it; a ply column wins)")
    parser.add_argument("--out", type=Path, default=None,
                        help="the CSV to write (default: printed)")


def run(args: argparse.Namespace) -> int:
    """Run ``drape probe``."""
    import numpy as np

    from fenicsx_drape.forming.running.measure import probe, read_formed, write_values

    formed = read_formed(args.formed)
    source = args.edge if args.edge is not None else args.points
    values = probe(formed, source, edge=args.edge is not None, ply=args.ply)
    kind = "edge points" if args.edge is not None else "points"
    comment = (f"drape probe {args.formed} --{'edge' if args.edge else 'points'} {source}: the "
               f"model's values at the {kind} (case {formed.case_name!r})")
    text = write_values(values, args.out, comment=comment)
    if args.out is None:
        sys.stdout.write(text)
    unmatched = int(np.sum(values["unmatched"]))
    n = len(values["unmatched"])
    ok = values["unmatched"] == 0
    said = [f"{n} {kind}"]
    if "shear_deg" in values and ok.any():
        γ = values["shear_deg"][ok]
        said.append(f"shear {γ.min():.2f}° to {γ.max():.2f}°")
    if args.edge is not None and ok.any():
        d = values["distance_mm"][ok]
        said.append(f"distance to the model's edge {d.min():.2f} to {d.max():.2f} mm")
    if ok.any():
        w = values["draw_in_mm"][ok]
        said.append(f"draw-in {w.min():.2f} to {w.max():.2f} mm")
    if unmatched:
        said.append(f"{unmatched} unmatched (off the blank or farther than 2 cells: NaN)")
    where = f"; written to {args.out}" if args.out is not None else ""
    print(f"drape probe: {', '.join(said)}{where}", file=sys.stderr)
    return 0
