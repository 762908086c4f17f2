"""The suite's verdict whatever stops it (``tests/verdict.py``, ``tests/run_part.sh``).

Each test runs pytest on a small file of its own, in a process of its own, with a time limit
of 0.4 CPU seconds per test (2 s of wall time for a test that waits) and 0.5 s between the
limit's steps, and reads what the suite's user reads: the output, the ledger and the part's line of
the verdict.
"""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("pytest_timeout")
pytest.importorskip("xdist")
pytestmark = pytest.mark.skip_in_parallel  # each test starts processes of its own

TESTS = Path(__file__).parent
OVER = r"(took more than 0.4 CPU seconds|waited more than 2 s)"  # a limit of 0.4 s
PART = TESTS / "run_part.sh"

# The tests the sessions below run: each stops in one of the ways the time limit handles.
HANGS = '''
import ctypes

import pytest


def test_first():
    pass


@pytest.mark.timeout(0.4)
def test_slow_in_python():
    while True:
        sum(range(1000))


@pytest.mark.timeout(0.4)
def test_stuck_without_gil():
    # a mutex locked twice: the call never returns, and lets go of the GIL (like an MPI wait)
    mutex = ctypes.create_string_buffer(64)
    ctypes.CDLL(None).pthread_mutex_lock(mutex)
    ctypes.CDLL(None).pthread_mutex_lock(mutex)


@pytest.mark.timeout(0.4)
def test_stuck_with_gil():
    # the same call through PyDLL keeps the GIL: no Python code runs in this process again
    mutex = ctypes.create_string_buffer(64)
    ctypes.PyDLL(None).pthread_mutex_lock(mutex)
    ctypes.PyDLL(None).pthread_mutex_lock(mutex)


def test_last():
    pass
'''

MPI_HANG = '''
import pytest
from mpi4py import MPI


def test_first():
    MPI.COMM_WORLD.Barrier()


@pytest.mark.timeout(0.4)
def test_rank_0_waits_for_a_message_never_sent():
    if MPI.COMM_WORLD.rank == 0:
        MPI.COMM_WORLD.recv(source=1, tag=77)


def test_last():
    MPI.COMM_WORLD.Barrier()
'''


