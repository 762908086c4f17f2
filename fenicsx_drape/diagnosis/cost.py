"""Where a diagnosis spends its time: the forming runs and seconds of each stage.

A diagnosis on forming tests is as slow as the runs it forms, and which stage asks for them
depends on the data (a set-up scan of the whole blank, a finer net's check, a candidate refit
with its folds). :class:`StageCost` counts, around each of :func:`~fenicsx_drape.diagnosis.
pipeline.diagnose`'s stages, the runs asked and formed (:func:`~fenicsx_drape.runs.
execution_record`) and the wall seconds; the report's ``cost`` lists them and the console's
last line before the conclusion names the stages that took most of the time.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

T = TypeVar("T")


def _runs() -> tuple[int, int]:
    from fenicsx_drape.runs import execution_record

    runs = execution_record()["runs"]
    return runs["asked"], runs["formed"]


class StageCost:
    """The runs and seconds of each stage, in the order they ran (:meth:`__call__`)."""

    def __init__(self) -> None:
        self.rows: list[dict[str, Any]] = []

    def __call__(self, stage: str, call: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """``call(*args, **kwargs)``, its runs asked and formed and its seconds recorded."""
        asked, formed = _runs()
        start = time.perf_counter()
        try:
            return call(*args, **kwargs)
        finally:
            now_asked, now_formed = _runs()
            self.rows.append({"stage": stage, "seconds": time.perf_counter() - start,
                              "runs_asked": now_asked - asked,
                              "runs_formed": now_formed - formed})


def cost_line(rows: Sequence[dict[str, Any]], largest: int = 3) -> str:
    """One line: the runs formed and seconds in all, then the ``largest`` stages by seconds."""
    if not rows:
        return ""
    seconds = sum(r["seconds"] for r in rows)
    formed = sum(r["runs_formed"] for r in rows)
    asked = sum(r["runs_asked"] for r in rows)
    top = sorted(rows, key=lambda r: -r["seconds"])[:largest]
    parts = ", ".join(f"{r['stage']} {r['seconds']:.0f} s ({r['runs_formed']} formed)"
                      for r in top)
    return (f"cost: {seconds:.0f} s, {formed} forming runs formed ({asked} asked); "
            f"most in {parts}")
