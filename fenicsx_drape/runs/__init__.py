"""Forming runs: remembered, and formed on every core, a pool of processes or MPI's ranks.

A forming test is simulated by forming its part for a model: its forming case (the paper's
hemisphere is ``meshes/hemisphere/case.toml``) run by
:func:`~fenicsx_drape.forming.running.run.run_case`. A diagnosis asks for dozens to hundreds
of such runs, many of them the same; it asks this package for them and knows nothing of
workers. :func:`form_many` forms ``(case, model)`` jobs: every run is known by the case's
content (its tables and the bytes of its geometry files, not the path it was read from), the
model and the solver options (:mod:`~fenicsx_drape.runs.keys`); it is kept in memory and,
with a cache folder, on disk across commands (:mod:`~fenicsx_drape.runs.store`: a stored run
proves it is the run asked for). The new runs of a call go through :mod:`concurrent.futures`
(:mod:`~fenicsx_drape.runs.pools`): local processes (as many as the cores, or
``DRAPE_WORKERS``, or the ``workers`` given: this process and a pool of the others, warmed up
as soon as it starts), the shared pool of ``mpi4py.futures`` when run as ``mpiexec -n N
python3 -m mpi4py.futures -m fenicsx_drape ...`` (:mod:`~fenicsx_drape.runs.mpi`), and, under
plain ``mpirun``, one run after the other on all ranks (or, with ``ranks_per_run``, runs at
once on groups of ranks: runs × ranks). The results are gathered in the order the runs were
asked, whichever process formed them: the same report from every executor. A run that fails
is raised after the others have finished, its case and model named. :func:`together` runs
independent calls (a diagnosis's candidates) so that their runs are formed in common batches
(:mod:`~fenicsx_drape.runs.scheduler`).

The runs' state -- the runs in memory, the disk store, the executor, the cells of
:func:`resolution`, the spare jobs of :func:`spare`, the values derived from the runs
(:func:`memo`) -- lives in a :class:`Runs` the caller owns (:mod:`~fenicsx_drape.runs.runner`).
The command line makes one from ``--workers``, ``--cache``, ``DRAPE_WORKERS`` and
``DRAPE_CACHE`` and makes it current for the command::

    with Runs(workers=2, cache="runs-cache"):
        report = diagnose(bundle, model)

The functions below ask the current one (:func:`current`); outside any ``with`` block, a
Python user's runs go to the process's default :class:`Runs` (in memory only, on the default
workers). By default a case runs on its own blank's ``cell_mm`` (the hemisphere's:
:data:`FULL_CELL_MM`, the paper's Δ); :func:`resolution` replaces it. A run that stops short of
full travel is kept as far as it got, and :func:`stopped_at` tells the travel it reached.

This package knows forming cases and models, not tests: the forming kind of the diagnosis
turns a test into a case. Importing it loads no DOLFINx (nor PETSc): the workers of
``mpi4py.futures`` import :mod:`~fenicsx_drape.runs.mpi` before each starts PETSc on itself.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, Any

from fenicsx_drape.runs.keys import USER_OPTIONS, describe, key_of, solver_options
from fenicsx_drape.runs.runner import MEMORY_SIZE, Deferred, Memo, Runs, current
from fenicsx_drape.runs.store import CACHE_ENV, RunStore, default_folder
from fenicsx_drape.runs.workers import WORKERS_ENV, capped, cores, default_workers

if TYPE_CHECKING:
    import os
    from concurrent.futures import Executor

    import numpy as np

    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.model import Model

__all__ = [
    "CACHE_ENV", "FULL_CELL_MM", "MEMORY_SIZE", "SCREEN_CELL_MM", "USER_OPTIONS", "WORKERS_ENV",
    "Deferred", "Memo", "RunStore", "Runs", "cached", "capped", "cell_override", "cores",
    "current", "default_folder", "default_workers", "describe", "execution",
    "execution_record", "executor", "form_many", "key_of", "memo", "resolution",
    "runs_at_once", "runs_of",
    "solver_options", "spare", "stopped_at", "together", "tool_forces",
]

FULL_CELL_MM = 10.0  # unit cell of the forming runs (mm), the paper's Δ
SCREEN_CELL_MM = 20.0  # a coarse screening mesh (mm), for data formed on it (tests)


def __getattr__(name: str):
    # case_key, importable from here as from diagnosis.forming_runs (its home: forming.case),
    # is imported when asked: importing this package loads no DOLFINx (a pool's worker
    # imports runs.mpi before its PETSc starts on itself alone).
    if name == "case_key":
        from fenicsx_drape.forming.case.format import case_key

        return case_key
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def memo(name: str, size: int = 64) -> Memo:
    """The current :class:`Runs`' table ``name`` (:meth:`Runs.memo`)."""
    return current().memo(name, size)


