"""The forming runs of compare and diagnose: remembered, and run on every core.

A forming test is simulated by forming its part for a model: its forming case (the paper's
hemisphere is ``meshes/hemisphere/case.toml``) run by
:func:`~fenicsx_drape.forming.running.run.run_case`. A diagnosis asks for dozens to hundreds
of such runs, many of them the same. :func:`form_many` forms ``(case, model)`` jobs: every
run is known by the case's content (its tables and the bytes of its geometry files, not the
path it was read from), the model and the solver options; it is kept in memory (the
:data:`_CACHE_SIZE` latest) and, inside :func:`execution` with a cache folder, on disk
(:mod:`~fenicsx_drape.diagnosis.run_store`, across commands). The new runs of one call go
through :mod:`concurrent.futures`, chosen by :func:`executor`: local processes (as many as
the machine has cores, or ``DRAPE_WORKERS``, or :func:`execution`'s: this process and a pool
of the others, warmed up as soon as it starts), the shared pool
of ``mpi4py.futures`` when run as ``mpiexec -n N python3 -m mpi4py.futures -m fenicsx_drape
...``, and, under plain ``mpirun``, one run after the other on all ranks (or, with
``ranks_per_run``, runs at once on groups of ranks: runs × ranks). The results are
gathered in the order the runs were asked, whichever process formed them: the same report
from every executor. A run that fails is raised after the others have finished, its case and
model named. The cells of the runs are set with :func:`resolution`: by default a case runs on
its own blank's ``cell_mm`` (the hemisphere's: :data:`FULL_CELL_MM`, the paper's Δ); a
resolution replaces it. A run that stops short of full travel is kept as far as it got, and
:func:`stopped_at` tells the travel it reached.

This module knows forming cases and models, not tests: the forming kind
(:mod:`~fenicsx_drape.diagnosis.forming_kind`) turns a test into a case.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case.format import case_key
from fenicsx_drape.provenance import file_digest
from fenicsx_drape.trust import set_trusted, trusted

if TYPE_CHECKING:
    from concurrent.futures import Executor

    from fenicsx_drape.diagnosis.run_store import RunStore
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.model import Model

FULL_CELL_MM = 10.0  # unit cell of the forming runs (mm), the paper's Δ
SCREEN_CELL_MM = 20.0  # a coarse screening mesh (mm), for data formed on it (tests)
WORKERS_ENV = "DRAPE_WORKERS"  # processes forming at once, when not given
# The PETSc options a user gives every solve (fe.newton.SOLVER_PREFIXES and log_*): those a
# run depends on, unlike the ones each problem keeps under its own prefix while it lives.
USER_OPTIONS = ("snes_", "ksp_", "pc_", "mat_", "npc_", "sub_", "log_")

# The cells of resolution(): a context variable, as a call of together() may set its own.
_cell_mm: contextvars.ContextVar[float | None] = contextvars.ContextVar("cell_mm", default=None)
# In spare(): form_many's jobs from this index on are spare.
_spare_from: contextvars.ContextVar[int | None] = contextvars.ContextVar("spare", default=None)
_settings: dict[str, Any] = {"workers": None,  # None: default_workers()
                             "ranks_per_run": None,  # under mpirun; None: all ranks
                             "store": None}  # a RunStore, or None: runs kept in memory only
_cache: dict[tuple, FormedGrid] = {}
_stopped: dict[tuple, float] = {}  # travel (mm) reached by the runs that stopped short
_forces: dict[tuple, dict] = {}  # the tools' force curves of the cached runs (run.tool_forces)
_CACHE_SIZE = 256
# Runs asked (each distinct run once per call of form_many), formed, read from the disk cache,
# and found in memory, since the process started.
counts = {"asked": 0, "formed": 0, "from_disk": 0, "from_memory": 0}
_executions: list[dict[str, Any]] = []  # the record of the last (or running) execution()


@contextlib.contextmanager
def resolution(cell_mm: float | None) -> Iterator[None]:
    """Run the forming simulations of compare/diagnose on cells of ``cell_mm`` (mm) inside.

    None: each case on its own blank's ``cell_mm`` (the hemisphere's: :data:`FULL_CELL_MM`).
    """
    if cell_mm is not None and not cell_mm > 0:
        raise DrapeInputError(f"forming cell size {cell_mm} mm must be > 0")
    token = _cell_mm.set(None if cell_mm is None else float(cell_mm))
    try:
        yield
    finally:
        _cell_mm.reset(token)


def cell_override() -> float | None:
    """The unit cell (mm) a :func:`resolution` sets for every run, None for the cases' own."""
    return _cell_mm.get()


