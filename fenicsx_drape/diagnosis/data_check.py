"""Data before physics (spec version 4): is each measurement one of the case it names?

A bundle may hold measurements that cannot belong to its case: axes swapped, another part's
grid, a flat frame shifted, a scan in metres. No effect or set-up explains them, and blaming
the model sends a user the wrong way. :func:`data_check` asks every measurement of a formed
part its kind's ``check`` against its case (the checks, and what makes a measurement
suspect: :mod:`~fenicsx_drape.diagnosis.kinds.checks` for positions, a shifted frame, a
registered scan and shear points against their test's grid;
:mod:`~fenicsx_drape.diagnosis.kinds.outline` for an edge in plan;
:mod:`~fenicsx_drape.diagnosis.kinds.punch_force` for a force curve), before any fit, and
returns the report's ``data_check`` entries (``suspect`` with ``why``, the first reason
found). A reading of the data that was chosen (a blank placed off-centre rather than a
shifted frame) is not suspect: its ``why`` starts "chosen:" and goes to the report's notes.

A travel against the tool's motion (``travel_mm`` ≤ 0) is impossible input: the function
raises :class:`~fenicsx_drape.errors.DrapeInputError` (exit 2; the case's overrides refuse
it first, when the bundle is read).
"""

from __future__ import annotations

from typing import Any

from fenicsx_drape.diagnosis.kinds import find_kind
from fenicsx_drape.errors import DrapeInputError


def data_check(bundle) -> list[dict[str, Any]]:
    """The report's ``data_check``: every forming measurement checked against its case.

    Returns:
        One entry per measurement: ``test`` (the forming test's id), ``measurement``
        (``"file"`` for the grid, or the lab measurement's name), ``suspect`` and ``why``
        (not suspect, a ``why`` starting "chosen:" is the reading of the data chosen).

    Raises:
        DrapeInputError: a travel against the tool's motion (``travel_mm`` ≤ 0).
    """
    from fenicsx_drape.diagnosis.kinds.forming import forming_case_of

    out = []
    checked = []
    for test in bundle.tests:
        kind = find_kind(test)
        if kind is None or not kind.formed:
            continue
        travel = test.forming.get("travel_mm", test.case_keys.get("travel_mm"))
        if travel is not None and not float(travel) > 0:
            raise DrapeInputError(f"test {test.id!r}: travel_mm = {travel:g}: a travel against "
                                  "the tool's motion (travel is the distance it moves, > 0)")
        lab = getattr(test, "lab", None)
        found = kind.check(test, forming_case_of(test))
        suspect, why = found or (False, "consistent with the case (extent, blank, tools, "
                                        "frame)")
        out.append({"test": lab.parent if lab is not None else test.id,
                    "measurement": lab.measurement if lab is not None else "file",
                    "suspect": suspect, "why": why})
        checked.append(test)
    _shear_against_grid(checked, out)
    return out


def _shear_against_grid(tests: list, entries: list[dict[str, Any]]) -> None:
    """Shear points of a test named when its grid of the same ply tells another pattern.

    Only a grid that passed its own checks (on the tools, on the blank) is the reference; the
    entries of ``tests`` (in the same order) are changed in place.
    """
    from fenicsx_drape.diagnosis.kinds.checks import check_shear_against_grid
    from fenicsx_drape.diagnosis.kinds.forming import forming_case_of

    grids = {(e["test"], getattr(t, "ply", None)): t for t, e in zip(tests, entries, strict=True)
             if e["measurement"] == "file" and not e["suspect"]}
    for test, entry in zip(tests, entries, strict=True):
        if entry["measurement"] != "shear_points" or entry["suspect"]:
            continue
        grid = grids.get((entry["test"], getattr(test, "ply", None)))
        if grid is None:
            continue
        try:
            noise = find_kind(test).noise(test)[0], find_kind(grid).noise(grid)[0]
        except DrapeInputError:  # a noise that cannot be told: the diagnosis says so later
            continue
        found = check_shear_against_grid(test, grid, forming_case_of(test), *noise)
        if found:
            entry["suspect"], entry["why"] = found


def suspect_tests(bundle, entries: list[dict[str, Any]]) -> set[str]:
    """The ids of the tests whose measurement the ``entries`` (:func:`data_check`) suspect."""
    bad = {(e["test"], e["measurement"]) for e in entries if e["suspect"]}
    out = set()
    for test in bundle.tests:
        lab = getattr(test, "lab", None)
        if ((lab.parent, lab.measurement) if lab is not None else (test.id, "file")) in bad:
            out.add(test.id)
    return out


def say_suspects(entries: list[dict[str, Any]], say) -> None:
    """A progress line for each suspect measurement, as soon as it is found."""
    for e in entries:
        if e["suspect"]:
            say(f"check the data: {e['test']}/{e['measurement']}: {e['why']}")


def apply_data_check(report: dict[str, Any], entries: list[dict[str, Any]]) -> None:
    """Put ``data_check`` into a diagnosis report; suspect data first in its conclusion.

    With a suspect measurement no effect is named (``missing_effect`` null, ``add_effects``
    empty): the conclusion starts "Check the data: ..." with each suspect's ``why``; what the
    fit found stays in the report's other fields (candidates, set-up). A reading chosen for
    data that are not suspect (a blank offset rather than a shifted frame) goes to ``notes``.
    """
    report["data_check"] = entries
    report.setdefault("notes", []).extend(
        f"{e['test']}/{e['measurement']}: {e['why']}" for e in entries
        if not e["suspect"] and e["why"].startswith("chosen:"))
    bad = [e for e in entries if e["suspect"]]
    if not bad:
        return
    report["missing_effect"] = None
    report["add_effects"] = []
    report["conclusion"] = (
        "Check the data: " + "; ".join(f"{e['test']}/{e['measurement']}: {e['why']}"
                                       for e in bad)
        + ". No effect is named on the evidence of data that cannot be of the case; set them "
        "right (or leave them out) and diagnose again.")
