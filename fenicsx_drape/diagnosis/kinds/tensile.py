"""Tensile tests (``kind = "tensile"``): the tows pulled along their axis, force per row (N).

The rows' kinematic strain is the Green-Lagrange strain of the loaded tows, ``e + e²/2`` with
``e = displacement / gauge length`` (eq. 13); the loading curve is soft, then stiff: the tows
decrimp, then stretch (section 3.2). Simulated, weighed, fitted and pictured as every coupon
(:mod:`~fenicsx_drape.diagnosis.kinds.coupon`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.diagnosis.kinds.coupon import CouponKind

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Test


def strain(test: Test) -> tuple[str, np.ndarray]:
    """The tow strain of the rows: ``("tow_strain", e + e²/2)``, eq. 13."""
    e = test.displacement_mm / test.gauge_length_mm
    return "tow_strain", e + 0.5 * e**2


TENSILE = CouponKind("tensile", strain, ("decrimping", "tow stretching"), "soft-stiff")
