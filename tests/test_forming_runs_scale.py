"""The forming runs at scale: every core through concurrent.futures, and remembered on disk.

The runs are those of the small octagon case of ``test_forming_case_diagnosis.py`` (39
nodes, under a second each). The same runs on 1, 2 and 3 worker processes (and under
``mpi4py.futures``) give the same sheets to the last digit, in the order asked; a run that
fails comes back as its error, naming its case and model, after the others; a second
``compare`` of a bundle with its cache forms nothing; a damaged cache entry or one of another
code is not used (``test_run_cache.py``: a cache corrupted in every way gives the same report).
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape import runs
from fenicsx_drape.cli import forming_runs_setting, main
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.running.post import FormedGrid
from fenicsx_drape.runs import pools
from fenicsx_drape.runs.store import RunStore

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
from test_forming_case_diagnosis import MESHED, STL, write_case  # noqa: E402


@pytest.fixture
def dolfinx():
    return pytest.importorskip("dolfinx")


@pytest.fixture
def fresh_memory():
    """No run in the default Runs' memory before or after the test (the disk cache is the
    test's own)."""
    runs.current().forget()
    yield
    runs.current().forget()


def octagon_jobs(folder: Path):
    from fenicsx_drape.forming.case.format import load_case

    return models_of(load_case(write_case(folder / "part")))


def models_of(case):
    """The octagon case's jobs: three holder frictions."""
    from fenicsx_drape.model import default_model

    return [(case, default_model().with_parameters(mu=mu)) for mu in (0.2, 0.3, 0.45)]


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_the_same_runs_on_one_two_and_three_workers_and_a_failed_run_named(
        tmp_path, dolfinx, fresh_memory):
    from fenicsx_drape.forming.case.format import load_case

    jobs = octagon_jobs(tmp_path)
    # A case whose punch surface is empty cannot run: its error names it, the others are kept
    # (on the 2-worker pool below, before it forms the jobs: one pool started fewer).
    write_case(tmp_path / "plate", MESHED)
    (tmp_path / "plate" / "punch.stl").write_text(STL)
    plate = load_case(tmp_path / "plate" / "case.toml")
    sheets = {}
    for workers in (1, 2, 3):
        with runs.execution(workers=workers) as made:  # a Runs of its own: nothing in memory
            assert runs.executor()[0] == ("this process" if workers == 1 else "processes")
            if workers == 2:
                with pytest.raises(Exception) as info:
                    runs.form_many([jobs[0], (plate, jobs[1][1]), jobs[2]])
                assert ("forming run of case 'plate'" in str(info.value)
                        and "mu = 0.3" in str(info.value))
                assert (made.cached(*jobs[0]) and made.cached(*jobs[2])
                        and not made.cached(plate, jobs[1][1]))
                made.forget()  # the sheets below formed again on this pool
            sheets[workers] = runs.form_many(jobs)
    for workers in (2, 3):  # bit for bit, in the order asked
        for a, b in zip(sheets[1], sheets[workers]):
            assert np.array_equal(a.x, b.x, equal_nan=True)
            assert np.array_equal(a.X, b.X, equal_nan=True)
    # The holder's friction draws the sheet in differently: the order is the jobs' own.
    first, _, last = sheets[1]
    assert np.nanmax(np.abs(first.x - last.x)) > 1e-3



@pytest.mark.parallel
@pytest.mark.slow
def test_runs_times_ranks_under_mpirun_give_each_rank_every_run(tmp_path_factory, dolfinx,
                                                                fresh_memory):
    """``ranks_per_run = 1`` under ``mpirun -n N``: N runs at once, one rank each; every rank
    gets every sheet, in the order asked, bit for bit that of the run formed on one process."""
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    folder = Path(comm.bcast(str(tmp_path_factory.mktemp("runs")) if comm.rank == 0 else None))
    if comm.rank == 0:
        octagon_jobs(folder)  # writes the case once
    comm.Barrier()
    from fenicsx_drape.forming.case.format import load_case

    case = load_case(folder / "part" / "case.toml")
    jobs = models_of(case)
    with runs.execution(workers=1, ranks_per_run=1):  # workers: on one process, itself
        sheets = runs.form_many(jobs)
        record = runs.execution_record()
    assert record["executor"] == ("all ranks" if comm.size > 1 else "this process")
    assert record["workers"] == comm.size and record["ranks"] == 1
    alone = pools.form(*jobs[comm.rank % len(jobs)], MPI.COMM_SELF)[0]
    assert np.array_equal(sheets[comm.rank % len(jobs)].x, alone.x, equal_nan=True)
    everywhere = comm.allgather([s.x for s in sheets])
    assert all(np.array_equal(a, b, equal_nan=True)
               for other in everywhere for a, b in zip(other, everywhere[0]))


