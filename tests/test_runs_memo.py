"""Values derived from runs live with the command's :class:`~fenicsx_drape.runs.Runs`.

A case a test names is read once per command: a file edited between two commands is read
again by the second (module-level caches kept the first reading for the whole process).
"""

import threading

import numpy as np

from fenicsx_drape.diagnosis.kinds.forming import forming_case_of
from fenicsx_drape.forming.case import case_file
from fenicsx_drape.measurements.bundle import Test
from fenicsx_drape.runs import Memo, Runs


def _case_test(path):
    return Test(id="f1", kind="forming", file="f1.csv", columns={"x_mm": np.zeros(1)},
                case="case.toml", case_path=path)


def test_a_case_edited_between_two_commands_is_read_again(tmp_path):
    path = tmp_path / "case.toml"
    path.write_text(case_file("hemisphere").read_text())
    test = _case_test(path)
    with Runs(workers=1):
        first = forming_case_of(test)
        assert forming_case_of(test) is first  # once per command
        path.write_text(path.read_text().replace("force_N = 133.0", "force_N = 66.5"))
        assert forming_case_of(test) is first  # the command's reading, as its runs
    with Runs(workers=1):
        again = forming_case_of(test)
    assert first.holder.force_N == 133.0 and again.holder.force_N == 66.5


def test_the_runs_forget_their_memos_and_a_memo_keeps_its_size():
    with Runs(workers=1) as runs:
        table = runs.memo("t", size=3)
        for k in range(5):
            assert table.put(k, k * k) == k * k
        assert len(table) == 3 and [k for k, _ in table.newest_first()] == [4, 3, 2]
        assert table.get(0) is None and table.get(4) == 16
        assert runs.memo("t") is table
        runs.forget()
        assert len(runs.memo("t")) == 0


def test_a_memo_filled_from_threads_keeps_its_bound():
    table = Memo(50)

    def fill(start):
        for k in range(start, start + 1000):
            table.put(k, k)

    threads = [threading.Thread(target=fill, args=(i * 1000,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(table) == 50
