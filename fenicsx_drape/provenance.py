"""Atomic output files and the record of how every output folder was made."""

from __future__ import annotations

import datetime
import hashlib
import json
import math
import os
import platform
import re
import sys
import tempfile
from pathlib import Path
from typing import Any

from fenicsx_drape import __version__

__all__ = ["atomic_write_bytes", "atomic_write_text", "file_digest", "json_text", "run_record",
           "save_figure", "toml_text", "write_json", "write_provenance"]

_digests: dict[tuple, str] = {}  # file digests by (path, size, modification time)


def file_digest(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes, read in blocks (memoised by path, size and time).

    Cache keys of inputs (a case's geometry files, a tool surface read): a file changed
    on disk gets a new key; a large one is never held in memory whole.
    """
    path = Path(path)
    stat = path.stat()
    key = (str(path), stat.st_size, stat.st_mtime_ns)
    if key not in _digests:
        with path.open("rb") as f:
            _digests[key] = hashlib.file_digest(f, "sha256").hexdigest()
    return _digests[key]


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file and a rename.

    A reader never sees a half-written file, and an interrupted run leaves the previous
    version in place.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) atomically, see :func:`atomic_write_bytes`."""
    return atomic_write_bytes(path, text.encode())


def json_text(obj: Any, *, indent: int | None = 2, sort_keys: bool = False) -> str:
    """``obj`` as valid JSON: NaN and ±infinity (no JSON value) become ``null``.

    The one place the project turns results into JSON: NumPy scalars and arrays, paths and
    sets are allowed; a missing value is ``null``, never ``NaN`` or ``Infinity``.
    """
    return json.dumps(_plain(obj), indent=indent, sort_keys=sort_keys, allow_nan=False)


def write_json(path: str | os.PathLike, obj: Any) -> Path:
    """Write ``obj`` as indented, valid JSON atomically (:func:`json_text`)."""
    return atomic_write_text(path, json_text(obj) + "\n")


def toml_text(data: dict, *, comment: str = "",
              notes: dict[tuple[str, str], str] | None = None) -> str:
    """``data`` as TOML text (the one writer of the project's TOML files: cases, bundles, models).

    Written by ``tomli_w``; NumPy values become Python ones, paths strings.

    Args:
        data: Tables as dicts (a list of dicts is an array of tables, ``[[test]]``).
        comment: Lines written first as ``#`` comments.
        notes: ``{(table, key): text}``: ``# text`` after that key's line (e.g. a unit);
            ``table`` is the dotted table name as in its header, ``""`` at the top.
    """
    import tomli_w

    plain = _toml_plain(data)
    # Arrays of tables as [[name]] blocks, as the formats' pages show them (tomli_w writes
    # short ones inline): each table dumped under its own header, which then says [[name]].
    tables = {k: v for k, v in plain.items()
              if isinstance(v, list) and v and all(isinstance(t, dict) for t in v)}
    chunks = [tomli_w.dumps({k: v for k, v in plain.items() if k not in tables})]
    for name, items in tables.items():
        chunks += [re.sub(rf"^\[{re.escape(name)}\]$", f"[[{name}]]",
                          tomli_w.dumps({name: item}), count=1, flags=re.M) for item in items]
    text = _inline_arrays("\n".join(c.strip("\n") + "\n" for c in chunks if c.strip()))
    if notes:
        table, lines = "", []
        for line in text.splitlines():
            if m := re.match(r"^\[\[?([^\]]+)\]\]?$", line):
                table = m.group(1)
            elif (m := re.match(r"^([A-Za-z0-9_-]+) = ", line)) and (table, m.group(1)) in notes:
                line += f"  # {notes[table, m.group(1)]}"
            lines.append(line)
        text = "\n".join(lines) + "\n"
    return "".join(f"# {line}\n" for line in comment.splitlines()) + text


# An array of scalars as ``tomli_w`` writes it: one item a line (no brackets in the items).
_ARRAY = re.compile(r"\[\n((?:[ ]+[^\n\[\]{}]+,\n)+)[ ]*\]")


def _inline_arrays(text: str) -> str:
    """Arrays of scalars on one line (``size_mm = [300.0, 200.0]``) where it fits 100 columns.

    ``tomli_w`` writes every array one item a line; the innermost arrays are joined first, so
    that a list of points becomes one point a line.
    """
    def join(m: re.Match) -> str:
        items = [line.strip().removesuffix(",") for line in m.group(1).splitlines()]
        inline = "[" + ", ".join(items) + "]"
        start = text.rfind("\n", 0, m.start()) + 1
        end = text.find("\n", m.end())
        rest = text[m.end():end if end >= 0 else len(text)]
        return inline if len(text[start:m.start()]) + len(inline) + len(rest) <= 100 else \
            m.group(0)

    while True:
        joined = _ARRAY.sub(join, text)
        if joined == text:
            return joined
        text = joined


def _toml_plain(obj: Any) -> Any:
    """Plain TOML values: NumPy scalars and arrays as Python ones, paths as strings."""
    if isinstance(obj, dict):
        return {str(k): _toml_plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_toml_plain(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "tolist"):
        return _toml_plain(obj.tolist())
    return obj


def save_figure(fig, path: str | os.PathLike, dpi: int = 150) -> Path:
    """Save a Matplotlib figure atomically as PNG and close it."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return atomic_write_bytes(path, buf.getvalue())


def _plain(obj: Any) -> Any:
    """Plain JSON values: non-finite floats as None, NumPy values as Python ones."""
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _plain(obj.tolist())
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, (set, frozenset)):
        return [_plain(v) for v in sorted(obj)]
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def run_record(**details: Any) -> dict[str, Any]:
    """How a result was made: version, command line, platform, time, plus ``details``.

    Pass the model (effects and parameters), the inputs and the random seed as ``details``.
    Where PETSc is loaded, the options in its database (``PETSC_OPTIONS``, ``--petsc-option``)
    are recorded too.
    """
    record = {
        "fenicsx_drape": __version__,
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "cwd": os.getcwd(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    try:
        import dolfinx

        record["dolfinx"] = dolfinx.__version__
    except ImportError:
        pass
    petsc = sys.modules.get("petsc4py.PETSc")
    if petsc is not None:  # not the per-solver defaults (fe/newton.py), only what was given
        record["petsc_options"] = {key: value or "" for key, value
                                   in petsc.Options().getAll().items()
                                   if not key.startswith("drape_")}
    record.update(details)
    return record


def write_provenance(out_dir: str | os.PathLike, **details: Any) -> Path:
    """Write ``provenance.json`` into ``out_dir`` (see :func:`run_record`)."""
    return write_json(Path(out_dir) / "provenance.json", run_record(**details))
