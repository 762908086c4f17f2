"""Test habits of DOLFINx: the same suite runs serially and under ``mpirun -n N``.

- ``@pytest.mark.skip_in_parallel``: the test runs on one process only.
- ``@pytest.mark.parallel``: the test concerns parallel behaviour; ``make test`` runs these again
  with ``mpirun -n 2`` (``python3 -m mpi4py -m pytest -m parallel``), and those not also marked
  ``slow`` with ``-n 3``.
- ``@pytest.mark.compares_ranks`` (with ``parallel``): the test compares a run on every rank
  with the same run on one process; skipped on one process, where it would compare a run with
  itself.
- After every test on several ranks, garbage is collected and the ranks meet, so that
  collective destructors of DOLFINx and PETSc objects run on all ranks together.
- Forms are compiled by FFCx into its cache (``~/.cache/fenics``, or ``$XDG_CACHE_HOME/fenics``;
  ``./drape`` keeps it on the host), so a run recompiles only the forms that changed.

mpi4py is optional: the pure-NumPy tests also run on a host without MPI.
"""

import gc
import os
import shutil
import tempfile
from collections import defaultdict

import pytest

try:
    from mpi4py import MPI
except ImportError:  # a host without MPI: one process
    MPI = None

COMM_SIZE = MPI.COMM_WORLD.size if MPI is not None else 1

# A time limit per test, a ledger of what ran and the tests that did not finish (tests/verdict.py).
pytest_plugins = ("verdict",)


# The modules that take the most CPU time (``--cpu-durations``), the heaviest first. Under
# ``make test`` each module runs whole on one pytest-xdist worker (``--dist loadfile``: its
# module fixtures are made once, not again on every worker that gets one of its tests, nor
# again after another module's test came in between) and the modules are handed out in this
# order, then those with a test marked ``slow``, then the others: the suite does not end
# waiting on a long module.
HEAVY = ("tests/test_scenarios.py", "tests/test_lab_user_path.py",
         "tests/test_reference_reports.py", "tests/test_run_cache.py", "tests/test_fit_real.py",
         "tests/test_demo_laminates.py", "tests/test_forming_runs_scale.py",
         "tests/test_forming_setup.py", "tests/test_setup_diagnosis.py",
         "tests/test_forming_stack.py", "tests/test_diagnose_hidden.py",
         "tests/test_diagnose_unknown.py", "tests/test_meshed_hemisphere.py",
         "tests/test_forming_stack_lab.py", "tests/test_docs_truth.py",
         "tests/test_forming_case_diagnosis.py", "tests/test_data_check.py",
         "tests/test_demos_diagnosis.py", "tests/test_forming_ply_angle.py",
         "tests/test_fe_newton.py", "tests/test_stack_diagnosis.py", "tests/test_lab_diagnose.py",
         "tests/test_verdict.py")  # light, but it waits: not at the end, when nothing else runs


def pytest_collection_modifyitems(config, items):
    """Order the modules (:data:`HEAVY` first, then those with a test marked ``slow``), each
    module's tests together in file order; skip the tests marked ``skip_in_parallel`` when
    running on more than one process."""
    def module(item) -> str:
        return item.nodeid.split("::")[0]

    slow = {module(item) for item in items if "slow" in item.keywords}

    def rank(item) -> int:
        name = module(item)
        return HEAVY.index(name) if name in HEAVY else len(HEAVY) + (name not in slow)

    items.sort(key=rank)  # stable: file order within each rank, each module's tests together
    if COMM_SIZE == 1:
        alone = pytest.mark.skip(reason="compares ranks: on one process a run with itself")
        for item in items:
            if "compares_ranks" in item.keywords:
                item.add_marker(alone)
        return
    skip = pytest.mark.skip(reason=f"runs on one process only (here {COMM_SIZE})")
    for item in items:
        if "skip_in_parallel" in item.keywords:
            item.add_marker(skip)