class Deferred(BaseException):  # not an Exception: it passes the callers' handlers
    """Raised by :func:`form_many` in :func:`spare` when spare runs were left unformed."""


@contextlib.contextmanager
def spare(first: int) -> Iterator[None]:
    """Inside, :func:`form_many`'s jobs from index ``first`` on are spare.

    A spare run is formed only in a slot the batch's other runs leave free (its new runs not
    a multiple of :func:`runs_at_once`: one run on two workers), or read where it is kept;
    when one is left, form_many keeps what it formed and raises :class:`Deferred`. A fit's
    finite differences are spare: formed beside its point for no extra time, never at the
    cost of a run (a rejected step's would be wasted). ``spare(0)``: only runs at hand.
    """
    token = _spare_from.set(first)
    try:
        yield
    finally:
        _spare_from.reset(token)


def default_workers() -> int:
    """Processes forming at once by default: ``DRAPE_WORKERS``, else the cores available.

    Raises:
        DrapeInputError: ``DRAPE_WORKERS`` is not a whole number >= 1.
    """
    given = os.environ.get(WORKERS_ENV, "").strip()
    if given:
        if not (given.isdigit() and int(given) >= 1):
            raise DrapeInputError(f"{WORKERS_ENV}={given!r}: a number of processes >= 1")
        return int(given)
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


@contextlib.contextmanager
def execution(workers: int | None = None, cache: str | os.PathLike | None = None, *,
              ranks_per_run: int | None = None) -> Iterator[None]:
    """Form the runs of :func:`form_many` inside on ``workers`` processes, remembered in ``cache``.

    Args:
        workers: Local processes forming at once (None: :func:`default_workers`; 1: in this
            process). Under ``python3 -m mpi4py.futures`` the MPI job's ranks are the workers.
        cache: A folder where runs are kept across commands
            (:class:`~fenicsx_drape.diagnosis.run_store.RunStore`); None: in memory only.
        ranks_per_run: Under plain ``mpirun -n N`` (no ``mpi4py.futures``): each run on
            this many ranks, N / ``ranks_per_run`` runs at once (runs × ranks); None: every
            run on all N ranks, one after the other.

    Raises:
        DrapeInputError: ``workers`` < 1, ``ranks_per_run`` does not divide the job's
            ranks, or ``cache`` is not a usable folder.
    """
    from mpi4py import MPI

    from fenicsx_drape.diagnosis.run_store import RunStore

    if workers is None:
        default_workers()  # a bad DRAPE_WORKERS is refused before anything runs
    elif not (int(workers) == workers and workers >= 1):
        raise DrapeInputError(f"--workers {workers}: a number of processes >= 1")
    size = MPI.COMM_WORLD.size
    if ranks_per_run is not None and not (ranks_per_run >= 1 and size % ranks_per_run == 0):
        raise DrapeInputError(f"--ranks-per-run {ranks_per_run}: a divisor of the job's "
                              f"{size} ranks")
    old = dict(_settings)
    store = RunStore(cache) if cache is not None else None
    _settings.update(workers=workers, store=store, ranks_per_run=ranks_per_run)
    _executions[:] = [{"cache": None if store is None else str(store.folder.resolve()),
                       "counts": dict(counts)}]
    try:
        yield
    finally:
        _executions[0].update(execution_record())
        _settings.update(workers=old["workers"], store=old["store"],
                         ranks_per_run=old["ranks_per_run"])
        if store is not None:
            store.close()


