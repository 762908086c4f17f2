"""What input may run code: data never does, unless the user says they trust it.

A measurement bundle, and any case or model it brings, is *data*: the Python geometry
(``.py``) of its case's tools and the ``plugins`` of a model its case names are refused, with
the file named, unless the user trusts them (``--trust`` on the command line, ``DRAPE_TRUST=1``
in the environment, or :func:`trusting` in Python). A case file or a MODEL.toml the user names
directly may run its own ``.py`` geometry and plugins: naming it is saying so.

Gmsh scripts (``.geo``) are data in every case: a command that reaches the shell
(``SystemCall``, ``OnelabRun``...), writes or removes files (``Save``, ``Print``,
``Printf > "file"``, ``CreateDir``...) or hands a file to another program (``Merge "x.py"``)
is refused unless the user trusts it (:func:`geo_problems`). No geometry needs any of them.

The switch is an environment variable so that worker processes inherit it.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterator
from pathlib import Path

from fenicsx_drape.errors import DrapeInputError

__all__ = ["GEO_DENIED", "GEO_READABLE", "TRUST_ENV", "UntrustedCodeError", "add_trust_option",
           "apply_trust_option", "check_geo", "geo_defines", "geo_problems", "require_trust",
           "set_trusted", "trusted", "trusting"]

TRUST_ENV = "DRAPE_TRUST"


class UntrustedCodeError(DrapeInputError):
    """Input would run code (or reach the shell) and the user has not said they trust it."""


def trusted() -> bool:
    """Whether the user trusts the input's code (``--trust``, ``DRAPE_TRUST=1``)."""
    return os.environ.get(TRUST_ENV, "") not in ("", "0")


def set_trusted(on: bool) -> None:
    """Trust (or stop trusting) the input's code for the rest of the process and its workers."""
    if on:
        os.environ[TRUST_ENV] = "1"
    else:
        os.environ.pop(TRUST_ENV, None)


@contextlib.contextmanager
def trusting(on: bool = True) -> Iterator[None]:
    """Trust the input's code inside the ``with`` block (the Python form of ``--trust``)."""
    before = os.environ.get(TRUST_ENV)
    set_trusted(on)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(TRUST_ENV, None)
        else:
            os.environ[TRUST_ENV] = before


def require_trust(path: str | os.PathLike, what: str, origin: str | None) -> None:
    """Refuse to run ``what`` in ``path`` when it came with data (``origin``), untrusted.

    Args:
        path: The file that would run.
        what: What it is ("Python geometry", "model plugin").
        origin: Where it came from when that is data (e.g. "the measurement bundle
            /data/b/bundle.toml"); None when the user named it directly.

    Raises:
        UntrustedCodeError: ``origin`` is data and the user did not pass ``--trust``.
    """
    if origin is None or trusted():
        return
    raise UntrustedCodeError(
        f"{path}: {what} that comes with {origin} would run as a program; data does not run "
        "code unless you trust it: pass --trust (or set DRAPE_TRUST=1) if you do")


def add_trust_option(parser) -> None:
    """Add ``--trust`` to a command's argument parser (:func:`apply_trust_option` reads it)."""
    parser.add_argument(
        "--trust", action="store_true",
        help="let the input run code: the Python geometry and model plugins a bundle's case "
        "brings, and .geo commands that reach the shell or write files (docs/untrusted-input.md)")


def apply_trust_option(args) -> None:
    """Switch trust on when the command line said ``--trust``."""
    if getattr(args, "trust", False):
        set_trusted(True)


# --------------------------------------------------------------------------------------------
# Gmsh scripts

# Commands of Gmsh's .geo language that run programs, talk to servers, or write, move or
# remove files (Gmsh 4.15's parser); and options that name programs to run.
GEO_DENIED = ("SystemCall", "NonBlockingSystemCall", "OnelabRun", "OnelabAction", "Shell",
              "SendToServer", "Save", "Print", "Printf", "CreateDir", "DeleteFile",
              "RenameFile", "Exit", "Abort", "Solver", "Plugin")
# Files a .geo may read: other .geo scripts (checked the same way), meshes and CAD. Merging
# anything else (a .py, a .pro) makes Gmsh run it as a ONELAB client.
GEO_READABLE = (".geo", ".geo_unrolled", ".msh", ".step", ".stp", ".iges", ".igs", ".brep",
                ".stl", ".pos")
