"""What a measurement kind is (:class:`Kind`), a region of its values, and a comparison.

``compare`` and ``diagnose`` ask a test's kind (:func:`~fenicsx_drape.diagnosis.kinds.kind_of`)
how it is measured, simulated, fitted, located, pictured and checked; the kinds they know are
:data:`~fenicsx_drape.diagnosis.kinds.KINDS`, one module each.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from fenicsx_drape.forming.case import FormingCase
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model


@dataclasses.dataclass(frozen=True)
class Region:
    """A range of one variable over the rows of one test."""

    variable: str  # e.g. "diagonal_strain", "time_s"
    range: tuple[float, float]  # (low, high) of the variable over the region's rows
    says: str  # what the region is physically, e.g. "lock-up"
    rows: np.ndarray  # boolean mask over the test's compared values


class FitHook(Protocol):
    """A kind's fit: the model with the parameters its tests determine fitted to them."""

    def __call__(self, bundle: Bundle, model: Model, *, kind_of: Callable[[Test], Kind | None],
                 tests: Sequence[str] | None, parameters: Sequence[str] | None,
                 max_iterations: int, from_features: bool,
                 progress: Callable[[str], None] | None, details: dict | None,
                 own: Sequence[str] = ()) -> Model:
        """Fit ``model`` to the tests of this kind in ``bundle`` (only ``tests`` if given).

        Args:
            bundle: The measurements (tests of other kinds are ignored).
            model: The model, with what earlier kinds fitted.
            kind_of: Each test's kind (:func:`~fenicsx_drape.diagnosis.kinds.kind_of`; None:
                no kind compares it).
            tests: Only these test ids; all tests of the kind when None.
            parameters: Only these parameters, when the kind fits any of them.
            max_iterations: Cap on the optimiser's iterations.
            from_features: Start from curve features rather than the model's values.
            progress: Called with a line of text as the fit proceeds.
            details: Filled with what the fit found, when it reports anything (the coupons:
                ``details["coupons"]``, the fit's result).
            own: A candidate's own parameters (in its refit): a kind whose tests are all
                that can move them fits them too (the forming kinds, when no coupon test
                fixes them).
        """
        ...


class Kind(Protocol):
    """A measurement kind: what its tests measure, and how a model is set against them.

    One object per kind, each in its own module of :mod:`fenicsx_drape.diagnosis.kinds` with
    its noise, simulation, regions, fit hook, picture and data check, listed once in
    :data:`~fenicsx_drape.diagnosis.kinds.KINDS`.
    """

    name: str  # the kind: a coupon's bundle kind, "grid", or a lab measurement's name
    test_kind: str  # the bundle's kind of its tests ("tensile", ..., "forming")
    formed: bool  # its tests are formed parts (set-up stage, resolution, data check)
    # Fits the parameters its tests determine; kinds sharing one fit run it once, in the
    # order of KINDS (the forming tests fit their friction after the coupons' material).
    fit: FitHook

    def holds(self, test: Test) -> bool:
        """Whether ``test`` is of this kind."""
        ...

    def unit(self, test: Test) -> str:
        """The unit of the compared values ("N", "mm", "deg")."""
        ...

    def measured(self, test: Test) -> np.ndarray:
        """The measured values: one or more per row, flattened."""
        ...

    def noise(self, test: Test) -> tuple[float, str]:
        """One standard deviation of a value's noise (in :meth:`unit`) and its source."""
        ...

    def value_sd(self, test: Test) -> np.ndarray:
        """Per compared value, the noise a fit weighs it with (``inf``: not fitted)."""
        ...

    def sd_column(self, test: Test) -> str:
        """The column of each row's standard deviation ("force_sd_N", "position_sd_mm")."""
        ...

    def simulate(self, test: Test, model: Model) -> np.ndarray:
        """The model's values, as :meth:`measured` (``(k, n)`` for a vectorised model)."""
        ...

    def regions(self, test: Test) -> list[Region]:
        """The physically meaningful regions of the compared values."""
        ...

    def abscissa(self, test: Test) -> tuple[str, np.ndarray]:
        """What the values are plotted against: ``(name, values)``."""
        ...

    def metrics(self, test: Test, simulated: np.ndarray, model: Model | None = None
                ) -> dict[str, Any] | None:
        """The kind's own measures of a comparison (None: it has none)."""
        ...

    def plot(self, comparisons: Mapping[str, Comparison], test: Test, path: Path,
             shares: Sequence[Mapping[str, Any]] = ()) -> Path:
        """The kind's picture of one or more models (by label) against ``test``."""
        ...

    def check(self, test: Test, case: FormingCase) -> tuple[bool, str] | None:
        """The data check against the test's case: ``(suspect, why)``; None when fine."""
        ...


class FormedKind(Kind, Protocol):
    """A kind measured on a formed part: its values are read off one formed sheet."""

    mirrorable: bool  # can be read from the run of its mirror image (a symmetric case)

    def on_sheet(self, test: Test, sheet: FormedGrid, model: Model,
                 plane: str | None = None) -> np.ndarray:
        """The model's values on one formed sheet.

        ``plane``: the sheet is the run of the mirror image in that symmetry plane ("x" or
        "y"), read at the image and mirrored back (:attr:`mirrorable` kinds only).
        """
        ...


@dataclasses.dataclass(frozen=True)
class Comparison:
    """A model against one test."""

    id: str  # the test's id
    kind: str  # the bundle's kind of the test ("tensile", ..., "forming")
    unit: str  # of the compared quantity (N for coupons)
    measured: np.ndarray  # the measured values, in ``unit``
    simulated: np.ndarray  # the model's values, in ``unit``
    noise: float  # one standard deviation of a row's measurement noise, in ``unit``
    noise_source: str  # "force_sd_N" | "second_differences" | ...
    regions: tuple[Region, ...]  # the regions of the values (the kind's)
    conditions: Mapping[str, float]  # the conditions that may vary across tests

    @property
    def residual(self) -> np.ndarray:
        """Measured minus simulated, per row."""
        return self.measured - self.simulated

    @property
    def rmse(self) -> float:
        """RMS error over the rows, in ``unit``."""
        return float(np.sqrt(np.mean(self.residual**2)))

    @property
    def mean_abs(self) -> float:
        """Mean absolute error (the paper's measure, section 3.2), in ``unit``."""
        return float(np.mean(np.abs(self.residual)))

    @property
    def percent(self) -> float:
        """Mean absolute error in % of the mean absolute measured value (the paper's 7-9 %)."""
        scale = float(np.mean(np.abs(self.measured)))
        return 100.0 * self.mean_abs / scale if scale > 0 else math.nan

    @property
    def normalised(self) -> float:
        """RMSE over noise: 1.0 is the noise floor."""
        return self.rmse / self.noise