def execution_record() -> dict[str, Any] | None:
    """How the forming runs of the last (or the running) :func:`execution` were made.

    For ``provenance.json``: the executor (``processes``, ``mpi4py.futures``, ``this
    process`` or ``all ranks``), its ``workers`` (runs formed at once; ``ranks`` a run's MPI
    ranks), the ``cache`` folder (None: none on disk), and the ``runs`` asked, ``formed``,
    read ``from_disk`` and found ``from_memory`` (``reused``: the last two) inside it. None
    when no :func:`execution` was entered.
    """
    if not _executions:
        return None
    if "executor" in _executions[0]:  # a finished one
        return {k: v for k, v in _executions[0].items() if k != "counts"}
    from mpi4py import MPI

    name, workers = _executor_kind()
    runs = {k: counts[k] - _executions[0]["counts"][k] for k in counts}
    runs["reused"] = runs["from_disk"] + runs["from_memory"]
    return {"executor": name, "workers": workers,
            "ranks": MPI.COMM_WORLD.size // workers if name == "all ranks" else 1,
            "cache": _executions[0]["cache"], "runs": runs}


def _key(case, model: Model) -> tuple:
    if "interply_friction" in model.effects and not case.stack:  # it acts on stacks only
        model = model.without_effects("interply_friction")
    params = tuple(sorted((k, float(v)) for k, v in model.parameters.items()))
    plugins = tuple(file_digest(p) if Path(p).is_file() else f"missing {p}"
                    for p in model.plugins)
    return (case_key(case), tuple(sorted(model.effects)), params, plugins, _solver_options())


def _solver_options() -> tuple[tuple[str, str], ...]:
    """The user's PETSc options (``--petsc-option``, ``PETSC_OPTIONS``): a run depends on them.

    Read from PETSc's database, without the options each problem keeps under its own prefix
    while it lives (``drape_truss_N_``), and given to each worker with its job.
    """
    import sys

    if "petsc4py.PETSc" not in sys.modules:  # nothing was set: no need to load PETSc
        return tuple(sorted(_options_from_env().items()))
    from petsc4py import PETSc

    return tuple(sorted((k, "" if v is None else str(v))  # None: a flag without a value
                        for k, v in PETSc.Options().getAll().items()
                        if k.startswith(USER_OPTIONS)))


def _options_from_env() -> dict[str, str]:
    import shlex

    given: dict[str, str] = {}
    name = None
    for token in shlex.split(os.environ.get("PETSC_OPTIONS", "")):
        if token.startswith("-") and not token.lstrip("-")[:1].isdigit():
            name = token.lstrip("-")
            given[name] = ""
        elif name is not None:
            given[name] = token
    return {k: v for k, v in given.items() if k.startswith(USER_OPTIONS)}


def describe(case, model: Model) -> str:
    """A run as a person names it: the case and the model's effects and parameters."""
    effects = ", ".join(model.effects) or "no effects"
    params = ", ".join(f"{k} = {float(v):.6g}" for k, v in sorted(model.parameters.items()))
    return (f"the forming run of case {case.name!r}"
            + (f" ({case.path})" if getattr(case, "path", None) else "")
            + f" with the model [{effects}]" + (f" ({params})" if params else ""))


def _form(case, model: Model, comm=None) -> tuple[FormedGrid, float | None, dict]:
    """One forming run (on this process alone by default): the formed sheet (modelled part).

    A model that cannot form the part to full travel (its solve fails at the smallest step)
    is compared as far as it got: the second value is then the travel reached (mm), which
    :func:`stopped_at` gives back, else None. The third is the tools' force curves
    (:func:`tool_forces`).
    """
    from mpi4py import MPI

    from fenicsx_drape.forming.running.run import run_case

    comm = comm or MPI.COMM_SELF
    run = run_case(case, model, comm=comm, allow_incomplete=True)
    rows = run.tool_forces
    curves = {k: np.array([r[k] for r in rows]) for k in (rows[0] if rows else {})}
    return run.grid, (run.travel_mm if run.stopped else None), curves


_applied: dict[str, str] = {}  # the PETSc options a worker was last given


