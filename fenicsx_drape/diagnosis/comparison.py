"""How far, and where, a model misses a measurement bundle (``drape compare``).

The definitions are those of the diagnosis contract (``docs/measurements.md``):

- the **noise** of a test is the RMS of its ``force_sd_N`` column, or else a model-free
  estimate from second differences of its rows (:mod:`fenicsx_drape.measurements.noise`);
- a test's error is the RMS of ``measured - simulated`` over its rows (N for coupons); its
  **normalised** error is that RMSE over the test's noise, and the bundle's ``normalised`` error
  is ``sqrt(mean over tests of (RMSE / noise)²)`` -- 1.0 is the noise floor;
- the **share** of a region is its part of the squared normalised error: a row ``i`` of test
  ``k`` (``n_k`` rows, noise ``s_k``, ``n`` tests) contributes ``r_i² / (s_k² n_k n)``, and these
  contributions sum to ``normalised²``.

The regions are the ranges of the variables that matter physically: per test, those its
kind gives (coupons, :mod:`~fenicsx_drape.diagnosis.kinds.coupon`: ranges of the kinematic
strain that separate the mechanisms of the paper's section 3.2, and the phases of the loading
history; a formed part's measurements, e.g. :mod:`~fenicsx_drape.diagnosis.kinds.grid`: parts
of the formed part), and across tests of one kind, each value of a condition that varies
(``speed_mm_per_min``, ``temperature_C``, ...).

This module knows no measurement kind by name: each test's kind is looked up in the table
:data:`~fenicsx_drape.diagnosis.kinds.KINDS` (:func:`~fenicsx_drape.diagnosis.kinds.kind_of`),
which says how to measure, simulate, fit and picture it.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds import (
    KINDS,
    TEST_KINDS,
    Comparison,
    Region,
    comparable,
    find_kind,
    is_formed,
    kind_of,
)
from fenicsx_drape.diagnosis.kinds.coupon import plot_curves
from fenicsx_drape.errors import DrapeInputError

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

# A row whose residual lies beyond this many robust standard deviations (and noise units)
# after the fit is an outlier (spec version 3, "bad and odd rows").
OUTLIER_SD = 5.0
# Regions listed in ``where``: those carrying at least this share of the error, at most this
# many (the complete list is in ``CompareResult.regions``).
WHERE_MIN_SHARE = 0.05
WHERE_MAX_ENTRIES = 12


# --------------------------------------------------------------------------------------------
# Errors and their location


def conditions_of(test: Test) -> dict[str, float]:
    """The scalars a test ran under: its conditions plus the crosshead speed when given."""
    conditions = dict(test.conditions)
    if getattr(test, "speed_mm_per_min", None) is not None:
        conditions.setdefault("speed_mm_per_min", float(test.speed_mm_per_min))
    return conditions


def prepare(bundle: Bundle) -> tuple[list[Test], list[str]]:
    """The tests of ``bundle`` that can be compared, and notes on the others.

    A note for each test that cannot be compared, and for each measurement of a stack that
    names no ply (it is read on the outermost ply away from the punch, spec version 4).
    """
    tests, skipped = [], []
    for test in bundle.tests:
        if comparable(test):
            tests.append(test)
            stack = getattr(test.forming_case, "plies", ())
            if is_formed(test) and test.ply is None and len(stack) > 1:
                skipped.append(f"test {test.id!r}: no ply named; compared with the outermost "
                               f"ply away from the punch (ply {len(stack)})")
        else:
            skipped.append(f"test {test.id!r}: {test.kind} tests cannot be compared yet "
                           "(no simulation for this kind); left out")
    if not tests:
        raise DrapeInputError(f"bundle {bundle.name!r}: no test of a comparable kind "
                              f"({', '.join(TEST_KINDS)})")
    return tests, skipped


def compare_tests(tests: Sequence[Test], simulated: Mapping[str, np.ndarray],
                  regions: Mapping[str, Sequence[Region]] | None = None,
                  noise: Mapping[str, tuple[float, str]] | None = None,
                  ) -> list[Comparison]:
    """Compare given simulated values with the tests (regions and noise computed if absent)."""
    out = []
    for test in tests:
        kind = kind_of(test)
        values = np.asarray(simulated[test.id], dtype=float)
        measured = np.asarray(kind.measured(test), dtype=float)
        if values.shape != measured.shape:
            raise ValueError(f"test {test.id!r}: {values.shape} simulated values for "
                             f"{measured.shape} measured")
        level, source = noise[test.id] if noise else kind.noise(test)
        test_regions = regions[test.id] if regions is not None else kind.regions(test)
        out.append(Comparison(test.id, test.kind, kind.unit(test), measured, values, level,
                              source, tuple(test_regions), conditions_of(test)))
    return out


def _row_lines(test: Test, folder: Path | None) -> np.ndarray:
    """The file line of each row of a test's table (0 where unknown)."""
    from fenicsx_drape.measurements.lab import row_lines

    lab = getattr(test, "lab", None)
    if lab is not None and lab.lines.size == test.n_rows:
        return np.asarray(lab.lines)
    lines = row_lines(Path(folder) / test.file) if folder is not None and test.file else []
    return np.asarray(lines) if len(lines) == test.n_rows else np.zeros(test.n_rows, int)


