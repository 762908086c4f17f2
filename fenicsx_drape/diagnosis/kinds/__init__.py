"""The measurement kinds ``compare`` and ``diagnose`` know: one module each, one table.

A kind (:class:`~fenicsx_drape.diagnosis.kinds.base.Kind`) says, for its tests, what is
measured, its noise, how the model simulates it, the regions of its values, its fit hook,
its picture and its data check. Each lives in its own module:

- coupons (forces per row, the material fitted): :mod:`~fenicsx_drape.diagnosis.kinds.tensile`,
  :mod:`~fenicsx_drape.diagnosis.kinds.bias_extension`,
  :mod:`~fenicsx_drape.diagnosis.kinds.picture_frame` (what they share:
  :mod:`~fenicsx_drape.diagnosis.kinds.coupon`);
- inter-ply friction tests (forces per row, the inter-ply law fitted):
  :mod:`~fenicsx_drape.diagnosis.kinds.interply_friction`;
- formed parts (the friction coefficients fitted): the drawn grid,
  :mod:`~fenicsx_drape.diagnosis.kinds.grid`, and what labs measure,
  :mod:`~fenicsx_drape.diagnosis.kinds.shear_points`,
  :mod:`~fenicsx_drape.diagnosis.kinds.surface`, :mod:`~fenicsx_drape.diagnosis.kinds.outline`,
  :mod:`~fenicsx_drape.diagnosis.kinds.punch_force` (what they share:
  :mod:`~fenicsx_drape.diagnosis.kinds.forming`, :mod:`~fenicsx_drape.diagnosis.kinds.lab`,
  the part's regions :mod:`~fenicsx_drape.diagnosis.kinds.part` and the data checks
  :mod:`~fenicsx_drape.diagnosis.kinds.checks`).

:data:`KINDS` is the table, in the order the kinds' fits run (the coupons fix the material
and the inter-ply friction tests the inter-ply law before the forming tests fit the friction
coefficients with them held); nothing registers
itself on import. Adding a kind is adding its module and its line here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fenicsx_drape.diagnosis.kinds.base import Comparison, FitHook, FormedKind, Kind, Region
from fenicsx_drape.diagnosis.kinds.bias_extension import BIAS_EXTENSION
from fenicsx_drape.diagnosis.kinds.grid import GRID
from fenicsx_drape.diagnosis.kinds.interply_friction import INTERPLY_FRICTION
from fenicsx_drape.diagnosis.kinds.outline import OUTLINE
from fenicsx_drape.diagnosis.kinds.picture_frame import PICTURE_FRAME
from fenicsx_drape.diagnosis.kinds.punch_force import PUNCH_FORCE
from fenicsx_drape.diagnosis.kinds.shear_points import SHEAR_POINTS
from fenicsx_drape.diagnosis.kinds.surface import SURFACE
from fenicsx_drape.diagnosis.kinds.tensile import TENSILE

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Test

__all__ = [
    "BIAS_EXTENSION",
    "GRID",
    "INTERPLY_FRICTION",
    "KINDS",
    "OUTLINE",
    "PICTURE_FRAME",
    "PUNCH_FORCE",
    "SHEAR_POINTS",
    "SURFACE",
    "TENSILE",
    "TEST_KINDS",
    "Comparison",
    "FitHook",
    "FormedKind",
    "Kind",
    "Region",
    "comparable",
    "find_kind",
    "is_formed",
    "kind_of",
    "row_sd",
]

KINDS: tuple[Kind, ...] = (TENSILE, BIAS_EXTENSION, PICTURE_FRAME, INTERPLY_FRICTION,
                           GRID, SHEAR_POINTS, SURFACE, OUTLINE, PUNCH_FORCE)
# The bundle's kinds of the tests the kinds compare ("tensile", ..., "forming").
TEST_KINDS: tuple[str, ...] = tuple(dict.fromkeys(k.test_kind for k in KINDS))


def find_kind(test: Test) -> Kind | None:
    """The kind of ``test`` (None: no kind compares it)."""
    return next((kind for kind in KINDS if kind.holds(test)), None)


def kind_of(test: Test) -> Kind:
    """The kind of ``test``.

    Raises:
        KeyError: no kind compares it (:func:`comparable` is false).
    """
    kind = find_kind(test)
    if kind is None:
        raise KeyError(f"test {test.id!r}: no kind compares {test.kind} tests")
    return kind


def comparable(test: Test) -> bool:
    """Whether a kind compares ``test``."""
    return find_kind(test) is not None


def is_formed(test: Test) -> bool:
    """Whether ``test`` is a measurement of a formed part (a forming kind's)."""
    kind = find_kind(test)
    return kind is not None and kind.formed


def row_sd(test: Test):
    """Each row's sd: its kind's sd column, else the test's noise at every row."""
    import numpy as np

    kind = kind_of(test)
    sd = test.column(kind.sd_column(test))
    return np.full(test.n_rows, kind.noise(test)[0]) if sd is None else sd
