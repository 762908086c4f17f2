"""``drape form``: form a case (a ``case.toml``, or a named one) and write its outputs.

Example::

    ./drape form meshes/hemisphere/case.toml --out results/case
    ./drape form my_part/case.toml --out out --cell-mm 5 --duration-s 20 --holder-force-N 300
    ./drape form hemisphere --out results/hemisphere
    ./drape --np 2 form hemisphere --out results/full --full --cell-mm 5
    ./drape form hemisphere --out results/ply3 --full --ply-angle-deg 3
    ./drape form meshes/double_dome/case.toml --out out --blank-offset-mm 8 0 --tool-offset-mm 0 2
    ./drape form double_dome --out out --lab-lines      # the bundle with shear lines and edge

``hemisphere`` is the paper's, ``meshes/hemisphere/case.toml``, formed like any case (and
``double_dome``, ``square_box``: every folder of ``meshes/`` with a ``case.toml``). The
outputs are listed in :mod:`fenicsx_drape.forming.running.outputs`; the same is one call in Python:
``form_case(out, load_case("hemisphere", cell_mm=5))``. Options given on the command line
override the case file's values
(:func:`~fenicsx_drape.forming.case.overrides.with_overrides`) before the case is checked. A
net fitted to the blank (a cell other than the one asked, or a side left partly out) is said
in a note; the paper's numbers are printed only for a run under the paper's conditions (any
other run on its tools says what differs). A set-up that breaks a symmetry plane of the case
(a turned ply, an offset blank or punch) is formed without that plane, and the command says
so.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fenicsx_drape.cli import petsc_option_argument, positive_float
from fenicsx_drape.errors import DrapeInputError, SolverError


def configure(parser: argparse.ArgumentParser) -> None:
    """Options of ``drape form``."""
    parser.add_argument("case", metavar="CASE",
                        help="a case file (case.toml, see docs/case-format.md) or a named "
                        "case: hemisphere (the paper's), double_dome, square_box")
    parser.add_argument("--out", required=True, type=Path, help="output folder")
    parser.add_argument("--cell-mm", type=float, default=None,
                        help="unit-cell size Δ (mm; default: the case's)")
    parser.add_argument("--duration-s", type=float, default=None,
                        help="forming time of the whole motion (s; default: the case's)")
    parser.add_argument("--holder-force-N", type=float, default=None,
                        help="total blank-holder force on the whole part (N; default: the "
                        "case's)")
    parser.add_argument("--holder-force-share", choices=("symmetric_part", "model"),
                        default=None,
                        help="eq. 1's reading: a symmetric model carries its share of the "
                        "force, symmetry-plane nodes counting ½ (symmetric_part, a case file's "
                        "default), or the whole force over the model's own nodes (model, as "
                        "the hemisphere's file says: docs/paper.md)")
    parser.add_argument("--mu", type=float, default=None,
                        help="textile-tool friction coefficient of eq. 1 (default: the case's "
                        "holder mu, else the model's)")
    parser.add_argument("--model", type=Path, default=None,
                        help="MODEL.toml (default: the case's, else the paper's, Table 2)")
    parser.add_argument("--with", dest="with_effects", action="append", default=[],
                        metavar="EFFECT", help="switch an effect on (repeatable), e.g. "
                        "tool_friction")
    parser.add_argument("--without", dest="without_effects", action="append", default=[],
                        metavar="EFFECT", help="switch an effect off (repeatable)")
    parser.add_argument("--full", action="store_true",
                        help="model the whole blank, without the case's symmetry planes")
    parser.add_argument("--ply-angle-deg", type=float, default=None, metavar="THETA",
                        help="initial ply angle: the tows at THETA to x (degrees; a ply "
                        "that breaks a symmetry plane of the case is formed without it)")
    parser.add_argument("--blank-offset-mm", type=float, nargs=2, default=None,
                        metavar=("X", "Y"), help="the blank (and its net) placed X, Y mm off "
                        "where the case puts it")
    parser.add_argument("--tool-offset-mm", type=float, nargs=2, default=None,
                        metavar=("X", "Y"), help="the punch misaligned by X, Y mm relative to "
                        "the die and holder")
    parser.add_argument("--no-die", action="store_true", help="leave the die(s) out")
    parser.add_argument("--penalty-factor", type=float, default=None,
                        help="contact stiffness in units of l_t E_o (default: the case's)")
    parser.add_argument("--stabilisation", type=float, default=None, metavar="N_PER_MM",
                        help="out-of-plane stabilisation stiffness (N/mm; default: the case's)")
    parser.add_argument("--step-mm", type=float, default=None,
                        help="travel of the fastest tool per load step (mm; default: the case's)")
    parser.add_argument("--grid-mm", type=positive_float, default=None,
                        help="spacing of the drawn grid written to the bundle (mm; default: "
                        "10 when the net's nodes lie on it, else the net's own cell)")
    parser.add_argument("--lab-lines", action="store_true",
                        help="the bundle's test also holds the model's shear along three "
                        "measuring lines and the blank's edge, as a lab's shear_points and "
                        "outline (docs/lab-measurements.md)")
    parser.add_argument("--no-fields", action="store_true",
                        help="skip the XDMF fields and tool meshes")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    petsc_option_argument(parser)


def _model(args: argparse.Namespace, default):
    from fenicsx_drape.model import load_model

    model = load_model(args.model) if args.model else default
    if args.with_effects:
        model = model.with_effects(*args.with_effects)
    if args.without_effects:
        model = model.without_effects(*args.without_effects)
    if args.mu is not None:
        if not args.mu >= 0:
            raise DrapeInputError(f"--mu {args.mu}: a friction coefficient must be >= 0")
        model = model.with_parameters(mu=args.mu)
    return model


def _offsets(args: argparse.Namespace) -> dict:
    return {k: tuple(v) for k, v in (("blank_offset_mm", args.blank_offset_mm),
                                     ("tool_offset_mm", args.tool_offset_mm)) if v is not None}


def _note_full(setup: dict, planes) -> None:
    from mpi4py import MPI

    from fenicsx_drape.forming.case import SETUP_OVERRIDES, broken_planes

    broken = sorted(broken_planes(setup) & set(planes))
    if broken and MPI.COMM_WORLD.rank == 0:
        text = ", ".join(f"{k} = {list(v) if isinstance(v, tuple) else v}"
                         for k, v in setup.items() if k in SETUP_OVERRIDES)
        print(f"drape form: note: {text} breaks the symmetry plane(s) "
              f"{' and '.join(p + ' = 0' for p in broken)}: modelled without them",
              file=sys.stderr)


def _case(args: argparse.Namespace):
    import dataclasses

    from fenicsx_drape.forming.case import case_file, load_case

    path = case_file(args.case)
    if path.suffix.lower() != ".toml":
        raise DrapeInputError(f"{args.case!r}: not a case file (.toml) nor a named case")
    case = load_case(path, cell_mm=args.cell_mm, duration_s=args.duration_s,
                     holder_force_N=args.holder_force_N,
                     holder_force_share=args.holder_force_share,
                     penalty_factor=args.penalty_factor,
                     stabilisation_N_per_mm=args.stabilisation, step_mm=args.step_mm,
                     ply_angle_deg=args.ply_angle_deg, symmetry=[] if args.full else None,
                     die=False if args.no_die else None, **_offsets(args))
    if not args.full:
        setup = {"ply_angle_deg": args.ply_angle_deg, **_offsets(args)}
        _note_full({k: v for k, v in setup.items() if v is not None},
                   _file_planes(path))
    if args.mu is not None and case.holder is not None and case.holder.mu is not None:
        # The command line wins over the case file's holder mu.
        case = dataclasses.replace(case, holder=dataclasses.replace(case.holder, mu=None))
    return case


def _file_planes(path: Path) -> tuple[str, ...]:
    """The symmetry planes the case file itself names (for the note on dropped planes)."""
    import tomllib

    try:
        return tuple(tomllib.loads(path.read_text(encoding="utf-8"))["blank"]["symmetry"])
    except (OSError, KeyError, TypeError, ValueError):
        return ()


def run(args: argparse.Namespace) -> int:
    """Run ``drape form``."""
    from mpi4py import MPI


    rank0 = MPI.COMM_WORLD.rank == 0

    def progress(line: str) -> None:
        print(line, flush=True)

    from fenicsx_drape.forming.running.outputs import (
        FormingOutputError,
        form_case,
        is_paper_hemisphere,
        kinematic_text,
    )
    from fenicsx_drape.forming.running.run import case_model

    try:
        case = _case(args)
        model = _model(args, case_model(case))
        _, result = form_case(args.out, case, model, grid_mm=args.grid_mm,
                              lab_lines=args.lab_lines, fields=not args.no_fields,
                              progress=None if args.quiet else progress)
    except SolverError as err:
        if rank0:
            print(f"drape form: the forming solve failed: {err}", file=sys.stderr)
        return 1
    except FormingOutputError as err:
        if rank0:
            print(f"drape form: error: {err}", file=sys.stderr)
        return 1
    if rank0:
        print(f"max shear {result['max_shear_deg']:.1f}°, total wrinkling "
              f"{100 * result['total_wrinkling_strain']:.2f} %, min wrinkling strain "
              f"{result['min_wrinkling_strain']:.3f}, {result['steps']} steps, "
              f"{result['snes_iterations']} Newton iterations, {result['wall_time_s']:.1f} s",
              file=sys.stderr if args.quiet else sys.stdout)
        if "note" in result.get("net", {}):
            print(f"note: {result['net']['note']}")
        hemisphere = is_paper_hemisphere(case)
        compared = hemisphere and result.get("paper_conditions", False)
        partial = not result.get("kinematic_complete", True)
        if hemisphere and not args.quiet:
            from fenicsx_drape.forming.paper.numbers import paper_comparison

            # The table (the kinematic drape's shear among its rows) under the paper's
            # conditions only; otherwise one line saying what differs.
            print(paper_comparison(result, model))
        if (not compared or partial) and result.get("kinematic_max_shear_deg") is not None:
            print(f"kinematic drape (pin-jointed net) on the same tools: "
                  f"{kinematic_text(result)}"
                  + (" (the tools end before the blank, or the net locks)" if partial else ""))
        for note in result.get("tool_force_notes", []):
            print(f"note: {note}")
        for name, why in result.get("outputs_left_out", {}).items():
            print(f"note: {name} left out ({why}); the other outputs are written")
        pictures = ["shear.png", "wrinkling.png", "kinematic_shear.png",
                    *(["paths.png"] if compared else [])]
        for k in range(1, len(result.get("plies", [])) + 1):  # a stack: each ply, the slip
            pictures += [f"shear_ply{k}.png", f"wrinkling_ply{k}.png"]
        pictures += ["interply.png"] if result.get("plies") else []
        pictures = [p for p in pictures if (args.out / p).is_file()]
        print(f"pictures: {', '.join(str(args.out / p) for p in pictures)}; summary: "
              f"{args.out / 'summary.json'}; formed sheet (drape probe): "
              f"{args.out / result.get('sheet_file', 'formed_sheet.csv')}")
    return 0
