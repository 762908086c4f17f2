"""The held-out folds of a diagnosis: the three schemes, in one place.

A candidate (an effect, a set-up) is judged on rows its fit did not see; every row is
predicted once, by the fold that held it out:

1. **Leave one test out** (:func:`folds_of`), for a test kind with several tests: each
   fold fits all the other tests of that kind and predicts the one left out (an unseen speed
   or temperature).
2. **Leave every** :data:`BLOCKS` **-th row out** (:func:`folds_of`), for a kind with a
   single test: each of :data:`BLOCKS` interleaved folds gives its rows infinite standard
   deviation (no weight in the fit; the history is still followed row by row,
   :func:`without_rows`) and predicts them. Interleaved rather than contiguous blocks: a
   contiguous end block would test the extrapolation of poorly determined parameters (the
   same for every candidate) rather than the physics; the physics is tested across
   conditions by leaving tests out. These folds are warm-started from the full fit and
   refit, to the other tests of the held-out test's kind, the parameters that kind
   identifies (tow law: tensile; shear law: bias extension), in at most
   :data:`FOLD_ITERATIONS` iterations.
3. **Leave every** :data:`NODE_FOLDS` **-th node out** (:func:`node_folds`), the set-up
   stage's: :data:`NODE_FOLDS` interleaved folds of each forming test's measured nodes, each
   refitting the set-up parameter by one Gauss-Newton step from the full fit without them
   (:mod:`~fenicsx_drape.diagnosis.setup_fit`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.diagnosis.kinds import kind_of, row_sd

if TYPE_CHECKING:
    from collections.abc import Sequence

    from fenicsx_drape.measurements.bundle import Bundle, Test

BLOCKS = 3  # interleaved folds of a kind with a single test
FOLD_ITERATIONS = 8  # iteration cap of a fold's refit
NODE_FOLDS = 3  # the set-up stage's interleaved folds of each forming test's nodes


@dataclasses.dataclass(frozen=True)
class Fold:
    """One held-out fit: what it is fitted to and which rows it predicts."""

    label: str
    bundle: Bundle  # the bundle fitted (held-out rows of a single test at infinite sd)
    fitted: tuple[str, ...]  # ids of the tests fitted (of the held-out test's kind)
    predicts: str  # id of the test it predicts
    rows: np.ndarray  # boolean mask of the rows of that test it predicts


def folds_of(bundle: Bundle) -> tuple[tuple[Fold, ...], str]:
    """The held-out folds of a bundle's tests and the scheme in words (module doc, 1. and 2.)."""
    by_kind: dict[str, list[Test]] = {}
    for test in bundle.tests:
        by_kind.setdefault(test.kind, []).append(test)
    folds: list[Fold] = []
    parts = []
    for kind, tests in sorted(by_kind.items()):
        if len(tests) > 1:
            parts.append(f"leave-one-test-out over the {len(tests)} {kind} tests")
            for test in tests:
                folds.append(Fold(f"without {test.id}", bundle,
                                  tuple(t.id for t in tests if t.id != test.id), test.id,
                                  np.ones(test.n_rows, bool)))
            continue
        (test,) = tests
        parts.append(f"leave-every-{ordinal(BLOCKS)}-row-out ({BLOCKS} interleaved folds) "
                     f"for the single {kind} test {test.id!r}")
        for b in range(BLOCKS):
            mask = np.arange(test.n_rows) % BLOCKS == b
            held = without_rows(test, mask)
            tests_b = tuple(held if t.id == test.id else t for t in bundle.tests)
            folds.append(Fold(f"{test.id} rows {b + 1}::{BLOCKS}",
                              dataclasses.replace(bundle, tests=tests_b), (test.id,), test.id,
                              mask))
    return tuple(folds), "; ".join(parts) + (
        ". Each row is predicted once by a fit that did not see it: warm-started from the "
        "full fit, it refits the parameters of the law the held-out test's kind identifies "
        "(tow law: tensile, shear law: bias extension) to the other tests of that kind, in at "
        f"most {FOLD_ITERATIONS} iterations.")


def ordinal(n: int) -> str:
    """``n`` as an ordinal word ("third")."""
    return {2: "second", 3: "third", 4: "fourth", 5: "fifth"}.get(n, f"{n}th")


def without_rows(test: Test, rows: np.ndarray) -> Test:
    """``test`` with the given rows at infinite standard deviation (no weight in a fit).

    The other rows keep their ``force_sd_N``, or get the test's model-free noise estimate,
    so that they weigh in the fit exactly as they do without a ``force_sd_N`` column.
    """
    columns = dict(test.columns)
    columns[kind_of(test).sd_column(test)] = np.where(rows, np.inf, row_sd(test))
    return dataclasses.replace(test, columns=columns)



def node_folds(tests: Sequence[Test]) -> list[dict[str, np.ndarray]]:
    """The set-up stage's folds (module doc, 3.): per fold, each test's rows it keeps."""
    return [{t.id: np.arange(t.n_rows) % NODE_FOLDS != b for t in tests}
            for b in range(NODE_FOLDS)]


NODE_SCHEME = (f"leave-every-{NODE_FOLDS}-node-out: {NODE_FOLDS} interleaved folds of each "
               "forming test's nodes, each predicted by one Gauss-Newton step from the full "
               "fit without them; the stated set-up fits nothing (its held-out error is its "
               "error)")
