"""``drape form hemisphere``: form the paper's hemisphere and write fields, pictures, a bundle.

Example::

    ./drape form hemisphere --out results/hemisphere
    ./drape --np 2 form hemisphere --out results/full --full --cell-mm 5
    ./drape form hemisphere --out results/ply3 --full --ply-angle-deg 3

The outputs are listed in :mod:`fenicsx_drape.forming.outputs`; the same is one call in
Python: :func:`fenicsx_drape.forming.outputs.form_hemisphere`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fenicsx_drape.errors import DrapeInputError, SolverError

CASES = ("hemisphere",)


def configure(parser: argparse.ArgumentParser) -> None:
    """Options of ``drape form``."""
    parser.add_argument("case", choices=CASES, help="the forming case")
    parser.add_argument("--out", required=True, type=Path, help="output folder")
    parser.add_argument("--cell-mm", type=float, default=10.0, help="unit-cell size Δ (mm)")
    parser.add_argument("--duration-s", type=float, default=40.0,
                        help="forming time for the 80 mm travel (s)")
    parser.add_argument("--holder-force-N", type=float, default=133.0,
                        help="total blank-holder force on the whole sheet (N)")
    parser.add_argument("--mu", type=float, default=None,
                        help="textile-tool friction coefficient of eq. 1 (default: the model's)")
    parser.add_argument("--model", type=Path, default=None,
                        help="MODEL.toml (default: the paper's model, Table 2)")
    parser.add_argument("--with", dest="with_effects", action="append", default=[],
                        metavar="EFFECT", help="switch an effect on (repeatable), e.g. "
                        "tool_friction")
    parser.add_argument("--without", dest="without_effects", action="append", default=[],
                        metavar="EFFECT", help="switch an effect off (repeatable)")
    parser.add_argument("--full", action="store_true",
                        help="model the full sheet (default: a symmetric quarter)")
    parser.add_argument("--ply-angle-deg", type=float, default=0.0, metavar="THETA",
                        help="initial ply angle: the tows at THETA to the sheet's edges "
                        "(degrees; needs --full)")
    parser.add_argument("--no-die", action="store_true", help="leave the matched die out")
    parser.add_argument("--penalty-factor", type=float, default=0.3,
                        help="contact stiffness in units of l_t E_o (default 0.3)")
    parser.add_argument("--stabilisation", type=float, default=None, metavar="N_PER_MM",
                        help="out-of-plane stabilisation stiffness (default 1.25 N/mm)")
    parser.add_argument("--grid-mm", type=float, default=10.0,
                        help="spacing of the drawn grid written to the bundle (mm)")
    parser.add_argument("--no-fields", action="store_true",
                        help="skip the XDMF fields and tool meshes")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")


def run(args: argparse.Namespace) -> int:
    """Run ``drape form``."""
    from mpi4py import MPI

    from fenicsx_drape.forming.hemisphere import HemisphereCase
    from fenicsx_drape.forming.outputs import form_hemisphere
    from fenicsx_drape.model import default_model, load_model

    model = load_model(args.model) if args.model else default_model()
    if args.with_effects:
        model = model.with_effects(*args.with_effects)
    if args.without_effects:
        model = model.without_effects(*args.without_effects)
    if args.mu is not None:
        if not args.mu >= 0:
            raise DrapeInputError(f"--mu {args.mu}: a friction coefficient must be >= 0")
        model = model.with_parameters(mu=args.mu)
    extra = {} if args.stabilisation is None else {"stabilisation_N_per_mm": args.stabilisation}
    case = HemisphereCase(cell_mm=args.cell_mm, duration_s=args.duration_s,
                          holder_force_N=args.holder_force_N, quarter=not args.full,
                          die=not args.no_die, penalty_factor=args.penalty_factor,
                          ply_angle_deg=args.ply_angle_deg, **extra)
    rank0 = MPI.COMM_WORLD.rank == 0

    def progress(line: str) -> None:
        print(line, flush=True)

    try:
        _, result = form_hemisphere(args.out, case, model, grid_mm=args.grid_mm,
                                    fields=not args.no_fields,
                                    progress=None if args.quiet else progress)
    except SolverError as err:
        if rank0:
            print(f"drape form: the forming solve failed: {err}", file=sys.stderr)
        return 1
    if rank0:
        print(f"max shear {result['max_shear_deg']:.1f}°, total wrinkling "
              f"{100 * result['total_wrinkling_strain']:.2f} %, min wrinkling strain "
              f"{result['min_wrinkling_strain']:.3f}, {result['steps']} steps, "
              f"{result['snes_iterations']} Newton iterations, {result['wall_time_s']:.1f} s",
              file=sys.stderr if args.quiet else sys.stdout)
        print(f"pictures: {args.out / 'shear.png'}, {args.out / 'wrinkling.png'}, "
              f"{args.out / 'paths.png'}; summary: {args.out / 'summary.json'}")
    return 0
