"""What the coupon kinds share: tensile, bias extension and picture frame tests.

A coupon test is compared row by row on its force (N): simulated by the unit-cell solutions
(:func:`fenicsx_drape.calibration.coupons.simulate`), weighed with the same noise as in the
fit (``force_sd_N``, or the model-free estimate), and fitted by
:func:`fenicsx_drape.calibration.fitting.fit` (the material's parameters: :func:`fit_material`,
the fit hook all coupon kinds share).

Its **regions** are the ranges of the kinematic strain (each kind's own, e.g.
:func:`fenicsx_drape.diagnosis.kinds.bias_extension.strain`) that separate the mechanisms of
the paper's section 3.2 (bias extension: initial tow bending, friction plateau, lock-up;
tension: decrimping, then tow stretching), found by tangent intersections on the loading
curve (:func:`_knees`), and the phases of the loading history (loading, hold, unloading).
Each kind is a :class:`CouponKind` in its own module.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds.base import FitHook, Region

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds.base import Comparison
    from fenicsx_drape.forming.case import FormingCase
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model


def coupon_noise(test: Test) -> tuple[float, str]:
    """A coupon's force noise (N) and its source: the fit's own (``test_noise``)."""
    from fenicsx_drape.calibration.coupons import test_noise

    _, noise, source = test_noise(test)  # the same noise the fit weighs the rows with
    return noise, source


def coupon_simulate(test: Test, model: Model) -> np.ndarray:
    """The force (N) of each row by the unit-cell solutions."""
    from fenicsx_drape.calibration.coupons import simulate as simulate_coupon

    return simulate_coupon(test, model)


def _loading_phases(time_s: np.ndarray, displacement_mm: np.ndarray) -> np.ndarray:
    """Per row: +1 loading, 0 hold, -1 unloading (the crosshead motion ending at the row)."""
    rate = np.diff(displacement_mm) / np.diff(time_s)
    tol = 1e-3 * np.abs(rate).max() if rate.size and np.abs(rate).max() > 0 else 0.0
    phase = np.where(rate > tol, 1, np.where(rate < -tol, -1, 0))
    return np.concatenate([phase[:1], phase])


def _window_lines(x: np.ndarray, y: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Slope and intercept of the least-squares line over every ``w`` consecutive points."""
    x0 = x.mean()
    xc = x - x0

    def sums(a):
        c = np.concatenate([[0.0], np.cumsum(a)])
        return c[w:] - c[:-w]

    sx, sy, sxx, sxy = sums(xc), sums(y), sums(xc * xc), sums(xc * y)
    slope = (w * sxy - sx * sy) / np.maximum(w * sxx - sx**2, 1e-300)
    intercept = (sy - slope * sx) / w - slope * x0
    return slope, intercept


