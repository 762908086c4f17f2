"""Synthetic measurement bundles: the project's own forward model plus stated noise.

:func:`synthetic_bundle` runs the unit-cell solutions of any :class:`~fenicsx_drape.model.Model`
over given test definitions (any displacement history: ramps, holds, unloading; any
conditions such as ``temperature_C``) and adds Gaussian noise of a stated standard deviation,
written as the ``force_sd_N`` column. :func:`standard_tests` gives the paper's test programme
(section 3.1): a tensile test at 2 mm/min on a 100 mm gauge, 25 mm wide specimen, and bias
extension at 10, 40 and 160 mm/min on 210 × 70 mm specimens.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fenicsx_drape.calibration.coupons import simulate
from fenicsx_drape.measurements.bundle import Bundle, Test, derived_tows, write_bundle

# The paper's material (Table 1): 7.1 tows/cm.
PAPER_TOWS_PER_MM = 0.71


def ramp(speed_mm_per_min: float, max_displacement_mm: float, n_rows: int,
         holds: Sequence[tuple[float, float]] = ()) -> tuple[np.ndarray, np.ndarray]:
    """A constant-speed crosshead history, optionally with holds.

    Args:
        speed_mm_per_min: Crosshead speed while moving (mm/min).
        max_displacement_mm: Final displacement (mm).
        n_rows: Number of rows over the whole history.
        holds: ``(displacement_mm, duration_s)`` pairs: the crosshead stops at that
            displacement for that long (a relaxation hold) before moving on.

    Returns:
        ``(time_s, displacement_mm)`` row by row, time strictly increasing from 0.
    """
    v = speed_mm_per_min / 60.0
    knots_d, knots_t = [0.0], [0.0]
    for d, duration in sorted(holds):
        knots_t.append(knots_t[-1] + (d - knots_d[-1]) / v)
        knots_d.append(d)
        knots_t.append(knots_t[-1] + duration)
        knots_d.append(d)
    knots_t.append(knots_t[-1] + (max_displacement_mm - knots_d[-1]) / v)
    knots_d.append(max_displacement_mm)
    # rows at the resolution of a test machine's log: 1 ms, 0.1 µm
    time_s = np.round(np.linspace(0.0, knots_t[-1], n_rows), 3)
    return time_s, np.round(np.interp(time_s, knots_t, knots_d), 4)


def tensile_test(test_id: str = "tensile", *, speed_mm_per_min: float = 2.0,
                 max_displacement_mm: float = 0.2, n_rows: int = 100,
                 gauge_length_mm: float = 100.0, width_mm: float = 25.0,
                 tows_per_mm: float = PAPER_TOWS_PER_MM,
                 conditions: Mapping[str, float] | None = None,
                 holds: Sequence[tuple[float, float]] = ()) -> Test:
    """A tensile test definition (no force yet); defaults as in section 3.1.

    0.2 mm on the 100 mm gauge (tow strain 0.002) puts the paper's mean tensile force, about
    90 N (its 7.1 N error is 7-9 %), past the decrimping transition ε̄ = 0.00144.
    """
    time_s, disp = ramp(speed_mm_per_min, max_displacement_mm, n_rows, holds)
    return Test(id=test_id, kind="tensile", file=f"{test_id}.csv",
                columns={"time_s": time_s, "displacement_mm": disp},
                gauge_length_mm=gauge_length_mm, width_mm=width_mm,
                tows=round(derived_tows("tensile", tows_per_mm, width_mm), 2),
                speed_mm_per_min=speed_mm_per_min, conditions=dict(conditions or {}))


def bias_test(test_id: str, speed_mm_per_min: float, *, max_displacement_mm: float = 50.0,
              n_rows: int = 100, length_mm: float = 210.0, width_mm: float = 70.0,
              tows_per_mm: float = PAPER_TOWS_PER_MM,
              conditions: Mapping[str, float] | None = None,
              holds: Sequence[tuple[float, float]] = ()) -> Test:
    """A bias-extension test definition (no force yet); defaults as in section 3.1.

    50 mm of crosshead travel on the 210 × 70 mm specimen take the gauge-region diagonal to
    a Green-Lagrange strain of 0.42 by eq. 21 (shear angle 56°), into the lock-up of the
    paper's Fig. 6; with Table 2 the force sensitivities then match the paper's Table 2.
    """
    time_s, disp = ramp(speed_mm_per_min, max_displacement_mm, n_rows, holds)
    return Test(id=test_id, kind="bias_extension", file=f"{test_id}.csv",
                columns={"time_s": time_s, "displacement_mm": disp},
                length_mm=length_mm, width_mm=width_mm,
                tows=round(derived_tows("bias_extension", tows_per_mm, width_mm), 2),
                speed_mm_per_min=speed_mm_per_min, conditions=dict(conditions or {}))


def picture_frame_test(test_id: str, speed_mm_per_min: float, *,
                       max_shear_deg: float = 60.0, n_rows: int = 100,
                       frame_side_mm: float = 180.0, fabric_side_mm: float = 140.0,
                       tows_per_mm: float = PAPER_TOWS_PER_MM,
                       conditions: Mapping[str, float] | None = None,
                       holds: Sequence[tuple[float, float]] = ()) -> Test:
    """A picture-frame test definition (no force yet): a ramp to ``max_shear_deg``.

    Defaults: the HKUST frame of Cao et al. (2008), 180 mm frame, 140 mm fabric square.
    """
    from fenicsx_drape.unitcell import picture_frame_displacement

    travel = float(picture_frame_displacement(max_shear_deg, frame_side_mm))
    time_s, disp = ramp(speed_mm_per_min, travel, n_rows, holds)
    return Test(id=test_id, kind="picture_frame", file=f"{test_id}.csv",
                columns={"time_s": time_s, "displacement_mm": disp},
                frame_side_mm=frame_side_mm, fabric_side_mm=fabric_side_mm,
                tows=round(derived_tows("picture_frame", tows_per_mm, fabric_side_mm), 2),
                speed_mm_per_min=speed_mm_per_min, conditions=dict(conditions or {}))


def standard_tests(*, bias_speeds_mm_per_min: Sequence[float] = (10.0, 40.0, 160.0),
                   conditions: Mapping[str, float] | None = None) -> tuple[Test, ...]:
    """The paper's programme: tensile at 2 mm/min, bias extension at the given speeds."""
    tests = [tensile_test("tensile", conditions=conditions)]
    tests += [bias_test(f"bias-{speed:g}", speed, conditions=conditions)
              for speed in bias_speeds_mm_per_min]
    return tuple(tests)


