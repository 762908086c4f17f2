"""Forming tests "measured" by the project's simulator plus noise: for demos, tests, studies.

:func:`synthetic_forming_test` forms the paper's hemisphere and :func:`synthetic_case_test`
any case, each read at a grid drawn on the flat sheet with Gaussian position noise;
:func:`write_case_bundle` writes such tests with copies of their cases as a bundle. What a
lab would measure instead (shear along lines, a scan, the edge, the press force) is
:mod:`~fenicsx_drape.diagnosis.lab_synthetic`'s.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.runs import FULL_CELL_MM, form_many

if TYPE_CHECKING:
    from fenicsx_drape.forming.case import FormingCase
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model


def synthetic_forming_test(model: Model, *, test_id: str = "hemisphere",
                           cell_mm: float = FULL_CELL_MM, grid_mm: float | None = None,
                           sd_mm: float = 0.3, seed: int = 0, quarter: bool = True,
                           duration_s: float = 40.0, holder_force_N: float = 133.0) -> Test:
    """A forming test "measured" by the project's simulator plus Gaussian position noise.

    The hemisphere formed by ``model`` on cells of ``cell_mm``, read at a drawn grid of
    ``grid_mm`` (default: the cell), with noise of ``sd_mm`` per coordinate written as the
    ``position_sd_mm`` column; the quarter grid, or the full sheet by symmetry.
    """
    from fenicsx_drape.forming.case import load_case
    from fenicsx_drape.forming.tools.shapes import HemisphereTools
    from fenicsx_drape.measurements.bundle import Test

    case = load_case("hemisphere", cell_mm=cell_mm, duration_s=duration_s,
                     holder_force_N=holder_force_N)
    (sheet,) = form_many([(case, model)])
    table = (sheet if quarter else sheet.full()).drawn_grid(grid_mm or cell_mm)
    rng = np.random.default_rng(seed)
    columns = {k: np.asarray(v, float) for k, v in table.items()}
    for c in ("x_mm", "y_mm", "z_mm"):
        columns[c] = np.round(columns[c] + rng.normal(0.0, sd_mm, columns[c].size), 4)
    columns["position_sd_mm"] = np.full(columns["i"].size, sd_mm)
    t = HemisphereTools(**case.tool("punch").params)
    setup = {"punch_radius_mm": t.punch_radius_mm, "fillet_radius_mm": t.fillet_radius_mm,
             "holder_opening_mm": t.holder_opening_mm, "sheet_mm": t.sheet_mm,
             "travel_mm": t.travel_mm, "duration_s": duration_s,
             "holder_force_N": holder_force_N, "grid_mm": grid_mm or cell_mm}
    return Test(id=test_id, kind="forming", file=f"{test_id}.csv", columns=columns,
                geometry="hemisphere", forming=setup)


def synthetic_case_test(model: Model, case: FormingCase, *, test_id: str | None = None,
                        grid_mm: float | None = None, sd_mm: float = 0.3, seed: int = 0,
                        full: bool = False, case_file: str = "case/case.toml",
                        ply: int | None = None) -> Test:
    """A forming test of any case "measured" by the project's simulator plus Gaussian noise.

    The case formed by ``model`` (on its own cells), read at a drawn grid of ``grid_mm``
    (default: the cell) on the modelled part, or on the whole blank by symmetry (``full``),
    with noise of ``sd_mm`` per coordinate written as the ``position_sd_mm`` column (none when
    0). The test names ``case_file`` and carries the case; its keys repeat the case's
    duration, travel and holding force. Write it with :func:`write_case_bundle`. On a stack,
    ``ply`` names the ply measured (its ``file_ply`` key); None: the outermost one.
    """
    from fenicsx_drape.measurements.bundle import Test

    (sheet,) = form_many([(case, model)])
    sheet = sheet.ply(ply)
    grid_mm = grid_mm or case.blank.cell_mm
    table = (sheet.full() if full else sheet).drawn_grid(grid_mm)
    rng = np.random.default_rng(seed)
    columns = {k: np.asarray(v, float) for k, v in table.items()}
    if sd_mm:
        for c in ("x_mm", "y_mm", "z_mm"):
            columns[c] = np.round(columns[c] + rng.normal(0.0, sd_mm, columns[c].size), 4)
        columns["position_sd_mm"] = np.full(columns["i"].size, sd_mm)
    keys = {"duration_s": case.duration_s, "travel_mm": case.total_travel_mm}
    if case.holder is not None:
        keys["holder_force_N"] = case.holder.force_N
    test_id = test_id or case.name
    return Test(id=test_id, kind="forming", file=f"{test_id}.csv", columns=columns,
                forming={**keys, "grid_mm": grid_mm}, case=case_file, case_keys=keys,
                forming_case=case, ply=ply)


def write_case_bundle(name: str, tests: Sequence[Test], folder: str | Path, *,
                      comment: str = "") -> Path:
    """Write forming tests that carry their case as a bundle folder, with copies of the cases.

    Each test's case is written (with its geometry files) at its ``case`` path inside the
    folder; the tests that name no case are written as they are.
    """
    from fenicsx_drape.forming.case import write_case
    from fenicsx_drape.measurements.bundle import Bundle, write_bundle

    folder = Path(folder)
    for test in tests:
        if test.forming_case is not None and test.case is not None:
            where = folder / test.case
            write_case(test.forming_case, where.parent, name=where.name, comment=comment)
    return write_bundle(Bundle(name=name, tests=tuple(tests)), folder, comment=comment)
