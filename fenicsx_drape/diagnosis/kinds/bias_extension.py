"""Bias-extension tests (``kind = "bias_extension"``): a ±45° strip pulled, force per row (N).

The rows' kinematic strain is the diagonal strain of the gauge region (eq. 21); the loading
curve is stiff, soft, stiff: the tows bend, the crossovers slide on a friction plateau, then
the shear locks up (section 3.2). Simulated, weighed, fitted and pictured as every coupon
(:mod:`~fenicsx_drape.diagnosis.kinds.coupon`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.diagnosis.kinds.coupon import CouponKind

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Test


def strain(test: Test) -> tuple[str, np.ndarray]:
    """The diagonal strain of the gauge region: ``("diagonal_strain", values)``, eq. 21."""
    from fenicsx_drape.unitcell import bias_diagonal_strain

    return "diagonal_strain", np.asarray(
        bias_diagonal_strain(test.displacement_mm, test.length_mm, test.width_mm))


BIAS_EXTENSION = CouponKind("bias_extension", strain,
                            ("initial tow bending", "friction plateau", "lock-up"),
                            "stiff-soft-stiff")
