"""What a test kind is: how it is measured, simulated, fitted and judged, and a comparison.

``compare`` and ``diagnose`` call a test's :class:`Kind` hooks; the kinds they know are the
table :data:`~fenicsx_drape.diagnosis.compare.KINDS` (the coupons' and the forming kind's).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model


@dataclasses.dataclass(frozen=True)
class Region:
    """A range of one variable over the rows of one test."""

    variable: str  # e.g. "diagonal_strain", "time_s"
    range: tuple[float, float]  # (low, high) of the variable over the region's rows
    says: str  # what the region is physically, e.g. "lock-up"
    rows: np.ndarray  # boolean mask over the test's rows


class FitHook(Protocol):
    """A kind's fit: the model with the parameters its tests determine fitted to them."""

    def __call__(self, bundle: Bundle, model: Model, *, tests: Sequence[str] | None,
                 parameters: Sequence[str] | None, max_iterations: int, from_features: bool,
                 progress: Callable[[str], None] | None) -> Model:
        """Fit ``model`` to the tests of this kind in ``bundle`` (only ``tests`` if given).

        Args:
            bundle: The measurements (tests of other kinds are ignored).
            model: The model, with what earlier kinds fitted.
            tests: Only these test ids; all tests of the kind when None.
            parameters: Only these parameters, when the kind fits any of them.
            max_iterations: Cap on the optimiser's iterations.
            from_features: Start from curve features rather than the model's values.
            progress: Called with a line of text as the fit proceeds.
        """
        ...


@dataclasses.dataclass(frozen=True)
class Kind:
    """How one test kind is compared: what is measured, its noise, how it is simulated."""

    # unit of the compared quantity ("N" for coupons, "mm" for forming), or per test
    # (a callable of the test: a forming test's shear points are in degrees, its force in N)
    unit: str | Callable[[Test], str]
    measured: Callable[[Test], np.ndarray]  # the measured values, one per row
    noise: Callable[[Test], tuple[float, str]]  # (noise in ``unit``, source)
    simulate: Callable[[Test, Model], np.ndarray]  # the model's values, one per row
    regions: Callable[[Test], list[Region]]  # physically meaningful regions of the rows
    abscissa: Callable[[Test], tuple[str, np.ndarray]]  # (name, values) to plot against
    # the per-row standard deviation column ("force_sd_N", "position_sd_mm"), or per test
    sd_column: str | Callable[[Test], str]
    # Optional: fitting the parameters the kind's tests determine (kinds sharing one fit run
    # it once; the kinds' fits run in the table's order, so forming fits after the coupons).
    fit: FitHook | None = None
    # Optional: the kind's own measures of a comparison (test, simulated values, model) and
    # its own picture (as :func:`fenicsx_drape.diagnosis.compare.plot_residuals`).
    metrics: Callable[[Test, np.ndarray, Model], dict[str, Any]] | None = None
    plot: Callable[..., Path] | None = None


def unit_of(kind: Kind, test: Test) -> str:
    """The unit of a test's compared values."""
    return kind.unit(test) if callable(kind.unit) else kind.unit


def sd_column_of(kind: Kind, test: Test) -> str:
    """The per-row standard deviation column of a test."""
    return kind.sd_column(test) if callable(kind.sd_column) else kind.sd_column


@dataclasses.dataclass(frozen=True)
class Comparison:
    """A model against one test."""

    id: str
    kind: str
    unit: str  # of the compared quantity (N for coupons)
    measured: np.ndarray
    simulated: np.ndarray
    noise: float  # one standard deviation of a row's measurement noise, in ``unit``
    noise_source: str  # "force_sd_N" | "second_differences" | ...
    regions: tuple[Region, ...]
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