def _run(case, model: Model, trust: bool, options: tuple) -> tuple[str, Any]:
    """A job in a worker process: ``("ok", run)`` or ``("error", exception)``.

    The parent's trust and PETSc options come with each job (a worker outlives a command).
    Errors come back as values, in a form that unpickles in the parent.
    """
    set_trusted(trust)
    wanted = dict(options)
    if wanted != _applied:
        from petsc4py import PETSc

        db = PETSc.Options()
        for name in set(_applied) - set(wanted):
            db.delValue(name)
        for name, value in wanted.items():
            db[name] = value
        _applied.clear()
        _applied.update(wanted)
    try:
        return "ok", _form(case, model)
    except Exception as error:  # sent back and raised in the parent
        return "error", _sendable(error)


def _sendable(error: Exception) -> Exception:
    """``error`` in a form that unpickles in another process."""
    import pickle

    if isinstance(error, DrapeInputError):  # its subclasses may not unpickle: the message
        return DrapeInputError(str(error))
    try:
        pickle.loads(pickle.dumps(error))
    except Exception:
        return RuntimeError(f"{type(error).__name__}: {error}")
    return error


_pools: dict[str, Executor] = {}  # the executor in use, kept between calls (warm workers)


def executor() -> tuple[str, Executor | None]:
    """The executor of the forming runs, by name: ``mpi4py.futures``, ``processes`` or None.

    None (``"this process"`` or ``"all ranks"``): the runs are formed here one after the
    other, on this process alone or, under ``mpirun`` without ``mpi4py.futures``, on all ranks.
    """
    from fenicsx_drape.diagnosis import mpi_pool

    kind, workers = _executor_kind()
    if kind == "mpi4py.futures":
        if "mpi" not in _pools:
            _pools["mpi"] = mpi_pool.pool()
        return "mpi4py.futures", _pools["mpi"]
    if kind != "processes":
        return kind, None
    name = f"processes {workers}"
    if name not in _pools:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        _shutdown()
        _ignore_broken_pipes()
        # Fresh processes (not forks of one where MPI is initialised); this process is the
        # last worker (it is warm: DOLFINx imported, forms compiled).
        pool = ProcessPoolExecutor(workers - 1, mp_context=multiprocessing.get_context("spawn"))
        with _fresh_workers():  # every process starts now and warms while this one works
            _warming[:] = [pool.submit(_warm) for _ in range(workers - 1)]
        _pools[name] = pool
    return "processes", _pools[name]


def _ignore_broken_pipes() -> None:
    """Give SIGPIPE back to Python (ignored: a write to a dead worker is BrokenPipeError).

    PETSc's signal handler turns it into ``MPI_Abort`` (error 59): a worker that died while
    a job was sent to it would stop the whole diagnosis instead of failing its own runs.
    """
    import signal
    import threading

    from petsc4py import PETSc  # noqa: F401 (its start installs the handler: after it)

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)


_warming: list = []  # the pool's warm-up jobs: a worker takes runs once its own is done


def _warm() -> None:
    """A new worker's first job: import DOLFINx and load the compiled forms (a tiny run)."""
    from fenicsx_drape.forming.case.format import load_case
    from fenicsx_drape.forming.running.run import run_case

    try:
        run_case(load_case("hemisphere", cell_mm=40.0, step_mm=10.0))
    except Exception:  # only a warm-up: the runs will say what is wrong
        pass


def _executor_kind() -> tuple[str, int]:
    """The name of :func:`executor`'s choice and how many runs it forms at once."""
    from mpi4py import MPI

    from fenicsx_drape.diagnosis import mpi_pool

    if mpi_pool.shared_pool():
        return "mpi4py.futures", MPI.COMM_WORLD.size - 1
    if MPI.COMM_WORLD.size > 1:
        return "all ranks", MPI.COMM_WORLD.size // (_settings["ranks_per_run"]
                                                    or MPI.COMM_WORLD.size)
    workers = _settings["workers"] or default_workers()
    return ("this process", 1) if workers == 1 else ("processes", workers)


def runs_at_once() -> int:
    """How many runs :func:`form_many` forms at once (its executor's workers or rank groups)."""
    return _executor_kind()[1]


def _shutdown() -> None:
    for name, pool in _pools.items():
        if name != "mpi":  # the shared pool of mpi4py.futures ends with the job
            pool.shutdown(wait=True, cancel_futures=True)
    _pools.clear()