def _knees(x: np.ndarray, y: np.ndarray, pattern: str) -> tuple[float, ...]:
    """Where the mechanisms of a loading curve ``y(x)`` hand over, by tangent intersections.

    The classic onset construction: straight lines fitted over windows of 1/8 of the rows at
    the start and at the end of the curve and, for ``pattern = "stiff-soft-stiff"`` (bias
    extension), over the window of least slope in between (the plateau); each knee is where
    two neighbouring lines cross. A knee is NaN (its two regions merge) when the stiffer line
    is not at least 1.5 times as steep as the softer one. ``pattern = "soft-stiff"`` (tension)
    has one knee, between the start and end lines.
    """
    order = np.argsort(x, kind="stable")
    x, y = x[order], y[order]
    w = max(5, x.size // 8)
    slope, intercept = _window_lines(x, y, w)
    lines = [(slope[0], intercept[0])]
    if pattern == "stiff-soft-stiff":
        j = int(np.argmin(slope[1:-1])) + 1 if slope.size > 2 else 0
        lines.append((slope[j], intercept[j]))
    lines.append((slope[-1], intercept[-1]))
    knees = []
    for i, ((s1, b1), (s2, b2)) in enumerate(itertools.pairwise(lines)):
        stiff, soft = (s1, s2) if (pattern == "stiff-soft-stiff" and i == 0) else (s2, s1)
        if stiff > 0 and stiff > 1.5 * max(soft, 0.0):
            knees.append(float(np.clip((b1 - b2) / (s2 - s1), x[0], x[-1])))
        else:
            knees.append(math.nan)
    return tuple(knees)


def coupon_regions(test: Test, variable: str, strain: np.ndarray, names: Sequence[str],
                   pattern: str) -> list[Region]:
    """The strain ranges (``names`` in order, by the ``pattern``'s knees) and the phases."""
    phases = _loading_phases(test.time_s, test.displacement_mm)
    regions: list[Region] = []
    loading = phases > 0
    knees = _knees(strain[loading], test.force_N[loading], pattern) \
        if loading.sum() >= 24 else (math.nan,) * (len(names) - 1)
    # A missing knee merges its two regions; the merged region keeps the later name.
    edges, kept = [-math.inf], []
    for name, knee in zip(names, knees):
        if not math.isnan(knee) and knee > edges[-1]:
            kept.append(name)
            edges.append(knee)
    kept.append(names[-1])
    edges.append(math.inf)
    for name, lo, hi in zip(kept, edges[:-1], edges[1:]):
        rows = (strain >= lo) & (strain < hi)
        if rows.any():
            regions.append(Region(variable, (float(strain[rows].min()),
                                             float(strain[rows].max())), name, rows))
    if len(np.unique(phases)) > 1:
        labels = {1: "loading", 0: "hold (relaxation)", -1: "unloading"}
        starts = np.flatnonzero(np.diff(phases, prepend=phases[0] + 1) != 0)
        for start, stop in zip(starts, [*starts[1:], len(phases)]):
            rows = np.zeros(len(phases), bool)
            rows[start:stop] = True
            t = test.time_s[rows]
            regions.append(Region("time_s", (float(t[0]), float(t[-1])),
                                  labels[int(phases[start])], rows))
    return regions


def fit_material(bundle: Bundle, model: Model, *, kind_of: Callable | None = None,
                 tests: Sequence[str] | None = None, parameters: Sequence[str] | None = None,
                 max_iterations: int = 200, from_features: bool = True,
                 progress: Callable[[str], None] | None = None,
                 details: dict | None = None, own: Sequence[str] = ()) -> Model:
    """The coupons' fit (:class:`~fenicsx_drape.diagnosis.kinds.base.FitHook`): the material.

    The coupon tests fix the material (:func:`fenicsx_drape.calibration.fitting.fit`) when some
    of ``parameters`` (all when None) act on them; it picks them by their kind itself
    (``kind_of`` is not needed). A fit from the features has the global
    stage; ``details["coupons"]`` receives the :class:`~fenicsx_drape.calibration.fitting.
    FitResult` (its starts, undetermined parameters, noise) when ``details`` is given.
    ``own`` (a candidate's own parameters) is among ``parameters`` already.
    """
    from fenicsx_drape.calibration.coupons import COUPON_KINDS
    from fenicsx_drape.calibration.fitting import fit

    if parameters is not None and not set(parameters) & set(
            model.active_parameters(COUPON_KINDS)):
        return model
    result = fit(bundle, model, tests=tests, parameters=parameters,
                 initial_guess_from_features=from_features, max_iterations=max_iterations,
                 progress=progress, analyse=False)
    if details is not None:
        details["coupons"] = result
    return result.model


def role_parameters(model: Model, role: str) -> tuple[str, ...]:
    """The active parameters of the law of ``role`` and of the effects acting on it."""
    from fenicsx_drape.effects import describe_effect

    laws = model.law_classes()
    names = list(laws[role].active_parameters(model.effects)) if role in laws else []
    for name in model.effects:
        effect = describe_effect(name)
        if effect.acts_on == role:
            names += effect.parameters
    active = model.active_parameters()
    return tuple(n for n in dict.fromkeys(names) if n in active)


def coupon_parameters(model: Model, kind: str) -> tuple[str, ...]:
    """The parameters coupon tests of ``kind`` fix: those of the law they load and its effects.

    A kind that loads no one law (not in :data:`~fenicsx_drape.calibration.coupons.
    BLOCK_ROLE`) fixes every active parameter.
    """
    from fenicsx_drape.calibration.coupons import BLOCK_ROLE

    if kind not in BLOCK_ROLE:
        return model.active_parameters()
    return role_parameters(model, BLOCK_ROLE[kind])


def plot_curves(comparisons: Mapping[str, Comparison], test: Test, path: Path,
                shares: Sequence[Mapping[str, Any]], abscissa: tuple[str, np.ndarray]) -> Path:
    """Measured against one or more models (top) and their residuals (bottom).

    Args:
        comparisons: The models' comparisons with ``test``, by label (e.g. "baseline").
        test: The test.
        path: The PNG to write.
        shares: Regions of the test (entries of :func:`~fenicsx_drape.diagnosis.comparison.
            locate`) to shade with their share of the first model's error.
        abscissa: What the rows are plotted against (the kind's ``abscissa``).
    """
    import matplotlib.pyplot as plt

    from fenicsx_drape.provenance import save_figure

    first = next(iter(comparisons.values()))
    name, x = abscissa
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 6),
                                      gridspec_kw={"height_ratios": [2, 1]})
    top.plot(x, first.measured, ".", ms=3, color="0.5", label="measured")
    bottom.axhspan(-first.noise, first.noise, color="C2", alpha=0.2, label="± noise")
    for i, (label, c) in enumerate(comparisons.items()):
        top.plot(x, c.simulated, "-", color=f"C{i}",
                 label=f"{label}: RMSE {c.rmse:.3g} {c.unit} = {c.normalised:.2f} × noise")
        bottom.plot(x, c.residual, ".", ms=3, color=f"C{i}", label=label)
    top.set_ylabel(f"value ({first.unit})")
    top.legend(loc="upper left", fontsize=7)
    top.set_title(f"{first.id} ({first.kind.replace('_', ' ')})")
    for i, entry in enumerate(e for e in shares if e["variable"] == name):
        lo, hi = entry["range"]
        bottom.axvspan(lo, hi, color=f"C{i % 10}", alpha=0.08)
        bottom.annotate(f"{entry['says']}\n{100 * entry['share_of_error']:.0f} %",
                        xy=(0.5 * (lo + hi), 1.0), xycoords=("data", "axes fraction"),
                        ha="center", va="top", fontsize=7)
    bottom.set_xlabel(name.replace("_", " "))
    bottom.set_ylabel(f"measured − model ({first.unit})")
    bottom.legend(loc="lower left", fontsize=7)
    return save_figure(fig, path)


