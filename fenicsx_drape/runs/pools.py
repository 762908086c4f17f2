"""Where forming runs are formed: this process, a pool of local processes, MPI's ranks.

:func:`executor_kind` names the executor an MPI job and a number of workers give: ``this
process``; ``processes`` (this process and a :class:`LocalPool` of N − 1 fresh ones, warmed up
as soon as it starts); ``mpi4py.futures`` (the shared pool of ``mpiexec -n N python3 -m
mpi4py.futures -m fenicsx_drape ...``, :mod:`~fenicsx_drape.runs.mpi`); or, under plain
``mpirun``, ``all ranks`` (one run after the other on all ranks, or, with ``ranks_per_run``,
runs at once on groups of ranks: :func:`form_in_groups`). Every path returns ``("ok", run)``
or ``("error", exception)`` per job in the order asked, whichever process formed it: the same
results from every executor.

A worker ignores SIGINT: a Ctrl-C reaches the command's process, which stops the workers
(:meth:`LocalPool.stop`) and says what was kept.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.runs.keys import apply_solver_options, solver_options
from fenicsx_drape.trust import set_trusted, trusted

if TYPE_CHECKING:
    from concurrent.futures import Executor, Future

    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.model import Model

# Open MPI's settings that ./drape gives (not a launcher's job): as root, without the
# libfabric transport, whose probe of the network costs a second of each worker's start.
_MPI_SETTINGS = ("OMPI_ALLOW_RUN_AS_ROOT", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "OMPI_MCA_btl")

Run = tuple["FormedGrid", "float | None", "dict[str, np.ndarray]"]
Job = tuple[Any, "Model"]


def form(case, model: Model, comm=None) -> Run:
    """One forming run (on this process alone by default): the formed sheet (modelled part).

    A model that cannot form the part to full travel (its solve fails at the smallest step)
    is compared as far as it got: the second value is then the travel reached (mm), else
    None. The third is the tools' force curves (``time_s``, ``travel_mm`` and each tool's
    force along its motion, one value per converged step).
    """
    from mpi4py import MPI

    from fenicsx_drape.forming.running.run import run_case

    comm = comm or MPI.COMM_SELF
    with interrupts_between_steps() as check:
        run = run_case(case, model, comm=comm, allow_incomplete=True, on_step=check)
    rows = run.tool_forces
    curves = {k: np.array([r[k] for r in rows]) for k in (rows[0] if rows else {})}
    return run.grid, (run.travel_mm if run.stopped else None), curves


@contextlib.contextmanager
def interrupts_between_steps() -> Iterator[Callable[[object], None]]:
    """Inside, a Ctrl-C (SIGINT) is raised as KeyboardInterrupt only between load steps.

    Raised inside a solve it would reach one of PETSc's calls back into Python (a residual, a
    convergence test), where it reads as a failed step: the step would be cut and the run go
    on, interrupted in nothing but its path. So SIGINT is noted while a run is formed and
    raised by the ``check`` yielded (called after each converged step), or at the end (also
    when the run raised an error meanwhile).
    Elsewhere than in the main thread (where Python handles signals), or under a handler of
    the caller's own, nothing changes.
    """
    noted: list[int] = []

    def check(problem=None) -> None:
        if noted:
            noted.clear()
            raise KeyboardInterrupt

    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield check  # a worker (SIGINT ignored), or a caller's own handler: left as it is
        return
    signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
    try:
        yield check
    except Exception as error:  # a run that failed after a Ctrl-C: the Ctrl-C is not lost
        if noted:
            noted.clear()
            raise KeyboardInterrupt from error
        raise
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    check()


def run_job(case, model: Model, trust: bool, options: tuple) -> tuple[str, Any]:
    """A job in a worker process: ``("ok", run)`` or ``("error", exception)``.

    The parent's trust and PETSc options come with each job (a worker outlives a command).
    Errors come back as values, in a form that unpickles in the parent.
    """
    set_trusted(trust)
    apply_solver_options(options)
    try:
        return "ok", form(case, model)
    except Exception as error:  # sent back and raised in the parent
        return "error", sendable(error)


def sendable(error: Exception) -> Exception:
    """``error`` in a form that unpickles in another process."""
    import pickle

    if isinstance(error, DrapeInputError):  # its subclasses may not unpickle: the message
        return DrapeInputError(str(error))
    try:
        pickle.loads(pickle.dumps(error))
    except Exception:
        return RuntimeError(f"{type(error).__name__}: {error}")
    return error


def form_here(jobs: list[Job], comm=None) -> list[tuple[str, Any]]:
    """The jobs formed one after the other in this process (on ``comm``; default: alone)."""
    results = []
    for case, model in jobs:
        try:
            results.append(("ok", form(case, model, comm)))
        except Exception as error:  # raised after the others
            results.append(("error", error))
    return results


def executor_kind(workers: int, ranks_per_run: int | None) -> tuple[str, int]:
    """The executor's name and how many runs it forms at once (workers, or groups of ranks)."""
    from mpi4py import MPI

    from fenicsx_drape.runs import mpi

    if mpi.shared_pool():
        return "mpi4py.futures", MPI.COMM_WORLD.size - 1
    if MPI.COMM_WORLD.size > 1:
        return "all ranks", MPI.COMM_WORLD.size // (ranks_per_run or MPI.COMM_WORLD.size)
    return ("this process", 1) if workers == 1 else ("processes", workers)


