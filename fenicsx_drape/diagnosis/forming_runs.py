"""The forming runs of compare and diagnose: cached, and in worker processes.

A forming test is simulated by forming its part for a model: its forming case (the paper's
hemisphere is ``meshes/hemisphere/case.toml``) run by
:func:`~fenicsx_drape.forming.running.run.run_case`. A diagnosis asks for a few dozen such
runs, many of them the same. :func:`form_many` forms ``(case, model)`` jobs: every run is
cached by the case's content (its tables and the bytes of its geometry files, not the path
it was read from) and the model (the :data:`_CACHE_SIZE` latest), and the new runs of one call
go to :data:`WORKERS` persistent worker processes at once (under ``mpirun`` they run one
after the other on all ranks). The cells of the runs are set with :func:`resolution`: by
default a case runs on its own blank's ``cell_mm`` (the hemisphere's: :data:`FULL_CELL_MM`,
the paper's Δ); a resolution replaces it. A run that stops short of full travel is
kept as far as it got, and :func:`stopped_at` tells the travel it reached.

This module knows forming cases and models, not tests: the forming kind
(:mod:`~fenicsx_drape.diagnosis.forming_kind`) turns a test into a case.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case.format import case_dict
from fenicsx_drape.provenance import file_digest
from fenicsx_drape.trust import set_trusted, trusted

if TYPE_CHECKING:
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.model import Model

FULL_CELL_MM = 10.0  # unit cell of the forming runs (mm), the paper's Δ
SCREEN_CELL_MM = 20.0  # a coarse screening mesh (mm), for data formed on it (tests)
WORKERS = max(1, min(2, os.cpu_count() or 1))  # processes running forming solves at once

_settings: dict[str, float | None] = {"cell_mm": None}  # None: each case's own cell
_cache: dict[tuple, FormedGrid] = {}
_stopped: dict[tuple, float] = {}  # travel (mm) reached by the runs that stopped short
_forces: dict[tuple, dict] = {}  # the tools' force curves of the cached runs (run.tool_forces)
_CACHE_SIZE = 256


@contextlib.contextmanager
def resolution(cell_mm: float | None) -> Iterator[None]:
    """Run the forming simulations of compare/diagnose on cells of ``cell_mm`` (mm) inside.

    None: each case on its own blank's ``cell_mm`` (the hemisphere's: :data:`FULL_CELL_MM`).
    """
    if cell_mm is not None and not cell_mm > 0:
        raise DrapeInputError(f"forming cell size {cell_mm} mm must be > 0")
    old = _settings["cell_mm"]
    _settings["cell_mm"] = None if cell_mm is None else float(cell_mm)
    try:
        yield
    finally:
        _settings["cell_mm"] = old


def cell_override() -> float | None:
    """The unit cell (mm) a :func:`resolution` sets for every run, None for the cases' own."""
    return _settings["cell_mm"]


def case_key(case) -> str:
    """What a forming run of ``case`` depends on, as text.

    A :class:`~fenicsx_drape.forming.case.format.FormingCase` by content: its tables (paths relative
    to its folder, the model file left out: the run's model is given) and the digests of the
    geometry files it reads, so that the same case read from two copies (a bundle's and the
    mesh folder's) shares its runs.
    """
    tables = case_dict(case, case.folder)
    tables["case"].pop("model", None)
    files = [t.path for t in case.tools if t.path is not None]
    if case.blank.path is not None:
        files.append(case.blank.path)
    digests = [file_digest(Path(p)) if Path(p).is_file() else f"missing {p}" for p in files]
    return json.dumps([tables, digests], sort_keys=True, default=str)


def _key(case, model: Model) -> tuple:
    params = tuple(sorted((k, float(v)) for k, v in model.parameters.items()))
    return (case_key(case), tuple(sorted(model.effects)), params,
            tuple(str(p) for p in model.plugins))


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


