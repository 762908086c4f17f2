"""``drape mesh``: the truss mesh of the woven sheet, written with Gmsh and meshio.

Writes into ``--out`` the sheet (or its symmetric quarter) of square unit cells: tow bars along
warp and weft, the two crossing diagonals of every cell (no node at the crossing), physical
groups for the bar kinds and the symmetry edges and border (see
:mod:`fenicsx_drape.fe.grid`), as ``sheet.msh`` (Gmsh) and ``sheet.xdmf`` (meshio), plus
``provenance.json``. ``drape mesh --cell-mm 10 --quarter --out meshes/quarter_10mm`` gives the
paper's 169-node quarter model.

The same is one call in Python: :func:`write_sheet`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from fenicsx_drape.fe.grid import sheet_grid, write_grid
from fenicsx_drape.provenance import write_provenance


def write_sheet(out: str | Path, size_mm: float = 240.0, cell_mm: float = 10.0,
                quarter: bool = False, rotation_deg: float = 0.0,
                formats: tuple[str, ...] = (".msh", ".xdmf")) -> list[Path]:
    """Write the sheet's truss mesh as ``out/sheet<suffix>`` for each format; returns paths.

    Args:
        out: Output folder.
        size_mm: Side of the square sheet (mm).
        cell_mm: Unit-cell size Δ (mm), adjusted to fit a half side.
        quarter: Only the quarter x, y >= 0 (symmetry edges on x = 0 and y = 0).
        rotation_deg: Turn the sheet about z (degrees).
        formats: File suffixes (``.msh`` by Gmsh; ``.xdmf``, ``.vtu``... by meshio).
    """
    grid = sheet_grid(size_mm, cell_mm, quarter, rotation_deg)
    out = Path(out)
    paths = [write_grid(grid, out / f"sheet{suffix}") for suffix in formats]
    write_provenance(out, sheet={"size_mm": size_mm, "cell_mm": grid.cell_mm,
                                 "quarter": quarter, "rotation_deg": rotation_deg,
                                 "nodes": (grid.nx + 1) * (grid.ny + 1),
                                 "cells": grid.nx * grid.ny})
    return paths


def configure(parser: argparse.ArgumentParser) -> None:
    """Options of ``drape mesh``."""
    parser.add_argument("--out", required=True, type=Path, help="output folder")
    parser.add_argument("--size-mm", type=float, default=240.0, help="sheet side (mm)")
    parser.add_argument("--cell-mm", type=float, default=10.0, help="unit-cell size Δ (mm)")
    parser.add_argument("--quarter", action="store_true", help="one symmetric quarter")
    parser.add_argument("--rotation-deg", type=float, default=0.0,
                        help="turn the sheet about z (degrees)")
    parser.add_argument("--format", nargs="+", default=[".msh", ".xdmf"],
                        help="file suffixes to write (default: .msh .xdmf)")


def run(args: argparse.Namespace) -> int:
    """Write the mesh files and say where they are."""
    formats = tuple(f if f.startswith(".") else f".{f}" for f in args.format)
    for path in write_sheet(args.out, args.size_mm, args.cell_mm, args.quarter,
                            args.rotation_deg, formats):
        print(path)
    return 0
