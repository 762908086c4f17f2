"""Moved: the forming runs are the package :mod:`fenicsx_drape.runs` (kept for one release).

``from fenicsx_drape.diagnosis.forming_runs import form_many`` still works; import from
:mod:`fenicsx_drape.runs` instead.
"""

import warnings

from fenicsx_drape.forming.case.format import case_key
from fenicsx_drape.runs import (
    CACHE_ENV,
    FULL_CELL_MM,
    SCREEN_CELL_MM,
    USER_OPTIONS,
    WORKERS_ENV,
    Deferred,
    Runs,
    cached,
    cell_override,
    current,
    default_workers,
    describe,
    execution,
    execution_record,
    executor,
    form_many,
    resolution,
    runs_at_once,
    runs_of,
    spare,
    stopped_at,
    together,
    tool_forces,
)

__all__ = [
    "CACHE_ENV", "FULL_CELL_MM", "SCREEN_CELL_MM", "USER_OPTIONS", "WORKERS_ENV", "Deferred",
    "Runs", "cached", "case_key", "cell_override", "current", "default_workers", "describe",
    "execution", "execution_record", "executor", "form_many", "resolution", "runs_at_once",
    "runs_of", "spare", "stopped_at", "together", "tool_forces",
]

warnings.warn("fenicsx_drape.diagnosis.forming_runs moved to fenicsx_drape.runs",
              DeprecationWarning, stacklevel=2)