def test_the_execution_record_counts_the_runs_asked_formed_and_reused(tmp_path, monkeypatch):
    """What provenance.json records of an execution(), with the forming replaced by a stub
    that counts its calls: the counts must agree with the calls made."""
    calls = []

    def form(case, model, comm=None):
        calls.append((case, model))
        return FormedGrid(np.zeros((2, 2, 3)), np.ones((2, 2, 3)), False), None, {}

    monkeypatch.setattr(pools, "form", form)
    with runs.execution(workers=1, cache=tmp_path / "runs") as made:
        monkeypatch.setattr(made, "key", lambda case, model: (case, model))
        runs.form_many([("a", "m"), ("b", "m"), ("a", "m")])  # "a" twice: asked once
        runs.form_many([("a", "m"), ("c", "m")])  # "a" from memory
        assert runs.execution_record() == made.record()  # the current Runs'
    record = made.record()
    assert len(calls) == 3
    assert record["executor"] == "this process" and record["workers"] == 1
    assert record["cache"] == str((tmp_path / "runs").resolve())
    assert record["runs"] == {"asked": 4, "formed": 3, "from_disk": 0, "from_memory": 1,
                              "reused": 1}
    with runs.execution(workers=3, cache=None) as made:
        monkeypatch.setattr(made, "key", lambda case, model: (case, model))
        runs.form_many([("a", "m")])
        assert runs.execution_record()["executor"] == "processes"  # while it runs
    record = made.record()
    assert record["cache"] is None and record["workers"] == 3
    assert record["runs"]["formed"] == 1 and len(calls) == 4


def test_a_batch_keeps_its_runs_in_memory_when_new_ones_fill_it(monkeypatch):
    """A run remembered from before is the oldest in memory: the batch's new runs must not
    push it out before the batch returns (a KeyError in a lab diagnosis's forming fit)."""

    def form(case, model, comm=None):
        return FormedGrid(np.full((2, 2, 3), float(ord(case))), np.ones((2, 2, 3)), False), \
            None, {}

    monkeypatch.setattr(pools, "form", form)
    with runs.Runs(workers=1, memory=2) as made:
        monkeypatch.setattr(made, "key", lambda case, model: (case, model))
        runs.form_many([("a", "m")])
        sheets = runs.form_many([("a", "m"), ("b", "m"), ("c", "m")])
    assert [float(g.X[0, 0, 0]) for g in sheets] == [ord("a"), ord("b"), ord("c")]
    assert made.in_memory() == 2


