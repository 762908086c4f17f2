r"""Unit-cell solutions of the tensile and bias-extension tests (section 2.2, eqs. 15-23).

**The cell.** Tow bars ``a`` (warp) and ``b`` (weft) of reference length L, diagonals
``d1 = a + b`` and ``d2 = a − b`` of reference length L√2. Their Green-Lagrange strains
satisfy ε_d1,2 = (ε_a + ε_b)/2 ± a·b/(2L²), hence ε_d1 + ε_d2 = ε_a + ε_b: eqs. 15 and 18.

**Bar forces.** As in the paper's eq. 11 (f/n_t = Σ σ r/|r|), the laws' σ (N/tow) is the
axial force per tow of a bar: a bar standing for n_t tows carries n_t σ along its current
direction. (The FE truss uses the same convention: its work-conjugate of ε is n_t σ/λ, see
:mod:`fenicsx_drape.fe.kinematics`; Table 2 was fitted with it.)

**One free-body view for both tests.** Cut the periodic net (every cell owns two tow bars and
two diagonals) across the load and along it; per period of the cut it crosses one tow bar of
each family and two diagonals of one kind. Resolving their forces gives (the same as the
homogenised "virial" stress Σ_bars N (r⊗r)/|r| of a cell):

- *Tension* (Fig. 3b; warp along the load, ε_1 = e + e²/2 known with e = u/L_g, weft ε_2
  unknown, both diagonals ε_d = (ε_1 + ε_2)/2 by eq. 15, no shear by symmetry; the diagonals
  make the angle φ with the load, sin²φ = (1 + 2ε_2)/(2 + 4ε_d)). Zero force across the load
  and the force per loaded tow:

      G(ε_2) + 2 H(ε_d) sin φ = 0,                                             (eq. 16)
      f = G(ε_1) + 2 H(ε_d) cos φ,   cos²φ = (1 + 2ε_1)/(2 + 4ε_d).            (eq. 17)

- *Bias extension* (Fig. 3c; major diagonal along the load with ε_d1 known from eq. 21, both
  tows ε_t unknown, minor diagonal ε_d2 = 2ε_t − ε_d1 by eq. 18; tows at ±θ to the load,
  sin²θ = (1 + 4ε_t − 2ε_d1)/(2 + 4ε_t), cos²θ = (1 + 2ε_d1)/(2 + 4ε_t)):

      H(2ε_t − ε_d1) + G(ε_t) sin θ = 0,                                       (eq. 19)
      f = 2 (G(ε_t) cos θ + τ_1) = 2 (τ_1 − τ_2 cot θ)   per tow of one family. (eq. 20)

Eq. 19 is exactly the printed one. The printed eq. 20, 2σ cos θ + τ_1 (stray ε_i1 dropped), and
the printed eqs. 16-17 (H sin φ + G = 0, f = τ cos φ + G) are node balances of a single,
isolated cell; a single cell's transverse balance in bias would be 2σ sin θ + τ_2 = 0, which
does not pair with the printed eq. 19: the printed equations mix two free bodies (NOTES.md).
Here everything follows from the periodic net. Check (tested): for path-independent laws the
work ∫ f du equals the stored energy per tow, with Φ(ε) = ∫ σ/√(1 + 2ε) dε per bar (σ is the
force, so its work over the length change L dε/λ).

Normalisation: "per tow" is per tow of one family crossing the specimen's width, invariant
under the pin-jointed deformation: l_t W for the tensile specimen (0.713 × 25 = 17.8) and
l_t W/√2 for the bias specimen (0.713 × 70/√2 = 35.3), as the paper divides its forces.

**Kinematics of the bias test** (eqs. 21-23): the crosshead displacement u is taken by the
full-shear region of length L_o − W_o, whose diagonal stretches by 1 + u/(L_o − W_o), so
ε_d = e + e²/2 with e = u/(L_o − W_o). The shear angle (90° minus the angle between tows) is
γ = arcsin((ε_d1 − ε_d2)/(1 + 2ε_t)), i.e. arcsin(2ε_d1) for inextensible tows. The
least-squares line through ε_d(t) at constant speed, taken over time up to the pin-jointed
limit ε_d = 0.5, has slope ε̇_eff = L̇/(L_o − W_o) · (3√2 + 5)/8 (eq. 23).

**Scheme.** Both tests follow the measured history row by row (holds, relaxation and
unloading included); the first row is reached from the virgin state in one step of zero
length. In each step the unknown strain (ε_2 or ε_t) solves the balance above by a bracketed
Newton iteration (the residual is non-decreasing in the unknown; bisection where Newton leaves
the bracket) with the laws' consistent tangents, started from a cubic extrapolation in time;
a row is accepted once the Newton correction is below 1e-10 in strain, the reported forces
corrected to first order in it, and the laws' states are committed (usually after one
update). The two bars of a role are updated in one call (call overhead, not array size, is
the cost). All of it is vectorised over parameter sets: a
:class:`~fenicsx_drape.model.Model` whose parameters are arrays of shape (k,) gives curves
shaped (n_rows, k) at about the cost of one; and over tests of one kind (:func:`curves`:
each test's own rows, geometry and conditions, stepped together), so that a fit's T tests
cost little more than one.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fenicsx_drape.effects import shear_tension_factor
from fenicsx_drape.errors import DrapeInputError, SolverError
from fenicsx_drape.model import Model

__all__ = [
    "EFFECTIVE_RATE_FACTOR",
    "UnitCellCurve",
    "bias_diagonal_strain",
    "bias_extension",
    "bias_extension_shear_force",
    "curves",
    "diagonal_response",
    "effective_strain_rate",
    "picture_frame",
    "picture_frame_displacement",
    "picture_frame_lock_mm",
    "picture_frame_shear_angle",
    "picture_frame_shear_force",
    "tensile",
]

EFFECTIVE_RATE_FACTOR = (3.0 * math.sqrt(2.0) + 5.0) / 8.0
"""The factor of eq. 23, 1.1553."""

_MAX_ITERATIONS = 100


@dataclass(frozen=True)
class UnitCellCurve:
    """The response of a coupon test, row by row.

    Arrays are shaped (n_rows,), or (n_rows, k) for a model with k parameter sets.
    """

    time_s: np.ndarray
    displacement_mm: np.ndarray
    force_per_tow_N: np.ndarray  # test force / number of tows (N/tow)
    tow_strain: np.ndarray  # tensile: loaded tows; bias: both tow families
    diagonal_strain: np.ndarray  # tensile: both diagonals; bias: the major diagonal (eq. 21)
    shear_deg: np.ndarray  # shear angle of the cell (0 in tension)
    transverse_strain: np.ndarray  # tensile: transverse tows ε_2; bias: minor diagonal ε_d2
    tow_stress_N: np.ndarray  # stress of the tows of tow_strain (N/tow)
    diagonal_stress_N: np.ndarray  # stress of the diagonal of diagonal_strain (N/tow)


def bias_diagonal_strain(displacement_mm, length_mm: float, width_mm: float) -> np.ndarray:
    """Green-Lagrange strain of the diagonals in the full-shear region, eq. 21.

    Args:
        displacement_mm: Crosshead displacement u (mm).
        length_mm: Specimen length L_o (mm).
        width_mm: Specimen width W_o (mm), L_o > W_o.
    """
    _check_bias_geometry(length_mm, width_mm)
    e = np.asarray(displacement_mm, dtype=float) / (length_mm - width_mm)
    return e + 0.5 * e**2


def effective_strain_rate(speed_mm_per_min: float, length_mm: float, width_mm: float) -> float:
    """Effective constant diagonal strain rate of a bias test, eq. 23 (1/s).

    The paper's 10, 40 and 160 mm/min on 210 × 70 mm give 0.001375, 0.005502 and
    0.022006 s⁻¹ (printed as 0.0013, 0.0055 and 0.022).
    """
    _check_bias_geometry(length_mm, width_mm)
    return speed_mm_per_min / 60.0 / (length_mm - width_mm) * EFFECTIVE_RATE_FACTOR


def _check_bias_geometry(length_mm: float, width_mm: float) -> None:
    if not (np.isfinite(length_mm) and np.isfinite(width_mm) and width_mm > 0.0
            and length_mm > width_mm):
        raise DrapeInputError(f"bias extension: need length_mm > width_mm > 0, got "
                              f"length_mm = {length_mm}, width_mm = {width_mm}")


def _history(time_s, displacement_mm) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(time_s, dtype=float)
    u = np.asarray(displacement_mm, dtype=float)
    if t.ndim != 1 or t.shape != u.shape or t.size == 0:
        raise DrapeInputError(f"time_s and displacement_mm must be 1-D of one length, got "
                              f"shapes {t.shape} and {u.shape}")
    for name, a in (("time_s", t), ("displacement_mm", u)):
        bad = ~np.isfinite(a)
        if bad.any():
            raise DrapeInputError(f"{name} is not finite at row {int(np.argmax(bad))}")
    if np.any(np.diff(t) < 0.0):
        raise DrapeInputError(f"time_s decreases at row {int(np.argmax(np.diff(t) < 0)) + 1}")
    return t, u


def _newton(residual: Callable, x: np.ndarray, lower: np.ndarray, what: str):
    """Root of a non-decreasing residual per point, by bracketed Newton; x > lower.

    ``residual(x) -> (r, dr/dx, payload)``. A point is done when the Newton correction
    δ = −r/(dr/dx) is below 1e-10 in strain. Returns ``(x, δ, payload)`` of the last
    evaluation, which is at the returned x for every point: the laws' states are those of x,
    and the callers correct what they report to x + δ to first order (leaving an error of
    order δ², and 1e-10 in the strain the states were committed at).
    """
    lo, hi = lower.copy(), np.full_like(x, np.inf)
    grow = np.full_like(x, 1e-4)
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(_MAX_ITERATIONS):
            r, dr, payload = residual(x)
            if not np.isfinite(r).all():
                raise SolverError(f"unit cell: a law returned a non-finite stress in the {what}")
            done = np.abs(r) <= 1e-10 * np.abs(dr) + 1e-15
            if done.all():
                return x, np.where(dr > 0.0, -r / dr, 0.0), payload
            lo = np.where(r < 0.0, x, lo)
            hi = np.where(r > 0.0, x, hi)
            x_new = x - r / dr
            inside = (x_new > lo) & (x_new < hi)  # False for dr <= 0 too
            if not inside.all():
                # Outside the bracket: bisect it, or search upward (no upper bound yet) or
                # halve the distance to the lower bound.
                bracketed = np.isfinite(hi)
                fallback = np.where(bracketed, 0.5 * (lo + hi),
                                    np.where(r < 0.0, x + grow, 0.5 * (lo + x)))
                grow = np.where(inside | bracketed, grow, 2.0 * grow)
                x_new = np.where(inside, x_new, fallback)
            if np.all(done | (np.abs(x_new - x) <= 4e-16 * (1.0 + np.abs(x)))):
                return x, np.where(done & (dr > 0.0), -r / dr, 0.0), payload
            x = np.where(done, x, x_new)
    raise SolverError(f"unit cell: the {what} did not converge in {_MAX_ITERATIONS} "
                      f"iterations (residual {np.max(np.abs(r)):.3g} N/tow)")


def _extrapolation(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic (Lagrange) extrapolation in time to each row from the unknown of the rows before.

    Lower order where fewer rows, or rows at one time, are available; the last value where
    the weights are not finite. Returns the weights of rows i-4..i-1 for each row i (n, 4),
    and how many of them are used (n,).
    """
    n = len(t)
    weights, used = np.zeros((n, 4)), np.zeros(n, dtype=int)
    for i in range(1, n):
        j = i
        while j > max(i - 4, 0) and t[j - 1] < t[j]:
            j -= 1
        ts, ti = t[j:i].tolist(), float(t[i])
        w = [math.prod((ti - tb) / (ta - tb) for b, tb in enumerate(ts) if b != a)
             for a, ta in enumerate(ts)]
        if i - j < 2 or not all(map(math.isfinite, w)):
            w = [1.0]
        weights[i, 4 - len(w):], used[i] = w, len(w)
    return weights, used


