"""Inter-ply friction tests (``kind = "interply_friction"``): a ply pulled out, force per row (N).

One ply is pulled between two others (pull-out, two interfaces) or over one (pull-through)
under a normal pressure p; the table gives the pulling force against the pulled ply's
displacement relative to the held plies (measurement spec, version 4). The kind
:data:`INTERPLY_FRICTION`:

- **values**: the measured force ``force_N`` (N), one per row;
- **noise**: ``force_sd_N`` (column), else a noise declared for the test (``force_sd_N`` or
  ``force_sd_rel`` key), else the model-free estimate from second differences of the force
  in time, as the coupons' (:func:`~fenicsx_drape.diagnosis.kinds.coupon.coupon_noise`);
- **simulation** (:func:`simulate`): the model's inter-ply law (:func:`law_of`) along the
  measured history, :func:`fenicsx_drape.calibration.interply.simulate_interply`:
  F = n A τ(s, p, v) with τ = τ₀ + μ p + η_f v, A the overlap (taken constant), n the
  interfaces; the law's μ, η_f and τ₀ are the model's ``mu_ply``, ``eta_f_MPa_s_per_mm``
  and ``tau0_MPa`` (the effect ``interply_friction``'s parameters), its regularisation slip
  ε its default. The ply angles (``ply_angles_deg``) do not enter: the law has none;
- **residual**: measured minus model, per row, over the noise (the coupons' measure);
- **regions**: the onset (the force rising to its sliding level: the interface sticking,
  then the tack and Coulomb friction built up over ε) and the sliding plateau, and the
  loading phases when the pull stops or returns (hold, unloading);
- **fit** (:func:`fit_interply_tests`): ``mu_ply``, ``eta_f_MPa_s_per_mm`` and ``tau0_MPa``
  by :func:`fenicsx_drape.calibration.interply.fit_interply` (what ``drape fit`` fits),
  each row weighed by its noise; the forming tests' fit leaves them to these tests;
- **picture**: the force against the displacement, measured and the models', and the
  residuals (:func:`~fenicsx_drape.diagnosis.kinds.coupon.plot_curves`);
- **data check** (:func:`table_problems`): the required columns, finite numbers, time
  increasing row by row, a pressure ≥ 0 and an overlap > 0, each problem naming the file,
  its row and column (the bundle reader refuses the same in the file itself, with its line).

**A bonded model** (one without ``interply_friction``) cannot slide: its interface is the
law's bonded limit τ = k_b s, the penalty bond (``bond_MPa_per_mm``) that holds a bonded
stack's plies together in a forming run. Its force is the force it takes to impose the
measured displacement on an interface that does not slide: growing in proportion to the
displacement and, at the bond's stiffness, orders of magnitude above any friction force
(2 × 5000 mm² × 10⁴ MPa/mm = 10⁸ N per mm of pull-out, against a measured plateau of a few
hundred N). The tests stay comparable (the same simulation as for the forming runs), the
bonded model misses a sliding test by far more than its noise, and ``interply_friction`` added
as a candidate explains it: that is what ``drape diagnose`` names. The size of the bonded
model's error is the penalty's, not a material's: it says "cannot slide", not by how much.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds.base import FitHook, Region
from fenicsx_drape.diagnosis.kinds.coupon import (
    ForceRows,
    _loading_phases,
    coupon_noise,
    plot_curves,
)
from fenicsx_drape.errors import InputFileError
from fenicsx_drape.forming.case.spec import MODEL_INTERPLY

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds.base import Comparison, Kind
    from fenicsx_drape.forming.case import FormingCase
    from fenicsx_drape.materials.interply import InterplyLaw
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

NAME = "interply_friction"
REQUIRED = ("time_s", "displacement_mm", "force_N")  # the spec's columns
ONSET_SHARE = 0.9  # the onset ends where the force first reaches this share of its plateau


def interply_parameters(model: Model) -> tuple[str, ...]:
    """The inter-ply parameters the model has and fits (with ``interply_friction`` only)."""
    active = model.active_parameters()
    return tuple(n for n in MODEL_INTERPLY if n in active)


def law_of(model: Model, index: int | None = None) -> InterplyLaw:
    """The model's inter-ply law: sliding at its μ, η_f, τ₀ with the effect, else bonded.

    ``index``: the parameter set of a vectorised model.
    """
    from fenicsx_drape.materials.interply import InterplyLaw

    if NAME not in model.effects:
        return InterplyLaw(interply_friction=False)

    def value(name: str) -> float:
        v = np.asarray(model.parameters[name], dtype=float)
        return float(v if v.ndim == 0 or index is None else v[index])

    return InterplyLaw(interply_friction=True, **{n: value(n) for n in MODEL_INTERPLY})


def table_problems(test: Test) -> list[str]:
    """What makes an inter-ply friction table unusable, each naming its file, row and column.

    The required columns, finite numbers, time increasing row by row, a pressure (key or
    column) ≥ 0 and an overlap (``contact_length_mm`` × ``contact_width_mm``) > 0.
    """
    at = f"{test.file or '(no file)'}: test {test.id!r}"
    missing = [c for c in REQUIRED if test.column(c) is None]
    if missing:
        return [f"{at}: missing column(s) {', '.join(missing)} (an interply_friction table "
                f"needs {', '.join(REQUIRED)})"]
    out = []
    for name in (*REQUIRED, "force_sd_N", "pressure_kPa"):
        values = test.column(name)
        if values is None:
            continue
        bad = np.flatnonzero(~np.isfinite(np.asarray(values, dtype=float)))
        if bad.size:
            value = float(values[bad[0]])
            out.append(f"{at}: row {bad[0] + 1}, column {name}: {value!r} is not a finite "
                       f"number ({bad.size} such row(s))")
    if out:
        return out
    back = np.flatnonzero(np.diff(test.time_s) <= 0)
    if back.size:
        r = int(back[0]) + 1
        out.append(f"{at}: row {r + 1}, column time_s: time must increase row by row "
                   f"({test.time_s[r - 1]:g} then {test.time_s[r]:g})")
    pressure = test.column("pressure_kPa")
    if pressure is not None and (neg := np.flatnonzero(np.asarray(pressure) < 0)).size:
        out.append(f"{at}: row {neg[0] + 1}, column pressure_kPa: {pressure[neg[0]]:g} kPa < 0")
    setup = test.interply
    if not setup.get("pressure_kPa", 0.0) >= 0:
        out.append(f"{at}: pressure_kPa = {setup['pressure_kPa']:g} must be >= 0")
    if not (setup.get("contact_length_mm", 0.0) > 0 and setup.get("contact_width_mm", 0.0) > 0):
        out.append(f"{at}: the overlap contact_length_mm × contact_width_mm must be > 0")
    return out


def checked(test: Test) -> Test:
    """``test`` when its table is usable (:func:`table_problems`).

    Raises:
        InputFileError: naming each problem (a DrapeInputError: exit status 2).
    """
    problems = table_problems(test)
    if problems:
        raise InputFileError(problems)
    return test


def simulate(test: Test, model: Model) -> np.ndarray:
    """The pulling force (N) of each row by the model's law (``(k, n)`` for k parameter sets)."""
    from fenicsx_drape.calibration.interply import simulate_interply

    checked(test)
    k = model.n_sets
    if k is None:
        return simulate_interply(test, law_of(model))
    if NAME not in model.effects:  # bonded: no parameter of the law varies
        return np.tile(simulate_interply(test, law_of(model)), (k, 1))
    return np.stack([simulate_interply(test, law_of(model, i)) for i in range(k)])