def test_workers_and_cache_options_are_checked(tmp_path, monkeypatch, capsys):
    with pytest.raises(DrapeInputError, match="--workers 0"):
        with runs.execution(workers=0):
            pass
    with pytest.raises(DrapeInputError, match="--ranks-per-run 2: a divisor of the job's 1"):
        with runs.execution(ranks_per_run=2):
            pass
    monkeypatch.setenv("DRAPE_WORKERS", "two")
    with pytest.raises(DrapeInputError, match="DRAPE_WORKERS='two'"):
        with runs.execution():
            pass
    monkeypatch.setenv("DRAPE_WORKERS", "1")
    assert runs.default_workers() == 1
    monkeypatch.delenv("DRAPE_WORKERS")
    assert runs.default_workers() == runs.cores() == len(os.sched_getaffinity(0))
    (tmp_path / "file").write_text("")
    with pytest.raises(DrapeInputError, match="not a folder"):
        runs.execution(cache=tmp_path / "file").__enter__()
    # On the command line: exit status 2, before anything runs.
    with pytest.raises(SystemExit) as info:
        main(["compare", str(tmp_path), "--out", str(tmp_path / "o"), "--workers", "0"])
    assert info.value.code == 2
    assert "--workers: '0' is not a whole number" in capsys.readouterr().err
    monkeypatch.setenv("DRAPE_CACHE", str(tmp_path / "c"))
    assert runs.default_folder() == tmp_path / "c"
    monkeypatch.setenv("DRAPE_CACHE", "off")
    assert runs.default_folder() is None
    monkeypatch.delenv("DRAPE_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert runs.default_folder() == tmp_path / "xdg" / "fenicsx-drape" / "runs"


def test_workers_above_the_cores_are_capped_with_a_note(monkeypatch, capsys):
    """``--workers 1000`` or ``DRAPE_WORKERS=1000``: as many workers as cores, and a note."""
    import argparse

    cores = runs.cores()
    options = argparse.Namespace(workers=1000, cache=None, no_cache=True, ranks_per_run=None)
    monkeypatch.delenv("DRAPE_WORKERS", raising=False)
    assert forming_runs_setting(options).workers == cores
    assert f"--workers 1000 is more than the {cores} core(s)" in capsys.readouterr().err
    monkeypatch.setenv("DRAPE_WORKERS", "1000")
    options.workers = None
    assert forming_runs_setting(options).workers == cores == runs.default_workers()
    assert f"DRAPE_WORKERS=1000 is more than the {cores} core(s)" in capsys.readouterr().err
    options.workers = cores  # as many as the cores: as given, no note
    assert forming_runs_setting(options).workers == cores
    assert capsys.readouterr().err == ""
    assert runs.Runs(workers=cores + 1).workers == cores + 1  # a Python caller's own choice


def made_up_run():
    X = np.stack(np.meshgrid(np.arange(3.0), np.arange(4.0), [0.0], indexing="ij"), -1)[:, :, 0]
    x = X + 0.5
    x[0, 0] = np.nan
    return FormedGrid(X, x, False, ("x",)), 41.5, {"time_s": np.arange(3.0),
                                                  "punch": np.array([1.0, 2.0, 4.0])}


def test_a_stored_run_comes_back_whole_and_a_damaged_one_or_another_runs_never(tmp_path):
    notes = []
    store = RunStore(tmp_path / "cache", say=notes.append)
    grid, stopped, curves = made_up_run()
    key = store.name(["a case", "a model"])
    assert key != store.name(["a case", "another model"])
    store.put(key, grid, stopped, curves)
    back, back_stopped, back_curves = store.get(key)
    assert np.array_equal(back.x, grid.x, equal_nan=True) and np.array_equal(back.X, grid.X)
    assert (back.quarter, back.symmetry, back_stopped) == (False, ("x",), 41.5)
    assert back_curves.keys() == curves.keys()
    assert all(np.array_equal(back_curves[k], curves[k]) for k in curves)
    # A run that reached full travel, of a quarter: no stopped travel, both planes.
    full = FormedGrid(grid.X, grid.x, True)
    store.put(key, full, None, {})
    again = store.get(key)
    assert again[0].symmetry is None and again[0].planes == ("x", "y") and again[1] is None
    assert notes == []

    # One byte changed in the stored bytes: not used, dropped, and said.
    data = bytearray(store._cache.get(key))
    data[-100] ^= 0xFF
    store._cache.set(key, bytes(data))
    assert store.get(key) is None and store._cache.get(key) is None
    assert "a damaged value: not used; the run is formed again" in notes[-1]
    store._cache.set(key, b"not a run")
    assert store.get(key) is None
    # Another run's value filed under this name (its checksum right): not used, and said.
    other = store.name(["a case", "another model"])
    store.put(other, grid, stopped, curves)
    store._cache.set(key, store._cache.get(other))
    assert store.get(key) is None and store._cache.get(key) is None
    assert store.get(other) is not None and len(store.replaced) == 3
    # The entry of another code version (same name): not used.
    store.put(key, grid, stopped, curves)
    newer = RunStore(tmp_path / "cache", code="another code", say=notes.append)
    assert newer.get(key) is None
    # Another code's runs have other names: the same inputs, another key.
    assert newer.name(["a case", "a model"]) != key
    store.close()
    assert "3 entries of the run cache" in notes[-1]
    newer.close()

    # A database that cannot be read: moved aside (a note names it) and a new one made.
    shutil.rmtree(tmp_path / "cache")
    (tmp_path / "cache").mkdir()
    (tmp_path / "cache" / "cache.db").write_bytes(b"garbage" * 1000)
    notes.clear()
    damaged = RunStore(tmp_path / "cache", say=notes.append)
    (aside,) = (tmp_path / "cache").glob("damaged-*")
    assert (aside / "cache.db").read_bytes() == b"garbage" * 1000
    assert len(notes) == 1 and f"rm -r '{aside}'" in notes[0] and damaged.usable
    assert damaged.get(key) is None
    damaged.put(key, grid, stopped, curves)
    assert len(damaged) == 1 and damaged.get(key) is not None
    damaged.close()

    # A folder that cannot be made: a note, no run kept, and not recorded as the cache.
    (tmp_path / "file").write_text("")
    notes.clear()
    with runs.Runs(workers=1, cache=tmp_path / "file" / "runs") as made:
        assert not made.store.usable and made.record()["cache"] is None
    assert len(notes) == 0  # said on standard error, not to this test's notes


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_a_second_compare_forms_nothing_and_reports_the_same(tmp_path, dolfinx, fresh_memory,
                                                             capsys):
    """The README's loop repeated: compare, then compare again, with the runs on disk."""
    from fenicsx_drape.forming.case.format import load_case
    from fenicsx_drape.forming.running.outputs import form_case

    case = load_case(write_case(tmp_path / "part"))
    form_case(tmp_path / "formed", case, fields=False, pictures=False)
    bundle, cache = tmp_path / "formed" / "bundle", tmp_path / "runs"
    reports = []
    for k in range(2):  # each command its own Runs: nothing in memory at its start
        assert main(["compare", str(bundle), "--out", str(tmp_path / f"c{k}"),
                     "--cache", str(cache), "--workers", "2"]) == 0
        # provenance.json says how the runs were made and which were reused.
        made = json.loads((tmp_path / f"c{k}" / "provenance.json").read_text())["forming_runs"]
        assert made["executor"] == "processes" and made["workers"] == 2
        assert made["cache"] == str(cache.resolve())
        formed, read = made["runs"]["formed"], made["runs"]["from_disk"]
        assert made["runs"]["reused"] == made["runs"]["asked"] - formed
        reports.append((formed, read, (tmp_path / f"c{k}" / "compare.json").read_text()))
    (formed, read, first), (formed_again, read_again, second) = reports
    assert formed > 0 and read == 0
    assert formed_again == 0 and read_again == formed
    assert json.loads(first)["per_test"] == json.loads(second)["per_test"]


def compare_report(bundle: Path, out: Path, *launcher: str, workers: int | None = None) -> dict:
    """compare.json of ``drape compare BUNDLE`` in a process of its own, without provenance."""
    futures = ["-m", "mpi4py.futures"] if launcher else []  # launcher: mpiexec -n N
    command = [*launcher, sys.executable, *futures, "-m", "fenicsx_drape", "compare",
               str(bundle), "--no-cache", "--out", str(out)]
    if workers is not None:
        command += ["--workers", str(workers)]
    subprocess.run(command, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)},
                   timeout=600, capture_output=True)
    report = json.loads((out / "compare.json").read_text())
    report.pop("provenance", None)
    return report