def synthetic_bundle(model, tests: Sequence[Test], *, noise_sd_N: float | Mapping[str, float]
                     | None = None, noise_rel: float | None = None, seed: int = 0,
                     out_dir: str | Path | None = None, name: str = "synthetic",
                     material: str = "synthetic (fenicsx_drape forward model)") -> Bundle:
    """Measurements made by the forward model of ``model`` plus Gaussian noise.

    Args:
        model: The :class:`~fenicsx_drape.model.Model` to simulate (any effects, plugins).
        tests: Test definitions (tensile or bias extension) holding at least the columns
            ``time_s`` and ``displacement_mm`` (see :func:`standard_tests`, :func:`ramp`).
        noise_sd_N: Noise standard deviation in N, one value or one per test id.
        noise_rel: Alternatively, noise as a fraction of each test's peak |force|.
        seed: Seed of the noise generator (the same seed gives the same bundle).
        out_dir: When given, the bundle is also written there.
        name: The bundle's name.
        material: Free text for ``[bundle] material``.

    Returns:
        The bundle, with ``force_N`` (noisy) and ``force_sd_N`` columns added.
    """
    if (noise_sd_N is None) == (noise_rel is None):
        raise ValueError("give exactly one of noise_sd_N (N) and noise_rel (fraction of peak)")
    rng = np.random.default_rng(seed)
    made = []
    for test in tests:
        if test.kind not in ("tensile", "bias_extension", "picture_frame"):
            raise ValueError(f"test {test.id!r}: cannot synthesise a {test.kind} test here")
        force = simulate(test, model)
        if noise_rel is not None:
            sd = noise_rel * float(np.max(np.abs(force)))
        elif isinstance(noise_sd_N, Mapping):
            sd = float(noise_sd_N[test.id])
        else:
            sd = float(noise_sd_N)
        if not (math.isfinite(sd) and sd > 0):
            raise ValueError(f"test {test.id!r}: noise standard deviation {sd} N must be > 0")
        digits = 2 - math.floor(math.log10(sd))  # a hundredth of the noise
        columns = {"time_s": test.time_s, "displacement_mm": test.displacement_mm,
                   "force_N": np.round(force + rng.normal(0.0, sd, force.shape), digits),
                   "force_sd_N": np.full(force.shape, round(sd, digits + 1))}
        made.append(dataclasses.replace(test, columns=columns))
    tows_per_mm = next((t.tows / t.width_mm * (math.sqrt(2) if t.kind == "bias_extension" else 1)
                        for t in made if t.tows and t.width_mm), None)
    tows_per_mm = tows_per_mm or next((t.tows / t.fabric_side_mm for t in made
                                       if t.tows and t.fabric_side_mm), None)
    bundle = Bundle(name=name, material=material, tows_per_mm=tows_per_mm, tests=tuple(made),
                    path=Path(out_dir) if out_dir is not None else None)
    if out_dir is not None:
        write_bundle(bundle, out_dir, comment=f"synthetic bundle {name!r}: forward model of "
                     f"fenicsx_drape, Gaussian noise (force_sd_N), seed {seed}")
    return bundle