def execution(workers: int | None = None, cache: str | os.PathLike | None = None, *,
              ranks_per_run: int | None = None) -> Runs:
    """A :class:`Runs` on ``workers`` processes, its runs remembered in ``cache``.

    ``with execution(...):`` makes it current inside (the name of earlier releases).
    """
    return Runs(workers, cache, ranks_per_run=ranks_per_run)


def execution_record() -> dict[str, Any]:
    """How the current :class:`Runs` made its runs (:meth:`Runs.record`): provenance.json's."""
    return current().record()


def form_many(jobs: Sequence[tuple[Any, Model]]) -> list[FormedGrid]:
    """Formed sheets of ``(case, model)`` jobs (:meth:`Runs.form_many` of :func:`current`)."""
    return current().form_many(jobs)


def together(calls: Sequence[Callable[[Callable[[str], None]], Any]],
             progress: Callable[[str], None] | None = None) -> list[Any]:
    """The results of ``calls`` as one after the other, their runs at once (:meth:`Runs.together`).

    Each call is given its own ``say`` (a line of progress, shown in the calls' order on
    ``progress``); a call's exception is raised once all are done.
    """
    return current().together(calls, progress)


def resolution(cell_mm: float | None) -> AbstractContextManager[None]:
    """Run the forming simulations on cells of ``cell_mm`` (mm) inside (:meth:`Runs.resolution`).

    None: each case on its own blank's ``cell_mm`` (the hemisphere's: :data:`FULL_CELL_MM`).
    """
    return current().resolution(cell_mm)


def cell_override() -> float | None:
    """The unit cell (mm) a :func:`resolution` sets for every run, None for the cases' own."""
    return current().cell_override()


def spare(first: int) -> AbstractContextManager[None]:
    """Inside, :func:`form_many`'s jobs from index ``first`` on are spare (:meth:`Runs.spare`)."""
    return current().spare(first)


def runs_at_once() -> int:
    """How many runs :func:`form_many` forms at once (its executor's workers or rank groups)."""
    return current().runs_at_once()


def executor() -> tuple[str, Executor | None]:
    """The executor of the forming runs, by name, and its pool (:meth:`Runs.executor`)."""
    return current().executor()


def cached(case, model: Model) -> bool:
    """Whether a run of ``(case, model)`` is in memory (:func:`form_many` will not form it)."""
    return current().cached(case, model)


def runs_of(jobs: Iterable[tuple[Any, Model]]) -> set[tuple]:
    """The distinct runs ``jobs`` ask for (:func:`form_many` forms each once), by their keys."""
    return current().runs_of(jobs)


def tool_forces(case, model: Model) -> dict[str, np.ndarray]:
    """The force curves of the run of ``(case, model)`` (:meth:`Runs.tool_forces`)."""
    return current().tool_forces(case, model)


def stopped_at(case, model: Model) -> float | None:
    """The travel (mm) a cached run of ``(case, model)`` reached if it stopped short, else None."""
    return current().stopped_at(case, model)
