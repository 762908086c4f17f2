"""The forming runs remembered on disk, by content, across commands.

A forming run of compare or diagnose (:mod:`~fenicsx_drape.diagnosis.forming_runs`) depends
on its case's content, the model, the solver options and the code: :func:`run_key` turns
them into a SHA-256 name, and :class:`RunStore` keeps each run's result under it in a folder
(``--cache DIR``; by default :func:`default_folder`) through diskcache. A result is stored as
NumPy arrays (``.npz``, no pickle: a cache folder is read as data) behind its own SHA-256, with
the code's digest inside: an entry that is damaged, unreadable or from another code version
is ignored (and dropped), never trusted. Removing the folder clears the cache.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import fenicsx_drape
from fenicsx_drape.errors import DrapeInputError

if TYPE_CHECKING:
    from fenicsx_drape.forming.running.post import FormedGrid

CACHE_ENV = "DRAPE_CACHE"  # a folder, or "off": the default of --cache
SIZE_LIMIT = 2**32  # bytes kept before the least recently used runs go (diskcache's culling)
_code: list[str] = []  # the package's digest, computed once


def code_digest() -> str:
    """SHA-256 of the package's version and the bytes of its source and data files.

    Any change of the code is another version: its runs are not the old ones.
    """
    if not _code:
        root = Path(fenicsx_drape.__file__).parent
        h = hashlib.sha256(fenicsx_drape.__version__.encode())
        for path in sorted(p for p in root.rglob("*") if p.is_file()
                           and p.suffix in (".py", ".csv", ".toml", ".json")):
            h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
        _code.append(h.hexdigest())
    return _code[0]


def default_folder() -> Path | None:
    """The default cache folder: ``DRAPE_CACHE``, else ``$XDG_CACHE_HOME/fenicsx-drape/runs``.

    None when ``DRAPE_CACHE`` is ``off``.
    """
    given = os.environ.get(CACHE_ENV, "")
    if given.lower() == "off":
        return None
    if given:
        return Path(given)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "fenicsx-drape" / "runs"


def run_key(parts: Any) -> str:
    """The name of a run in the store: SHA-256 of its inputs (JSON) and the code's digest."""
    text = json.dumps([parts, code_digest()], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def encode(grid: FormedGrid, stopped_mm: float | None, curves: dict[str, np.ndarray]) -> bytes:
    """A run's result as bytes: its own SHA-256, then an ``.npz`` of its arrays."""
    arrays = {"X": grid.X, "x": grid.x, "quarter": np.array(grid.quarter),
              "symmetry": np.array(["-"] if grid.symmetry is None else list(grid.symmetry) or
                                   [""]),
              "stopped_mm": np.array(np.nan if stopped_mm is None else stopped_mm),
              "code": np.array(code_digest()),
              **{f"curve {k}": np.asarray(v) for k, v in curves.items()},
              **{f"ply{k} {a}": getattr(p, a) for k, p in enumerate(grid.plies, 1)
                 for a in ("X", "x")}}
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    payload = buffer.getvalue()
    return hashlib.sha256(payload).digest() + payload


def decode(data: bytes) -> tuple[FormedGrid, float | None, dict[str, np.ndarray]] | None:
    """The run :func:`encode` wrote, or None if ``data`` is damaged or of another code."""
    from fenicsx_drape.forming.running.post import FormedGrid

    digest, payload = data[:32], data[32:]
    if hashlib.sha256(payload).digest() != digest:
        return None
    try:
        with np.load(io.BytesIO(payload), allow_pickle=False) as z:
            if str(z["code"]) != code_digest():
                return None
            symmetry = [str(s) for s in z["symmetry"]]
            planes = None if symmetry == ["-"] else tuple(s for s in symmetry if s)
            plies = tuple(FormedGrid(z[f"ply{k} X"], z[f"ply{k} x"], bool(z["quarter"]), planes)
                          for k in range(1, 1 + sum(f.endswith(" X") and f.startswith("ply")
                                                    for f in z.files)))
            grid = FormedGrid(z["X"], z["x"], bool(z["quarter"]), planes, plies)
            stopped = float(z["stopped_mm"])
            curves = {k[len("curve "):]: z[k] for k in z.files if k.startswith("curve ")}
    except (ValueError, KeyError, OSError):
        return None
    return grid, (None if np.isnan(stopped) else stopped), curves


class RunStore:
    """Forming runs' results on disk under their :func:`run_key` (diskcache, ``folder``).

    A database that cannot be opened (damaged) is left alone with a warning: the runs are
    formed again, as without a cache.

    Raises:
        DrapeInputError: ``folder`` is a file, or diskcache is not installed.
    """

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        if self.folder.exists() and not self.folder.is_dir():
            raise DrapeInputError(f"--cache {folder}: not a folder")
        try:
            import diskcache
        except ImportError:
            raise DrapeInputError(f"--cache {folder}: the run cache needs the diskcache "
                                  "package (Debian: python3-diskcache)") from None
        try:
            self._cache = diskcache.Cache(str(self.folder), size_limit=SIZE_LIMIT,
                                          eviction_policy="least-recently-used")
        except Exception as err:  # sqlite's and the file system's errors alike
            print(f"drape: the run cache {folder} cannot be opened ({err}): no run is kept",
                  file=sys.stderr)
            self._cache = None

    def get(self, key: str) -> tuple[FormedGrid, float | None, dict] | None:
        """The run stored under ``key``, None if absent, damaged or of another code."""
        if self._cache is None:
            return None
        try:
            data = self._cache.get(key)
        except Exception as err:  # a damaged database: no run from it
            print(f"drape: the run cache {self.folder} is not readable ({err}): runs are "
                  "formed again", file=sys.stderr)
            return None
        if data is None:
            return None
        run = decode(data) if isinstance(data, bytes) else None
        if run is None:
            self.discard(key)
        return run

    def put(self, key: str, grid: FormedGrid, stopped_mm: float | None,
            curves: dict[str, np.ndarray]) -> None:
        """Store a run (a store that cannot be written loses the run, not the command)."""
        if self._cache is None:
            return
        try:
            self._cache.set(key, encode(grid, stopped_mm, curves))
        except Exception as err:
            print(f"drape: the run cache {self.folder} is not writable ({err})", file=sys.stderr)

    def discard(self, key: str) -> None:
        """Drop the entry under ``key`` (damaged or of another code)."""
        try:
            self._cache.delete(key)
        except Exception:  # nothing is lost: the entry is not used
            pass

    def __len__(self) -> int:
        return 0 if self._cache is None else len(self._cache)

    def close(self) -> None:
        """Close the database."""
        if self._cache is not None:
            self._cache.close()
