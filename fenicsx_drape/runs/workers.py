"""How many processes form runs at once: given, ``DRAPE_WORKERS``, or the cores; never more.

A forming run is one process's work, bound by its CPU: a worker beyond the cores forms
nothing sooner, and each holds DOLFINx and a run in memory (a few hundred MB) and starts with
a warm-up run of its own. So ``--workers N`` and ``DRAPE_WORKERS=N`` above the cores this
process may use are capped to them, with a note (:func:`capped`); a Python caller that names
its workers (:class:`~fenicsx_drape.runs.Runs`) gets what it asks.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable

from fenicsx_drape.errors import DrapeInputError

WORKERS_ENV = "DRAPE_WORKERS"  # processes forming at once, when not given


def cores() -> int:
    """The cores this process may run on (its CPU affinity)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _from_env() -> int | None:
    given = os.environ.get(WORKERS_ENV, "").strip()
    if not given:
        return None
    if not (given.isdigit() and int(given) >= 1):
        raise DrapeInputError(f"{WORKERS_ENV}={given!r}: a number of processes >= 1")
    return int(given)


def default_workers() -> int:
    """Processes forming at once by default: ``DRAPE_WORKERS`` at most the cores, else them.

    Raises:
        DrapeInputError: ``DRAPE_WORKERS`` is not a whole number >= 1.
    """
    given = _from_env()
    return cores() if given is None else min(given, cores())


def capped(workers: int | None, say: Callable[[str], None] | None = None) -> int | None:
    """``workers`` (``--workers``; None: ``DRAPE_WORKERS``) checked and capped to the cores.

    Returns the number given, at most :func:`cores` (None when none is given and
    ``DRAPE_WORKERS`` is not set either); a number above is capped, and ``say`` (default:
    standard error) gets a note saying so.

    Raises:
        DrapeInputError: ``workers`` or ``DRAPE_WORKERS`` is not a whole number >= 1.
    """
    say = say or (lambda line: print(f"drape: {line}", file=sys.stderr, flush=True))
    if workers is None:
        given, name = _from_env(), f"{WORKERS_ENV}="
    elif int(workers) == workers and workers >= 1:
        given, name = int(workers), "--workers "
    else:
        raise DrapeInputError(f"--workers {workers}: a number of processes >= 1")
    if given is not None and given > cores():
        say(f"{name}{given} is more than the {cores()} core(s) this process may use: "
            f"{cores()} worker(s) (a run is one process's work; more would only wait, each "
            "holding DOLFINx and a run in memory)")
        return cores()
    return given
