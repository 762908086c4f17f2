"""Calls made together (runs.together): their results as one after the other, their runs in
common batches.

A "run" here is a stand-in: the forming of a job is replaced by a function of the job, and
every batch handed to the executor is recorded. Each call is a little fit that asks one run
at a time, its next job depending on the last result (as a Gauss-Newton fit does).
"""

import threading

import pytest

from fenicsx_drape import runs


@pytest.fixture
def batches(monkeypatch):
    """Runs formed as a function of their job; each batch of new runs recorded (a Runs of the
    test's own, made current)."""
    seen = []

    def form_all(jobs):
        seen.append(list(jobs))
        return [("error", RuntimeError("diverged")) if model == "bad" else
                ("ok", (f"{case}:{model}", None, {})) for case, model in jobs]

    made = runs.Runs(workers=1)
    monkeypatch.setattr(made, "key", lambda case, model: (case, model))
    monkeypatch.setattr(made, "_form_all", form_all)
    monkeypatch.setattr(made, "describe", lambda case, model: f"the run of {case!r} ({model})")
    with made:
        yield seen


def fit(name, steps, say):
    """A call: ``steps`` runs, each job named by the last result; a line per run."""
    last = "start"
    for k in range(steps):
        (last,) = runs.form_many([(name, f"{k}<{len(last)}")])
        say(f"{name} {k}")
    return last


def test_together_gives_each_calls_result_and_forms_their_runs_in_common_batches(batches):
    steps = {"a": 3, "b": 1, "c": 2}
    alone_lines = []
    alone = [fit(n, s, alone_lines.append) for n, s in steps.items()]
    assert [len(b) for b in batches] == [1] * 6  # one after the other: a run at a time
    batches.clear()
    runs.current().forget()
    lines = []
    made = runs.together([lambda say, n=n, s=s: fit(n, s, say) for n, s in steps.items()],
                         lines.append)
    assert made == alone
    # Each round: the first run of every call still going, in the calls' order.
    assert [[job[0] for job in b] for b in batches] == [["a", "b", "c"], ["a", "c"], ["a"]]
    assert lines == alone_lines  # each call's lines together, in the calls' order


def test_a_call_within_a_call_asks_with_the_outer_batch(batches):
    def folds(say):
        return runs.together([lambda say, n=n: fit(n, 2, say) for n in ("f1", "f2")], say)

    made = runs.together([folds, lambda say: fit("x", 2, say)])
    assert made == [[fit("f1", 2, print), fit("f2", 2, print)], fit("x", 2, print)]
    assert [sorted(job[0] for job in b) for b in batches] == [["f1", "f2", "x"]] * 2


def test_a_failing_call_or_run_is_raised_after_the_others_are_done(batches):
    finished = []

    def breaks(say):
        runs.form_many([("p", "0")])
        raise ValueError("a call's own error")

    def done(say):
        finished.append(fit("q", 3, say))

    with pytest.raises(ValueError, match="a call's own error"):
        runs.together([done, breaks])
    assert finished == [fit("q", 3, print)]

    def bad_run(say):
        try:
            runs.form_many([("r", "bad")])
        except RuntimeError as error:  # the run's error, named, reaches its own call only
            return str(error)

    message, ok = runs.together([bad_run, lambda say: fit("s", 1, say)])
    assert "diverged" in message and "'r'" in message and ok == fit("s", 1, print)


def test_each_call_sees_the_callers_resolution_and_keeps_its_own(batches):
    seen = {}

    def finer(say):  # a job carries the cells it is formed on (as a case does)
        with runs.resolution(5.0):
            runs.form_many([("fine", f"{runs.cell_override()} mm")])  # waits in its resolution
            seen["finer"] = runs.cell_override()

    def own(say):
        runs.form_many([("own", f"{runs.cell_override()} mm")])
        seen["own"] = runs.cell_override()

    with runs.resolution(7.0):  # the command's (drape diagnose --forming-cell-mm 7)
        runs.together([finer, own])
        assert runs.cell_override() == 7.0
    assert seen == {"finer": 5.0, "own": 7.0} and runs.cell_override() is None
    assert batches == [[("fine", "5.0 mm"), ("own", "7.0 mm")]]
    assert not [t for t in threading.enumerate() if t.name.startswith("together-")]


def test_spare_runs_fill_the_free_slots_of_a_batch_and_no_more(batches, monkeypatch):
    """A fit's finite differences are spare: formed beside its point only where a worker would
    wait (runs.spare), else left, and never formed for their own sake."""
    monkeypatch.setattr(runs.current(), "runs_at_once", lambda: 2)
    with runs.spare(1):  # a point and one difference: two workers, one batch
        assert runs.form_many([("p", 0), ("p", 1)]) == ["p:0", "p:1"]
    assert batches == [[("p", 0), ("p", 1)]]
    batches.clear()
    with runs.spare(1), pytest.raises(runs.Deferred):  # two differences: one has no slot
        runs.form_many([("q", 0), ("q", 1), ("q", 2)])
    assert batches == [[("q", 0), ("q", 1)]]
    with runs.spare(0):  # only what is at hand: nothing formed
        assert runs.form_many([("q", 1)]) == ["q:1"]
        with pytest.raises(runs.Deferred):
            runs.form_many([("q", 1), ("q", 2)])
    assert len(batches) == 1
    assert runs.form_many([("q", 2)]) == ["q:2"]  # asked as a run: formed
    batches.clear()

    def point(name, say):  # a call whose point fills the batch: its difference waits
        with runs.spare(1):
            try:
                return runs.form_many([(name, 0), (name, 1)])
            except runs.Deferred:
                return runs.cached(name, 1)

    assert runs.together([lambda say, n=n: point(n, say) for n in "ab"]) == [False, False]
    assert batches == [[("a", 0), ("b", 0)]]
    batches.clear()
    monkeypatch.setattr(runs.current(), "runs_at_once", lambda: 1)  # one worker: no free slot
    with runs.spare(1), pytest.raises(runs.Deferred):
        runs.form_many([("r", 0), ("r", 1)])
    assert batches == [[("r", 0)]]