# Open MPI's settings that ./drape gives (not a launcher's job): as root, without the
# libfabric transport, whose probe of the network costs a second of each worker's start.
_MPI_SETTINGS = ("OMPI_ALLOW_RUN_AS_ROOT", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "OMPI_MCA_btl")


@contextlib.contextmanager
def _fresh_workers() -> Iterator[None]:
    """Start local workers as fresh programs: each its own MPI job, not the caller's script.

    Without the MPI launcher's environment a worker is a job of one process (the settings of
    how Open MPI runs here stay: :data:`_MPI_SETTINGS`); without the caller's ``__main__``
    (the worker would run a script again, e.g. a demo, to import it) it imports only this
    package.
    """
    import sys
    import types

    launcher = {k: v for k, v in os.environ.items()
                if k.startswith(("OMPI_", "PMIX_", "PMI_")) and k not in _MPI_SETTINGS}
    for k in launcher:
        del os.environ[k]
    main = sys.modules["__main__"]
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        sys.modules["__main__"] = main
        os.environ.update(launcher)


def _form_all(jobs: list[tuple[Any, Model]]) -> list[tuple[str, Any]]:
    """``("ok", run)`` or ``("error", exception)`` for each job, in the order of ``jobs``."""
    from mpi4py import MPI

    name, pool = executor()
    groups = _executor_kind()[1] if name == "all ranks" else 1
    if groups > 1 and len(jobs) > 1:
        return _form_in_groups(jobs, groups)
    if pool is None or (len(jobs) == 1 and name != "mpi4py.futures"):
        comm = MPI.COMM_WORLD if name == "all ranks" else MPI.COMM_SELF
        results = []
        for case, model in jobs:
            try:
                results.append(("ok", _form(case, model, comm)))
            except Exception as error:  # raised after the others
                results.append(("error", error))
        return results
    if name == "processes":
        return _share(jobs, pool, _executor_kind()[1] - 1)
    from concurrent.futures import BrokenExecutor

    options = _solver_options()
    order = _largest_first(jobs)
    try:
        with _fresh_workers():
            futures = {k: pool.submit(_run, *jobs[k], trusted(), options) for k in order}
    except BrokenExecutor:  # a worker died since the last batch: a new pool
        _shutdown()
        name, pool = executor()
        with _fresh_workers():
            futures = {k: pool.submit(_run, *jobs[k], trusted(), options) for k in order}
    results, broken = [], False
    for k in range(len(jobs)):  # in the order asked: the same gathering whichever finishes first
        future = futures[k]
        try:
            results.append(future.result())
        except Exception as error:  # a worker that died, a job that did not pickle
            broken |= isinstance(error, BrokenExecutor)
            results.append(("error", RuntimeError(f"forming worker failed: {error!r}")))
    if broken:  # the next batch starts a new pool
        _shutdown()
    return results


def _share(jobs: list[tuple[Any, Model]], pool: Executor, workers: int
           ) -> list[tuple[str, Any]]:
    """The jobs formed by this process and the pool's ``workers`` together, in the order asked.

    Each next job, the largest first (:func:`_largest_first`), goes to whichever is free
    first (a feeding thread per worker waits on it). A run is the same wherever it is
    formed, so the results do not depend on who formed what. A job the pool refuses (a
    worker died since the last batch) is formed here; one whose worker died comes back as
    its error, and the next batch starts a new pool.
    """
    import threading
    from concurrent.futures import BrokenExecutor, wait

    from mpi4py import MPI

    options = _solver_options()
    results: list[tuple[str, Any] | None] = [None] * len(jobs)
    queue = _largest_first(jobs)[::-1]  # popped from the end
    lock = threading.Lock()
    died = []

    def take() -> int | None:
        with lock:
            return queue.pop() if queue else None

    def feed(warm) -> None:  # a thread: the pool's worker forms job after job ...
        if warm is not None:  # ... once warm (until then this process takes the jobs)
            wait([warm])
        while (k := take()) is not None:
            try:
                future = pool.submit(_run, *jobs[k], trusted(), options)
            except BrokenExecutor:  # refused: this process forms it
                with lock:
                    queue.append(k)
                died.append(True)
                return
            try:
                results[k] = future.result()
            except Exception as error:  # a worker that died, a job that did not pickle
                died.append(isinstance(error, BrokenExecutor))
                results[k] = ("error", RuntimeError(f"forming worker failed: {error!r}"))

    warm = (_warming + [None] * workers)[:workers]
    feeders = [threading.Thread(target=feed, args=(w,), daemon=True) for w in warm]
    for thread in feeders:
        thread.start()
    while True:  # this process forms too
        k = take()
        if k is None:
            alive = [t for t in feeders if t.is_alive()]
            if not alive:
                break
            alive[0].join(0.05)  # a refused job may still come back to the queue
            continue
        try:
            results[k] = ("ok", _form(*jobs[k], MPI.COMM_SELF))
        except Exception as error:  # raised after the others
            results[k] = ("error", error)
    if any(died):  # the next batch starts a new pool
        _shutdown()
    return results