@pytest.fixture(scope="module")
def one_worker(tmp_path_factory):
    """A formed part's bundle and its compare.json on one worker."""
    pytest.importorskip("dolfinx")
    from fenicsx_drape.forming.case.format import load_case
    from fenicsx_drape.forming.running.outputs import form_case
    from fenicsx_drape.model import default_model

    folder = tmp_path_factory.mktemp("executors")
    case = load_case(write_case(folder / "part"))
    form_case(folder / "formed", case, default_model().with_parameters(mu=0.35),
              fields=False, pictures=False)
    bundle = folder / "formed" / "bundle"
    # Here, in this process (a command's Runs of its own): no second start of DOLFINx.
    assert main(["compare", str(bundle), "--no-cache", "--out", str(folder / "one"),
                 "--workers", "1"]) == 0
    report = json.loads((folder / "one" / "compare.json").read_text())
    report.pop("provenance", None)
    return bundle, report


@pytest.mark.slow
@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("executor", [
    "mpi4py.futures",
    # the runs on 2 and 3 workers are the one worker's, bit for bit (the test above)
    pytest.param("2 workers", marks=pytest.mark.bench),
    pytest.param("3 workers", marks=pytest.mark.bench)])
def test_the_same_report_whichever_executor_and_workers(one_worker, executor, tmp_path):
    """compare.json of a bundle: the same on one worker as on two and three, and under
    mpi4py.futures (3 processes)."""
    bundle, first = one_worker
    if executor == "mpi4py.futures":
        if not shutil.which("mpiexec"):
            pytest.skip("needs mpiexec")
        report = compare_report(bundle, tmp_path / "out", "mpiexec", "-n", "3")
    else:
        report = compare_report(bundle, tmp_path / "out", workers=int(executor.split()[0]))
    assert first["per_test"] and report == first


