"""The forming runs remembered on disk, by content, across commands.

A forming run depends on its case's content, the model, the solver options and the code:
:func:`run_key` turns them into a SHA-256 name, and :class:`RunStore` keeps each run's result
under it in a folder (``--cache DIR``; by default :func:`default_folder`) through diskcache.

A stored value proves what it is. It is NumPy arrays (``.npz``, no pickle: a cache folder is
read as data) behind their own SHA-256, and among the arrays the name the run was filed under
(which holds the code's digest). Every read checks both: a value whose bytes do not match
their checksum (truncated, scribbled, a byte flipped, half written), or that is another run's
(values swapped or moved between entries), or of another code, is a miss -- the run is formed
again and the entry replaced -- and a note says so; it is never a result. A database that
cannot be read is moved aside into a folder of its own inside the cache folder and a new one
made, with a note naming the folder to delete. Removing the cache folder clears the cache.
"""

from __future__ import annotations

import datetime
import functools
import hashlib
import io
import json
import os
import sqlite3
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
DAMAGED = "damaged-"  # the prefix of a folder a damaged database was moved into

# What a value can be found to be when read (RunStore.get): only "ok" is a result.
OK, ABSENT, DAMAGED_VALUE, OTHER_CODE, OTHER_RUN = (
    "ok", "absent", "damaged", "another code's", "another run's")


@functools.cache  # the code this process runs: files edited since are not what runs here
def code_digest() -> str:
    """SHA-256 of the package's version and the bytes of its source and data files.

    Any change of the code is another version: its runs are not the old ones. Read once in a
    process (at its first store).
    """
    root = Path(fenicsx_drape.__file__).parent
    h = hashlib.sha256(fenicsx_drape.__version__.encode())
    for path in sorted(p for p in root.rglob("*") if p.is_file()
                       and p.suffix in (".py", ".csv", ".toml", ".json")):
        h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


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


