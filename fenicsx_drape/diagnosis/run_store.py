"""Moved: the run store is :mod:`fenicsx_drape.runs.store` (kept for one release)."""

import warnings

from fenicsx_drape.runs.store import (
    CACHE_ENV,
    SIZE_LIMIT,
    RunStore,
    code_digest,
    decode,
    default_folder,
    encode,
    run_key,
)

__all__ = ["CACHE_ENV", "SIZE_LIMIT", "RunStore", "code_digest", "decode", "default_folder",
           "encode", "run_key"]

warnings.warn("fenicsx_drape.diagnosis.run_store moved to fenicsx_drape.runs.store",
              DeprecationWarning, stacklevel=2)
