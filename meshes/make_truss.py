"""Write the truss meshes of the woven sheet used by the paper's cases.

    ./drape exec python3 meshes/make_truss.py [--out meshes]

Writes the quarter model of the 240 mm sheet at Δ = 10 mm (the paper's 169 nodes) into
``quarter_10mm/`` as Gmsh ``.msh`` and meshio ``.xdmf`` with bar-kind and node-set groups (see
``fenicsx_drape/fe/grid.py``); ``--full`` adds the full sheet. The same as ``drape mesh``;
the solver builds its meshes in memory and needs none of these files.
"""

import argparse
from pathlib import Path

from fenicsx_drape.commands.mesh import write_sheet

CASES = {"quarter_10mm": {"cell_mm": 10.0, "quarter": True}}
FULL = {"full_10mm": {"cell_mm": 10.0, "quarter": False}}

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).parent)
    parser.add_argument("--full", action="store_true", help="also the full sheet")
    args = parser.parse_args()
    for name, case in (CASES | FULL if args.full else CASES).items():
        for path in write_sheet(args.out / name, 240.0, **case):
            print(path)