OUTLIER_NEIGHBOURS = 6  # rows an outlier is told apart from (nearest in the row's coordinates)


def _row_coordinates(test: Test) -> np.ndarray:
    """Where each row of a test was measured: its position, flat position, travel or time."""
    c = test.columns
    for names in (("x_mm", "y_mm", "z_mm"), ("x_mm", "y_mm"), ("x0_mm", "y0_mm"),
                  ("travel_mm",), ("time_s",)):
        if all(n in c for n in names):
            return np.column_stack([c[n] for n in names])
    return np.arange(test.n_rows, dtype=float)[:, None]


def find_outliers(comparisons: Sequence[Comparison], tests: Sequence[Test],
                  folder: Path | None = None) -> list[dict[str, Any]]:
    """The rows whose residual stands out of their neighbours' (spec version 3, outliers).

    Per test, the residuals in noise units r, and each row's departure from the median
    residual of its :data:`OUTLIER_NEIGHBOURS` nearest rows (in position, flat position,
    travel or time: :func:`_row_coordinates`), per value (x, y, z of a grid node). A row whose
    departure lies beyond :data:`OUTLIER_SD` robust standard deviations of the departures
    (1.4826 × their median absolute deviation, at least 1), with a residual beyond
    :data:`OUTLIER_SD` noise units and :data:`OUTLIER_SD` robust standard deviations of the
    test's residuals from their median, is an outlier unless its nearest row shares its residual
    (the same way, at least half of it): a single wild row, not a region the model misses.
    Each: ``test`` (the forming test's id), ``measurement`` ("file" for a grid or a coupon's
    table), ``id`` (the compared test), ``file``, ``line``, ``row`` and ``residual`` (noise
    units).
    """
    from scipy.spatial import cKDTree

    from fenicsx_drape.measurements.lab import measurement_of

    by_id = {t.id: t for t in tests}
    out = []
    for c in comparisons:
        test = by_id.get(c.id)
        if test is None or test.n_rows <= OUTLIER_NEIGHBOURS or c.residual.size % test.n_rows:
            continue
        row_r = (c.residual / c.noise).reshape(test.n_rows, -1)
        X = _row_coordinates(test)
        _, near = cKDTree(X).query(X, k=OUTLIER_NEIGHBOURS + 1)
        local = np.median(row_r[near[:, 1:]], axis=1)  # (rows, values): the neighbours'
        d = row_r - local
        sd = max(1.4826 * float(np.median(np.abs(d - np.median(d)))), 1.0)
        worst = np.abs(d).max(axis=1)
        column = np.abs(d).argmax(axis=1)
        signed = row_r[np.arange(len(row_r)), column]
        # ... and beyond OUTLIER_SD robust sd of the test's residuals (about their median).
        centre = np.median(row_r)
        spread = max(1.4826 * float(np.median(np.abs(row_r - centre))), 1.0)
        wild = ((worst > OUTLIER_SD * sd) & (np.abs(signed) > OUTLIER_SD)
                & (np.abs(signed - centre) > OUTLIER_SD * spread))
        # A row whose nearest row shares its residual (same way, at least half) is part of a
        # region the model misses.
        shared = row_r[near[:, 1], column] / np.where(signed == 0, 1.0, signed) >= 0.5
        rows = np.flatnonzero(wild & ~shared)
        if not rows.size:
            continue
        lines = _row_lines(test, folder)
        lab = getattr(test, "lab", None)
        for k in rows:
            out.append({"test": lab.parent if lab is not None else c.id,
                        "measurement": measurement_of(test) or "file", "id": c.id,
                        "file": test.file, "line": int(lines[k]), "row": int(k),
                        "residual": float(signed[k])})
    return out