def largest_first(jobs: list[Job]) -> list[int]:
    """The jobs' places, the runs with the most nodes first (a batch's last run is short).

    Nodes: the blank's area over Δ², halved by each symmetry plane, times the plies.
    """
    def nodes(job) -> float:
        blank = job[0].blank
        return (blank.area_mm2 / blank.cell_mm**2 / 2 ** len(job[0].planes)
                * max(1, len(job[0].plies)))

    return sorted(range(len(jobs)), key=lambda k: -nodes(jobs[k]))


def ignore_interrupts() -> None:
    """A worker's start: SIGINT ignored (the command's process stops the workers)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def fresh_workers() -> Iterator[None]:
    """Start local workers as fresh programs: each its own MPI job, not the caller's script.

    Without the MPI launcher's environment a worker is a job of one process (the settings of
    how Open MPI runs here stay: :data:`_MPI_SETTINGS`); without the caller's ``__main__``
    (the worker would run a script again, e.g. a demo, to import it) it imports only this
    package. A worker started inside has SIGINT blocked from its first instruction (the
    signal mask is inherited; :func:`ignore_interrupts` then ignores it): a Ctrl-C, which
    reaches every process of the terminal's group, is the command's to handle. Here SIGINT is
    only held back meanwhile, and raised when the block ends.
    """
    import sys
    import types

    launcher = {k: v for k, v in os.environ.items()
                if k.startswith(("OMPI_", "PMIX_", "PMI_")) and k not in _MPI_SETTINGS}
    for k in launcher:
        del os.environ[k]
    main = sys.modules["__main__"]
    sys.modules["__main__"] = types.ModuleType("__main__")
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        sys.modules["__main__"] = main
        os.environ.update(launcher)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _ignore_broken_pipes() -> None:
    """Give SIGPIPE back to Python (ignored: a write to a dead worker is BrokenPipeError).

    PETSc's signal handler turns it into ``MPI_Abort`` (error 59): a worker that died while
    a job was sent to it would stop the whole diagnosis instead of failing its own runs.
    """
    from petsc4py import PETSc  # noqa: F401 (its start installs the handler: after it)

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)


def warm() -> None:
    """A new worker's first job: import DOLFINx and load the compiled forms (a tiny run)."""
    from fenicsx_drape.forming.case.format import load_case
    from fenicsx_drape.forming.running.run import run_case

    try:
        run_case(load_case("hemisphere", cell_mm=40.0, step_mm=10.0))
    except Exception:  # only a warm-up: the runs will say what is wrong
        pass


