"""Moved: the MPI pool is :mod:`fenicsx_drape.runs.mpi` (kept for one release)."""

import warnings

from fenicsx_drape.runs.mpi import petsc_alone, pool, shared_pool

__all__ = ["petsc_alone", "pool", "shared_pool"]

warnings.warn("fenicsx_drape.diagnosis.mpi_pool moved to fenicsx_drape.runs.mpi",
              DeprecationWarning, stacklevel=2)
