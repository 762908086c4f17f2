"""Picture-frame tests (``kind = "picture_frame"``): a sheet sheared in a hinged frame (N).

The rows' kinematic strain is the diagonal strain sin γ / 2 of the frame's shear angle γ
(:func:`fenicsx_drape.unitcell.picture_frame_shear_angle`); the loading curve has the bias
extension's three mechanisms (section 3.2). Simulated, weighed, fitted and pictured as every
coupon (:mod:`~fenicsx_drape.diagnosis.kinds.coupon`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.diagnosis.kinds.coupon import CouponKind

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Test


def strain(test: Test) -> tuple[str, np.ndarray]:
    """The diagonal strain sin γ / 2 of the frame's shear angle: ``("diagonal_strain", ...)``."""
    from fenicsx_drape.unitcell import picture_frame_shear_angle

    γ = np.radians(picture_frame_shear_angle(test.displacement_mm, test.frame_side_mm))
    return "diagonal_strain", 0.5 * np.sin(γ)


PICTURE_FRAME = CouponKind("picture_frame", strain,
                           ("initial tow bending", "friction plateau", "lock-up"),
                           "stiff-soft-stiff")