def run_key(parts: Any, code: str | None = None) -> str:
    """The name of a run in the store: SHA-256 of its inputs (JSON) and the code's digest."""
    text = json.dumps([parts, code or code_digest()], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def encode(grid: FormedGrid, stopped_mm: float | None, curves: dict[str, np.ndarray],
           key: str = "", code: str | None = None) -> bytes:
    """A run's result as bytes: its own SHA-256, then an ``.npz`` of its arrays.

    ``key`` is the name it is filed under (:func:`run_key`), kept inside: a value read under
    another name is another run's.
    """
    arrays = {"X": grid.X, "x": grid.x, "quarter": np.array(grid.quarter),
              "symmetry": np.array(["-"] if grid.symmetry is None else list(grid.symmetry) or
                                   [""]),
              "stopped_mm": np.array(np.nan if stopped_mm is None else stopped_mm),
              "code": np.array(code or code_digest()), "key": np.array(key),
              **{f"curve {k}": np.asarray(v) for k, v in curves.items()},
              **{f"ply{k} {a}": getattr(p, a) for k, p in enumerate(grid.plies, 1)
                 for a in ("X", "x")}}
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    payload = buffer.getvalue()
    return hashlib.sha256(payload).digest() + payload


def read_value(data: Any, key: str = "", code: str | None = None
               ) -> tuple[str, tuple[FormedGrid, float | None, dict[str, np.ndarray]] | None]:
    """What ``data`` is and the run it holds: ``(OK, run)``, else ``(why, None)``.

    ``why`` is :data:`DAMAGED_VALUE` (its bytes do not match their checksum or do not read),
    :data:`OTHER_CODE` or :data:`OTHER_RUN` (filed under a name not ``key``; not checked when
    ``key`` is empty).
    """
    from fenicsx_drape.forming.running.post import FormedGrid

    if not isinstance(data, bytes):
        return DAMAGED_VALUE, None
    digest, payload = data[:32], data[32:]
    if hashlib.sha256(payload).digest() != digest:
        return DAMAGED_VALUE, None
    try:
        with np.load(io.BytesIO(payload), allow_pickle=False) as z:
            if key and ("key" not in z.files or str(z["key"]) != key):
                return OTHER_RUN, None  # its key holds its code: checked first
            if str(z["code"]) != (code or code_digest()):
                return OTHER_CODE, None
            symmetry = [str(s) for s in z["symmetry"]]
            planes = None if symmetry == ["-"] else tuple(s for s in symmetry if s)
            plies = tuple(FormedGrid(z[f"ply{k} X"], z[f"ply{k} x"], bool(z["quarter"]), planes)
                          for k in range(1, 1 + sum(f.endswith(" X") and f.startswith("ply")
                                                    for f in z.files)))
            grid = FormedGrid(z["X"], z["x"], bool(z["quarter"]), planes, plies)
            stopped = float(z["stopped_mm"])
            curves = {k[len("curve "):]: z[k] for k in z.files if k.startswith("curve ")}
    except (ValueError, KeyError, OSError, EOFError):
        return DAMAGED_VALUE, None
    return OK, (grid, (None if np.isnan(stopped) else stopped), curves)


def decode(data: bytes, key: str = "", code: str | None = None
           ) -> tuple[FormedGrid, float | None, dict[str, np.ndarray]] | None:
    """The run :func:`encode` wrote; None if damaged, of another code or not ``key``'s run."""
    return read_value(data, key, code)[1]


def damaged(error: BaseException) -> bool:
    """Whether ``error`` is SQLite's word for a damaged database (not a busy or locked one)."""
    if not isinstance(error, sqlite3.DatabaseError):
        return False
    code = getattr(error, "sqlite_errorcode", None)
    if code is None:  # no code given: the plain DatabaseError is the damaged file's
        return type(error) is sqlite3.DatabaseError
    return code & 0xFF in (sqlite3.SQLITE_CORRUPT, sqlite3.SQLITE_NOTADB)


class RunStore:
    """Forming runs' results on disk under their :func:`run_key` (diskcache, ``folder``).

    A database that cannot be read (damaged) is moved aside into ``folder/damaged-TIME`` and a
    new one made, with a note naming the folder to delete. A folder that cannot be opened at
    all (no permission, a full disk) gives a note and the runs are formed as without a cache:
    :attr:`usable` is then False and the store is not recorded as the cache.

    Args:
        folder: The cache folder (made if absent).
        code: The code's digest (:func:`code_digest` by default): runs of another are not read.
        say: Where the notes go (one line each; default: standard error).

    Raises:
        DrapeInputError: ``folder`` is a file, or diskcache is not installed.
    """

    def __init__(self, folder: str | os.PathLike, code: str | None = None, say=None):
        self.folder = Path(folder)
        self.code = code or code_digest()
        self._say = say or (lambda line: print(f"drape: {line}", file=sys.stderr, flush=True))
        self.replaced: list[str] = []  # the names of the entries that were not what they said
        self.rebuilt = 0  # how many times a damaged database was replaced while in use
        if self.folder.exists() and not self.folder.is_dir():
            raise DrapeInputError(f"--cache {folder}: not a folder")
        try:
            import diskcache  # noqa: F401
        except ImportError:
            raise DrapeInputError(f"--cache {folder}: the run cache needs the diskcache "
                                  "package (Debian: python3-diskcache)") from None
        self._cache = self._open()

    @property
    def usable(self) -> bool:
        """Whether runs are kept in this folder (False: it could not be opened)."""
        return self._cache is not None

    def _open(self, again: bool = True):
        import diskcache

        try:
            cache = diskcache.Cache(str(self.folder), size_limit=SIZE_LIMIT,
                                    eviction_policy="least-recently-used")
            cache.get("")  # a database that opens but cannot be read is damaged too
            return cache
        except Exception as err:  # sqlite's and the file system's errors alike
            if damaged(err) and again and self._move_aside(err):
                return self._open(again=False)
            problem = err
        self._say(f"the run cache {self.folder} cannot be opened ({problem}): no run is kept "
                  "on disk")
        return None

    def _move_aside(self, err: Exception) -> bool:
        """Move the damaged database (every entry of the folder) into a folder of its own."""
        stamp = datetime.datetime.now(datetime.UTC).strftime("%Y%m%dT%H%M%S.%fZ")
        aside = self.folder / f"{DAMAGED}{stamp}"
        try:
            aside.mkdir()
            for entry in self.folder.iterdir():
                if entry != aside and not entry.name.startswith(DAMAGED):
                    entry.rename(aside / entry.name)
        except OSError as move_err:
            self._say(f"the run cache {self.folder} is damaged ({err}) and cannot be moved "
                      f"aside ({move_err}): delete the folder {self.folder}")
            return False
        self._say(f"the run cache {self.folder} was damaged ({err}): moved aside into "
                  f"{aside}, and a new one made (delete that folder: rm -r '{aside}')")
        return True

    def _rebuild(self, err: Exception) -> None:
        """A database found damaged while in use: closed, moved aside, a new one opened.

        The runs read from it before are not in the new one: its user puts them back
        (:attr:`rebuilt` counts the rebuilds).
        """
        try:
            self._cache.close()
        except Exception:  # a damaged database may not close cleanly: it is moved aside
            pass
        self._cache = self._open() if self._move_aside(err) else None
        self.rebuilt += 1

    def name(self, parts: Any) -> str:
        """The name of the run made of ``parts`` in this store (:func:`run_key`)."""
        return run_key(parts, self.code)

    def get(self, key: str) -> tuple[FormedGrid, float | None, dict] | None:
        """The run stored under ``key``; None if absent or not the run filed under ``key``.

        A value that is damaged or another run's is dropped with a note: the run is formed
        again and its entry replaced (:meth:`put`).
        """
        if self._cache is None:
            return None
        try:
            data = self._cache.get(key)
        except Exception as err:
            if damaged(err):
                self._rebuild(err)
                return None
            # the file system's (or a database locked too long): no run from it this time
            self._say(f"the run cache {self.folder} is not readable ({err}): runs are formed "
                      "again")
            return None
        if data is None:
            return None
        why, run = read_value(data, key, self.code)
        if run is None:
            self._note_replaced(key, why)
            self.discard(key)
        return run

    def _note_replaced(self, key: str, why: str) -> None:
        self.replaced.append(key)
        if len(self.replaced) == 1:  # one line; the count when the store closes
            self._say(f"the run cache {self.folder} holds, under {key[:16]}..., "
                      f"{'a damaged value' if why == DAMAGED_VALUE else why + ' result'}: "
                      "not used; the run is formed again and the entry replaced")

    def put(self, key: str, grid: FormedGrid, stopped_mm: float | None,
            curves: dict[str, np.ndarray]) -> None:
        """Store a run (a store that cannot be written loses the run, not the command)."""
        if self._cache is None:
            return
        data = encode(grid, stopped_mm, curves, key, self.code)
        try:
            self._cache.set(key, data)
        except Exception as err:
            if damaged(err):
                self._rebuild(err)
                if self._cache is not None:
                    self.put(key, grid, stopped_mm, curves)  # into the new database
                return
            self._say(f"the run cache {self.folder} is not writable ({err})")

    def discard(self, key: str) -> None:
        """Drop the entry under ``key`` (damaged, another run's or of another code)."""
        try:
            self._cache.delete(key)
        except Exception:  # nothing is lost: the entry is not used
            pass

    def __len__(self) -> int:
        return 0 if self._cache is None else len(self._cache)

    def close(self) -> None:
        """Close the database (and say how many entries were replaced, if more than one)."""
        if len(self.replaced) > 1:
            self._say(f"{len(self.replaced)} entries of the run cache {self.folder} were not "
                      "the runs filed under them: formed again and replaced")
            self.replaced.clear()
        if self._cache is not None:
            self._cache.close()
