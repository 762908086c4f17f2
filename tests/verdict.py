"""A verdict whatever stops the suite: a time limit per test, and a ledger of what ran.

A pytest plugin (``tests/conftest.py`` loads it):

- **A limit per test.** pytest-timeout reads the limit (``timeout`` in ``pyproject.toml``, a
  test's ``@pytest.mark.timeout(s)``, ``--timeout``); this plugin counts it, in CPU seconds of
  the test's process (and of the processes it waited for), so that a test on a machine busy
  with other work is not stopped for being slow there; a test that waits without computing (a
  lock, a pool whose worker died) is stopped after :data:`WALL_FACTOR` times the limit in
  wall seconds. A thread of the test's process watches both, and stops the test in three
  steps, because it may be stuck where Python cannot interrupt it:

  1. at the limit, SIGALRM fails the test where it is (its traceback shows where), and the
     session goes on with the next test; the handler runs as soon as the main thread runs
     Python again;
  2. :data:`GRACE` seconds later, if the test still runs (stuck in compiled code that let go
     of the GIL, such as an MPI collective that never completes, or code that caught the
     failure and went on, as a forming run's step cut-back does), the thread prints the
     test's name and the stack of the main thread and ends the process with exit status 1:
     pytest-xdist then reports the test as failed, names it and starts a new worker;
     ``mpirun`` stops the other ranks;
  3. when compiled code holds the GIL, no thread of Python runs: the C watchdog of
     :mod:`faulthandler` prints the stacks and ends the process, :data:`GRACE` seconds after
     the limit in wall seconds and step 2 would have.

  There is no dump of stacks while a test is only slow (pytest's ``faulthandler_timeout`` is
  not used). pytest-timeout's own methods each do half: ``signal`` never ends a test stuck in
  compiled code, ``thread`` ends the process at the limit even when the test is only slow,
  after printing every thread's stack; both count wall seconds. pytest-xdist runs the tests
  in each worker's main thread, where SIGALRM can be used; under ``mpirun`` a rank whose test
  failed at the limit goes on while the others may wait for it in a collective: those end at
  step 2 (a rank waiting in a collective spins, so its CPU seconds run on).

- **A ledger** (``--ledger=PATH``; under ``mpirun`` one per rank, ``PATH.rank<r>``): one line
  per event, written as it happens, so that it tells what ran even when the process is killed::

      collected 1003
      start tests/test_x.py::test_y
      passed tests/test_x.py::test_y
      end 0

  ``tests/run_part.sh`` reads it into the one-line verdict of a part of ``make test``. Under
  pytest-xdist the controller writes it (the workers send it their reports).

- At the end of a session that was stopped, the tests that did not finish and the number not
  started are printed after pytest's summary.
"""

from __future__ import annotations

import faulthandler
import os
import resource
import signal
import sys
import threading
import time
import traceback

import pytest

#: The callers of a test, left out of the stack printed at step 2.
INTERNALS = ("/_pytest/", "/pluggy/", "/execnet/", "/xdist/")

#: Seconds between the steps of a test's time limit (above; ``DRAPE_TEST_GRACE_S`` for the
#: test of this plugin).
GRACE = float(os.environ.get("DRAPE_TEST_GRACE_S", 60))

#: A test that waits without computing is stopped after this many times its limit in seconds
#: of wall time.
WALL_FACTOR = 5.0


