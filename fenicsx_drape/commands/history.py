"""``drape history DIR [DIR ...] [--out DIR]``: the ledger of model versions and their errors."""

from __future__ import annotations

import argparse


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the command's arguments."""
    parser.add_argument("dirs", nargs="+", metavar="DIR",
                        help="output folders of 'drape compare' (each holds a ledger.jsonl)")
    parser.add_argument("--out", default="history",
                        help="where to write history.png and history.json (default: ./history)")


def run(args: argparse.Namespace) -> int:
    """Print the table of versions and write the plot; returns the exit status."""
    from fenicsx_drape.diagnosis import history, history_table

    versions = history(args.dirs, out_dir=args.out)
    print(history_table(versions))
    print(f"written to {args.out}/history.png")
    return 0
