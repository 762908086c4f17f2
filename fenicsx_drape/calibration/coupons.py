"""Coupon tests as least squares sees them: shared by the fit and the sensitivity analysis.

- **forward model** (:func:`simulate`): the unit-cell solutions
  (:mod:`fenicsx_drape.unitcell`) give the force per row of a tensile, bias-extension or
  picture-frame test (the crosshead force of a frame without linkage),
  for one parameter set or, vectorised, for k sets at once;
- **noise** (:func:`test_noise`): the per-row standard deviation a row is weighed with, from
  ``force_sd_N`` or the model-free estimate of :mod:`fenicsx_drape.measurements.noise`;
- **variables** (:class:`Variables`): the logarithm of each positive parameter (others scaled
  linearly), bounded by the physical range and :data:`DECADES` decades around the start;
- **residuals** (:class:`Residuals`): ``(simulated - measured) / σ_row / √n_test`` and their
  forward-difference Jacobian, all perturbed sets in one vectorised call per test.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.measurements.bundle import Bundle, Test
from fenicsx_drape.measurements.noise import (
    FLOOR_RELATIVE,
    implausible,
    noise_from_sd,
    noise_from_second_differences,
)

COUPON_KINDS = ("tensile", "bias_extension", "picture_frame")
# The law role whose parameters each coupon kind identifies (the paper's blocks).
BLOCK_ROLE = {"tensile": "tow", "bias_extension": "shear", "picture_frame": "shear"}
# The geometry of each coupon kind: a test's keys the unit cell takes.
_GEOMETRY = {"tensile": ("gauge_length_mm",), "bias_extension": ("length_mm", "width_mm"),
             "picture_frame": ("frame_side_mm", "fabric_side_mm")}


def law_role(kind: str) -> str:
    """The law a test kind identifies (:data:`BLOCK_ROLE`); other kinds (forming) are their own."""
    return BLOCK_ROLE.get(kind, kind)


# Forward-difference step in the fitting variables (log parameters): 1e-6 relative.
FD_STEP = 1e-6
# Bounds: at most this many decades away from the starting value (within physical bounds).
DECADES = 4.0


# --------------------------------------------------------------------------------------------
# Forward model


def simulate(bundle_or_test: Bundle | Test, model) -> np.ndarray | dict[str, np.ndarray]:
    """Simulated force (N) per row of a coupon test, or a dict of them for a bundle.

    With a model whose parameters are arrays of k values, each test gives an array shaped
    ``(k, n_rows)``.
    """
    if isinstance(bundle_or_test, Bundle):
        tests = bundle_or_test.of_kind(*COUPON_KINDS)
        return {t.id: f for t, f in zip(tests, simulate_tests(tests, model))}
    return simulate_tests([bundle_or_test], model)[0]


def simulate_tests(tests: Sequence[Test], model) -> list[np.ndarray]:
    """:func:`simulate` of each test; the tests of one kind are solved side by side."""
    from fenicsx_drape import unitcell

    for test in tests:
        if test.kind not in COUPON_KINDS:
            raise ValueError(f"test {test.id!r}: a {test.kind} test is not a coupon test")
    forces: list[np.ndarray] = [np.empty(0)] * len(tests)
    for kind in COUPON_KINDS:
        chosen = [i for i, t in enumerate(tests) if t.kind == kind]
        runs = [{"time_s": tests[i].time_s, "displacement_mm": tests[i].displacement_mm,
                 "conditions": tests[i].conditions,
                 **{name: getattr(tests[i], name) for name in _GEOMETRY[kind]}}
                for i in chosen]
        for i, curve in zip(chosen, unitcell.curves(model, kind, runs)):
            # curves are (n_rows,) or (n_rows, k): one row per parameter set
            forces[i] = np.asarray(curve.force_per_tow_N).T * tests[i].tows
    return forces


def test_noise(test: Test) -> tuple[np.ndarray, float, str]:
    """Per-row noise (N), the test's noise (RMS, N) and its source.

    In this order: the ``force_sd_N`` column (the spec); a noise declared for the test
    (bundle.toml ``force_sd_N`` in N or ``force_sd_rel`` of the peak |force|, in the test's
    table or in [bundle]; MODEL.toml [noise], see :func:`declare_noise`), source
    ``"declared"``; the model-free estimate from second differences (the spec), source
    ``"second_differences"``, or -- when that estimate is implausible
    (:func:`~fenicsx_drape.measurements.noise.implausible`: a smoothed or digitised curve) --
    at least :data:`~fenicsx_drape.measurements.noise.FLOOR_RELATIVE` of the peak force,
    source ``"relative_floor"``. :func:`noise_notes` says why, per test.
    """
    if test.force_sd_N is not None:
        return np.asarray(test.force_sd_N), noise_from_sd(test.force_sd_N), "force_sd_N"
    peak = float(np.max(np.abs(test.force_N)))
    if test.noise_sd_N is not None or test.noise_rel is not None:
        level = test.noise_sd_N if test.noise_sd_N is not None else test.noise_rel * peak
        return np.full(test.n_rows, level), float(level), "declared"
    noise = noise_from_second_differences(test.time_s, test.force_N)
    if not noise > 0 and not peak > 0:
        raise DrapeInputError(f"test {test.id!r}: no noise can be estimated from the force "
                              "column (give force_sd_N)")
    if implausible(test.time_s, test.force_N, noise) and noise < FLOOR_RELATIVE * peak:
        level = FLOOR_RELATIVE * peak
        return np.full(test.n_rows, level), level, "relative_floor"
    return np.full(test.n_rows, noise), noise, "second_differences"


def noise_notes(tests: Sequence[Test]) -> dict[str, dict[str, Any]]:
    """Per test: the noise used, its source and, in words, where it came from and why."""
    out = {}
    for test in tests:
        _, level, source = test_noise(test)
        record: dict[str, Any] = {"noise_N": level, "source": source}
        if source == "declared":
            what = (f"force_sd_N = {test.noise_sd_N:g} N" if test.noise_sd_N is not None
                    else f"force_sd_rel = {test.noise_rel:g} of the peak force")
            record["says"] = f"declared in {test.noise_declared_by}: {what}"
        elif source in ("second_differences", "relative_floor"):
            estimate = noise_from_second_differences(test.time_s, test.force_N)
            why = implausible(test.time_s, test.force_N, estimate)
            record["estimate_N"] = estimate
            if why:
                record["implausible"] = why
            record["says"] = (
                f"model-free estimate {estimate:.3g} N from second differences"
                + (f", implausible: {why}" if why else "")
                + (f"; the fit weighs the rows with {100 * FLOOR_RELATIVE:g} % of the peak "
                   f"force ({level:.3g} N) instead: declare the noise (force_sd_N or "
                   "force_sd_rel in bundle.toml, or [noise] in MODEL.toml)"
                   if source == "relative_floor" else ""))
        else:
            record["says"] = "the force_sd_N column of the table"
        out[test.id] = record
    return out


def declare_noise(bundle: Bundle, noise: Mapping[str, float] | None) -> Bundle:
    """``bundle`` with MODEL.toml's [noise] declared on coupon tests that have none."""
    from fenicsx_drape.measurements.bundle import declared_noise

    if not noise:
        return bundle
    tests = tuple(declared_noise(t, noise, "MODEL.toml [noise]")
                  if t.kind in COUPON_KINDS else t for t in bundle.tests)
    return dataclasses.replace(bundle, tests=tests)