def part(tmp_path, name, *command, args=(), select=None, options=()):
    """Run ``run_part.sh NAME`` on pytest in ``tmp_path``: (pytest's output, the part's line)."""
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    results = tmp_path / "results"
    results.mkdir(exist_ok=True)
    env = dict(os.environ, DRAPE_TEST_GRACE_S="0.5", PYTHONPATH=f"{TESTS}{os.pathsep}"
               + os.environ.get("PYTHONPATH", ""))
    for variable in ("PYTEST_XDIST_WORKER", "PYTEST_XDIST_WORKER_COUNT", "PYTEST_ADDOPTS"):
        env.pop(variable, None)  # the session running this test's, not the one it starts
    pytest_args = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                   "-p", "verdict", "--ledger={ledger}"]
    pytest_args += [*args, *(["-k", select] if select else [])]
    run = subprocess.run([str(PART), *options, name, str(results), "--", *command, *pytest_args],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    line = (results / "verdict").read_text().rstrip("\n").split("\t")
    return run.stdout + run.stderr, line


def test_each_stuck_test_fails_by_name_under_xdist(tmp_path):
    """Under pytest-xdist: the slow test fails at its limit, the stuck ones end their worker,
    which xdist reports by the test's name; the other tests run and the session ends with its
    summary."""
    (tmp_path / "test_hangs.py").write_text(HANGS)
    output, (name, verdict, _, text) = part(tmp_path, "serial", args=["-n", "2"])
    assert "3 failed, 2 passed" in output  # pytest's own summary
    # 0.4 CPU seconds, or 2 s of wall time on a machine too busy to give it that
    assert re.search(rf"Failed: Timeout: the test {OVER} \(its limit\) and was stopped here",
                     output)
    assert "test_stuck_without_gil waited more than 2 s (its limit) and still ran 0.5 s" in output
    assert "worker 'gw" in output and "crashed while running 'test_hangs.py::test_stuck_with_gil'" \
        in output
    assert (name, verdict) == ("serial", "FAILED")
    assert text.startswith("2 passed, 3 failed (")
    for test in ("test_slow_in_python", "test_stuck_without_gil", "test_stuck_with_gil"):
        assert f"test_hangs.py::{test}" in text


@pytest.mark.parametrize("args", [[], ["-n", "2"]], ids=["one process", "xdist"])
def test_a_part_that_passes(tmp_path, args):
    """A session where every test passes: the part is ok and its line gives the count."""
    (tmp_path / "test_hangs.py").write_text(HANGS)
    _, (_, verdict, _, text) = part(tmp_path, "serial", args=args, select="first or last")
    assert (verdict, text) == ("ok", "2 passed")


@pytest.mark.parametrize(("options", "verdict"), [((), "FAILED"), (("--none-ok",), "ok")])
def test_a_part_that_selects_no_test_fails_unless_allowed(tmp_path, options, verdict):
    """The one-process part must run tests; an MPI part's marker may select none."""
    (tmp_path / "test_hangs.py").write_text(HANGS)
    _, line = part(tmp_path, "mpi-3", select="no_such_test", options=options)
    assert line[1:2] + line[3:] == [verdict, "no test selected"]


def test_a_process_stuck_holding_the_gil_still_ends_with_a_verdict(tmp_path):
    """On one process, a test stuck in compiled code that holds the GIL: faulthandler ends
    the process; the part's line still counts what ran and names the test that did not
    finish, and how many did not start."""
    (tmp_path / "test_hangs.py").write_text(HANGS)
    output, (_, verdict, _, text) = part(tmp_path, "serial", select="not without_gil")
    assert "Timeout (0:00:03)!" in output  # faulthandler's stacks, 2 s + 2 × 0.5 s
    assert verdict == "FAILED"
    assert text == ("1 passed, 1 failed (test_hangs.py::test_slow_in_python); did not finish: "
                    "test_hangs.py::test_stuck_with_gil; 1 of 4 not started")


def test_the_part_limit_interrupts_with_pytest_summary(tmp_path):
    """A part stopped by its own limit (``timeout -s INT``, as the Makefile's LIMIT): pytest
    prints its summary and the tests that did not finish; the part's line says so."""
    (tmp_path / "test_hangs.py").write_text(HANGS.replace("@pytest.mark.timeout(0.4)\n", "")
                                            .replace("sum(range(1000))", "time.sleep(1)")
                                            .replace("import ctypes", "import ctypes\nimport time"))
    # 12 s: pytest starts (a few seconds on a busy machine) and the slow test is under way
    output, (_, verdict, _, text) = part(
        tmp_path, "serial", "timeout", "--foreground", "-s", "INT", "-k", "30", "12",
        select="first or slow or last")
    assert "DID NOT FINISH test_hangs.py::test_slow_in_python" in output
    assert "1 of 3 tests not started" in output
    assert "KeyboardInterrupt" in output and "1 passed, 2 deselected in" in output
    assert verdict == "FAILED"
    assert text == ("1 passed; did not finish: test_hangs.py::test_slow_in_python; "
                    "1 of 3 not started; stopped by the part's time limit")


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="needs mpirun")
def test_a_hung_collective_ends_the_mpi_run(tmp_path):
    """Under ``mpirun -n 2``: rank 0 waits for a message rank 1 never sends. Rank 0 is ended
    after its limit; mpirun then ends rank 1; each rank's ledger tells what it ran."""
    pytest.importorskip("mpi4py")
    (tmp_path / "test_mpi.py").write_text(MPI_HANG)
    output, (_, verdict, _, text) = part(tmp_path, "mpi-2", "mpirun", "-n", "2")
    assert re.search(rf"test_rank_0_waits_for_a_message_never_sent {OVER} \(its limit\)", output)
    assert "Ending this process on rank 0." in output
    assert verdict == "FAILED"
    assert text == (
        "rank 0: 1 passed; did not finish: test_mpi.py::"
        "test_rank_0_waits_for_a_message_never_sent (over its limit); 1 of 3 not started; "
        "rank 1: 2 passed; did not finish: test_mpi.py::test_last")


def test_the_verdict_counts_every_part(tmp_path):
    """``--verdict``: a line per part, the number of failed parts, exit status 1."""
    results = tmp_path / "results"
    results.mkdir()
    (results / "verdict").write_text("serial\tok\t7 min 00 s\t1003 passed\n"
                                     "ruff\tFAILED\t0 min 01 s\texit status 1 (its output above)\n")
    run = subprocess.run([str(PART), "--verdict", str(results)], capture_output=True, text=True)
    assert run.returncode == 1
    assert "make test: FAILED (1 of 2 parts" in run.stdout
    assert run.stdout.count("\n  ") == 2
    (results / "verdict").write_text("serial\tok\t7 min 00 s\t1003 passed\n")
    run = subprocess.run([str(PART), "--verdict", str(results)], capture_output=True, text=True)
    assert run.returncode == 0 and "make test: passed (every part of 1)" in run.stdout
    assert not results.exists()