def pytest_configure(config):
    """Register :class:`CpuDurations` when asked (``--cpu-durations``).

    The commands' default run cache is the session's own, never the user's.

    On one process the tests share one cache folder, made here and removed at the end (the
    xdist workers inherit it): a run one test formed is read back by another, as a user's
    second command reads it (runs are known by their content; ``test_forming_runs_scale.py``
    checks a stored run comes back whole). Under ``mpirun`` there is none: every rank must
    form the same runs. A test of the cache names its own folder.

    Make Hypothesis draw the same examples on every rank, and share no database file.
    """
    if config.getoption("cpu_durations", None) is not None:
        config.pluginmanager.register(CpuDurations(config.getoption("cpu_durations")))
    if COMM_SIZE > 1:
        os.environ["DRAPE_CACHE"] = "off"
    elif not hasattr(config, "workerinput"):  # this process starts the session
        os.environ["DRAPE_CACHE"] = config._drape_runs = tempfile.mkdtemp(
            prefix="fenicsx-drape-test-runs-")
    # Under pytest-xdist every core already runs a test: a pool of forming workers per test
    # would put two processes on each core (measured 16 % slower on the lab diagnosis tests).
    # The pools themselves are tested with their workers named (test_forming_runs_scale.py).
    if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
        os.environ.setdefault("DRAPE_WORKERS", "1")
    if COMM_SIZE == 1:
        return
    try:
        from hypothesis import settings
    except ImportError:
        return
    settings.register_profile("mpi", derandomize=True, database=None)
    settings.load_profile("mpi")


def pytest_unconfigure(config):
    """Remove the session's run cache (:func:`pytest_configure`)."""
    folder = getattr(config, "_drape_runs", None)
    if folder:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(autouse=True)
def _collective_cleanup():
    """Under ``mpirun``, collect garbage, then wait for all ranks, after each test.

    On one process nothing is collective (a collection costs 0.05-0.1 s with DOLFINx loaded:
    about a minute of the suite's summed time).
    """
    yield
    if COMM_SIZE > 1:
        gc.collect()
        MPI.COMM_WORLD.Barrier()


@pytest.fixture
def tight_solver():
    """Solver options for comparing runs on different numbers of ranks.

    At the forming tolerance (1e-3 N per node) a solve stops anywhere in a ball of about
    2e-3 mm around the equilibrium, and round-off picks the iterates that get there (
    1.3e-4 to 1.9e-3 mm over four 3-rank runs of a coarse case); at 1e-5 N the ranks agree to
    1e-7 mm. LU: valid for unsymmetric Jacobians too.
    """
    from fenicsx_drape.fe.solver import SolverOptions

    return SolverOptions(snes_atol=1e-8, node_atol_N=1e-5)


# --- CPU seconds per test (``--cpu-durations=N``) ----------------------------------------------


def pytest_addoption(parser):
    """``--cpu-durations=N``: the N tests that took the most CPU seconds, and the total."""
    parser.addoption(
        "--cpu-durations", type=int, default=None, metavar="N",
        help="show the N tests that took the most CPU seconds (0: all) and the sum over the "
             "tests (a test's process and the processes it waited for; on a shared machine "
             "these compare where wall seconds do not)")


class CpuDurations:
    """Each report carries the CPU seconds since the previous phase's report (``cpu_s`` in its
    ``user_properties``, which pytest-xdist sends to the controller); the controller adds them
    up per test."""

    def __init__(self, count: int):
        from verdict import cpu_seconds  # loaded as a plugin by then (its asserts rewritten)

        self.cpu_seconds = cpu_seconds
        self.count = count
        self.seconds = defaultdict(float)

    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_logstart(self, nodeid, location):
        self.mark = self.cpu_seconds()

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(self, item, call):
        outcome = yield
        report, now = outcome.get_result(), self.cpu_seconds()
        mark = getattr(item, "_drape_cpu_mark", None)
        if mark is None:
            mark = self.mark
        report.user_properties = [*report.user_properties, ("cpu_s", now - mark)]
        item._drape_cpu_mark = now

    def pytest_runtest_logreport(self, report):
        self.seconds[report.nodeid] += sum(v for k, v in report.user_properties if k == "cpu_s")

    def pytest_terminal_summary(self, terminalreporter):
        if hasattr(terminalreporter.config, "workerinput"):
            return
        ranked = sorted(self.seconds.items(), key=lambda kv: -kv[1])
        shown = ranked if self.count == 0 else ranked[:self.count]
        write = terminalreporter.write_line
        terminalreporter.section("CPU seconds per test")
        for nodeid, seconds in shown:
            write(f"{seconds:9.2f}  {nodeid}")
        write(f"{sum(self.seconds.values()):9.1f}  in all ({len(self.seconds)} tests)")