_READS = ("Include", "Merge", "MergeWithBoundingBox", "ShapeFromFile")
_COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/", re.S)
_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')
_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _code(text: str) -> str:
    """The script with comments removed and string literals emptied (line numbers kept)."""
    def blank(m: re.Match) -> str:
        return re.sub(r"[^\n]", " ", m.group(0))

    out, pos = [], 0
    # Comments and strings in one left-to-right pass: a "//" inside a string is not a comment.
    for m in re.finditer(r'//[^\n]*|/\*.*?\*/|"(?:[^"\\\n]|\\.)*"', text, re.S):
        out.append(text[pos:m.start()])
        s = m.group(0)
        out.append('""' + " " * (len(s) - 2) if s.startswith('"') else blank(m))
        pos = m.end()
    out.append(text[pos:])
    return "".join(out)


def geo_problems(path: str | os.PathLike, _seen: set[Path] | None = None) -> list[str]:
    """What in a Gmsh script (and the scripts it includes) would reach beyond geometry.

    Returns one ``file:line: problem`` per command that runs a program, writes or removes a
    file, or reads a file Gmsh would run (or a file named by a computed string); empty when
    the script only makes geometry and meshes.
    """
    path = Path(path).resolve()
    seen = set() if _seen is None else _seen
    if path in seen:
        return []
    seen.add(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as err:
        return [f"{path}: cannot read it ({err.strerror})"]
    code = _code(text)
    problems = []
    for m in _WORD.finditer(code):
        word = m.group(0)
        line = code.count("\n", 0, m.start()) + 1
        if word == "Printf" and not re.match(r"[^;]*\)\s*>", code[m.end():]):
            continue  # a message, not a file: Printf("...") > "file" writes one
        if word in GEO_DENIED:
            problems.append(f"{path}:{line}: the command {word!r} runs a program or writes "
                            "files: no geometry needs it")
        elif word in _READS:
            literal = _STRING.match(text, _skip(text, m.end()))
            if literal is None:
                problems.append(f"{path}:{line}: {word} of a computed file name (only a "
                                "plain \"file\" can be checked)")
                continue
            name = literal.group(0)[1:-1]
            target = (path.parent / name).resolve()
            if target.suffix.lower() not in GEO_READABLE:
                problems.append(f"{path}:{line}: {word} \"{name}\": Gmsh would run it (files "
                                f"it may read: {', '.join(GEO_READABLE)})")
            elif target.suffix.lower() in (".geo", ".geo_unrolled") and target.is_file():
                problems += geo_problems(target, seen)
    return problems


def _skip(text: str, pos: int) -> int:
    """The position after blanks and an opening parenthesis (``ShapeFromFile("x")``)."""
    while pos < len(text) and text[pos] in " \t\r\n(":
        pos += 1
    return pos


def check_geo(path: str | os.PathLike) -> None:
    """Refuse a Gmsh script that reaches beyond geometry, unless trusted (:func:`geo_problems`).

    Raises:
        UntrustedCodeError: listing every such command with its file and line.
    """
    if trusted():
        return
    problems = geo_problems(path)
    if problems:
        raise UntrustedCodeError(
            "\n  ".join([f"{path}: the Gmsh script reaches beyond geometry; pass --trust (or "
                         "set DRAPE_TRUST=1) to run it anyway:", *problems]))


def geo_defines(path: str | os.PathLike, name: str, _seen: set[Path] | None = None) -> bool:
    """Whether a Gmsh script (or a script it includes) uses the parameter ``name``.

    A plain name must appear as a word of the script's code; a ONELAB name (with a ``/``)
    as a string (``DefineConstant[r = {60, Name "Parameters/r"}]``).
    """
    path = Path(path).resolve()
    seen = set() if _seen is None else _seen
    if path in seen or not path.is_file():
        return False
    seen.add(path)
    text = path.read_text(encoding="utf-8", errors="replace")
    if "/" in name:
        if f'"{name}"' in _COMMENT.sub("", text):
            return True
    elif name in _WORD.findall(_code(text)):
        return True
    for m in re.finditer(r'\bInclude\s*"([^"]*)"', _code_keep_strings(text)):
        if geo_defines(path.parent / m.group(1), name, seen):
            return True
    return False


def _code_keep_strings(text: str) -> str:
    return _COMMENT.sub("", text)
