"""The registry of test kinds: how a kind of test is measured, simulated, fitted and judged.

``compare`` and ``diagnose`` know no test kind by name: they look each test's kind up in
:data:`KINDS` and call its hooks. A kind registers itself with :func:`register_kind` when its
module is imported; :mod:`fenicsx_drape.diagnosis` imports the built-in ones (coupons first,
then forming), so importing anything of the diagnosis package makes them comparable.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
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
    # it once; the kinds' fits run in registration order, so forming fits after the coupons).
    fit: FitHook | None = None
    # Optional: the kind's own measures of a comparison (test, simulated values, model) and
    # its own picture (as :func:`fenicsx_drape.diagnosis.compare.plot_residuals`).
    metrics: Callable[[Test, np.ndarray, Model], dict[str, Any]] | None = None
    plot: Callable[..., Path] | None = None


KINDS: dict[str, Kind] = {}


def unit_of(kind: Kind, test: Test) -> str:
    """The unit of a test's compared values."""
    return kind.unit(test) if callable(kind.unit) else kind.unit


def sd_column_of(kind: Kind, test: Test) -> str:
    """The per-row standard deviation column of a test."""
    return kind.sd_column(test) if callable(kind.sd_column) else kind.sd_column


def register_kind(name: str, kind: Kind) -> None:
    """Make tests of kind ``name`` comparable (and diagnosable)."""
    KINDS[name] = kind
