"""A run cache corrupted in every way gives the report of an intact one, to the last digit.

A stored run carries the name it is filed under and its own checksum, and both are checked on
every read (``fenicsx_drape/runs/store.py``): a value swapped with another entry's, values
rotated among four entries, a flipped byte (the three in one cache), a database truncated,
scribbled over or half written -- each is a miss (the run formed again, the entry replaced)
and a note, never another run's result. The bundle: two forming tests of the small octagon
case (39 nodes, 6 steps, under a quarter of a second a run), at two holder forces, whose
``compare`` fits μ through 8 stored runs.
"""

import contextlib
import json
import os
import shutil
import sqlite3
import sys
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.cli import main

sys.path.insert(0, str(Path(__file__).parent))
from test_forming_case_diagnosis import write_case

pytestmark = pytest.mark.skip_in_parallel  # a cache folder of one process

RUNS = 8  # the runs compare forms for the bundle (two tests, each at its μ of the fit)


@pytest.fixture(scope="module")
def intact(tmp_path_factory):
    """The bundle, the model, and the intact cache and report of its ``compare``."""
    pytest.importorskip("dolfinx")
    from fenicsx_drape.diagnosis import synthetic_case_test, write_case_bundle
    from fenicsx_drape.forming.case.format import load_case, with_overrides
    from fenicsx_drape.model import default_model

    tmp = tmp_path_factory.mktemp("run_cache")
    case = load_case(write_case(tmp / "part"))
    truth = default_model().with_parameters(mu=0.45)
    tests = [synthetic_case_test(truth, with_overrides(case, holder_force_N=force,
                                                          step_mm=10.0),  # 6 steps a run
                                    test_id=f"oct{force:g}", sd_mm=0.3, seed=k,
                                    case_file=f"c{force:g}/case.toml")
             for k, force in enumerate((100.0, 400.0))]
    write_case_bundle("two forces", tests, tmp / "bundle")
    model = default_model().without_effects("tow_buckling")
    (tmp / "model.toml").write_text(
        "effects = [" + ", ".join(f'"{e}"' for e in model.effects) + "]\n")
    report, made = compare(tmp, tmp / "cache", "intact")
    assert made["formed"] == RUNS and made["from_disk"] == 0
    return tmp, report


def compare(tmp: Path, cache: Path, label: str) -> tuple[dict, dict]:
    """``drape compare`` of the bundle on ``cache``: compare.json (without its provenance)
    and the runs of provenance.json."""
    out = tmp / label
    assert main(["compare", str(tmp / "bundle"), "--model", str(tmp / "model.toml"),
                 "--out", str(out), "--cache", str(cache), "--workers", "1"]) == 0
    report = json.loads((out / "compare.json").read_text())
    report.pop("provenance", None)
    return report, json.loads((out / "provenance.json").read_text())["forming_runs"]["runs"]


def rows(db: sqlite3.Connection) -> list[tuple]:
    """The entries' rows and values (diskcache's columns: a value inline or in a file)."""
    return db.execute("SELECT rowid, size, mode, filename, value FROM Cache ORDER BY rowid"
                      ).fetchall()


def move_values(folder: Path, order: list[int]) -> None:
    """Give the k-th entry the value of entry ``order[k]`` (the names stay)."""
    with sqlite3.connect(folder / "cache.db") as db:
        entries = rows(db)
        for (rowid, *_), (_, *value) in zip(entries, [entries[k] for k in order]):
            db.execute("UPDATE Cache SET size = ?, mode = ?, filename = ?, value = ? "
                       "WHERE rowid = ?", (*value, rowid))


def swapped(folder: Path) -> None:
    """Entries 0 and 1 hold each other's value."""
    n = len(rows(sqlite3.connect(folder / "cache.db")))
    move_values(folder, [1, 0, *range(2, n)])


def rotated(folder: Path) -> None:
    """Entries 2 to 5 hold the next one's value, the last the first's."""
    n = len(rows(sqlite3.connect(folder / "cache.db")))
    move_values(folder, [0, 1, 3, 4, 5, 2, *range(6, n)])


def flipped_byte(folder: Path) -> None:
    """A byte of entry 6's value flipped."""
    with sqlite3.connect(folder / "cache.db") as db:
        rowid, _, _, filename, value = rows(db)[6]
        if filename:  # a value kept in a file of its own
            path = folder / filename
            data = bytearray(path.read_bytes())
            data[len(data) // 2] ^= 0x01
            path.write_bytes(bytes(data))
        else:
            data = bytearray(value)
            data[len(data) // 2] ^= 0x01
            db.execute("UPDATE Cache SET value = ? WHERE rowid = ?", (bytes(data), rowid))


def truncated(folder: Path) -> None:
    path = folder / "cache.db"
    path.write_bytes(path.read_bytes()[:1000])


def half_written(folder: Path) -> None:
    path = folder / "cache.db"
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])


def scribbled(folder: Path) -> None:
    path = folder / "cache.db"
    data = bytearray(path.read_bytes())
    start, end = len(data) // 4, len(data) // 2
    data[start:end] = np.random.default_rng(1).integers(0, 256, end - start, np.uint8).tobytes()
    path.write_bytes(bytes(data))


