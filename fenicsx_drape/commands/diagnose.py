"""``drape diagnose BUNDLE --model MODEL.toml --json REPORT.json [--out DIR]``.

Which physical effect is the model missing? Writes the report of the diagnosis contract
(version 2, ``shared/spec/measurements.md``). Exit status 0 when the report was written,
whatever it concludes; 2 for bad input; 1 for an internal failure.
"""

from __future__ import annotations

import argparse
import sys


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the command's arguments."""
    parser.add_argument("bundle", help="measurement bundle folder (or its bundle.toml)")
    parser.add_argument("--model", help="MODEL.toml (effects, plugins, starting parameters); "
                        "default: the paper's model with Table 2 parameters")
    parser.add_argument("--json", required=True, metavar="REPORT.json",
                        help="where to write the report")
    parser.add_argument("--out", help="folder for the plots of the candidates' gains")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")


def run(args: argparse.Namespace) -> int:
    """Diagnose, write the report and print its summary; returns the exit status."""
    from fenicsx_drape.bundle import load_bundle
    from fenicsx_drape.diagnose import diagnose, summary, write_diagnosis
    from fenicsx_drape.model import default_model, load_model

    bundle = load_bundle(args.bundle)
    model = load_model(args.model) if args.model else default_model()
    progress = None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    report = diagnose(bundle, model, progress=progress)
    write_diagnosis(report, args.json, args.out, bundle=bundle)
    print(summary(report))
    print(f"report written to {args.json}" + (f", plots to {args.out}" if args.out else ""))
    return 0