def _inside(guess: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """The guess where it is above the lower bound, else a point above it."""
    return np.where(guess > lower, guess, np.where(lower < 0.0, 0.5 * lower, lower + 1e-3))


def _built_in(model: Model) -> bool:
    """Whether the model's coupon laws are the paper's (they take a step per lane)."""
    from fenicsx_drape.materials import BUILT_IN_LAWS, get_law

    classes = model.law_classes()
    return all(classes[role] is get_law(BUILT_IN_LAWS[role]) for role in ("tow", "shear"))


class _Lanes:
    """T tests of one kind side by side, each with the model's m parameter sets.

    Lane j·m + s is parameter set s on test j. A test's rows end with its last row repeated
    (steps of 0 s: the laws' states do not move), so that all tests step row by row
    together: the cost of a row is its calls (NumPy's per-call overhead), not its lanes.
    The unit cell updates two bars of one role in one call (the two diagonals in bias
    extension, the two tow families in tension): :attr:`stacked` holds those laws, with
    every lane twice.
    """

    def __init__(self, model: Model, runs: Sequence[Mapping]) -> None:
        self.histories = [_history(run["time_s"], run["displacement_mm"]) for run in runs]
        self.k, self.m, self.T = model.n_sets, model.n_sets or 1, len(runs)
        self.n_rows = [len(t) for t, _ in self.histories]
        self.t = self.rows([t for t, _ in self.histories])
        self.lane = np.repeat(np.arange(self.T), self.m)  # the test of each lane
        weights, used = zip(*(_extrapolation(self.t[:, j]) for j in range(self.T)))
        self._weights = np.repeat(np.stack(weights, axis=2), self.m, axis=2)  # (n, 4, lanes)
        # Which of the 3 changes between rows i-4..i-1 the safeguard of predict() looks at.
        self._changes = np.repeat(np.stack(used, axis=1), self.m, axis=1)[:, None, :] > (
            3 - np.arange(3))[None, :, None]
        conditions = [run.get("conditions") or {} for run in runs]
        lanes = dict(conditions[0])
        if self.T > 1:  # the callers group tests by the names of their conditions
            model = dataclasses.replace(model, parameters={
                n: np.tile(v, self.T) if np.ndim(v) else v for n, v in model.parameters.items()})
            lanes = {name: self.lanes([float(c[name]) for c in conditions]) for name in lanes}
        self.laws = model.laws(lanes)
        twice = {n: np.tile(v, 2) if np.ndim(v) else v for n, v in lanes.items()}
        self.stacked = dataclasses.replace(model, parameters={
            n: np.tile(v, 2) if np.ndim(v) else v
            for n, v in model.parameters.items()}).laws(twice)
        self.k_st = (model.parameters["k_st"] if "shear_tension_coupling" in model.effects
                     else 0.0)

    def rows(self, columns: Sequence[np.ndarray]) -> np.ndarray:
        """One column per test (n, T), each padded with its last row."""
        n = max(self.n_rows)
        return np.column_stack([np.pad(c, (0, n - len(c)), mode="edge") for c in columns])

    def lanes(self, per_test) -> np.ndarray:
        """A value per test (T,) as a value per lane (T·m,)."""
        return np.repeat(np.asarray(per_test, dtype=float), self.m)
    def step(self, i: int):
        """The step to row i (s): per lane and per stacked lane (one number for one test)."""
        if self.T == 1:
            dt = self.t[i, 0] - self.t[i - 1, 0] if i else 0.0
            return dt, dt
        dt = self.lanes(self.t[i] - self.t[i - 1] if i else np.zeros(self.T))
        return dt, np.tile(dt, 2)

    def predict(self, i: int, xs: np.ndarray) -> np.ndarray:
        """The extrapolation (:func:`_extrapolation`) of the unknown ``xs`` to row i.

        Safeguard against ill-conditioned extrapolation (very uneven steps): it moves at most
        a few times the last changes from the last value.
        """
        rows = xs[max(i - 4, 0):i]
        rows = np.concatenate([np.zeros((4 - len(rows), xs.shape[1])), rows]) if i < 4 else rows
        last = rows[3]
        changes = np.where(self._changes[i], np.abs(np.diff(rows, axis=0)), 0.0)
        reach = 4.0 * changes.max(axis=0) + 1e-4
        return np.clip(np.einsum("ql,ql->l", self._weights[i], rows), last - reach,
                       last + reach)

    def curves(self, **columns: np.ndarray) -> list[UnitCellCurve]:
        """Each test's curve: its (time, displacement) and its rows and lanes of ``columns``."""
        out = []
        for j, (t, u) in enumerate(self.histories):
            lanes = slice(j * self.m, (j + 1) * self.m)
            test = {name: c[:len(t), lanes] for name, c in columns.items()}
            if self.k is None:
                test = {name: c[:, 0] for name, c in test.items()}
            out.append(UnitCellCurve(time_s=t, displacement_mm=u, **test))
        return out


def _batches(model: Model, runs: Sequence[Mapping]) -> list[list[int]]:
    """Indices of the runs formed side by side: those whose conditions have the same names.

    Every run alone when a law is a user's (its update may take one step for all points).
    """
    if not _built_in(model):
        return [[i] for i in range(len(runs))]
    groups: dict[tuple[str, ...], list[int]] = {}
    for i, run in enumerate(runs):
        groups.setdefault(tuple(sorted(run.get("conditions") or {})), []).append(i)
    return list(groups.values())


def curves(model: Model, kind: str, runs: Sequence[Mapping]) -> list[UnitCellCurve]:
    """Curves of several coupon tests of one kind, solved side by side.

    Args:
        model: The model (scalar parameters, or arrays of k parameter sets).
        kind: ``"tensile"``, ``"bias_extension"`` or ``"picture_frame"``.
        runs: Per test, the keyword arguments of that kind's function (``time_s``,
            ``displacement_mm``, the geometry and ``conditions``).

    Returns:
        Each run's curve, as the kind's function gives it; a row of T tests costs about
        one test's (tests whose conditions have the same names are stepped together).
    """
    solvers = {"tensile": _tensile, "bias_extension": _bias_extension,
               "picture_frame": _picture_frame}
    if kind not in solvers:
        raise ValueError(f"unit cell: no coupon test of kind {kind!r} (one of {list(solvers)})")
    solve = solvers[kind]
    out: list[UnitCellCurve | None] = [None] * len(runs)
    for batch in _batches(model, runs):
        for i, curve in zip(batch, solve(model, [runs[i] for i in batch])):
            out[i] = curve
    return out


def tensile(
    model: Model,
    time_s,
    displacement_mm,
    *,
    gauge_length_mm: float,
    conditions: Mapping[str, float] | None = None,
) -> UnitCellCurve:
    """Tensile test along the warp, eqs. 15-17 (see the module docstring).

    Args:
        model: The model (scalar parameters, or arrays of k parameter sets).
        time_s: Time of each row (s), non-decreasing.
        displacement_mm: Crosshead displacement of each row (mm).
        gauge_length_mm: Gauge length L_g (mm); the tow strain is e + e²/2, e = u/L_g.
        conditions: The test's conditions (e.g. ``temperature_C``).

    Returns:
        The curve; the test force in N is ``force_per_tow_N`` times the test's tows.
    """
    (curve,) = _tensile(model, [{"time_s": time_s, "displacement_mm": displacement_mm,
                                 "gauge_length_mm": gauge_length_mm,
                                 "conditions": conditions}])
    return curve


def _tensile(model: Model, runs: Sequence[Mapping]) -> list[UnitCellCurve]:
    for run in runs:
        L_g = run["gauge_length_mm"]
        if not (np.isfinite(L_g) and L_g > 0.0):
            raise DrapeInputError(f"tensile: gauge_length_mm = {L_g} must be > 0")
    cell = _Lanes(model, runs)
    tows, shear, k_st = cell.stacked["tow"], cell.laws["shear"], cell.k_st
    e = [u / run["gauge_length_mm"] for run, (_, u) in zip(runs, cell.histories)]
    ε1_rows = cell.rows([e_j + 0.5 * e_j**2 for e_j in e])
    n, m = ε1_rows.shape[0], cell.T * cell.m
    xs = np.zeros((n, m))
    out = {name: np.zeros((n, m)) for name in ("force", "sigma_1", "tau")}
    s_tows, s_d = tows.initial_state(2 * m), shear.initial_state(m)
    lower = np.full(m, -0.5)
    for i in range(n):
        dt, _ = cell.step(i)
        ε1 = cell.lanes(ε1_rows[i])

        def residual(ε2, ε1=ε1, dt=dt, s_tows=s_tows, s_d=s_d):
            σ, dσ, s_tows_new = tows._update(np.concatenate([ε1, ε2]), dt, s_tows)
            σ1, σ2, dσ2 = σ[:m], σ[m:], dσ[m:]
            τ, dτ, s_d_new = shear._update(0.5 * (ε1 + ε2), dt, s_d)
            c, dc = shear_tension_factor(0.5 * (σ1 + σ2), k_st)
            q = 2.0 + 2.0 * ε1 + 2.0 * ε2  # 2 + 4ε_d
            sin_φ = np.sqrt((1.0 + 2.0 * ε2) / q)
            dsin_φ = (1.0 + 2.0 * ε1) / (q * q * sin_φ)
            r = σ2 + 2.0 * c * τ * sin_φ
            dr = dσ2 + 2.0 * (c * (0.5 * dτ * sin_φ + τ * dsin_φ) + 0.5 * dc * dσ2 * τ * sin_φ)
            # Eq. 17, f = G(ε_1) + 2 H cos φ, and the diagonal stress with their derivatives.
            cos_φ = np.sqrt((1.0 + 2.0 * ε1) / q)
            dcτ = 0.5 * (dc * dσ2 * τ + c * dτ)
            f = σ1 + 2.0 * c * τ * cos_φ
            df = 2.0 * (dcτ * cos_φ - c * τ * cos_φ / q)
            return r, dr, (s_tows_new, s_d_new, σ1, f, df, c * τ, dcτ)

        guess = _inside(cell.predict(i, xs), lower)
        x, δ, (s_tows, s_d, σ1, f, df, τ, dτ) = _newton(residual, guess, lower,
                                                        f"tensile balance at row {i}")
        xs[i], out["force"][i] = x + δ, f + df * δ
        out["sigma_1"][i], out["tau"][i] = σ1, τ + dτ * δ
    ε1 = ε1_rows[:, cell.lane]
    return cell.curves(force_per_tow_N=out["force"], tow_strain=ε1,
                       diagonal_strain=0.5 * (ε1 + xs),
                       shear_deg=np.zeros((n, m)), transverse_strain=xs,
                       tow_stress_N=out["sigma_1"], diagonal_stress_N=out["tau"])


def bias_extension(
    model: Model,
    time_s,
    displacement_mm,
    *,
    length_mm: float,
    width_mm: float,
    conditions: Mapping[str, float] | None = None,
) -> UnitCellCurve:
    """Bias-extension test, eqs. 18-21 (see the module docstring).

    Args:
        model: The model (scalar parameters, or arrays of k parameter sets).
        time_s: Time of each row (s), non-decreasing.
        displacement_mm: Crosshead displacement of each row (mm).
        length_mm: Specimen length L_o (mm).
        width_mm: Specimen width W_o (mm).
        conditions: The test's conditions (e.g. ``temperature_C``).

    Returns:
        The curve; the test force in N is ``force_per_tow_N`` times the test's tows.
    """
    (curve,) = _bias_extension(model, [{"time_s": time_s, "displacement_mm": displacement_mm,
                                        "length_mm": length_mm, "width_mm": width_mm,
                                        "conditions": conditions}])
    return curve


def _bias_extension(model: Model, runs: Sequence[Mapping]) -> list[UnitCellCurve]:
    cell = _Lanes(model, runs)
    strains = []
    for run, (_, u) in zip(runs, cell.histories):
        strains.append(bias_diagonal_strain(u, run["length_mm"], run["width_mm"]))
        if np.any(strains[-1] <= -0.5):
            raise DrapeInputError(f"bias extension: displacement {u.min()} mm closes the gauge "
                                  "region (diagonal strain <= -0.5)")
    tow, diagonals, k_st = cell.laws["tow"], cell.stacked["shear"], cell.k_st
    εd1_rows = cell.rows(strains)
    n, m = εd1_rows.shape[0], cell.T * cell.m
    xs = np.zeros((n, m))
    out = {name: np.zeros((n, m)) for name in ("force", "sigma", "tau_1")}
    s_t, s_d = tow.initial_state(m), diagonals.initial_state(2 * m)
    for i in range(n):
        dt, dt2 = cell.step(i)
        εd1 = cell.lanes(εd1_rows[i])
        lower = np.maximum(0.5 * (εd1 - 0.5), -0.5)  # both ε_d2 and ε_t above -0.5

        def residual(εt, εd1=εd1, dt=dt, dt2=dt2, s_t=s_t, s_d=s_d):
            σ, dσ, s_t_new = tow._update(εt, dt, s_t)
            τ, dτ, s_d_new = diagonals._update(np.concatenate([εd1, 2.0 * εt - εd1]), dt2, s_d)
            τ1, τ2, dτ2 = τ[:m], τ[m:], dτ[m:]
            c, dc = shear_tension_factor(σ, k_st)
            q = 2.0 + 4.0 * εt
            sin_θ = np.sqrt((1.0 + 4.0 * εt - 2.0 * εd1) / q)
            dsin_θ = 2.0 * (1.0 + 2.0 * εd1) / (q * q * sin_θ)
            r = c * τ2 + σ * sin_θ
            dr = 2.0 * c * dτ2 + dc * dσ * τ2 + dσ * sin_θ + σ * dsin_θ
            # Eq. 20 as f = 2(τ_1 − τ_2 cot θ) (insensitive to the stiff tows' stress), the
            # tow and the major diagonal's stresses, with their derivatives.
            p = 1.0 + 4.0 * εt - 2.0 * εd1
            cot_θ = np.sqrt((1.0 + 2.0 * εd1) / p)
            f = 2.0 * c * (τ1 - τ2 * cot_θ)
            df = 2.0 * (dc * dσ * (τ1 - τ2 * cot_θ) - c * cot_θ * (2.0 * dτ2 - 2.0 * τ2 / p))
            return r, dr, (s_t_new, s_d_new, f, df, σ, dσ, c * τ1, dc * dσ * τ1)

        guess = _inside(cell.predict(i, xs), lower)
        x, δ, (s_t, s_d, f, df, σ, dσ, τ1, dτ1) = _newton(
            residual, guess, lower, f"bias-extension balance at row {i}")
        xs[i], out["force"][i] = x + δ, f + df * δ
        out["sigma"][i], out["tau_1"][i] = σ + dσ * δ, τ1 + dτ1 * δ
    εd1 = εd1_rows[:, cell.lane]
    εd2 = 2.0 * xs - εd1
    shear_deg = np.degrees(np.arcsin(np.clip((εd1 - εd2) / (1.0 + 2.0 * xs), -1.0, 1.0)))
    return cell.curves(force_per_tow_N=out["force"], tow_strain=xs, diagonal_strain=εd1,
                       shear_deg=shear_deg, transverse_strain=εd2, tow_stress_N=out["sigma"],
                       diagonal_stress_N=out["tau_1"])


def picture_frame_shear_angle(displacement_mm, frame_side_mm: float) -> np.ndarray:
    r"""Shear angle γ (deg) of a picture frame pulled along its diagonal, Cao et al. eqs. 1-2.

    A rhombus of side L_frame hinged at its corners, pulled apart at two opposite corners
    by d: its diagonal is 2 L_frame cos θ, θ the angle of a side to the pulled diagonal, and
    √2 L_frame at the start (θ = 45°), so

        cos θ = (√2 L_frame + d) / (2 L_frame),   γ = 90° − 2θ,                   (Cao eq. 1-2)

    i.e. cos(π/4 − γ/2) = (√2 L_frame + d)/(2 L_frame). The frame locks at γ = 90° (θ = 0,
    d = (2 − √2) L_frame) and folds the other way at d = −√2 L_frame.

    Args:
        displacement_mm: Crosshead displacement d (mm).
        frame_side_mm: Frame side L_frame, hinge to hinge (mm).
    """
    c = (math.sqrt(2.0) * frame_side_mm + np.asarray(displacement_mm, dtype=float)) / (
        2.0 * frame_side_mm)
    if np.any((c <= 0.0) | (c >= 1.0)):
        raise DrapeInputError(
            f"picture frame: displacement outside ({-math.sqrt(2.0) * frame_side_mm:.4g}, "
            f"{picture_frame_lock_mm(frame_side_mm):.4g}) mm, where the frame of side "
            f"{frame_side_mm:g} mm folds or locks (shear angle ±90°)")
    return 90.0 - 2.0 * np.degrees(np.arccos(c))


def picture_frame_displacement(shear_deg, frame_side_mm: float) -> np.ndarray:
    """Crosshead displacement (mm) at a shear angle: the inverse of eqs. 1-2 (Cao et al.)."""
    γ = np.radians(np.asarray(shear_deg, dtype=float))
    return frame_side_mm * (2.0 * np.cos(0.25 * math.pi - 0.5 * γ) - math.sqrt(2.0))


def picture_frame_lock_mm(frame_side_mm: float) -> float:
    """The displacement at which the frame locks (γ = 90°): (2 − √2) L_frame (mm)."""
    return (2.0 - math.sqrt(2.0)) * frame_side_mm


def picture_frame_shear_force(force_N, displacement_mm, frame_side_mm: float,
                              fabric_side_mm: float | None = None) -> np.ndarray:
    """Shear force F_s = F/(2 cos θ) (Cao eq. 3), normalised by L_frame/L_fabric² (eq. 10).

    Without ``fabric_side_mm``: F_s in N, the force along the frame's sides. With it: the
    energy method's normalised shear force F_s L_frame / L_fabric² in N/mm (Peng et al.,
    Cao et al. eq. 10; Harrison et al. 2004's F_s/L when the fabric fills the frame), the
    measure that makes frames of different sizes comparable.
    """
    θ = np.radians(45.0 - 0.5 * picture_frame_shear_angle(displacement_mm, frame_side_mm))
    shear = np.asarray(force_N, dtype=float) / (2.0 * np.cos(θ))
    return shear if fabric_side_mm is None else shear * frame_side_mm / fabric_side_mm**2


def bias_extension_shear_force(force_N, displacement_mm, length_mm: float,
                               width_mm: float) -> tuple[np.ndarray, np.ndarray]:
    r"""Shear angle (deg) and normalised shear force (N/mm) of a bias test, Harrison's way.

    Not this module's model: the three-zone energy balance of Harrison et al. (2004) as Cao
    et al. (2008) eq. 16 state it, with the gauge zone A (area W (L − 1.5 W)) at the shear
    angle γ of the pin-jointed kinematics, cos(π/4 − γ/2) = (L − W + d)/(√2 (L − W)), and
    the two zones B (area W²) at γ/2:

        F_sh(γ) = [(L/W − 1) F (cos γ/2 − sin γ/2) − W F_sh(γ/2) cos γ/2] / ((2L − 3W) cos γ),

    unrolled over γ/2, γ/4, ... (F interpolated in the measured curve, F_sh(0) = 0). It is
    comparable with a picture frame's :func:`picture_frame_shear_force` with the fabric side
    (both per unit length, Cao et al. Fig. 45). This module's bias model instead takes the
    whole gauge region W (L − W) at γ (eq. 21): for the same shear law its force exceeds
    Harrison's by up to (L − W)/(L − 1.5 W).

    Args:
        force_N: Crosshead force of each row (N).
        displacement_mm: Crosshead displacement of each row (mm), increasing.
        length_mm: Specimen length L (mm), more than 1.5 W.
        width_mm: Specimen width W (mm).

    Returns:
        ``(shear_deg, F_sh)`` per row.
    """
    L, W = float(length_mm), float(width_mm)
    if not (W > 0.0 and L > 1.5 * W):
        raise DrapeInputError(f"bias extension (Harrison): need length_mm > 1.5 width_mm > 0, "
                              f"got {L:g} and {W:g}")
    d = np.asarray(displacement_mm, dtype=float)
    c = np.clip((L - W + d) / (math.sqrt(2.0) * (L - W)), -1.0, 1.0)
    γ = np.radians(90.0) - 2.0 * np.arccos(c)
    F = np.asarray(force_N, dtype=float)

    def first(g):  # the zone-A term, and the factor on F_sh(γ/2)
        denominator = (2.0 * L - 3.0 * W) * np.cos(g)
        a = (L / W - 1.0) * np.interp(g, γ, F) * (np.cos(g / 2) - np.sin(g / 2)) / denominator
        return a, W * np.cos(g / 2) / denominator

    shear, factor, g = np.zeros_like(γ), np.ones_like(γ), γ.copy()
    for _ in range(60):  # F_sh(γ) = a(γ) − b(γ) F_sh(γ/2) − ...: γ/2⁶⁰ is 0 in practice
        a, b = first(g)
        shear += factor * a
        factor *= -b
        g = g / 2
        if np.all(np.abs(factor * a) <= 1e-15 * (1.0 + np.abs(shear))):
            break
    return np.degrees(γ), shear


def picture_frame(
    model: Model,
    time_s,
    displacement_mm,
    *,
    frame_side_mm: float,
    fabric_side_mm: float,
    conditions: Mapping[str, float] | None = None,
) -> UnitCellCurve:
    r"""Picture-frame test: the unit cell in pure shear, driven by the frame's kinematics.

    **Kinematics.** The frame's hinges hold the tows along its sides at their length, so the
    cell shears at the frame's angle with inextensible tows (ε_a = ε_b = 0): by eq. 15
    the diagonals have ε_d1,2 = ± a·b/(2L²) = ± sin γ / 2, with γ from
    :func:`picture_frame_shear_angle` (Cao et al. eqs. 1-2). No balance is left to solve:
    the frame is a mechanism of one degree of freedom. The diagonals' laws follow this
    strain history row by row (the shear rate follows from the measured d(t), so rate
    dependence, holds and unloading act as in the other coupons).

    **Force through the linkage (virtual work).** The net's power per unit reference area is
    √2 l_t Σ τ_i λ̇_i (l_t tows per mm, a diagonal standing for the tows of its cell, λ_i =
    √(1 + 2ε_i); the same density that gives eq. 20 in bias extension). The fabric square of
    side L_fabric takes it all; the crosshead gives F ḋ with ḋ = L_frame sin θ γ̇. With
    λ_1 = √2 cos θ, λ_2 = √2 sin θ (θ = 45° − γ/2) this is

        F = l_t L_fabric² / L_frame · (τ_1 − τ_2 cot θ),

    the bias extension's per-tow force f/2 (eq. 20) carried by the fabric's l_t L_fabric
    tows and scaled by L_fabric/L_frame. It agrees with the usual reduction of a
    picture-frame test: the shear force F_s = F/(2 cos θ) (Cao et al. eq. 3; Harrison et al.
    2004) normalised by the energy method, F_s L_frame/L_fabric² (Peng et al. 2004; Cao et
    al. eq. 10), is the fabric's shear force per unit length l_t (τ_1 − τ_2 cot θ)/(2 cos θ),
    independent of the frame's and the fabric's sizes (:func:`picture_frame_shear_force`),
    and the torque per unit area is that times cos γ (Cao et al. eq. 17). ``force_N`` is the
    crosshead force of a frame without amplifying linkage (a linkage of ratio a multiplies
    it by a, Cao et al. eq. 9); the fabric's arms outside the square are not modelled.

    Args:
        model: The model (scalar parameters, or arrays of k parameter sets).
        time_s: Time of each row (s), non-decreasing.
        displacement_mm: Crosshead displacement d of each row (mm).
        frame_side_mm: Frame side L_frame, hinge to hinge (mm).
        fabric_side_mm: Side of the sheared fabric square L_fabric (mm), at most L_frame.
        conditions: The test's conditions (e.g. ``temperature_C``).

    Returns:
        The curve; the test force in N is ``force_per_tow_N`` times the test's tows (tows of
        one family across the fabric side, l_t L_fabric), i.e. force_per_tow_N =
        (L_fabric/L_frame)(τ_1 − τ_2 cot θ).
    """
    (curve,) = _picture_frame(model, [{"time_s": time_s, "displacement_mm": displacement_mm,
                                       "frame_side_mm": frame_side_mm,
                                       "fabric_side_mm": fabric_side_mm,
                                       "conditions": conditions}])
    return curve


def _picture_frame(model: Model, runs: Sequence[Mapping]) -> list[UnitCellCurve]:
    for run in runs:
        frame, fabric = run["frame_side_mm"], run["fabric_side_mm"]
        if not (np.isfinite(frame) and np.isfinite(fabric) and 0.0 < fabric <= frame):
            raise DrapeInputError(f"picture frame: need 0 < fabric_side_mm <= frame_side_mm, "
                                  f"got fabric_side_mm = {fabric}, frame_side_mm = {frame}")
    cell = _Lanes(model, runs)
    γ = cell.rows([np.radians(picture_frame_shear_angle(u, run["frame_side_mm"]))
                   for run, (_, u) in zip(runs, cell.histories)])[:, cell.lane]
    n, m = γ.shape
    diagonals, tow = cell.stacked["shear"], cell.laws["tow"]
    # The tows stay at their length: their stress is the law's at zero strain (what a
    # shear-tension coupling sees).
    σ_t, _, _ = tow._update(np.zeros(m), 0.0, tow.initial_state(m))
    c, _ = shear_tension_factor(σ_t, cell.k_st)
    εd = 0.5 * np.sin(γ)
    cot_θ = np.sqrt((1.0 + np.sin(γ)) / (1.0 - np.sin(γ)))  # λ_1/λ_2
    ratio = cell.lanes([run["fabric_side_mm"] / run["frame_side_mm"] for run in runs])
    force, tau_1 = np.zeros((n, m)), np.zeros((n, m))
    state = diagonals.initial_state(2 * m)
    for i in range(n):
        _, dt2 = cell.step(i)
        τ, _, state = diagonals._update(np.concatenate([εd[i], -εd[i]]), dt2, state)
        τ1, τ2 = c * τ[:m], c * τ[m:]
        force[i] = ratio * (τ1 - τ2 * cot_θ[i])
        tau_1[i] = τ1
    return cell.curves(force_per_tow_N=force, tow_strain=np.zeros((n, m)),
                       diagonal_strain=εd, shear_deg=np.degrees(γ), transverse_strain=-εd,
                       tow_stress_N=σ_t + 0.0 * force, diagonal_stress_N=tau_1)


def diagonal_response(
    model: Model,
    time_s,
    strain,
    *,
    conditions: Mapping[str, float] | None = None,
) -> np.ndarray:
    """Stress history (N/tow) of one shear diagonal driven through a strain history.

    The law-level response of Fig. 2b (loading, relaxation, reloading, unloading).
    """
    t, ε = _history(time_s, strain)
    shear = model.laws(conditions)["shear"]
    m = model.n_sets or 1
    state = shear.initial_state(m)
    stress = np.zeros((t.size, m))
    for i in range(t.size):
        dt = t[i] - t[i - 1] if i else 0.0
        stress[i], _, state = shear.update(np.full(m, ε[i]), dt, state)
    return stress if model.n_sets else stress[:, 0]
