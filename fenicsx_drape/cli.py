"""The ``drape`` command line: ``python3 -m fenicsx_drape COMMAND ...``.

Each command lives in ``fenicsx_drape/commands/<name>.py`` with two functions,
``configure(parser)`` and ``run(args) -> int``; it is imported only when called, so the
commands that need no DOLFINx start fast and work without it.

Exit status: 0 success, 2 bad input (the message names the file, line or parameter),
1 internal failure.

The commands that form (``form``, ``compare``, ``diagnose``) take ``--petsc-option`` for SNES
(:func:`petsc_option_argument`; ``docs/solver.md``); ``compare`` and ``diagnose`` take
``--workers`` and ``--cache`` for their many runs (:func:`forming_runs_arguments`;
``docs/scale.md``).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import traceback
import warnings
from types import ModuleType

from fenicsx_drape import __version__
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.trust import add_trust_option, apply_trust_option

COMMANDS: dict[str, str] = {
    "curves": "tensile and bias-extension curves of a model (the paper's Figs. 2b and 6)",
    "fit": "fit a model's parameters to a measurement bundle (section 3.2)",
    "compare": "fit, then show how far and where a model misses a bundle",
    "diagnose": "find which physical effect a model is missing (REPORT.json contract)",
    "history": "the ledger of model versions and their errors",
    "form": "run a forming case (case.toml, or hemisphere): fields, pictures, a bundle",
    "probe": "the model's shear, positions and draw-in at a lab's points, from drape form",
    "drape": "kinematic (pin-jointed net) drape of a case's formed surface",
    "mesh": "build a truss mesh of the woven sheet with Gmsh and write it",
}


def _top_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="drape",
        description="Forming and wrinkling of woven prepregs: the truss model of Skordos, "
        "Monroy Aceves & Sutcliffe on FEniCSx.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="commands:\n"
        + "\n".join(f"  {name:<10} {text}" for name, text in COMMANDS.items())
        + "\n\n'drape COMMAND --help' gives a command's options.",
    )
    parser.add_argument("--version", action="version", version=f"fenicsx_drape {__version__}")
    parser.add_argument("command", metavar="COMMAND", help="one of: " + ", ".join(COMMANDS))
    return parser


class _HelpFormatter(argparse.HelpFormatter):
    """argparse's help, its lines broken at spaces only (a path keeps its hyphens whole)."""

    def _split_lines(self, text, width):
        import textwrap

        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)


def command_parser(name: str) -> tuple[ModuleType, argparse.ArgumentParser]:
    """The module of command ``name`` (one of :data:`COMMANDS`) and its argument parser."""
    module = importlib.import_module(f"fenicsx_drape.commands.{name}")
    parser = argparse.ArgumentParser(prog=f"drape {name}", description=COMMANDS[name],
                                     formatter_class=_HelpFormatter)
    module.configure(parser)
    add_trust_option(parser)  # the same rule in every command (fenicsx_drape.trust)
    return module, parser


HELP_COLUMNS = 80  # the width of the CLI page's help (docs/cli.md): a code block's


def help_text(name: str, columns: int = HELP_COLUMNS) -> str:
    """Command ``name``'s ``--help`` as a terminal ``columns`` wide prints it (the CLI page's).

    The text is the machine's own only in the terminal's width: no option's help names this
    machine's cores, memory or paths.
    """
    import os

    before = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(columns)  # argparse wraps at the terminal's width
    try:
        return command_parser(name)[1].format_help()
    finally:
        if before is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = before


def petsc_option_argument(parser: argparse.ArgumentParser) -> None:
    """``--petsc-option OPTION`` (repeatable): PETSc options for the load steps' SNES.

    With it, every forming command takes ``--max-steps`` (:mod:`fenicsx_drape.limits`).
    """
    from fenicsx_drape.limits import max_steps_argument

    max_steps_argument(parser)
    parser.add_argument("--petsc-option", dest="petsc_options", action="append", default=[],
                        metavar="OPTION", help="PETSc options for the forming solves, e.g. "
                        "'-snes_type newtontr' or --petsc-option=-log_view (repeatable; "
                        "docs/solver.md)")