def _largest_first(jobs: list[tuple[Any, Model]]) -> list[int]:
    """The jobs' places, the runs with the most nodes first (a batch's last run is short).

    Nodes: the blank's area over Δ², halved by each symmetry plane, times the plies.
    """
    def nodes(job) -> float:
        blank = job[0].blank
        return (blank.area_mm2 / blank.cell_mm**2 / 2 ** len(job[0].planes)
                * max(1, len(job[0].plies)))

    return sorted(range(len(jobs)), key=lambda k: -nodes(jobs[k]))


def _form_in_groups(jobs: list[tuple[Any, Model]], groups: int) -> list[tuple[str, Any]]:
    """The jobs under plain ``mpirun``, in ``groups`` groups of ranks, each run on one group.

    Group g (ranks g·K to g·K + K − 1) forms the jobs g, g + groups, ...; every rank gets
    every result, in the order of ``jobs``.
    """
    from mpi4py import MPI

    world = MPI.COMM_WORLD
    size = world.size // groups
    colour = world.rank // size
    group = world.Split(colour, world.rank)
    mine = []
    try:
        for j in range(colour, len(jobs), groups):
            try:
                mine.append((j, ("ok", _form(*jobs[j], group))))
            except Exception as error:  # raised after the others
                mine.append((j, ("error", _sendable(error))))
    finally:
        group.Free()
    results: list[tuple[str, Any]] = [("error", RuntimeError("not formed"))] * len(jobs)
    for part in world.allgather(mine if world.rank % size == 0 else []):
        for j, result in part:
            results[j] = result
    return results


class _Cancelled(BaseException):  # not an Exception: it passes the calls' handlers
    """Raised in the calls of :func:`together` when forming their batch failed."""


_task = threading.local()  # in a call of together(): its group (.group) and place (.index)


class _Turns:
    """The calls of one :func:`together`: which one runs, and the runs each waits for."""

    def __init__(self) -> None:
        self.changed = threading.Condition()
        self.running: int | None = None  # the call whose turn it is; None: the caller's
        self.asked: dict[int, tuple[list, list]] = {}  # each waiting call's jobs and spares
        self.answers: dict[int, Any] = {}  # their results, or _Cancelled

    def give(self, i: int) -> None:
        """The caller's side: call ``i`` runs until it asks for runs or returns."""
        with self.changed:
            self.running = i
            self.changed.notify_all()
            self.changed.wait_for(lambda: self.running is None)

    def wait(self, i: int) -> None:
        with self.changed:
            self.changed.wait_for(lambda: self.running == i)

    def back(self) -> None:
        with self.changed:
            self.running = None
            self.changed.notify_all()

    def ask(self, i: int, jobs: list, spares: list) -> list[tuple[str, Any] | None]:
        """A call's side: the results of its jobs, formed with the other calls' (its turn ends)."""
        self.asked[i] = jobs, spares
        self.back()
        self.wait(i)
        answer = self.answers.pop(i)
        if answer is _Cancelled:
            raise _Cancelled
        return answer


