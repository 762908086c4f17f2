"""``drape diagnose BUNDLE --model MODEL.toml --json REPORT.json [--out DIR]``.

Which physical effect is the model missing? Writes the report of the diagnosis contract
(``docs/measurements.md``; ``REPORT.json``'s ``contract`` is the spec's version). Exit status
0 when the report was written, whatever it concludes; 2 for bad input; 1 for an internal
failure.
"""

from __future__ import annotations

import argparse
import sys

from fenicsx_drape.cli import forming_runs_arguments, petsc_option_argument


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the command's arguments."""
    parser.add_argument("bundle", help="measurement bundle folder (or its bundle.toml)")
    parser.add_argument("--model", help="MODEL.toml (effects, plugins, starting parameters); "
                        "default: the paper's model with Table 2 parameters")
    parser.add_argument("--json", required=True, metavar="REPORT.json",
                        help="where to write the report")
    parser.add_argument("--out", help="folder for the plots of the candidates' gains")
    parser.add_argument("--forming-cell-mm", type=float, default=None, metavar="MM",
                        help="unit cell of the forming runs (default: a case's own cell_mm; "
                        "the hemisphere 10 mm, the paper's; a coarser mesh is only sound "
                        "where its error is below the noise)")
    parser.add_argument("--confirm-cell-mm", type=float, default=0.0, metavar="MM",
                        help="also refit the baseline and the winner on this mesh and compare "
                        "them with the forming tests there (e.g. 5; default: no)")
    parser.add_argument("--setup", nargs="*", default=None, metavar="PARAMETER",
                        help="the set-up candidates tried on forming tests before the effects "
                        "(default: all of ply_angle_deg, blank_offset_mm, holder_force_N, mu, "
                        "tool_offset_mm; none given: no set-up candidates)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    petsc_option_argument(parser)
    forming_runs_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Diagnose, write the report and print its summary; returns the exit status."""
    from fenicsx_drape.cli import forming_runs_setting, load_bundle_reported
    from fenicsx_drape.diagnosis import confirm, diagnose, summary, write_diagnosis
    from fenicsx_drape.errors import DrapeInputError
    from fenicsx_drape.model import default_model, load_model
    from fenicsx_drape.runs import resolution

    if ((args.forming_cell_mm is not None and not args.forming_cell_mm > 0)
            or not args.confirm_cell_mm >= 0):
        raise DrapeInputError(f"--forming-cell-mm {args.forming_cell_mm} must be > 0 and "
                              f"--confirm-cell-mm {args.confirm_cell_mm} >= 0 (mm)")
    bundle = load_bundle_reported(args.bundle)
    model = load_model(args.model) if args.model else default_model()
    progress = None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    forming = any(t.kind == "forming" for t in bundle.tests)
    with forming_runs_setting(args):  # provenance.json records its runs: written inside
        with resolution(args.forming_cell_mm):
            report = diagnose(bundle, model, progress=progress, setup=args.setup)
        if forming and args.confirm_cell_mm:
            report["confirmation"] = confirm(bundle, report, args.confirm_cell_mm, progress)
        write_diagnosis(report, args.json, args.out, bundle=bundle)
    print(summary(report))  # the conclusion once (first when data are suspect)
    for label, entry in report.get("confirmation", {}).items():
        if label != "cell_mm":
            print(f"confirmed on {args.confirm_cell_mm:g} mm cells, {label}: "
                  f"{entry['error']['normalised']:.2f} × noise")
    print(f"report written to {args.json}" + (f", plots to {args.out}" if args.out else ""))
    return 0