def forming_runs_arguments(parser: argparse.ArgumentParser) -> None:
    """``--workers``, ``--cache``, ``--no-cache``, ``--ranks-per-run``: where runs go, kept."""
    parser.add_argument("--workers", type=positive_int, default=None, metavar="N",
                        help="processes forming at once (default: DRAPE_WORKERS, else one "
                        "per core; under 'python3 -m mpi4py.futures' the job's other ranks). "
                        "More than the cores (given here or in DRAPE_WORKERS) is capped to them, "
                        "with a note: a run is one "
                        "process's work, and a worker beyond the cores only waits, holding "
                        "DOLFINx and a run in memory")
    parser.add_argument("--cache", metavar="DIR", default=None,
                        help="folder keeping the forming runs across commands, by content "
                        "(default: DRAPE_CACHE, else $XDG_CACHE_HOME/fenicsx-drape/runs; "
                        "remove it to clear it). Each run read is checked to be the run "
                        "asked for; a damaged database is moved aside into DIR/damaged-TIME, "
                        "with a note")
    parser.add_argument("--no-cache", action="store_true", help="keep no forming run on disk")
    parser.add_argument("--ranks-per-run", type=positive_int, default=None, metavar="K",
                        help="under plain mpirun: each run on K ranks, (ranks / K) runs at "
                        "once (default: every run on all ranks, one after the other)")


def forming_runs_setting(args: argparse.Namespace, cell_mm: float | None = None):
    """The :class:`~fenicsx_drape.runs.Runs` the options ask for (``with`` it: current).

    ``--workers`` above the cores is capped to them with a note; ``cell_mm``: the forming
    runs' cells (``--forming-cell-mm``; None: each case's own).
    """
    from fenicsx_drape.runs import Runs, capped, default_folder

    cache = None if args.no_cache else (args.cache or default_folder())
    return Runs(capped(args.workers), cache, ranks_per_run=args.ranks_per_run, cell_mm=cell_mm)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    top = _top_parser()
    if not argv or argv[0] in ("-h", "--help"):
        top.print_help()
        return 0 if argv else 2
    if argv[0] == "--version":
        print(f"fenicsx_drape {__version__}")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        top.print_usage(sys.stderr)
        print(f"drape: error: unknown command {name!r} (choose from {', '.join(COMMANDS)})",
              file=sys.stderr)
        return 2
    module, parser = command_parser(name)
    args = parser.parse_args(rest)  # exits 2 on bad options
    if "mpi4py.futures._core" in sys.modules:  # rank 0 of python3 -m mpi4py.futures
        from fenicsx_drape.runs.mpi import petsc_alone, shared_pool

        if shared_pool():
            petsc_alone()
    apply_trust_option(args)
    try:
        from fenicsx_drape.limits import apply_max_steps

        apply_max_steps(args)
        if getattr(args, "petsc_options", None):
            from fenicsx_drape.fe.newton import set_petsc_options

            set_petsc_options(args.petsc_options)
        with warnings.catch_warnings():  # an old name read: a note, as the command's own
            warnings.showwarning = _old_name_notes(warnings.showwarning)
            return int(module.run(args) or 0)
    except DrapeInputError as err:
        print(f"drape {name}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as err:  # Ctrl-C: what was kept, in one line (no traceback)
        kept = "; ".join(getattr(err, "__notes__", ()))
        print(f"drape {name}: interrupted" + (f"; {kept}" if kept else ""), file=sys.stderr,
              flush=True)
        return 130
    except Exception:
        traceback.print_exc()
        print(f"drape {name}: internal error (see the traceback above)", file=sys.stderr)
        return 1


def _old_name_notes(show):
    """A ``warnings.showwarning`` that prints the package's notes of an earlier name read.

    The package's :class:`FutureWarning` of a renamed key becomes one line, ``drape: note:
    case.toml: [holder] 'force_N' is now called 'holder_force_N' (...)``; any other warning
    goes to ``show``.
    """
    def note(message, category, filename, lineno, file=None, line=None) -> None:
        if issubclass(category, FutureWarning) and " is now called " in str(message):
            print(f"drape: note: {message}", file=sys.stderr if file is None else file)
        else:
            show(message, category, filename, lineno, file, line)

    return note


def positive_float(text: str) -> float:
    """An ``argparse`` type: a positive, finite number (refused up front, exit status 2)."""
    import math

    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number")
    return value


def positive_int(text: str) -> int:
    """An ``argparse`` type: a whole number >= 1 (refused up front, exit status 2)."""
    if not (text.strip().isdigit() and int(text) >= 1):
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number >= 1")
    return int(text)


def load_bundle_reported(path):
    """Load a measurement bundle and print what it kept beyond the spec (unknown keys).

    The spec's rule: unknown keys are kept and reported, never silently dropped; every
    command that reads a bundle reads it through here. The case files its forming tests
    name are read and checked with it.
    """
    from fenicsx_drape.forming.case import case_for_test
    from fenicsx_drape.measurements.bundle import load_bundle

    bundle = load_bundle(path, read_case=case_for_test)
    for line in bundle.report().splitlines():
        print(f"note: {line}", file=sys.stderr)
    return bundle
