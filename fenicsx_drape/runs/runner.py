"""A :class:`Runs`: the forming runs of a command, remembered, and the executor that forms them.

Everything the runs of a command share lives in the one object the caller owns: the runs in
memory, the disk store (:class:`~fenicsx_drape.runs.store.RunStore`), the executor and its
warm workers (:mod:`~fenicsx_drape.runs.pools`), the counts of :meth:`Runs.record`, the
cells a :meth:`Runs.resolution` sets and the spare jobs a :meth:`Runs.spare` names (the last
two in context variables of the object's own, as each call of :meth:`Runs.together` may set
its own). The module-level functions of :mod:`fenicsx_drape.runs` ask the *current* one
(:func:`current`): the one a ``with`` block made current, else the process's default.
"""

from __future__ import annotations

import contextlib
import contextvars
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.runs import pools as ex
from fenicsx_drape.runs.keys import describe, key_of
from fenicsx_drape.runs.scheduler import together as _together
from fenicsx_drape.runs.workers import capped, default_workers

if TYPE_CHECKING:
    import os
    from concurrent.futures import Executor

    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.model import Model
    from fenicsx_drape.runs.store import RunStore

MEMORY_SIZE = 256  # runs kept in memory (the latest)
COUNTED = ("asked", "formed", "from_disk", "from_memory")


class Deferred(BaseException):  # not an Exception: it passes the callers' handlers
    """Raised by :meth:`Runs.form_many` in :meth:`Runs.spare` when spare runs were left."""