def without_outliers(comparisons: Sequence[Comparison], outliers: Sequence[Mapping[str, Any]],
                     tests: Sequence[Test]) -> list[Comparison]:
    """The comparisons with the outliers' rows left out (regions with them)."""
    by_id = {t.id: t for t in tests}
    out = []
    for c in comparisons:
        rows = [o["row"] for o in outliers if o["id"] == c.id]
        if not rows:
            out.append(c)
            continue
        n = by_id[c.id].n_rows
        keep = np.ones(n, bool)
        keep[rows] = False
        keep = np.repeat(keep, c.residual.size // n)
        regions = tuple(dataclasses.replace(r, rows=r.rows[keep]) for r in c.regions)
        out.append(dataclasses.replace(c, measured=c.measured[keep], simulated=c.simulated[keep],
                                       regions=regions))
    return out


def normalised_error(comparisons: Iterable[Comparison]) -> float:
    """``sqrt(mean over tests of (RMSE / noise)²)`` (contract definition)."""
    ratios = [c.normalised for c in comparisons]
    return float(np.sqrt(np.mean(np.square(ratios))))


def pooled_rmse(comparisons: Iterable[Comparison]) -> float:
    """The RMS error over all rows of all tests (for information only)."""
    residuals = np.concatenate([c.residual for c in comparisons])
    return float(np.sqrt(np.mean(residuals**2)))


def _contributions(comparisons: Sequence[Comparison]) -> dict[str, np.ndarray]:
    """Each row's part of the squared normalised error (they sum to ``normalised²``)."""
    n = len(comparisons)
    return {c.id: c.residual**2 / (c.noise**2 * c.residual.size * n) for c in comparisons}


def locate(comparisons: Sequence[Comparison]) -> list[dict[str, Any]]:
    """Every region with its share of the error, largest first.

    The regions: each region of each test; each strain range or phase summed over the tests
    of a kind (when several tests have it); each value of a condition that varies across the
    tests of a kind. Each entry: ``test`` (an id, or ids joined by ", "), ``tests``, ``kind``,
    ``variable``, ``range``, ``share_of_error``, ``share_of_rows`` (of the rows of its
    test(s), or of its kind for a condition), ``says`` and, for strain ranges and phases,
    ``region`` (its name).
    """
    parts = _contributions(comparisons)
    total = sum(float(p.sum()) for p in parts.values()) or 1.0
    entries: list[dict[str, Any]] = []
    summed: dict[tuple[str, str, str], list[tuple[Comparison, Region]]] = {}
    for c in comparisons:
        for region in c.regions:
            entries.append({
                "test": c.id, "tests": [c.id], "kind": c.kind, "variable": region.variable,
                "range": [round(region.range[0], 6), round(region.range[1], 6)],
                "share_of_error": float(parts[c.id][region.rows].sum()) / total,
                "share_of_rows": float(region.rows.mean()), "says": region.says,
                "region": region.says,
            })
            summed.setdefault((c.kind, region.variable, region.says), []).append((c, region))
    for (kind, variable, says), members in summed.items():
        if len(members) < 2:
            continue
        ids = [c.id for c, _ in members]
        entries.append({
            "test": ", ".join(ids), "tests": ids, "kind": kind, "variable": variable,
            "range": [round(min(r.range[0] for _, r in members), 6),
                      round(max(r.range[1] for _, r in members), 6)],
            "share_of_error": sum(float(parts[c.id][r.rows].sum()) for c, r in members) / total,
            "share_of_rows": sum(int(r.rows.sum()) for _, r in members)
            / sum(c.residual.size for c, _ in members),
            "says": f"{says}, all {kind.replace('_', ' ')} tests", "region": says,
        })
    for kind, variable, groups in _condition_groups(comparisons):
        rows_total = sum(c.residual.size for group in groups.values() for c in group)
        for value, group in sorted(groups.items()):
            ids = [c.id for c in group]
            entries.append({
                "test": ", ".join(ids), "tests": ids, "kind": kind, "variable": variable,
                "range": [value, value],
                "share_of_error": sum(float(parts[i].sum()) for i in ids) / total,
                "share_of_rows": sum(c.residual.size for c in group) / rows_total,
                "says": f"{kind.replace('_', ' ')} tests at {variable} = {value:g}",
            })
    entries.sort(key=lambda e: (-e["share_of_error"], e["test"], e["variable"]))
    return entries


def where(comparisons: Sequence[Comparison]) -> list[dict[str, Any]]:
    """The regions carrying most of the error (contract field ``where``).

    Those with at least :data:`WHERE_MIN_SHARE` of the squared normalised error, at most
    :data:`WHERE_MAX_ENTRIES`, largest first (always at least the largest one).
    """
    entries = locate(comparisons)
    top = [e for e in entries if e["share_of_error"] >= WHERE_MIN_SHARE][:WHERE_MAX_ENTRIES]
    return top or entries[:1]


def _condition_groups(comparisons: Sequence[Comparison]):
    """Per kind, the conditions taking several values: (kind, variable, {value: tests})."""
    by_kind: dict[str, list[Comparison]] = {}
    for c in comparisons:
        by_kind.setdefault(c.kind, []).append(c)
    for kind, group in sorted(by_kind.items()):
        names = sorted({name for c in group for name in c.conditions})
        for name in names:
            values: dict[float, list[Comparison]] = {}
            for c in group:
                if name in c.conditions:
                    values.setdefault(c.conditions[name], []).append(c)
            if len(values) > 1:
                yield kind, name, values


def trends(comparisons: Sequence[Comparison]) -> list[dict[str, Any]]:
    """How the error varies with each condition that varies across tests of one kind.

    For each (kind, condition) with at least three values: the Spearman rank correlation
    between the value and the mean squared normalised error of the tests at that value, and
    the ratio of the largest to the smallest of those errors. ``says`` is set when the error
    follows the condition (``|rho| >= 0.8`` and a ratio of at least 2).
    """
    out = []
    for kind, variable, groups in _condition_groups(comparisons):
        if len(groups) < 3:
            continue
        values = np.array(sorted(groups))
        errors = np.array([np.mean([c.normalised**2 for c in groups[v]]) for v in values])
        rho = _spearman(values, errors)
        ratio = float(errors.max() / errors.min()) if errors.min() > 0 else math.inf
        entry = {"kind": kind, "variable": variable, "values": values.tolist(),
                 "normalised": np.sqrt(errors).tolist(), "spearman": rho,
                 "ratio": ratio, "says": ""}
        if abs(rho) >= 0.8 and ratio >= 2.0:
            direction = "grows" if rho > 0 else "falls"
            entry["says"] = (f"the residual of the {kind.replace('_', ' ')} tests {direction} "
                             f"with {_variable_words(variable)}")
        out.append(entry)
    return out


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    rx, ry = np.argsort(np.argsort(x)), np.argsort(np.argsort(y))
    if np.std(rx) == 0 or np.std(ry) == 0:
        return 0.0
    return float(np.corrcoef(rx, ry)[0, 1])


_WORDS = {"speed_mm_per_min": "crosshead speed", "temperature_C": "temperature"}


def _variable_words(variable: str) -> str:
    return _WORDS.get(variable, variable.replace("_", " "))


# --------------------------------------------------------------------------------------------
# The compare command's result


@dataclasses.dataclass(frozen=True)
class CompareResult:
    """A (fitted) model against a bundle: how far, and where."""

    bundle: str  # the bundle's name
    model: Model  # the model compared (fitted when ``compare`` fitted it)
    tests: tuple[Comparison, ...]
    skipped: tuple[str, ...] = ()  # tests left out, with the reason
    metrics: Mapping[str, Mapping[str, Any]] = dataclasses.field(default_factory=dict)
    outliers: tuple[Mapping[str, Any], ...] = ()  # rows beyond OUTLIER_SD (find_outliers)
    compared: tuple[Test, ...] = ()  # the tests compared (to leave the outliers' rows out)
    # The data check run before the fit (spec version 4); None: not run (evaluate alone).
    data_check: tuple[Mapping[str, Any], ...] | None = None

    @property
    def normalised(self) -> float:
        """The bundle's normalised error (1.0 is the noise floor)."""
        return normalised_error(self.tests)

    @property
    def rmse(self) -> float:
        """Pooled RMS error over all rows (information only)."""
        return pooled_rmse(self.tests)

    def where(self) -> list[dict[str, Any]]:
        """The regions carrying most of the error, see :func:`where`."""
        return where(self.tests)

    def to_dict(self) -> dict[str, Any]:
        """The content of ``compare.json``."""
        return {
            "bundle": self.bundle,
            "model": model_record(self.model),
            "error": error_record(self.tests),
            "noise_floor": noise_record(self.tests),
            "per_test": {c.id: {"kind": c.kind, "unit": c.unit, "rmse": c.rmse,
                                "mean_abs": c.mean_abs,
                                "percent": c.percent if math.isfinite(c.percent) else None,
                                "noise": c.noise, "noise_source": c.noise_source,
                                "normalised": c.normalised, "rows": int(c.measured.size),
                                **self.metrics.get(c.id, {})}
                         for c in self.tests},
            "where": self.where(),
            "regions": locate(self.tests),
            "trends": trends(self.tests),
            "skipped": list(self.skipped),
            "outliers": list(self.outliers),
            "error_without_outliers": error_record(
                without_outliers(self.tests, self.outliers, self.compared)
                if self.outliers else self.tests),
        }


def model_record(model: Model) -> dict[str, Any]:
    """Effects, parameters and plugins of a model, as written in reports."""
    return {"effects": list(model.effects),
            "parameters": {k: float(v) for k, v in sorted(model.parameters.items())},
            "plugins": [str(p) for p in model.plugins]}


def error_record(comparisons: Sequence[Comparison]) -> dict[str, Any]:
    """The contract's ``error`` object: pooled ``rmse_N``, ``normalised``, ``per_test``."""
    return {"rmse_N": pooled_rmse(comparisons), "normalised": normalised_error(comparisons),
            "per_test": {c.id: c.rmse for c in comparisons}}


def noise_record(comparisons: Sequence[Comparison]) -> dict[str, Any]:
    """The contract's ``noise_floor`` object (``source`` is "mixed" when tests differ)."""
    sources = sorted({c.noise_source for c in comparisons})
    rows = np.array([c.measured.size for c in comparisons], dtype=float)
    levels = np.array([c.noise for c in comparisons])
    return {"rmse_N": float(np.sqrt(np.sum(rows * levels**2) / rows.sum())),
            "per_test": {c.id: c.noise for c in comparisons},
            "source": sources[0] if len(sources) == 1 else "mixed",
            "sources": {c.id: c.noise_source for c in comparisons}}


def kind_metrics(tests: Iterable[Test], comparisons: Sequence[Comparison],
                 model: Model) -> dict[str, dict[str, Any]]:
    """The kinds' own measures (e.g. forming: mean distance), by test id, where defined."""
    by_id = {c.id: c for c in comparisons}
    out = {}
    for t in tests:
        if t.id in by_id:
            measures = kind_of(t).metrics(t, by_id[t.id].simulated, model)
            if measures is not None:
                out[t.id] = measures
    return out


def simulate(tests: Iterable[Test], model: Model) -> dict[str, np.ndarray]:
    """The model's values for each test (N per row for coupons), by test id."""
    return {test.id: kind_of(test).simulate(test, model) for test in tests}


def evaluate(bundle: Bundle, model: Model) -> CompareResult:
    """Compare ``model`` as it is (no fit) with the comparable tests of ``bundle``."""
    tests, skipped = prepare(bundle)
    comparisons = compare_tests(tests, simulate(tests, model))
    return CompareResult(bundle.name, model, tuple(comparisons), tuple(skipped),
                         kind_metrics(tests, comparisons, model),
                         tuple(find_outliers(comparisons, tests, bundle.path)), tuple(tests))


def compare(bundle: Bundle, model: Model, *, fit: bool = True,
            progress: Callable[[str], None] | None = None) -> CompareResult:
    """Fit ``model`` to ``bundle`` (unless ``fit=False``) and compare it with every test.

    The measurements are checked against their cases first
    (:func:`~fenicsx_drape.diagnosis.data_check.data_check`, spec version 4): the fit leaves
    out those that cannot be of their case (all of them suspect: no fit), and the result
    carries the check (``data_check``), named first in :func:`conclusion`.

    Args:
        bundle: The measurements.
        model: The model (effects and starting parameters).
        fit: Fit the model's parameters first (:func:`fit_bundle`: each test kind's fit).
        progress: Called with a line of text as the fit proceeds.

    Returns:
        How far the model is from each test and where it fails.
    """
    from fenicsx_drape.diagnosis.data_check import data_check, say_suspects, suspect_tests

    # Data before physics (spec version 4): each measurement checked against its case before
    # any fit; no parameter is fitted on the evidence of a suspect one.
    checked = data_check(bundle)
    say_suspects(checked, progress or (lambda line: None))
    suspect = suspect_tests(bundle, checked)
    kept = [t.id for t in bundle.tests if t.id not in suspect]
    if fit and kept:
        model = fit_bundle(bundle, model, tests=kept if suspect else None, progress=progress)
    result = evaluate(bundle, model)
    skipped = (f"not fitted on {', '.join(sorted(suspect))}: data that cannot be of the case "
               "(data_check)",) if fit and suspect else ()
    return dataclasses.replace(result, data_check=tuple(checked),
                               skipped=result.skipped + skipped)


def conclusion(result: CompareResult) -> str:
    """The comparison in a sentence; data that cannot be of the case named first."""
    bad = [e for e in result.data_check or () if e["suspect"]]
    text = f"The model is {result.normalised:.3g} × the noise floor (normalised error)." + "".join(
        f" {e['test']}/{e['measurement']}: {e['why']}." for e in result.data_check or ()
        if not e["suspect"] and e["why"].startswith("chosen:"))  # a reading of the data
    if not bad:
        return text
    return ("Check the data: " + "; ".join(f"{e['test']}/{e['measurement']}: {e['why']}"
                                           for e in bad)
            + ". No parameter was fitted on them and their error says nothing of the model. "
            + text)


def fit_bundle(bundle: Bundle, model: Model, *, tests: Sequence[str] | None = None,
               parameters: Sequence[str] | None = None, max_iterations: int = 200,
               from_features: bool = True, progress: Callable[[str], None] | None = None,
               details: dict | None = None, own: Sequence[str] = ()) -> Model:
    """Fit a model to a bundle that may mix test kinds: each kind's own ``fit`` in turn.

    The fits of the kinds present among the chosen tests run once each, in the order
    of :data:`~fenicsx_drape.diagnosis.kinds.KINDS`: the coupons fix the material
    (:func:`fenicsx_drape.calibration.fitting.fit`), then the forming tests fit the friction
    coefficients with the material held (:func:`~fenicsx_drape.diagnosis.kinds.forming.
    fit_forming`), but for a candidate's ``own`` parameters that no coupon test fixes.

    Args:
        bundle: The measurements.
        model: The model (effects and starting parameters).
        tests: Only these test ids; all tests when None.
        parameters: Only these parameters (of the kinds that fit them); all when None.
        max_iterations: Cap on each optimiser's iterations.
        from_features: Start the coupon fit from curve features (section 3.2) rather than
            the model's values.
        progress: Called with a line of text as the fits proceed.
        details: Filled by the kinds' fits with what they found (the coupons:
            ``details["coupons"]``, the :class:`~fenicsx_drape.calibration.fitting.FitResult`).
        own: A candidate's own parameters, in its refit (the kinds' ``FitHook``).

    Returns:
        The fitted model.
    """
    present = [find_kind(t) for t in bundle.tests if tests is None or t.id in tests]
    done: list[Callable[..., Model]] = []
    for kind in KINDS:
        if any(k is kind for k in present) and kind.fit not in done:
            done.append(kind.fit)
            model = kind.fit(bundle, model, kind_of=find_kind, tests=tests,
                             parameters=parameters, max_iterations=max_iterations,
                             from_features=from_features, progress=progress, details=details,
                             own=tuple(own))
    return model


# --------------------------------------------------------------------------------------------
# Output


def safe_name(text: str) -> str:
    """A file-name-safe version of a test id."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text)


def plot_residuals(comparisons: Mapping[str, Comparison], test: Test, path: Path,
                   shares: Sequence[Mapping[str, Any]] = ()) -> Path:
    """Measured against one or more models (top) and their residuals (bottom).

    Against the test kind's abscissa (:func:`~fenicsx_drape.diagnosis.kinds.coupon.
    plot_curves`); a kind's own picture is its ``plot``.

    Args:
        comparisons: The models' comparisons with ``test``, by label (e.g. "baseline").
        test: The test.
        path: The PNG to write.
        shares: Regions of the test (entries of :func:`locate`) to shade with their share of
            the first model's error.
    """
    return plot_curves(comparisons, test, path, shares, kind_of(test).abscissa(test))


def plot_where(entries: Sequence[Mapping[str, Any]], path: Path, title: str = "") -> Path:
    """Horizontal bars: the share of the squared normalised error of each region."""
    import matplotlib.pyplot as plt

    from fenicsx_drape.provenance import save_figure

    entries = list(entries)[::-1]
    fig, ax = plt.subplots(figsize=(8, 0.4 * len(entries) + 1.2))
    labels = [e["says"] if e["variable"] in e["says"] else
              f"{e['says'] if len(e['tests']) > 1 else e['test'] + ': ' + e['says']}  "
              f"[{e['range'][0]:.3g}, {e['range'][1]:.3g}]" for e in entries]
    ax.barh(range(len(entries)), [100 * e["share_of_error"] for e in entries], color="C3",
            label="share of the error")
    ax.barh(range(len(entries)), [100 * e["share_of_rows"] for e in entries], height=0.25,
            color="0.3", label="share of the rows")
    ax.set_yticks(range(len(entries)), labels, fontsize=8)
    ax.set_xlabel("share of the squared normalised error (%)")
    ax.set_title(title or "where the model misses")
    ax.legend(loc="lower right", fontsize=8)
    return save_figure(fig, path)


def write_compare(result: CompareResult, bundle: Bundle, out_dir: str | Path, *,
                  model_path: str | Path | None = None) -> Path:
    """Write the comparison into ``out_dir`` and record the version in its ledger.

    Files: ``compare.json``, ``model.toml`` (the fitted model, loadable), one
    ``residual_<test>.png`` per test, ``where.png`` and ``provenance.json``.

    Returns:
        The path of ``compare.json``.
    """
    from fenicsx_drape.diagnosis import ledger
    from fenicsx_drape.provenance import atomic_write_text, write_json, write_provenance
    from fenicsx_drape.runs import execution_record

    out = Path(out_dir)
    record = result.to_dict()
    if result.data_check is None:  # a result of evaluate: checked here (spec version 4)
        from fenicsx_drape.diagnosis.data_check import data_check

        result = dataclasses.replace(result, data_check=tuple(data_check(bundle)))
    record["data_check"] = list(result.data_check)
    record["conclusion"] = conclusion(result)
    path = write_json(out / "compare.json", record)
    atomic_write_text(out / "model.toml", result.model.to_toml())
    tests = {t.id: t for t in bundle.tests}
    regions = record["regions"]
    for c in result.tests:
        kind_of(tests[c.id]).plot({"model": c}, tests[c.id],
                                  out / f"residual_{safe_name(c.id)}.png",
                                  [e for e in regions if e["tests"] == [c.id]])
    plot_where(record["where"], out / "where.png",
               f"{result.bundle}: normalised error {result.normalised:.2f}")
    ledger.record(out, result, bundle=bundle, model_path=model_path)
    write_provenance(out, bundle=str(bundle.path) if bundle.path else bundle.name,
                     model=str(model_path) if model_path else "default",
                     effects=list(result.model.effects),
                     parameters=record["model"]["parameters"], seed=None,
                     forming_runs=execution_record())
    return path