# --------------------------------------------------------------------------------------------
# Fitting variables and residuals


@dataclasses.dataclass(frozen=True)
class Variables:
    """Map between parameter values and the optimiser's variables (log or scaled)."""

    names: tuple[str, ...]
    log: np.ndarray  # bool per name: log-transformed
    scale: np.ndarray  # linear scale for the others
    lower: np.ndarray  # bounds in variable space
    upper: np.ndarray

    @classmethod
    def make(cls, model, names: Sequence[str]) -> Variables:
        """The variables of the parameters ``names`` of ``model``, bounded around its values."""
        from fenicsx_drape.model import parameter_info

        p0 = np.array([float(model.parameters[n]) for n in names])
        bounds = np.array([parameter_info(n).bounds for n in names], dtype=float)
        log = (bounds[:, 0] >= 0.0) & (p0 > 0.0)  # a parameter starting at 0 stays linear
        scale = np.where(log | (p0 == 0.0), 1.0, np.abs(p0))
        span = 10.0**DECADES
        lo = np.where(log, np.maximum(bounds[:, 0], p0 / span), bounds[:, 0])
        hi = np.where(log, np.minimum(bounds[:, 1], p0 * span), bounds[:, 1])
        with np.errstate(divide="ignore"):
            lower = np.where(log, np.log(lo), lo / scale)
            upper = np.where(log, np.log(hi), hi / scale)
        return cls(tuple(names), log, scale, lower, upper)

    def to_x(self, p: np.ndarray) -> np.ndarray:
        """Parameter values to variables."""
        return np.where(self.log, np.log(np.maximum(p, 1e-300)), p / self.scale)

    def to_p(self, x: np.ndarray) -> np.ndarray:
        """Variables to parameter values."""
        return np.where(self.log, np.exp(x), x * self.scale)


class Residuals:
    """Weighted residuals of a set of tests as a function of some parameters."""

    def __init__(self, model, tests: Sequence[Test], variables: Variables):
        self.model, self.tests, self.v = model, tuple(tests), variables
        self.weights = []
        for test in self.tests:
            sd, _, _ = test_noise(test)
            self.weights.append(1.0 / (sd * math.sqrt(test.n_rows)))
        self.evaluations = 0

    def model_at(self, P: np.ndarray):
        """The model with parameter sets ``P`` (k × n, or n for a single set)."""
        values = {n: (P[..., j] if P.ndim == 2 else float(P[j]))
                  for j, n in enumerate(self.v.names)}
        return self.model.with_parameters(**values)

    def forces(self, P: np.ndarray) -> list[np.ndarray]:
        """Simulated forces (k × n_rows per test) for parameter sets ``P``."""
        model = self.model_at(P)
        self.evaluations += 1 if P.ndim == 1 else P.shape[0]
        return [np.atleast_2d(f) for f in simulate_tests(self.tests, model)]

    def residuals_sets(self, X: np.ndarray) -> np.ndarray:
        """Residual vectors (k × m) for variable sets ``X`` (k × n)."""
        forces = self.forces(self.v.to_p(X))
        return np.concatenate([(f - t.force_N) * w for f, t, w
                               in zip(forces, self.tests, self.weights)], axis=1)

    def jacobian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residuals at ``x`` and their forward-difference Jacobian (one vectorised call)."""
        h = FD_STEP * np.maximum(1.0, np.abs(x))
        h = np.where(x + h > self.v.upper, -h, h)  # step inwards at an upper bound
        X = np.vstack([x, x + np.diag(h)])
        R = self.residuals_sets(X)
        return R[0], ((R[1:] - R[0]) / h[:, None]).T