class Runs:
    """The forming runs of a command: remembered, and formed on ``workers`` processes.

    A run is known by its content (:func:`~fenicsx_drape.runs.keys.key_of`): the
    :data:`MEMORY_SIZE` latest are kept in memory and, with a ``cache`` folder, on disk across
    commands. The new runs of a call go to the executor (:mod:`~fenicsx_drape.runs.pools`)
    and are gathered in the order asked, whichever process formed them.

    Used as a context manager, the object is made current inside (the module-level functions
    of :mod:`fenicsx_drape.runs` ask it) and closed at the end: its disk store closed, its
    workers stopped (killed on an interrupt).

    Args:
        workers: Local processes forming at once (None: ``DRAPE_WORKERS`` at most the cores,
            else the cores; 1: in this process). Under ``python3 -m mpi4py.futures`` the MPI
            job's ranks are the workers.
        cache: A folder where runs are kept across commands
            (:class:`~fenicsx_drape.runs.store.RunStore`); None: in memory only.
        ranks_per_run: Under plain ``mpirun -n N`` (no ``mpi4py.futures``): each run on
            this many ranks, N / ``ranks_per_run`` runs at once (runs × ranks); None: every
            run on all N ranks, one after the other.
        cell_mm: The unit cell (mm) of every run (:meth:`resolution`); None: each case's own,
            or the one in force where the object is made current.
        memory: How many runs are kept in memory.

    Raises:
        DrapeInputError: ``workers`` < 1 (or a bad ``DRAPE_WORKERS``), ``ranks_per_run``
            does not divide the job's ranks, or ``cache`` is not a usable folder.
    """

    def __init__(self, workers: int | None = None, cache: str | os.PathLike | None = None, *,
                 ranks_per_run: int | None = None, cell_mm: float | None = None,
                 memory: int = MEMORY_SIZE):
        from mpi4py import MPI

        from fenicsx_drape.runs.store import RunStore

        if workers is None:
            capped(None)  # a bad DRAPE_WORKERS is refused before anything runs (and capped)
        elif not (int(workers) == workers and workers >= 1):
            raise DrapeInputError(f"--workers {workers}: a number of processes >= 1")
        size = MPI.COMM_WORLD.size
        if ranks_per_run is not None and not (ranks_per_run >= 1 and size % ranks_per_run == 0):
            raise DrapeInputError(f"--ranks-per-run {ranks_per_run}: a divisor of the job's "
                                  f"{size} ranks")
        self.workers = workers
        self.ranks_per_run = ranks_per_run
        self.store: RunStore | None = RunStore(cache) if cache is not None else None
        self.memory = memory
        self._rebuilt = 0  # the store's rebuilds seen
        self.counts = dict.fromkeys(COUNTED, 0)
        self._kept: dict[tuple, ex.Run] = {}  # the runs in memory, the oldest first
        self._memos: dict[str, Memo] = {}  # values derived from runs and tests (:meth:`memo`)
        self._pool: ex.LocalPool | None = None
        self._mpi_pool: Executor | None = None
        self._cell: contextvars.ContextVar[float | None] = contextvars.ContextVar(
            f"cell_mm {id(self)}", default=None)
        self._spare_from: contextvars.ContextVar[int | None] = contextvars.ContextVar(
            f"spare {id(self)}", default=None)
        self._task = threading.local()  # in a call of together(): its group and place
        self._tokens: list[contextvars.Token] = []
        self._memo_lock = threading.Lock()
        self._own_cell = cell_mm is not None
        if cell_mm is not None:
            self._cell.set(_checked_cell(cell_mm))

    # -- made current, closed ---------------------------------------------------------------

    def __enter__(self) -> Runs:
        outer = _current.get() or (_default[0] if _default else None)
        if outer is not None and not self._own_cell and self._cell.get() is None:
            self._cell.set(outer.cell_override())  # the resolution in force where it is entered
        self._tokens.append(_current.set(self))
        return self

    def __exit__(self, kind, error, trace) -> None:
        _current.reset(self._tokens.pop())
        self.close(interrupted=kind is not None and issubclass(kind, KeyboardInterrupt))
        if isinstance(error, KeyboardInterrupt):
            error.add_note(self.kept())

    def close(self, interrupted: bool = False) -> None:
        """Close the disk store and stop the workers (killed at once when ``interrupted``)."""
        if self._pool is not None:
            self._pool.stop(now=interrupted)
            self._pool = None
        if self._mpi_pool is not None and interrupted:  # the shared pool ends with the job
            with contextlib.suppress(Exception):
                self._mpi_pool.shutdown(wait=False, cancel_futures=True)
        if self.store is not None:
            self.store.close()

    def kept(self) -> str:
        """What the runs so far left behind, in a sentence (for an interrupted command)."""
        made = self.counts["formed"]
        if self.store is None or not self.store.usable:
            return f"no run is kept ({made} formed, no cache folder)"
        if not made:
            return f"no run was formed yet (the cache {self.store.folder} is as it was)"
        return (f"the {made} run(s) formed so far are kept in the cache {self.store.folder}: "
                "the same command again reads them")

    # -- settings ---------------------------------------------------------------------------

    @contextlib.contextmanager
    def resolution(self, cell_mm: float | None) -> Iterator[None]:
        """Form the runs on cells of ``cell_mm`` (mm) inside; None: each case's own cells."""
        token = self._cell.set(None if cell_mm is None else _checked_cell(cell_mm))
        try:
            yield
        finally:
            self._cell.reset(token)

    def cell_override(self) -> float | None:
        """The unit cell (mm) a :meth:`resolution` sets for every run, None for the cases'."""
        return self._cell.get()

    @contextlib.contextmanager
    def spare(self, first: int) -> Iterator[None]:
        """Inside, :meth:`form_many`'s jobs from index ``first`` on are spare.

        A spare run is formed only in a slot the batch's other runs leave free (its new runs
        not a multiple of :meth:`runs_at_once`: one run on two workers), or read where it is
        kept; when one is left, form_many keeps what it formed and raises :class:`Deferred`.
        A fit's finite differences are spare: formed beside its point for no extra time,
        never at the cost of a run (a rejected step's would be wasted). ``spare(0)``: only
        runs at hand.
        """
        token = self._spare_from.set(first)
        try:
            yield
        finally:
            self._spare_from.reset(token)

    def executor_kind(self) -> tuple[str, int]:
        """The executor's name and how many runs it forms at once (workers or rank groups)."""
        return ex.executor_kind(self.workers or default_workers(), self.ranks_per_run)

    def runs_at_once(self) -> int:
        """How many runs :meth:`form_many` forms at once (its executor's workers or groups)."""
        return self.executor_kind()[1]

    def executor(self) -> tuple[str, Executor | None]:
        """The executor of the runs, by name: ``mpi4py.futures``, ``processes`` or None.

        None (``"this process"`` or ``"all ranks"``): the runs are formed here one after the
        other, on this process alone or, under ``mpirun`` without ``mpi4py.futures``, on all
        ranks. A local pool starts here (its workers warming up at once) and is kept until
        the object closes, or a worker dies.
        """
        kind, workers = self.executor_kind()
        if kind == "mpi4py.futures":
            if self._mpi_pool is None:
                from fenicsx_drape.runs import mpi

                self._mpi_pool = mpi.pool()
            return kind, self._mpi_pool
        if kind != "processes":
            return kind, None
        if self._pool is not None and (self._pool.broken or self._pool.workers != workers):
            self._pool.stop()
            self._pool = None
        if self._pool is None:
            self._pool = ex.LocalPool(workers)
        return kind, self._pool.pool

    def record(self) -> dict[str, Any]:
        """How the runs were made, for ``provenance.json``.

        The executor (``processes``, ``mpi4py.futures``, ``this process`` or ``all
        ranks``), its ``workers`` (runs formed at once; ``ranks`` a run's MPI ranks), the
        ``cache`` folder (None: none on disk, or one that could not be opened), and the
        ``runs`` asked, ``formed``, read ``from_disk`` and found ``from_memory`` (``reused``:
        the last two).
        """
        from mpi4py import MPI

        name, workers = self.executor_kind()
        runs = dict(self.counts)
        runs["reused"] = runs["from_disk"] + runs["from_memory"]
        usable = self.store is not None and self.store.usable
        return {"executor": name, "workers": workers,
                "ranks": MPI.COMM_WORLD.size // workers if name == "all ranks" else 1,
                "cache": str(self.store.folder.resolve()) if usable else None, "runs": runs}

    # -- the runs ---------------------------------------------------------------------------

    def key(self, case, model: Model) -> tuple:
        """A run's identity (:func:`~fenicsx_drape.runs.keys.key_of`)."""
        return key_of(case, model)

    def describe(self, case, model: Model) -> str:
        """A run as a person names it (:func:`~fenicsx_drape.runs.keys.describe`)."""
        return describe(case, model)

    def form_many(self, jobs: Sequence[tuple[Any, Model]]) -> list[FormedGrid]:
        """Formed sheets (modelled parts) of ``(case, model)`` jobs: remembered, new ones at once.

        The runs not in memory are looked up in the disk store, the rest formed by
        :meth:`executor`'s processes and stored; inside :meth:`together`, with the runs the
        other calls wait for. A run that fails is raised (its message naming the case and
        model) once the others are formed and kept. Inside :meth:`spare`, the jobs from its
        index on are spare: :class:`Deferred` is raised when one is left unformed.
        """
        jobs = list(jobs)
        first = self._spare_from.get()
        first = len(jobs) if first is None else first
        results = self._gathered(jobs[:first], jobs[first:])
        for (case, model), got in zip(jobs, results):
            if got is not None and got[0] == "error":
                raise _named(got[1], self.describe(case, model))
        if None in results:
            raise Deferred
        return [grid for _, grid in results]

    def together(self, calls: Sequence[Callable[[Callable[[str], None]], Any]],
                 progress: Callable[[str], None] | None = None) -> list[Any]:
        """The results of ``calls`` as made one after the other, their runs formed at once.

        Each call runs in a thread of its own, but only one at a time and in a fixed order: a
        call runs until it asks :meth:`form_many` for runs or returns, then the next one;
        when every call waits or is done, the runs they wait for go to the workers in one
        batch (the independent candidates of a diagnosis keep every core busy, where one
        after the other they asked a run or two at a time). Every result is the one calling
        them in turn gives: a run is the same whichever batch formed it. Calls may nest (a
        candidate's held-out folds): an inner group's batch is a request of its caller's.

        Args:
            calls: Each is given its own ``say`` (a line of progress): the lines of every
                call reach ``progress`` in the calls' order, each call's once those before
                it are done.
            progress: Where the lines go (None: nowhere).

        Returns:
            Each call's result, in order. A call's exception is raised once all are done
            (the first one's).
        """
        return _together(calls, progress, task=self._task, batch=self._gathered)

    def cached(self, case, model: Model) -> bool:
        """Whether a run of ``(case, model)`` is in memory (:meth:`form_many` will not form it)."""
        return self.key(case, model) in self._kept

    def runs_of(self, jobs: Iterable[tuple[Any, Model]]) -> set[tuple]:
        """The distinct runs ``jobs`` ask for (:meth:`form_many` forms each once), by key."""
        return {self.key(case, model) for case, model in jobs}

    def tool_forces(self, case, model: Model) -> dict[str, np.ndarray]:
        """The force curves of the run of ``(case, model)`` (formed if not in memory).

        ``time_s``, ``travel_mm`` and each tool's force along its motion (N, the whole part;
        :func:`~fenicsx_drape.forming.running.run.record_tool_forces`), one value per
        converged step.
        """
        key = self.key(case, model)
        if key not in self._kept:
            self.form_many([(case, model)])
        return self._kept[key][2]

    def stopped_at(self, case, model: Model) -> float | None:
        """The travel (mm) the run of ``(case, model)`` in memory reached if it stopped short."""
        kept = self._kept.get(self.key(case, model))
        return None if kept is None else kept[1]

    def in_memory(self) -> int:
        """How many runs are in memory."""
        return len(self._kept)

    def forget(self) -> None:
        """Forget the runs in memory and their memos (the disk store keeps its own)."""
        self._kept.clear()
        self._memos.clear()

    def memo(self, name: str, size: int = 64) -> Memo:
        """The table ``name`` of values derived from this object's runs and their tests.

        What is costly to derive again within a command (a formed sheet's triangulation, a
        lab measurement matched to it, a case's built tools) is kept here, not in a module:
        it lives as long as the command's runs, and a new command starts without it.
        """
        with self._memo_lock:
            if name not in self._memos:
                self._memos[name] = Memo(size)
            return self._memos[name]

    # -- inside -----------------------------------------------------------------------------

    def _gathered(self, jobs: list[tuple[Any, Model]], spares: list[tuple[Any, Model]] = ()
                  ) -> list[tuple[str, Any] | None]:
        """``("ok", sheet)`` or ``("error", exception)`` per job, then per spare (None: left).

        In a call of :meth:`together`: from its group's batch; else formed here
        (:meth:`_gather`).
        """
        turns = getattr(self._task, "group", None)
        if turns is not None:
            return turns.ask(self._task.index, jobs, list(spares))
        return self._gather(jobs, list(spares))

    def _gather(self, jobs: list[tuple[Any, Model]], spares: list[tuple[Any, Model]] = ()
                ) -> list[tuple[str, Any] | None]:
        """:meth:`_gathered`'s work: memory, then the disk store, then the executor.

        The spare jobs (:meth:`spare`) fill the batch's free slots, the first first.
        """
        kept = self._kept
        keys = [self.key(case, model) for case, model in jobs]
        extra = [self.key(case, model) for case, model in spares]
        for k in dict.fromkeys(keys + extra):  # the batch's runs in memory are the newest
            if k in kept:
                kept[k] = kept.pop(k)
        got: dict[tuple, tuple[str, Any]] = {k: ("ok", kept[k][0])
                                             for k in keys + extra if k in kept}
        in_memory = set(got)
        todo = {k: job for k, job in zip(keys, jobs) if k not in kept}
        maybe = {k: job for k, job in zip(extra, spares) if k not in kept and k not in todo}
        store = self.store
        names = {}
        if store is not None:
            names = {k: store.name(k) for k in (*todo, *maybe)}
            for k in (*todo, *maybe):
                found = store.get(names[k])
                if found is not None:
                    self._keep(k, found)
                    got[k] = ("ok", found[0])
                    self.counts["from_disk"] += 1
                    todo.pop(k, None)
                    maybe.pop(k, None)
        if todo:  # the spares that fill the last round of runs at once
            free = -len(todo) % self.runs_at_once()
            todo.update(list(maybe.items())[:free])
            for k, (status, value) in zip(todo, self._form_all(list(todo.values()))):
                if status == "error":
                    got[k] = (status, value)
                    continue
                self.counts["formed"] += 1
                self._keep(k, value)
                got[k] = ("ok", value[0])
                if store is not None:
                    store.put(names[k], *value)
        if store is not None and store.rebuilt != self._rebuilt:  # a new database: the runs
            self._rebuilt = store.rebuilt  # read from the damaged one go into it
            for k, run in self._kept.items():
                store.put(store.name(k), *run)
        asked = set(keys) | (set(extra) & set(got))
        self.counts["asked"] += len(asked)
        self.counts["from_memory"] += len(asked & in_memory)
        return [got[k] for k in keys] + [got.get(k) for k in extra]

    def _form_all(self, jobs: list[tuple[Any, Model]]) -> list[tuple[str, Any]]:
        """``("ok", run)`` or ``("error", exception)`` for each job, in the order of ``jobs``."""
        from concurrent.futures import BrokenExecutor

        from mpi4py import MPI

        name, pool = self.executor()
        groups = self.executor_kind()[1] if name == "all ranks" else 1
        if groups > 1 and len(jobs) > 1:
            return ex.form_in_groups(jobs, groups)
        if pool is None or (len(jobs) == 1 and name != "mpi4py.futures"):
            return ex.form_here(jobs, MPI.COMM_WORLD if name == "all ranks" else MPI.COMM_SELF)
        if name == "processes":
            return self._pool.share(jobs)
        try:
            futures = ex.submit_all(jobs, pool)
        except BrokenExecutor:  # a worker died since the last batch: a new pool
            self._mpi_pool = None
            futures = ex.submit_all(jobs, self.executor()[1])
        results, broken = ex.gather(futures)
        if broken:  # the next batch starts a new pool
            self._mpi_pool = None
        return results

    def _keep(self, key: tuple, run: ex.Run) -> None:
        if len(self._kept) >= self.memory:
            del self._kept[next(iter(self._kept))]
        self._kept[key] = run


