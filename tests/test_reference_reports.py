"""The kept diagnoses: every field of each report as its reference says (no behaviour change).

Each case of ``tests/reference_reports.py`` (the shipped bundles with the models the README
and docs use, a set-up error, a stack) is diagnosed and its report compared with
``tests/data/reference/<name>.json``, written by that script: the same keys in the same
order, strings and booleans equal, numbers equal to :data:`RELATIVE` (the same arithmetic on
any number of workers; a reordered sum may move the last bits). A change meant to change the
reports writes them again with the script, and the diff of the files is what is reviewed.
The cheap cases run in ``make test``; the README's lab bundle and the real coupon curves of
several labs, minutes of runs and fits, in ``make bench``.
"""

from __future__ import annotations

import json
import math

import pytest
from reference_reports import CASES, DATA, report_of

RELATIVE = 1e-9  # numbers agree to this share of their size (or absolutely, near zero)


def differences(got, want, path: str = "report") -> list[str]:
    """Where ``got`` differs from ``want`` (JSON values), one line a difference."""
    if isinstance(want, dict):
        if not isinstance(got, dict):
            return [f"{path}: {type(got).__name__}, the reference an object"]
        if list(got) != list(want):
            return [f"{path}: keys {list(got)}, the reference {list(want)}"]
        return [d for k in want for d in differences(got[k], want[k], f"{path}.{k}")]
    if isinstance(want, list):
        if not isinstance(got, list) or len(got) != len(want):
            return [f"{path}: {got!r:.200}, the reference {want!r:.200}"]
        return [d for i, (g, w) in enumerate(zip(got, want)) for d in
                differences(g, w, f"{path}[{i}]")]
    numbers = (int, float)
    if (isinstance(want, numbers) and not isinstance(want, bool)
            and isinstance(got, numbers) and not isinstance(got, bool)):
        if math.isclose(got, want, rel_tol=RELATIVE, abs_tol=RELATIVE):
            return []
    elif type(got) is type(want) and got == want:
        return []
    return [f"{path}: {got!r:.300}, the reference {want!r:.300}"]


def test_differences_are_found_field_by_field():
    want = {"a": 1.0, "b": [{"c": "x", "d": True}], "e": None}
    assert differences(json.loads(json.dumps(want)), want) == []
    assert differences({"a": 1.0 + 1e-12, "b": [{"c": "x", "d": True}], "e": None}, want) == []
    assert differences({"a": 1.001, "b": [{"c": "y", "d": 1}], "e": 0}, want) == [
        "report.a: 1.001, the reference 1.0", "report.b[0].c: 'y', the reference 'x'",
        "report.b[0].d: 1, the reference True", "report.e: 0, the reference None"]
    assert differences({"b": [], "a": 1.0, "e": None}, want) == [
        "report: keys ['b', 'a', 'e'], the reference ['a', 'b', 'e']"]


# The bench cases (minutes of runs) get a longer time limit than the suite's.
CASE_PARAMETERS = [pytest.param(name, id=name, marks=[pytest.mark.slow] + (
    [pytest.mark.bench, pytest.mark.timeout(1200)] if case.bench else []))
    for name, case in CASES.items()]


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("name", CASE_PARAMETERS)
def test_the_report_is_its_reference(name):
    pytest.importorskip("dolfinx")
    want = json.loads((DATA / f"{name}.json").read_text())
    found = differences(report_of(CASES[name]), want)
    assert not found, f"{len(found)} field(s) differ:\n" + "\n".join(found[:20])
