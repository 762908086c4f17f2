"""Forming runs on the ranks of an MPI job: ``mpiexec -n N python3 -m mpi4py.futures ...``.

Under ``mpi4py.futures`` rank 0 runs the command and the other ranks are a pool of workers
(:class:`mpi4py.futures.MPIPoolExecutor`), each forming a run on its own. PETSc's start is
collective over ``MPI.COMM_WORLD``, which the pool's ranks never join together: each process
starts PETSc on itself alone (:func:`petsc_alone`) before DOLFINx is imported -- rank 0 from the
command line, a worker as the pool's initializer. This module imports no DOLFINx.
"""

from __future__ import annotations

import sys


def shared_pool() -> bool:
    """Whether this is rank 0 of ``python3 -m mpi4py.futures`` (the other ranks are workers)."""
    core = sys.modules.get("mpi4py.futures._core")
    return getattr(core, "SharedPool", None) is not None


def petsc_alone() -> None:
    """Start PETSc on this process alone (``PETSC_COMM_WORLD`` = ``MPI.COMM_SELF``).

    Nothing to do once PETSc is started (then it was started so, or the job is not a pool).
    """
    if "petsc4py.PETSc" in sys.modules:
        return
    import petsc4py
    from mpi4py import MPI

    petsc4py.init(comm=MPI.COMM_SELF)


def pool():
    """The pool of the job's other ranks (workers started with :func:`petsc_alone`)."""
    from mpi4py.futures import MPIPoolExecutor

    # The workers import no script: a job names its functions by module.
    return MPIPoolExecutor(main=False, initializer=petsc_alone)