class Memo:
    """A table of at most ``size`` entries, the oldest dropped first; safe across threads."""

    def __init__(self, size: int):
        self.size = size
        self._items: dict[Any, Any] = {}
        self._lock = threading.Lock()

    def get(self, key: Any, default: Any = None) -> Any:
        """The value kept under ``key``, else ``default``."""
        return self._items.get(key, default)

    def put(self, key: Any, value: Any) -> Any:
        """Keep ``value`` under ``key`` (dropping the oldest entry when full); return it."""
        with self._lock:
            self._items.pop(key, None)
            while len(self._items) >= self.size:
                del self._items[next(iter(self._items))]
            self._items[key] = value
        return value

    def newest_first(self) -> list[tuple[Any, Any]]:
        """The entries, the latest kept first."""
        with self._lock:
            return list(reversed(self._items.items()))

    def clear(self) -> None:
        """Drop every entry."""
        with self._lock:
            self._items.clear()

    def __len__(self) -> int:
        return len(self._items)


def _checked_cell(cell_mm: float) -> float:
    if not cell_mm > 0:
        raise DrapeInputError(f"forming cell size {cell_mm} mm must be > 0")
    return float(cell_mm)


def _named(error: Exception, run: str) -> Exception:
    """``error`` with ``run`` (the case and model) in front of its message."""
    if error.args and isinstance(error.args[0], str) and run not in error.args[0]:
        error.args = (f"{run}: {error.args[0]}", *error.args[1:])
    elif not error.args:
        error.args = (run,)
    return error


# The Runs a ``with`` block made current; outside any, the process's default (made when first
# asked for: a Python user's runs, in memory, on the default workers).
_current: contextvars.ContextVar[Runs | None] = contextvars.ContextVar("fenicsx_drape.runs",
                                                                      default=None)
_default: list[Runs] = []


def current() -> Runs:
    """The :class:`Runs` the module-level functions ask.

    The innermost one a ``with`` block made current, else the process's default (in memory
    only, on the default workers).
    """
    runs = _current.get()
    if runs is not None:
        return runs
    if not _default:
        _default.append(Runs())
    return _default[0]