def cpu_seconds() -> float:
    """CPU seconds of this process and of the processes it waited for."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _rank() -> tuple[int, int]:
    """(rank, size) of ``MPI.COMM_WORLD`` when mpi4py is loaded; (0, 1) otherwise."""
    try:
        from mpi4py import MPI
    except ImportError:
        return 0, 1
    return MPI.COMM_WORLD.rank, MPI.COMM_WORLD.size


def pytest_addoption(parser):
    """``--ledger=PATH``: write what runs, as it runs (the module's docstring)."""
    parser.addoption("--ledger", default=None, metavar="PATH",
                     help="write a line per test started and per test finished (with its "
                          "outcome) to PATH, PATH.rank<r> under mpirun")


def pytest_configure(config):
    """Register the plugin's state for this session."""
    config.pluginmanager.register(Verdict(config), "drape-verdict")


class Verdict:
    """The ledger, the tests that did not finish, and the timers of the time limit."""

    def __init__(self, config):
        self.config = config
        self.worker = hasattr(config, "workerinput")  # an xdist worker: the controller writes
        rank, size = _rank()
        self.where = f" on rank {rank}" if size > 1 else ""
        path = config.getoption("ledger", None)
        if path and size > 1:
            path = f"{path}.rank{rank}"
        self.ledger = open(path, "w", buffering=1) if path and not self.worker else None
        self.collected: int | None = None
        self.running: dict[str, str] = {}  # started, not finished: nodeid -> outcome so far
        self.finished = 0
        # Written to from the watchdog while the terminal's streams may be captured.
        self.stderr = os.dup(2)

    def _write(self, line: str) -> None:
        if self.ledger is not None:
            self.ledger.write(line + "\n")

    # --- the ledger --------------------------------------------------------------------------

    def pytest_collection_finish(self, session):
        if not self.worker and not hasattr(session.config, "workerinput"):
            self.collected = len(session.items)
            self._write(f"collected {self.collected}")

    @pytest.hookimpl(optionalhook=True)
    def pytest_xdist_node_collection_finished(self, node, ids):
        if self.collected is None:
            self.collected = len(ids)
            self._write(f"collected {self.collected}")

    def pytest_runtest_logstart(self, nodeid, location):
        if nodeid not in self.running:
            self.running[nodeid] = "passed"
            self._write(f"start {nodeid}")

    def pytest_runtest_logreport(self, report):
        outcome = self.running.get(report.nodeid, "passed")
        if report.when == "setup" and report.failed:
            outcome = "error"
        elif report.when == "setup" and report.skipped:
            outcome = "skipped"
        elif report.when == "call":
            outcome = report.outcome
            if hasattr(report, "wasxfail"):
                outcome = "xfailed" if report.skipped else "xpassed"
        elif report.when == "teardown" and report.failed and outcome == "passed":
            outcome = "error"
        elif report.when not in ("setup", "call", "teardown") and report.failed:
            # pytest-xdist's report of a test whose worker died: no logfinish follows
            self.running.pop(report.nodeid, None)
            self.finished += 1
            self._write(f"failed {report.nodeid}")
            return
        self.running[report.nodeid] = outcome

    def pytest_runtest_logfinish(self, nodeid, location):
        outcome = self.running.pop(nodeid, None)
        if outcome is not None:
            self.finished += 1
            self._write(f"{outcome} {nodeid}")

    @pytest.hookimpl(trylast=True)
    def pytest_sessionfinish(self, session, exitstatus):
        self._write(f"end {int(exitstatus)}")

    def pytest_terminal_summary(self, terminalreporter):
        """After a stop: the tests that did not finish and how many did not start."""
        if self.worker or self.config.option.collectonly:
            return
        started = self.finished + len(self.running)
        unstarted = self.collected - started if self.collected is not None else 0
        if not self.running and unstarted <= 0:
            return
        terminalreporter.section(f"did not finish{self.where}", sep="!", red=True)
        for nodeid in self.running:
            terminalreporter.write_line(f"DID NOT FINISH {nodeid}")
        if unstarted > 0:
            terminalreporter.write_line(f"{unstarted} of {self.collected} tests not started")

    def pytest_unconfigure(self, config):
        if self.ledger is not None:
            self.ledger.close()
        os.close(self.stderr)

    # --- the time limit ----------------------------------------------------------------------

    @pytest.hookimpl(optionalhook=True, tryfirst=True)
    def pytest_timeout_set_timer(self, item, settings):
        """Watch one test's limit (the module's docstring)."""
        limit, wall_limit = settings.timeout, WALL_FACTOR * settings.timeout
        done = threading.Event()
        main = threading.current_thread() is threading.main_thread()
        main_id = threading.main_thread().ident
        why = []  # what the test ran over, once it has

        if main:
            def fail(signum, frame):
                __tracebackhide__ = True
                if why and not done.is_set():  # not a signal meant for the test before
                    pytest.fail(f"Timeout: the test {why[0]} (its limit) and was stopped here",
                                pytrace=True)

            signal.signal(signal.SIGALRM, fail)

        def watch():
            cpu0, wall0 = cpu_seconds(), time.monotonic()
            while not done.wait(min(1.0, limit / 10)):
                cpu, wall = cpu_seconds() - cpu0, time.monotonic() - wall0
                if not why and (cpu > limit or wall > wall_limit):
                    why.append(f"took more than {limit:g} CPU seconds" if cpu > limit else
                               f"waited more than {wall_limit:g} s")
                    stopped = time.monotonic()
                    if main:
                        signal.pthread_kill(main_id, signal.SIGALRM)
                elif why and time.monotonic() - stopped > GRACE and not done.is_set():
                    self._stuck(item.nodeid, why[0], main_id)

        watchdog = threading.Thread(target=watch, name=f"time limit of {item.nodeid}",
                                    daemon=True)
        watchdog.start()
        faulthandler.dump_traceback_later(wall_limit + 2 * GRACE, exit=True, file=self.stderr)

        def cancel():
            done.set()
            if main:
                signal.signal(signal.SIGALRM, signal.SIG_DFL)
            watchdog.join()
            faulthandler.cancel_dump_traceback_later()

        item.cancel_timeout = cancel
        return True

    @pytest.hookimpl(optionalhook=True, tryfirst=True)
    def pytest_timeout_cancel_timer(self, item):
        """Stop watching the test's limit (also called when its setup was skipped)."""
        cancel = getattr(item, "cancel_timeout", None)
        if cancel is not None:
            cancel()
        return True

    def _stuck(self, nodeid: str, why: str, main_id: int) -> None:
        """Step 2: the test still runs; name it, show where, end the process."""
        frame = sys._current_frames().get(main_id)
        frames = traceback.extract_stack(frame) if frame is not None else []
        callers = [k for k, f in enumerate(frames) if any(p in f.filename for p in INTERNALS)]
        stack = "".join(traceback.format_list(frames[callers[-1] + 1 if callers else 0:]))
        text = (f"\n{'+' * 30} Timeout{self.where} {'+' * 30}\n"
                f"{nodeid} {why} (its limit) and still ran {GRACE:g} s after it was failed "
                "there (in compiled code, or its failure was caught). Where the test is:\n"
                f"{stack}Ending this process{self.where}.\n")
        try:
            os.write(self.stderr, text.encode())
            self._write(f"stuck {nodeid}")
            if self.ledger is not None:
                self.ledger.flush()
        finally:
            os._exit(1)
