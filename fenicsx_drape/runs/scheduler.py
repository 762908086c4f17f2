"""Calls made together: their results as one after the other, their runs formed in batches.

The scheduler of :meth:`Runs.together <fenicsx_drape.runs.Runs.together>`: each call runs in
a thread of its own, one at a time in a fixed order; when every call waits for runs or is
done, the runs they wait for go to the executor in one batch.
"""

from __future__ import annotations

import contextvars
import threading
from collections.abc import Callable, Sequence
from typing import Any


class Cancelled(BaseException):  # not an Exception: it passes the calls' handlers
    """Raised in the calls of :func:`together` when forming their batch failed."""


class Turns:
    """The calls of one :func:`together`: which one runs, and the runs each waits for."""

    def __init__(self) -> None:
        self.changed = threading.Condition()
        self.running: int | None = None  # the call whose turn it is; None: the caller's
        self.asked: dict[int, tuple[list, list]] = {}  # each waiting call's jobs and spares
        self.answers: dict[int, Any] = {}  # their results, or Cancelled

    def give(self, i: int) -> None:
        """The caller's side: call ``i`` runs until it asks for runs or returns."""
        with self.changed:
            self.running = i
            self.changed.notify_all()
            self.changed.wait_for(lambda: self.running is None)

    def wait(self, i: int) -> None:
        """A call's thread waits for its turn."""
        with self.changed:
            self.changed.wait_for(lambda: self.running == i)

    def back(self) -> None:
        """The turn goes back to the caller."""
        with self.changed:
            self.running = None
            self.changed.notify_all()

    def ask(self, i: int, jobs: list, spares: list) -> list[tuple[str, Any] | None]:
        """A call's side: the results of its jobs, formed with the other calls' (its turn ends)."""
        self.asked[i] = jobs, spares
        self.back()
        self.wait(i)
        answer = self.answers.pop(i)
        if answer is Cancelled:
            raise Cancelled
        return answer


def together(calls: Sequence[Callable[[Callable[[str], None]], Any]],
             progress: Callable[[str], None] | None, *, task: threading.local,
             batch: Callable[[list, list], list]) -> list[Any]:
    """The results of ``calls`` as made one after the other, their runs formed in batches.

    Args:
        calls: Each is given its own ``say`` (a line of progress): the lines of every call
            reach ``progress`` in the calls' order, each call's once those before it are done.
        progress: Where the lines go (None: nowhere).
        task: Where a call's thread keeps its group (``.group``, a :class:`Turns`) and place
            (``.index``): a request for runs made in it goes to :meth:`Turns.ask`.
        batch: ``batch(jobs, spares)`` forms a batch's runs (results per job, then per spare).

    Returns:
        Each call's result, in order. A call's exception is raised once all are done (the
        first one's).
    """
    calls = list(calls)
    progress = progress or (lambda line: None)
    turns = Turns()
    results: list[Any] = [None] * len(calls)
    errors: dict[int, BaseException] = {}
    lines: list[list[str]] = [[] for _ in calls]
    done: set[int] = set()
    shown = [0]  # the first call whose lines are not all shown

    def show() -> None:
        while shown[0] < len(calls):
            i = shown[0]
            for line in lines[i]:
                progress(line)
            lines[i].clear()
            if i not in done:
                return
            shown[0] += 1

    contexts = [contextvars.copy_context() for _ in calls]  # each call sees the caller's

    def body(i: int) -> None:
        task.group, task.index = turns, i
        turns.wait(i)

        def say(line: str) -> None:
            lines[i].append(line)
            show()

        try:
            results[i] = contexts[i].run(calls[i], say)
        except BaseException as error:  # raised by together() once all are done
            errors[i] = error
        finally:
            done.add(i)
            show()
            turns.back()

    threads = [threading.Thread(target=body, args=(i,), daemon=True, name=f"together-{i}")
               for i in range(len(calls))]
    for thread in threads:
        thread.start()
    ready = list(range(len(calls)))
    while ready:
        for i in ready:
            turns.give(i)
        ready = sorted(turns.asked)
        if not ready:
            break
        asked = [turns.asked.pop(i) for i in ready]
        try:
            formed = batch([job for jobs, _ in asked for job in jobs],
                           [job for _, spares in asked for job in spares])
        except BaseException:  # every waiting call stops; then this is raised
            for i in ready:
                turns.answers[i] = Cancelled
                turns.give(i)
            raise
        n = sum(len(jobs) for jobs, _ in asked)
        ran, spared = formed[:n], formed[n:]
        for i, (jobs, spares) in zip(ready, asked):
            turns.answers[i] = ran[:len(jobs)] + spared[:len(spares)]
            ran, spared = ran[len(jobs):], spared[len(spares):]
    for thread in threads:
        thread.join()
    if errors:
        raise errors[min(errors)]
    return results