class LocalPool:
    """This process and ``workers`` − 1 fresh local processes forming runs together.

    The processes start at once (:func:`fresh_workers`) and each warms up on a tiny run of
    its own (:func:`warm`); until a worker is warm this process takes the batch's runs.
    """

    def __init__(self, workers: int):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.workers = workers
        _ignore_broken_pipes()
        # Fresh processes (not forks of one where MPI is initialised); this process is the
        # last worker (it is warm: DOLFINx imported, forms compiled).
        self.pool = ProcessPoolExecutor(workers - 1, initializer=ignore_interrupts,
                                        mp_context=multiprocessing.get_context("spawn"))
        self.broken = False  # a worker died: the next batch needs a new pool
        try:
            with fresh_workers():  # every process starts now and warms while this one works
                self.warming: list[Future] = [self.pool.submit(warm)
                                              for _ in range(workers - 1)]
        except BaseException:  # interrupted as it starts: no worker left behind
            self.stop(now=True)
            raise

    def share(self, jobs: list[Job]) -> list[tuple[str, Any]]:
        """The jobs formed by this process and the pool's workers together, in the order asked.

        Each next job, the largest first (:func:`largest_first`), goes to whichever is free
        first (a feeding thread per worker waits on it). A run is the same wherever it is
        formed, so the results do not depend on who formed what. A job the pool refuses (a
        worker died since the last batch) is formed here; one whose worker died comes back as
        its error, and :attr:`broken` is set (the next batch starts a new pool).
        """
        from concurrent.futures import BrokenExecutor, wait

        from mpi4py import MPI

        options = solver_options()
        results: list[tuple[str, Any] | None] = [None] * len(jobs)
        queue = largest_first(jobs)[::-1]  # popped from the end
        lock = threading.Lock()
        died = []

        def take() -> int | None:
            with lock:
                return queue.pop() if queue else None

        def feed(warming) -> None:  # a thread: the pool's worker forms job after job ...
            if warming is not None:  # ... once warm (until then this process takes the jobs)
                wait([warming])
            while (k := take()) is not None:
                try:
                    future = self.pool.submit(run_job, *jobs[k], trusted(), options)
                except (BrokenExecutor, RuntimeError):  # refused (died, or stopped)
                    with lock:
                        queue.append(k)
                    died.append(True)
                    return
                try:
                    results[k] = future.result()
                except BaseException as error:  # a worker that died, a job that did not pickle
                    died.append(isinstance(error, BrokenExecutor))
                    results[k] = ("error", RuntimeError(f"forming worker failed: {error!r}"))

        warming = (self.warming + [None] * self.workers)[:self.workers - 1]
        feeders = [threading.Thread(target=feed, args=(w,), daemon=True) for w in warming]
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
                results[k] = ("ok", form(*jobs[k], MPI.COMM_SELF))
            except Exception as error:  # raised after the others
                results[k] = ("error", error)
        self.broken |= any(died)
        return results

    def stop(self, now: bool = False) -> None:
        """Shut the pool down, or ``now`` (an interrupt): its processes killed.

        Not ``now``, nothing waits: the batches are gathered, and a worker still warming up
        ends once its warm-up is done (the interpreter's exit waits for it).
        """
        if now:
            with contextlib.suppress(Exception):
                if hasattr(self.pool, "kill_workers"):  # Python >= 3.14
                    self.pool.kill_workers()
                else:
                    for process in list((self.pool._processes or {}).values()):
                        process.kill()
        self.pool.shutdown(wait=False, cancel_futures=True)


def submit_all(jobs: list[Job], pool: Executor) -> dict[int, Future]:
    """Every job to a worker of ``pool`` (the shared pool of ``mpi4py.futures``), largest first.

    Raises:
        concurrent.futures.BrokenExecutor: The pool refuses jobs (a worker died).
    """
    options = solver_options()
    with fresh_workers():
        return {k: pool.submit(run_job, *jobs[k], trusted(), options)
                for k in largest_first(jobs)}


def gather(futures: dict[int, Future]) -> tuple[list[tuple[str, Any]], bool]:
    """The results of :func:`submit_all`'s futures in the order asked, and whether one died.

    A worker that died leaves the pool broken: the next batch needs a new one.
    """
    from concurrent.futures import BrokenExecutor

    results, broken = [], False
    for k in range(len(futures)):  # in the order asked, whichever finishes first
        try:
            results.append(futures[k].result())
        except Exception as error:  # a worker that died, a job that did not pickle
            broken |= isinstance(error, BrokenExecutor)
            results.append(("error", RuntimeError(f"forming worker failed: {error!r}")))
    return results, broken


def form_in_groups(jobs: list[Job], groups: int) -> list[tuple[str, Any]]:
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
                mine.append((j, ("ok", form(*jobs[j], group))))
            except Exception as error:  # raised after the others
                mine.append((j, ("error", sendable(error))))
    finally:
        group.Free()
    results: list[tuple[str, Any]] = [("error", RuntimeError("not formed"))] * len(jobs)
    for part in world.allgather(mine if world.rank % size == 0 else []):
        for j, result in part:
            results[j] = result
    return results