def together(calls: Sequence[Callable[[Callable[[str], None]], Any]],
             progress: Callable[[str], None] | None = None) -> list[Any]:
    """The results of ``calls`` as made one after the other, their forming runs formed at once.

    Each call runs in a thread of its own, but only one at a time and in a fixed order: a call
    runs until it asks :func:`form_many` for runs or returns, then the next one; when every
    call waits or is done, the runs they wait for go to the workers in one batch (the
    independent candidates of a diagnosis keep every core busy, where one after the other
    they asked a run or two at a time). Every result is the one calling them in turn gives:
    a run is the same whichever batch formed it. Calls may nest (a candidate's held-out
    folds): an inner group's batch is a request of its caller's.

    Args:
        calls: Each is given its own ``say`` (a line of progress): the lines of every call
            reach ``progress`` in the calls' order, each call's once those before it are done.
        progress: Where the lines go (None: nowhere).

    Returns:
        Each call's result, in order. A call's exception is raised once all are done (the
        first one's).
    """
    calls = list(calls)
    progress = progress or (lambda line: None)
    turns = _Turns()
    results: list[Any] = [None] * len(calls)
    errors: dict[int, BaseException] = {}
    lines: list[list[str]] = [[] for _ in calls]
    done: set[int] = set()
    shown = [0]  # the first call whose lines are not all shown

    def show() -> None:
        while shown[0] < len(calls):
            i = shown[0]
            for line in lines[i]:
                progress(line)
            lines[i].clear()
            if i not in done:
                return
            shown[0] += 1

    contexts = [contextvars.copy_context() for _ in calls]  # each call sees the caller's

    def body(i: int) -> None:
        _task.group, _task.index = turns, i
        turns.wait(i)

        def say(line: str) -> None:
            lines[i].append(line)
            show()

        try:
            results[i] = contexts[i].run(calls[i], say)
        except BaseException as error:  # raised by together() once all are done
            errors[i] = error
        finally:
            done.add(i)
            show()
            turns.back()

    threads = [threading.Thread(target=body, args=(i,), daemon=True, name=f"together-{i}")
               for i in range(len(calls))]
    for thread in threads:
        thread.start()
    ready = list(range(len(calls)))
    while ready:
        for i in ready:
            turns.give(i)
        ready = sorted(turns.asked)
        if not ready:
            break
        asked = [turns.asked.pop(i) for i in ready]
        try:
            formed = _gathered([job for jobs, _ in asked for job in jobs],
                               [job for _, spares in asked for job in spares])
        except BaseException:  # every waiting call stops; then this is raised
            for i in ready:
                turns.answers[i] = _Cancelled
                turns.give(i)
            raise
        n = sum(len(jobs) for jobs, _ in asked)
        ran, spared = formed[:n], formed[n:]
        for i, (jobs, spares) in zip(ready, asked):
            turns.answers[i] = ran[:len(jobs)] + spared[:len(spares)]
            ran, spared = ran[len(jobs):], spared[len(spares):]
    for thread in threads:
        thread.join()
    if errors:
        raise errors[min(errors)]
    return results


def form_many(jobs: Sequence[tuple[Any, Model]]) -> list[FormedGrid]:
    """Formed sheets (modelled parts) of ``(case, model)`` jobs: remembered, new ones at once.

    The runs not in memory are looked up in the disk cache of :func:`execution`, the rest
    formed by :func:`executor`'s processes and stored; inside :func:`together`, with the
    runs the other calls wait for. A run that fails is raised (its message naming the case
    and model) once the others are formed and kept. Inside :func:`spare`, the jobs from its
    index on are spare: :class:`Deferred` is raised when one is left unformed.
    """
    jobs = list(jobs)
    first = _spare_from.get()
    first = len(jobs) if first is None else first
    results = _gathered(jobs[:first], jobs[first:])
    for (case, model), got in zip(jobs, results):
        if got is not None and got[0] == "error":
            raise _named(got[1], describe(case, model))
    if None in results:
        raise Deferred
    return [grid for _, grid in results]


def _gathered(jobs: list[tuple[Any, Model]], spares: list[tuple[Any, Model]] = ()
              ) -> list[tuple[str, Any] | None]:
    """``("ok", sheet)`` or ``("error", exception)`` per job, then per spare (None: left).

    In a call of :func:`together`: from its group's batch; else formed here (:func:`_gather`).
    """
    turns = getattr(_task, "group", None)
    if turns is not None:
        return turns.ask(_task.index, jobs, list(spares))
    return _gather(jobs, list(spares))


