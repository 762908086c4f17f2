"""What ``drape form`` says about its run is what the run had: the net's own cell and how
much of the blank it models, the drawn grid's spacing (no NumPy beyond; no forming run)."""

import dataclasses

import numpy as np
import pytest

from fenicsx_drape.forming.case.format import load_case
from fenicsx_drape.forming.running import outputs
from fenicsx_drape.forming.running.post import FormedGrid


def flat_sheet(blank) -> FormedGrid:
    """The unformed sheet of a blank's net (its nodes where they lie), as a run gives it."""
    g = blank.grid()
    ij = g.ij
    X = np.full((g.nx + 1, g.ny + 1, 3), np.nan)
    X[ij[:, 0], ij[:, 1]] = g.nodes
    symmetry = None if g.planes in (("x", "y"), ()) else g.planes
    return FormedGrid(X, X.copy(), g.planes == ("x", "y"), symmetry)


def test_a_net_fitted_to_the_blank_says_so_and_by_how_much():
    """The double dome's 300 × 200 mm blank asked for 20 mm cells: 16 cells of 18.75 mm
    along x, 10 of them (187.5 mm) along y, 93.75 % of the blank modelled."""
    case = load_case("double_dome", cell_mm=20.0)
    fit = outputs.net_fit(case, flat_sheet(case.blank))
    assert fit["cell_mm"] == 18.75
    assert fit["net"]["cell_asked_mm"] == 20.0 and fit["net"]["area_share"] == 0.9375
    note = fit["net"]["note"]
    assert "cell 18.75 mm, not the 20 mm asked, so that 16 whole cells span its 300 mm" in note
    assert "10 cells span 187.5 mm of the blank's 200 mm along y: 6.25 mm" in note
    assert note.endswith("a cell of 25 mm or 16.67 mm keeps the whole blank")
    # A cell that fits both sides: no note, the whole blank.
    for cell, shown in ((10.0, 10.0), (25.0, 25.0)):
        case = load_case("double_dome", cell_mm=cell)
        fit = outputs.net_fit(case, flat_sheet(case.blank))
        assert fit["cell_mm"] == shown and "note" not in fit["net"]
        assert fit["net"]["area_share"] == pytest.approx(1.0)
    # The hemisphere's 240 mm sheet at 25 mm: 5 cells of 24 mm on each half, whole.
    case = load_case("hemisphere", cell_mm=25.0)
    fit = outputs.net_fit(case, flat_sheet(case.blank))
    assert fit["cell_mm"] == 24.0 and fit["net"]["area_share"] == pytest.approx(1.0)
    assert fit["net"]["note"].startswith("the net is fitted to the blank: cell 24 mm, not the "
                                         "25 mm asked")
    assert "left out" not in fit["net"]["note"] and "keeps" not in fit["net"]["note"]


def test_a_stack_is_judged_on_its_ply_along_the_blank():
    """A [0, 45] stack on the hemisphere: the turned ply's ragged net is its own, not a
    clipped blank; the aligned ply says the blank is whole."""
    case = load_case("hemisphere", cell_mm=20.0, symmetry=[])
    case = dataclasses.replace(case, plies=(_ply(0.0), _ply(45.0)))
    plies = [flat_sheet(b) for b in case.ply_blanks()]
    stack = dataclasses.replace(plies[-1], plies=tuple(plies))
    fit = outputs.net_fit(case, stack)
    assert fit["cell_mm"] == 20.0 and "note" not in fit["net"]
    assert fit["net"]["area_share"] == pytest.approx(1.0)


def _ply(angle):
    from fenicsx_drape.forming.case.format import PlySpec

    return PlySpec(angle_deg=angle, thickness_mm=0.3)


def test_the_drawn_grid_lies_on_the_nets_nodes():
    assert outputs.default_grid_mm(10.0) == 10.0
    assert outputs.default_grid_mm(5.0) == 10.0 and outputs.default_grid_mm(2.5) == 10.0
    assert outputs.default_grid_mm(18.75) == 18.75 and outputs.default_grid_mm(30.0) == 30.0
    assert outputs.whole_blank_cells(150.0, 100.0, 20.0) == [25.0, pytest.approx(50 / 3)]
    assert outputs.whole_blank_cells(120.0, 120.0, 25.0) == [30.0, 24.0]
    assert outputs.whole_blank_cells(150.0, 100.0 * np.sqrt(2), 20.0) == []
