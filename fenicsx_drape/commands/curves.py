"""``drape curves``: the characterisation curves of a model, as the paper's Figs. 2b and 6.

Writes into ``--out`` the tests simulated with the unit-cell solutions, the shear law through
a loading history, their pictures and ``provenance.json`` (:mod:`fenicsx_drape.curves`). The
same is one call in Python: :func:`~fenicsx_drape.curves.write_curves`.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from fenicsx_drape.curves import BIAS, effective_rate, write_curves
from fenicsx_drape.model import default_model, load_model


def configure(parser: argparse.ArgumentParser) -> None:
    """Options of ``drape curves``."""
    parser.add_argument("--model", type=Path, default=None,
                        help="MODEL.toml (default: the paper's model with Table 2)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")


def run(args: argparse.Namespace) -> int:
    """Run ``drape curves``."""
    model = load_model(args.model) if args.model else default_model()
    print("effective strain rates of the bias tests (eq. 23):")
    for speed in BIAS["speeds_mm_per_min"]:
        rate = effective_rate(speed)
        digits = 10 ** math.floor(math.log10(rate) - 1)
        print(f"  {speed:5g} mm/min: {rate:.6f} 1/s (the paper prints "
              f"{math.floor(rate / digits) * digits:.2g})")
    files = write_curves(model, args.out)
    for name in files:
        print(f"wrote {args.out / name}")
    return 0