class ForceRows:
    """What kinds whose rows are measured forces share: the unit, the values, their sd.

    A kind using it defines ``noise(test) -> (sd_N, source)``.
    """

    def unit(self, test: Test) -> str:
        """Newtons."""
        return "N"

    def measured(self, test: Test) -> np.ndarray:
        """The measured force per row (N)."""
        return np.asarray(test.force_N, dtype=float)

    def value_sd(self, test: Test) -> np.ndarray:
        """Each row's force sd (N): its ``force_sd_N``, else the test's noise."""
        sd = test.column("force_sd_N")
        return np.full(test.n_rows, self.noise(test)[0]) if sd is None else np.asarray(sd)

    def sd_column(self, test: Test) -> str:
        """``force_sd_N``."""
        return "force_sd_N"


@dataclasses.dataclass(frozen=True)
class CouponKind(ForceRows):
    """A coupon kind (:class:`~fenicsx_drape.diagnosis.kinds.base.Kind`): forces per row."""

    name: str  # the bundle's kind of its tests
    # the kinematic strain of a test's rows, from the displacement alone: (variable, values)
    strain: Callable[[Test], tuple[str, np.ndarray]]
    mechanisms: tuple[str, ...]  # the strain ranges' names, in order (section 3.2)
    pattern: str  # the loading curve's shape: "stiff-soft-stiff" or "soft-stiff"
    fit: FitHook = fit_material  # the material, shared by every coupon kind
    formed: bool = False  # a coupon is not a formed part

    @property
    def test_kind(self) -> str:
        """The bundle's kind of its tests: the kind's own name."""
        return self.name

    def holds(self, test: Test) -> bool:
        """Whether ``test`` is of this kind."""
        return test.kind == self.name

    def noise(self, test: Test) -> tuple[float, str]:
        """The force noise (N) and its source (:func:`coupon_noise`)."""
        return coupon_noise(test)

    def simulate(self, test: Test, model: Model) -> np.ndarray:
        """The force per row (N) by the unit-cell solutions (:func:`coupon_simulate`)."""
        return coupon_simulate(test, model)

    def regions(self, test: Test) -> list[Region]:
        """The mechanisms' strain ranges and the loading phases (module doc)."""
        variable, strain = self.strain(test)
        return coupon_regions(test, variable, strain, self.mechanisms, self.pattern)

    def abscissa(self, test: Test) -> tuple[str, np.ndarray]:
        """The kinematic strain of the rows."""
        return self.strain(test)

    def metrics(self, test: Test, simulated: np.ndarray, model: Model | None = None) -> None:
        """None: a coupon has no measures beyond its error."""
        return None

    def plot(self, comparisons: Mapping[str, Comparison], test: Test, path: Path,
             shares: Sequence[Mapping[str, Any]] = ()) -> Path:
        """The force curves and residuals against the strain (:func:`plot_curves`)."""
        return plot_curves(comparisons, test, path, shares, self.abscissa(test))

    def check(self, test: Test, case: FormingCase) -> None:
        """None: a coupon names no case to be checked against."""
        return None