def test_entries_corrupted_each_its_own_way_give_the_intact_report_and_heal(intact, capsys):
    """Two values swapped, four rotated, a byte flipped, in one cache (entry 7 left whole):
    each of those seven entries is a miss, formed again and replaced, the whole one read."""
    tmp, expected = intact
    cache = tmp / "entries"
    shutil.copytree(tmp / "cache", cache)
    for corrupt in (swapped, rotated, flipped_byte):
        corrupt(cache)
    capsys.readouterr()
    report, made = compare(tmp, cache, "entries 1")
    notes = [line for line in capsys.readouterr().err.splitlines()
             if line.startswith("drape: the run cache") or "entries of the run cache" in line]
    assert report == expected  # to the last digit: every number of compare.json
    assert made["formed"] == 7 and made["from_disk"] == 1  # those entries only, replaced
    assert "not used; the run is formed again and the entry replaced" in notes[0]
    assert "7 entries of the run cache" in notes[-1]
    # The cache is whole again: the same command forms nothing, and says nothing.
    again, made = compare(tmp, cache, "entries 2")
    assert again == expected and made["formed"] == 0 and made["from_disk"] == RUNS
    assert "drape: the run cache" not in capsys.readouterr().err


@pytest.mark.parametrize("corrupt", [truncated, half_written, scribbled],
                         ids=lambda f: f.__name__)
def test_a_corrupted_database_gives_the_intact_report_and_heals(intact, corrupt, capsys):
    tmp, expected = intact
    cache = tmp / corrupt.__name__
    shutil.copytree(tmp / "cache", cache)
    corrupt(cache)
    capsys.readouterr()
    report, made = compare(tmp, cache, f"{corrupt.__name__} 1")
    notes = [line for line in capsys.readouterr().err.splitlines()
             if line.startswith("drape: the run cache") or "entries of the run cache" in line]
    assert report == expected  # to the last digit: every number of compare.json
    assert notes and made["formed"] > 0  # said, and the runs not trusted formed again
    if corrupt in (truncated, half_written):  # the database moved aside, a new one made
        (aside,) = cache.glob("damaged-*")
        assert f"rm -r '{aside}'" in notes[0]
    # The cache is whole again: the same command forms nothing, and says nothing.
    again, made = compare(tmp, cache, f"{corrupt.__name__} 2")
    assert again == expected and made["formed"] == 0 and made["from_disk"] == RUNS
    assert "drape: the run cache" not in capsys.readouterr().err


def descendants(pid: int) -> set[int]:
    """The processes ``pid`` started, and theirs (from /proc)."""
    found = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            found |= {int(c) for c in (task / "children").read_text().split()}
        except OSError:  # gone meanwhile
            pass
    for child in list(found):
        found |= descendants(child)
    return found


def cpu_seconds(pid: int) -> float:
    """The CPU seconds a process has used (user and system, from /proc; 0 once gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def running(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not yet reaped, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_ctrl_c_on_a_parallel_diagnose_stops_the_workers_and_says_what_was_kept(intact):
    """SIGINT to the command's process group, as a terminal's Ctrl-C sends it, once its pool of
    workers forms runs: exit status 130, one line saying the runs are kept in the cache, no
    traceback, and no worker left running."""
    import signal
    import subprocess
    import time

    tmp, _ = intact
    cache = tmp / "interrupted"
    command = [sys.executable, "-m", "fenicsx_drape", "diagnose", str(tmp / "bundle"),
               "--model", str(tmp / "model.toml"), "--json", str(tmp / "REPORT.json"),
               "--cache", str(cache), "--workers", "2"]
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root), "PYTHONFAULTHANDLER": "1"}
    # SIGINT at its default in the command, as a shell starts a foreground command: a suite
    # started in the background of a script (`make test &`) ignores SIGINT, and a command
    # started with SIGINT ignored keeps ignoring it (Python does not catch it then), so
    # it would run to its end.
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True, env=env,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        start = time.monotonic()
        while not descendants(process.pid) and time.monotonic() - start < 300:
            time.sleep(0.1)  # the pool starts with the first batch of runs
        time.sleep(1.0)
        workers = descendants(process.pid)
        assert workers and process.poll() is None
        os.killpg(process.pid, signal.SIGINT)
        # It stops at its next load step: a fraction of a CPU second, however long a busy
        # machine takes to give it that (its CPU seconds are counted, not the wall's).
        used = cpu_seconds(process.pid)
        while True:
            try:
                _, err = process.communicate(timeout=5)
                break
            except subprocess.TimeoutExpired:
                if cpu_seconds(process.pid) - used > 60 or time.monotonic() - start > 1200:
                    os.kill(process.pid, signal.SIGABRT)  # every thread's stack (faulthandler)
                    time.sleep(5.0)
                    os.killpg(process.pid, signal.SIGKILL)  # and its workers: none left
                    pytest.fail("not stopped 60 CPU seconds after SIGINT:\n"
                                + process.communicate(timeout=60)[1][-8000:])
    finally:
        if process.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)
    lines = err.splitlines()
    assert process.returncode == 130
    assert "Traceback" not in err and [line for line in lines if "interrupted" in line] == [
        lines[-1]]
    assert lines[-1].startswith("drape diagnose: interrupted; ") and str(cache) in lines[-1]
    time.sleep(1.0)
    assert not [pid for pid in workers if running(pid)]


def test_a_ctrl_c_while_a_run_fails_is_raised_not_lost():
    """A SIGINT noted during a run that then raises an error is raised as KeyboardInterrupt
    (the run's error its cause): a caller that takes a failed run as a failed candidate
    would otherwise go on as if no Ctrl-C came."""
    import signal

    from fenicsx_drape.runs.pools import interrupts_between_steps

    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        pytest.skip("SIGINT is not Python's here (started ignoring it)")
    with pytest.raises(KeyboardInterrupt) as info, interrupts_between_steps():
        os.kill(os.getpid(), signal.SIGINT)
        raise ValueError("the run failed")
    assert isinstance(info.value.__cause__, ValueError)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(ValueError), interrupts_between_steps():  # no Ctrl-C: its own error
        raise ValueError("the run failed")