def sliding_rows(test: Test) -> np.ndarray:
    """The rows past the onset (the sliding plateau).

    From the first row whose force reaches :data:`ONSET_SHARE` of the plateau (the median
    force of the second half of the loading rows) on.
    """
    force = np.abs(test.force_N)
    loading = np.flatnonzero(_loading_phases(test.time_s, test.displacement_mm) > 0)
    rows = loading if loading.size >= 4 else np.arange(force.size)
    plateau = float(np.median(force[rows[rows.size // 2:]]))
    reached = np.flatnonzero(force >= ONSET_SHARE * plateau)
    first = int(reached[0]) if reached.size and plateau > 0 else force.size
    return np.arange(force.size) >= first


def fit_interply_tests(bundle: Bundle, model: Model, *,
                       kind_of: Callable[[Test], Kind | None],
                       tests: Sequence[str] | None = None,
                       parameters: Sequence[str] | None = None, max_iterations: int = 200,
                       from_features: bool = True,
                       progress: Callable[[str], None] | None = None,
                       details: dict | None = None, own: Sequence[str] = ()) -> Model:
    """The kind's fit hook (:class:`~fenicsx_drape.diagnosis.kinds.base.FitHook`).

    ``mu_ply``, ``eta_f_MPa_s_per_mm`` and ``tau0_MPa`` (those of ``parameters`` the model
    has, none when it has no ``interply_friction``) fitted to the kind's tests by
    :func:`~fenicsx_drape.calibration.interply.fit_interply`, from the model's values, each
    row weighed with its sd (a held-out row's is infinite), in at most ``max_iterations``
    residual evaluations. What the tests cannot tell apart is held (τ₀ with one pressure, η_f
    with one speed). ``details["interply"]`` receives the fit. ``from_features`` and ``own``
    do not concern it (its parameters are all its own, fitted from the model's values).
    """
    from fenicsx_drape.calibration.interply import fit_interply

    chosen = [t for t in bundle.tests if kind_of(t) is INTERPLY_FRICTION
              and (tests is None or t.id in tests)]
    names = [n for n in interply_parameters(model) if parameters is None or n in parameters]
    if not chosen or not names:
        return model
    result = fit_interply([checked(t) for t in chosen], law_of(model), parameters=names,
                          noise=[INTERPLY_FRICTION.value_sd(t) for t in chosen],
                          max_evaluations=max_iterations)
    if details is not None:
        details["interply"] = result
    if progress is not None:
        progress("  inter-ply fit: " + ", ".join(
            f"{n} {getattr(result.law, n):.4g}" for n in names if n not in result.held)
            + f"; normalised error {result.normalised:.3g}")
    return model.with_parameters(**{n: float(getattr(result.law, n)) for n in names})


@dataclasses.dataclass(frozen=True)
class InterplyFrictionKind(ForceRows):
    """Inter-ply friction tests (:class:`~fenicsx_drape.diagnosis.kinds.base.Kind`)."""

    name: str = NAME
    test_kind: str = NAME
    formed: bool = False  # a pull-out is not a formed part
    fit: FitHook = fit_interply_tests

    def holds(self, test: Test) -> bool:
        """Whether ``test`` is an inter-ply friction test."""
        return test.kind == NAME

    def noise(self, test: Test) -> tuple[float, str]:
        """The force noise (N) and its source, as a coupon's (module doc)."""
        return coupon_noise(checked(test))

    def simulate(self, test: Test, model: Model) -> np.ndarray:
        """The pulling force per row (N) by the model's inter-ply law (:func:`simulate`)."""
        return simulate(test, model)

    def regions(self, test: Test) -> list[Region]:
        """The onset and the sliding plateau over the displacement, and the loading phases."""
        d = np.asarray(test.displacement_mm, dtype=float)
        slide = sliding_rows(test)
        out = []
        for rows, says in ((~slide, "onset (sticking, friction building up)"),
                           (slide, "sliding (friction plateau)")):
            if rows.any():
                out.append(Region("displacement_mm", (float(d[rows].min()),
                                                      float(d[rows].max())), says, rows))
        phases = _loading_phases(test.time_s, d)
        if len(np.unique(phases)) > 1:
            labels = {1: "loading", 0: "hold (relaxation)", -1: "unloading"}
            starts = np.flatnonzero(np.diff(phases, prepend=phases[0] + 1) != 0)
            for start, stop in zip(starts, [*starts[1:], len(phases)]):
                rows = np.zeros(len(phases), bool)
                rows[start:stop] = True
                t = test.time_s[rows]
                out.append(Region("time_s", (float(t[0]), float(t[-1])),
                                  labels[int(phases[start])], rows))
        return out

    def abscissa(self, test: Test) -> tuple[str, np.ndarray]:
        """The pulled ply's displacement (mm)."""
        return "displacement_mm", np.asarray(test.displacement_mm, dtype=float)

    def metrics(self, test: Test, simulated: np.ndarray, model: Model | None = None
                ) -> dict[str, Any]:
        """The mean shear stress on the interfaces while sliding (MPa), measured and model's.

        τ = F / (n A) over the sliding rows (:func:`sliding_rows`; all rows when none).
        """
        setup = test.interply
        area = setup["interfaces"] * setup["contact_length_mm"] * setup["contact_width_mm"]
        rows = sliding_rows(test)
        rows = rows if rows.any() else np.ones(test.n_rows, bool)
        return {"sliding_shear_stress_MPa": float(np.mean(test.force_N[rows]) / area),
                "model_sliding_shear_stress_MPa": float(np.mean(
                    np.asarray(simulated, dtype=float)[..., rows]) / area)}

    def plot(self, comparisons: Mapping[str, Comparison], test: Test, path: Path,
             shares: Sequence[Mapping[str, Any]] = ()) -> Path:
        """The force against the displacement, measured and the models', and the residuals."""
        return plot_curves(comparisons, test, path, shares, self.abscissa(test))

    def check(self, test: Test, case: FormingCase) -> None:
        """None: a pull-out names no case (its table is checked by :func:`table_problems`)."""
        return None


INTERPLY_FRICTION = InterplyFrictionKind()
