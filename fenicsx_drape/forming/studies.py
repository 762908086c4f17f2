"""Parameter studies of the hemisphere (the paper's Figs. 9 and 12): run a list, tabulate.

Each study in ``demos/study_*.py`` builds a list of :class:`HemisphereCase` s (or forming
cases of any part, :class:`~fenicsx_drape.forming.case.FormingCase`, e.g.
``load_case(path, duration_s=d)``), runs them with :func:`sweep` and writes the rows with
:func:`write_rows` and a plot; rank 0 writes.
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from fenicsx_drape.forming.case import FormingCase
from fenicsx_drape.forming.hemisphere import HemisphereCase, run_hemisphere
from fenicsx_drape.forming.outputs import case_summary, summary
from fenicsx_drape.forming.post import FormedGrid
from fenicsx_drape.forming.run import run_case
from fenicsx_drape.provenance import atomic_write_text

COLUMNS = ("max_shear_deg", "total_wrinkling_strain", "min_wrinkling_strain", "nodes", "steps",
           "cutbacks", "snes_iterations", "wall_time_s", "max_penetration_mm")


def sweep(cases: Iterable[HemisphereCase | FormingCase], model=None, options=None,
          progress: Callable[[str], None] | None = print) -> tuple[list[dict], list[FormedGrid]]:
    """Run every case; returns one summary row per case and the formed grids.

    A case whose solve fails gives a row with ``failed`` set to the error message (the study
    goes on), and ``None`` for its grid.
    """
    from fenicsx_drape.errors import SolverError

    rows, grids = [], []
    for case in cases:
        generic = isinstance(case, FormingCase)
        try:
            run = (run_case if generic else run_hemisphere)(case, model, options)
        except SolverError as err:
            rows.append({"failed": str(err)})
            grids.append(None)
            if progress is not None:
                progress(f"{case}: failed ({err})")
            continue
        s = case_summary(run) if generic else summary(run)
        row = {k: s[k] for k in COLUMNS}
        draw_in = s.get("draw_in_mm") or {}
        row["draw_in_mid_side_mm"] = draw_in.get("mid_side_mm", np.nan)
        row["draw_in_corner_mm"] = draw_in.get("corner_mm", np.nan)
        rows.append(row)
        grids.append(run.grid)
        if progress is not None:
            progress(", ".join(f"{k} {v:.4g}" for k, v in row.items()))
    return rows, grids


def write_rows(path: str | os.PathLike, rows: list[dict], first: dict[str, Iterable],
               comment: str = "") -> Path:
    """Write a study's table as CSV: the varied columns ``first``, then the rows' values."""
    names = list(first) + [k for k in (*COLUMNS, "draw_in_mid_side_mm", "draw_in_corner_mm")]
    varied = [list(v) for v in first.values()]
    buf = io.StringIO()
    buf.writelines(f"# {line}\n" for line in comment.splitlines())
    buf.write(",".join(names) + "\n")
    for k, row in enumerate(rows):
        values = [v[k] for v in varied] + [row.get(n, np.nan) for n in names[len(first):]]
        buf.write(",".join(f"{float(v):.6g}" for v in values) + "\n")
    return atomic_write_text(path, buf.getvalue())