def _in_workers(jobs: list[tuple[Any, Model]]) -> list[tuple]:
    """Run forming jobs on :data:`WORKERS` persistent worker processes, a batch at a time.

    Fresh processes (not forks: MPI is initialised here) started once and kept: each imports
    DOLFINx and compiles the forms once, then reads pickled jobs on stdin and writes the
    pickled grids on stdout. The MPI launcher's environment is left out so that each runs as
    its own single-process MPI job.
    """
    import pickle

    results: list = [None] * len(jobs)
    pending = list(enumerate(jobs))
    while pending:
        batch, pending = pending[:WORKERS], pending[WORKERS:]
        workers = _pool(len(batch))
        for (_, job), proc in zip(batch, workers):
            pickle.dump((*job, trusted()), proc.stdin)  # the trust of now, not of the start
            proc.stdin.flush()
        for (i, _), proc in zip(batch, workers):
            try:
                status, value = pickle.load(proc.stdout)
            except EOFError:
                _workers.remove(proc)
                raise RuntimeError(f"forming worker failed (exit status {proc.wait()})") from None
            if status == "error":
                raise value
            results[i] = value
    return results


_workers: list = []  # the persistent worker processes of _in_workers


def _pool(n: int) -> list:
    """``n`` live worker processes, started on first use and stopped at exit."""
    import subprocess
    import sys

    _workers[:] = [p for p in _workers if p.poll() is None]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "PMI_"))}
    command = [sys.executable, "-c",
               "from fenicsx_drape.diagnosis.forming_runs import _worker; _worker()"]
    while len(_workers) < n:
        _workers.append(subprocess.Popen(command, stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, env=env))
    return _workers[:n]


@atexit.register
def _stop_workers() -> None:
    for proc in _workers:
        proc.stdin.close()
        proc.wait()
    _workers.clear()


def _worker() -> None:
    """Entry point of a worker process (:func:`_in_workers`): jobs until stdin closes."""
    import pickle
    import sys

    jobs, result = sys.stdin.buffer, os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # whatever the solver prints goes to stderr, not into the pickles
    while True:
        try:
            case, model, trust = pickle.load(jobs)
        except EOFError:
            return
        set_trusted(trust)
        try:
            reply = ("ok", _form(case, model))
        except DrapeInputError as error:  # its subclasses may not unpickle: send the message
            reply = ("error", DrapeInputError(str(error)))
        except Exception as error:  # sent back and raised in the parent
            reply = ("error", error)
        try:
            data = pickle.dumps(reply)
        except Exception:
            data = pickle.dumps(("error", RuntimeError(f"forming worker: {reply[1]!r}")))
        result.write(data)
        result.flush()


def form_many(jobs: Sequence[tuple[Any, Model]]) -> list[FormedGrid]:
    """Formed sheets (modelled parts) of ``(case, model)`` jobs: cached, new ones in parallel.

    With one MPI process the new runs go to :data:`WORKERS` worker processes; under
    ``mpirun`` they run one after the other on all ranks.
    """
    from mpi4py import MPI

    keys = [_key(case, model) for case, model in jobs]
    todo = {k: job for k, job in zip(keys, jobs) if k not in _cache}
    if todo:
        comm = MPI.COMM_WORLD
        if comm.size > 1 or WORKERS == 1 or len(todo) == 1:
            results = [_form(c, m, comm) for c, m in todo.values()]
        else:
            results = _in_workers(list(todo.values()))
        for k, (grid, stopped_mm, curves) in zip(todo, results):
            if len(_cache) >= _CACHE_SIZE:
                oldest = next(iter(_cache))
                del _cache[oldest]
                _stopped.pop(oldest, None)
                _forces.pop(oldest, None)
            _cache[k] = grid
            _forces[k] = curves
            if stopped_mm is not None:
                _stopped[k] = stopped_mm
    return [_cache[k] for k in keys]


def cached(case, model: Model) -> bool:
    """Whether a run of ``(case, model)`` is in the cache (:func:`form_many` will not form it)."""
    return _key(case, model) in _cache


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