@pytest.mark.skip_in_parallel
def test_a_worker_that_dies_fails_its_runs_and_the_next_batch_has_a_new_pool(tmp_path, dolfinx,
                                                                              fresh_memory):
    import signal

    jobs = octagon_jobs(tmp_path)[:2]
    with runs.execution(workers=2):
        _, pool = runs.executor()
        with pools.fresh_workers():
            futures = [pool.submit(signal.pause) for _ in range(2)]  # two workers, waiting
        # A write to the dead worker's pipe is Python's BrokenPipeError, not PETSc's abort.
        os.kill(os.getpid(), signal.SIGPIPE)
        for process in list(pool._processes.values()):
            process.kill()
        assert all("terminated abruptly" in str(f.exception(timeout=60)) for f in futures)
        # The broken pool is replaced: the runs are formed.
        assert len(runs.form_many(jobs)) == 2 and runs.executor()[1] is not pool


@pytest.mark.skip_in_parallel
def test_the_petsc_options_are_in_a_runs_key_and_go_with_its_job(tmp_path, dolfinx):
    from petsc4py import PETSc

    from fenicsx_drape.fe.newton import SOLVER_PREFIXES, set_petsc_options

    assert runs.USER_OPTIONS == (*SOLVER_PREFIXES, "log_")
    case, model = octagon_jobs(tmp_path)[0]
    db = PETSc.Options()
    names = ("snes_linesearch_order", "ksp_converged_reason")
    assert not any(db.hasName(n) for n in names)
    before, plain = dict(runs.solver_options()), runs.key_of(case, model)
    db["drape_truss_99_snes_atol"] = "1e-3"  # a problem's own option: not the user's
    try:
        assert runs.key_of(case, model) == plain
        set_petsc_options("-snes_linesearch_order 2 -ksp_converged_reason")
        given = runs.solver_options()
        assert dict(given) == {**before, "snes_linesearch_order": "2",
                               "ksp_converged_reason": ""}
        assert runs.key_of(case, model) != plain
    finally:
        for name in (*names, "drape_truss_99_snes_atol"):
            db.delValue(name)
    assert runs.key_of(case, model) == plain
    # A worker sets the job's options and drops those of its last job that are not given.
    status, _ = pools.run_job(None, model, False, given)  # no case: fails after the options
    assert status == "error" and db.getString("snes_linesearch_order") == "2"
    assert db.hasName("ksp_converged_reason")
    pools.run_job(None, model, False, tuple(before.items()))
    assert not any(db.hasName(n) for n in names)


def test_a_local_worker_leaves_the_launchers_job_and_keeps_how_mpi_runs_here(monkeypatch):
    """A worker is an MPI job of its own (not the launcher's rank), with ./drape's settings:
    without the libfabric transport its MPI starts in 0.6 s, not 1.6 s (docs/install.md)."""
    job = {"OMPI_COMM_WORLD_SIZE": "2", "PMIX_RANK": "1", "OMPI_MCA_ess_base_jobid": "7"}
    settings = {"OMPI_MCA_btl": "^ofi", "OMPI_ALLOW_RUN_AS_ROOT": "1"}
    for name, value in {**job, **settings}.items():
        monkeypatch.setenv(name, value)
    with pools.fresh_workers():
        assert not set(job) & set(os.environ)
        assert all(os.environ[name] == value for name, value in settings.items())
    assert all(os.environ[name] == value for name, value in {**job, **settings}.items())


def test_the_runs_package_imports_no_dolfinx():
    """A worker of mpi4py.futures imports runs.mpi (its initializer) before it starts PETSc on
    itself alone: had the package started PETSc on MPI.COMM_WORLD, every rank would wait
    for the others in a collective that never comes."""
    code = ("import sys, fenicsx_drape.runs, fenicsx_drape.runs.mpi; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'dolfinx', 'petsc4py', 'ufl', 'basix', 'ffcx'}))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, check=True, timeout=120)
    assert done.stdout.strip() == "[]"