def _gather(jobs: list[tuple[Any, Model]], spares: list[tuple[Any, Model]] = ()
            ) -> list[tuple[str, Any] | None]:
    """:func:`_gathered`'s work: memory, then the disk cache, then the executor.

    The spare jobs (:func:`spare`) fill the batch's free slots, the first first.
    """
    keys = [_key(case, model) for case, model in jobs]
    extra = [_key(case, model) for case, model in spares]
    for k in dict.fromkeys(keys + extra):  # the batch's runs in memory are the newest: kept
        if k in _cache:
            _cache[k] = _cache.pop(k)
    got: dict[tuple, tuple[str, Any]] = {k: ("ok", _cache[k])
                                         for k in keys + extra if k in _cache}
    in_memory = set(got)
    todo = {k: job for k, job in zip(keys, jobs) if k not in _cache}
    maybe = {k: job for k, job in zip(extra, spares) if k not in _cache and k not in todo}
    store: RunStore | None = _settings["store"]
    names = {}
    if store is not None:
        from fenicsx_drape.diagnosis.run_store import run_key

        names = {k: run_key(k) for k in (*todo, *maybe)}
        for k in (*todo, *maybe):
            found = store.get(names[k])
            if found is not None:
                _keep(k, found)
                got[k] = ("ok", found[0])
                counts["from_disk"] += 1
                todo.pop(k, None)
                maybe.pop(k, None)
    if todo:  # the spares that fill the last round of runs at once
        free = -len(todo) % runs_at_once()
        todo.update(list(maybe.items())[:free])
        for k, (status, value) in zip(todo, _form_all(list(todo.values()))):
            if status == "error":
                got[k] = (status, value)
                continue
            counts["formed"] += 1
            _keep(k, value)
            got[k] = ("ok", value[0])
            if store is not None:
                store.put(names[k], *value)
    asked = set(keys) | (set(extra) & set(got))
    counts["asked"] += len(asked)
    counts["from_memory"] += len(asked & in_memory)
    return [got[k] for k in keys] + [got.get(k) for k in extra]


def _named(error: Exception, run: str) -> Exception:
    """``error`` with ``run`` (the case and model) in front of its message."""
    if error.args and isinstance(error.args[0], str) and run not in error.args[0]:
        error.args = (f"{run}: {error.args[0]}", *error.args[1:])
    elif not error.args:
        error.args = (run,)
    return error


def _keep(key: tuple, run: tuple[FormedGrid, float | None, dict]) -> None:
    grid, stopped_mm, curves = run
    if len(_cache) >= _CACHE_SIZE:
        oldest = next(iter(_cache))
        del _cache[oldest]
        _stopped.pop(oldest, None)
        _forces.pop(oldest, None)
    _cache[key] = grid
    _forces[key] = curves
    if stopped_mm is not None:
        _stopped[key] = stopped_mm


def cached(case, model: Model) -> bool:
    """Whether a run of ``(case, model)`` is in memory (:func:`form_many` will not form it)."""
    return _key(case, model) in _cache


def runs_of(jobs: Iterable[tuple[Any, Model]]) -> set[tuple]:
    """The distinct runs ``jobs`` ask for (:func:`form_many` forms each once), by their keys."""
    return {_key(case, model) for case, model in jobs}


def tool_forces(case, model: Model) -> dict[str, np.ndarray]:
    """The force curves of a cached run of ``(case, model)`` (run :func:`form_many` first).

    ``time_s``, ``travel_mm`` and each tool's force along its motion (N, the whole part;
    :func:`~fenicsx_drape.forming.running.run.record_tool_forces`), one value per converged step.
    """
    key = _key(case, model)
    if key not in _forces:
        form_many([(case, model)])
    return _forces[key]


def stopped_at(case, model: Model) -> float | None:
    """The travel (mm) a cached run of ``(case, model)`` reached if it stopped short, else None."""
    return _stopped.get(_key(case, model))
