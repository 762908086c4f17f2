"""Newton's method for one load step, around PETSc assembly and a reused direct factorisation.

The problem supplies its residual ``F(x)`` and Jacobian ``J(x)`` as callbacks that fill PETSc
objects; :class:`Newton` drives the iteration, :class:`LinearSolver` solves ``J d = −F``.
It replaces PETSc SNES for three reasons (issue 17):

- **Factorisation reuse.** On large sheets the sparse factorisation is three quarters of the
  time. The factor of an earlier Jacobian is kept and used as the preconditioner of GMRES on
  the current one (right preconditioning, so the Newton direction is that of the current
  Jacobian to ``krylov_rtol``); it is refactorised only when GMRES needs more than
  ``max_krylov`` iterations or fails. SNES's lagging cannot fall back within an iteration.
- **Line searches** on the residual norm that accept the full step when it reduces the
  residual enough (the common case: one residual evaluation per iteration) and otherwise
  fit a parabola to ‖F(x + λd)‖² (the ``l2`` search of PETSc, which never cut a hemisphere
  step back; the backtracking ``bt`` search did five times at Δ = 10 mm).
- **A hook per iterate** (``monitor``) for the diagnostics of ``benchmarks/bench_stepping.py``
  without slowing normal runs.

Iteration counts, reasons and tolerances follow SNES: an iteration is one linear solve and
update; converged when ‖F‖ ≤ ``atol`` or ‖F‖ ≤ ``rtol`` ‖F₀‖; ``DIVERGED_MAX_IT`` after
``max_it`` iterations; a non-finite residual (a bar collapsed, a law failed) makes the line
search back off, or fails the solve when it is the starting point.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping

from petsc4py import PETSc

# Line searches: the full step, backtracking on ‖F‖², parabola in ‖F‖².
LINE_SEARCHES = ("basic", "bt", "l2", "l2a", "l2a0.9", "l2a0.5", "l2a0.2", "l2a0.1")
_MAX_STEP = 1.0  # EXPERIMENT


@dataclasses.dataclass(frozen=True)
class Iterate:
    """One Newton iterate, as handed to a monitor."""

    iteration: int  # 0 for the starting point
    residual_norm: float  # ‖F‖₂ at the iterate (N)
    step_length: float  # λ of the line search that led here (0 at the start)
    krylov_iterations: int  # GMRES iterations of the solve that led here (0: direct)
    factorised: bool  # whether that solve factorised the Jacobian
    residual_evaluations: int  # residual evaluations of the line search that led here


@dataclasses.dataclass
class NewtonResult:
    """How one Newton solve went."""

    converged: bool
    reason: str  # SNES-style reason, e.g. CONVERGED_FNORM_ABS, DIVERGED_MAX_IT
    iterations: int  # linear solves and updates
    factorisations: int = 0
    krylov_iterations: int = 0
    residual_evaluations: int = 0


class LinearSolver:
    """``J d = b`` by a direct factorisation that is reused while it pays.

    Args:
        A: The Jacobian matrix (reassembled in place before every solve).
        comm: Its communicator.
        prefix: PETSc options prefix of the KSP (user options under it override ours).
        options: PETSc options (``pc_type``, ``pc_factor_mat_solver_type``, ``mat_mumps_*``),
            set under ``prefix`` before the first factorisation.
        max_krylov: Refactorise when GMRES on a stale factor needs more than this many
            iterations; 0 factorises every Jacobian (no reuse).
        krylov_rtol: Relative tolerance of GMRES on a stale factor.
    """

    def __init__(self, A: PETSc.Mat, comm, prefix: str, options: Mapping[str, object],
                 max_krylov: int = 0, krylov_rtol: float = 1e-10):
        self.A = A
        self.max_krylov = int(max_krylov)
        ksp = PETSc.KSP().create(comm)
        ksp.setOptionsPrefix(prefix)
        defaults: dict[str, object] = {"pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
        if self.max_krylov:
            # P holds the factorised Jacobian; PETSc refactorises when P changes.
            self.P = A.duplicate()
            ksp.setOperators(A, self.P)
            defaults.update(ksp_type="gmres", ksp_pc_side="right",
                            ksp_norm_type="unpreconditioned", ksp_rtol=krylov_rtol,
                            ksp_atol=0.0, ksp_max_it=self.max_krylov,
                            ksp_gmres_restart=self.max_krylov)
        else:
            self.P = A
            ksp.setOperators(A)
            defaults.update(ksp_type="preonly")
        db = PETSc.Options()
        self._keys = []
        for key, value in {**defaults, **options}.items():
            if not db.hasName(prefix + key):
                db[prefix + key] = value
                self._keys.append(prefix + key)
        ksp.setFromOptions()
        self.ksp = ksp
        self.factorisations = 0
        self._fresh = False  # P holds the current Jacobian
        self._refactorise = True  # the next solve factorises

    def release_options(self) -> None:
        """Remove our options from the database (the factor has read them)."""
        db = PETSc.Options()
        for key in self._keys:
            db.delValue(key)
        self._keys = []

    def _factorise(self) -> None:
        if self.P is not self.A:
            self.A.copy(self.P, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.factorisations += 1
        self._fresh = True
        self._refactorise = False

    def solve(self, b: PETSc.Vec, x: PETSc.Vec, reuse: bool = True) -> tuple[bool, int, bool]:
        """Solve ``A x = b`` for the Jacobian just assembled in ``A``.

        Args:
            b, x: Right-hand side and solution.
            reuse: Whether the factor of an earlier Jacobian may precondition this solve.

        Returns:
            ``(ok, krylov_iterations, factorised)``.
        """
        if self.P is self.A:  # no reuse: factorise every Jacobian
            self.factorisations += 1
            self.ksp.setOperators(self.A)
            self.ksp.solve(b, x)
            return self.ksp.getConvergedReason() > 0, 0, True
        factorised = False
        if self._refactorise or not reuse:
            self._factorise()
            factorised = True
        self.ksp.solve(b, x)
        its = self.ksp.getIterationNumber()
        ok = self.ksp.getConvergedReason() > 0
        if not ok and not factorised:  # the stale factor no longer preconditions: refresh
            self._factorise()
            factorised = True
            self.ksp.solve(b, x)
            its += self.ksp.getIterationNumber()
            ok = self.ksp.getConvergedReason() > 0
        return ok, its, factorised

    def invalidate(self) -> None:
        """Factorise at the next solve (e.g. after the matrix changed structurally)."""
        self._refactorise = True


class Newton:
    """Newton's method with a line search on one PETSc vector of unknowns.

    Args:
        residual: ``residual(x, F) -> bool`` fills ``F(x)`` (owned entries, ghosts updated by
            the callee); False (on every rank) when ``x`` is outside the domain.
        jacobian: ``jacobian(x)`` assembles ``J(x)`` into the linear solver's matrix.
        linear: The :class:`LinearSolver`.
        F: Work vector for the residual (its layout is that of ``x``).
        atol, rtol, max_it: Convergence test (see the module docstring).
        line_search: One of :data:`LINE_SEARCHES`.
        monitor: Called with an :class:`Iterate` at the start and after every iteration.
    """

    def __init__(self, residual: Callable[[PETSc.Vec, PETSc.Vec], bool],
                 jacobian: Callable[[PETSc.Vec], None], linear: LinearSolver, F: PETSc.Vec,
                 *, atol: float, rtol: float, max_it: int, line_search: str = "l2",
                 monitor: Callable[[Iterate], None] | None = None):
        if line_search not in LINE_SEARCHES:
            raise ValueError(f"line search {line_search!r}: choose from "
                             f"{', '.join(LINE_SEARCHES)}")
        self.residual, self.jacobian, self.linear = residual, jacobian, linear
        self.F = F
        self.atol, self.rtol, self.max_it = float(atol), float(rtol), int(max_it)
        self.line_search = line_search
        self.monitor = monitor
        self.updated = None  # EXPERIMENT
        self.predict = None  # EXPERIMENT
        self.release = None
        self.rounds = 3
        self.predicted = 0
        self.first_release = None
        self.reuse_ratio = 0.1
        self.release_after = 1
        self._d = F.duplicate()
        self._y = F.duplicate()
        self._G = F.duplicate()

    def _norm_at(self, x: PETSc.Vec, d: PETSc.Vec, λ: float) -> float:
        """‖F(x + λ d)‖ (inf outside the domain); leaves F(x + λ d) in ``self._G``."""
        x.copy(self._y)
        self._y.axpy(λ, d)
        if not self.residual(self._y, self._G):
            return math.inf
        value = self._G.norm()
        return value if math.isfinite(value) else math.inf

    def _search(self, x: PETSc.Vec, d: PETSc.Vec, f0: float) -> tuple[float, float, int]:
        """Pick λ along ``d`` from ``x`` (‖F(x)‖ = f0); returns (λ, ‖F‖ there, evaluations).

        On return ``self._G`` holds F at the chosen point (λ = 0 on failure).
        """
        φ0 = f0 * f0
        slope = -φ0  # d/dλ ‖F‖² / 2 at 0 along an exact Newton direction is −‖F‖²
        α = 1e-4
        if self.line_search == "l2":
            return self._parabola(x, d, φ0)
        if self.line_search.startswith("l2a"):  # EXPERIMENT: full step first
            f1 = self._norm_at(x, d, 1.0)
            factor = float(self.line_search[3:] or 0.5)
            if f1 <= factor * math.sqrt(φ0):
                return 1.0, f1, 1
            λ, f, n = self._parabola(x, d, φ0)
            return λ, f, n + 1
        f1 = self._norm_at(x, d, 1.0)
        evaluations = 1
        if self.line_search == "basic" or (f1 * f1 <= φ0 + 2 * α * slope):
            return 1.0, f1, evaluations
        return self._backtrack(x, d, φ0, slope, 1.0, evaluations, f1 * f1)

    def _parabola(self, x, d, φ0):
        """The parabola through ‖F‖² at λ = 0, ½ and 1, and the step to its minimum.

        The step is taken whatever ‖F‖ is there (PETSc's ``l2`` with one iteration): a
        larger residual after a step that straightens a buckled tow (eq. 4) is cheaper to
        correct at the next iteration than to back off from. A parabola open downwards
        gives the step downhill from λ = 1; a non-finite residual at λ = 1 (a collapsed bar)
        falls back to backtracking.
        """
        f1 = self._norm_at(x, d, 1.0)
        if not math.isfinite(f1):
            return self._backtrack(x, d, φ0, -φ0, 0.5, 1)
        fh = self._norm_at(x, d, 0.5)
        φ1, φh = f1 * f1, fh * fh
        slope1 = 3 * φ1 - 4 * φh + φ0  # dφ/dλ at 1 and ...
        slope0 = -3 * φ0 + 4 * φh - φ1  # ... at 0, of the parabola
        curvature = slope1 - slope0
        λ = 1.0 - slope1 / curvature if curvature > 0 else 1.0 + slope1 / curvature
        if not math.isfinite(λ) or λ > _MAX_STEP:
            λ = 1.0
        elif λ < 1e-8:
            λ = 0.5
        f = self._norm_at(x, d, λ)
        if not math.isfinite(f):
            return self._backtrack(x, d, φ0, -φ0, 0.5 * λ, 3)
        return λ, f, 3

    def _backtrack(self, x, d, φ0, slope, λ, evaluations, φλ=None):
        """Armijo backtracking on ‖F‖²/2 with quadratic, then cubic, interpolation (bt)."""
        α, λ_prev, φ_prev = 1e-4, None, None
        while True:
            if φλ is None:
                f = self._norm_at(x, d, λ)
                evaluations += 1
                φλ = f * f
            if φλ <= φ0 + 2 * α * λ * slope:
                return λ, math.sqrt(φλ), evaluations
            if λ < 1e-10:
                return 0.0, math.sqrt(φ0), evaluations
            if not math.isfinite(φλ):
                λ_new = 0.1 * λ
            elif λ_prev is None:  # quadratic model of φ(λ)/2
                λ_new = -slope * λ * λ / (φλ / 2 - φ0 / 2 - slope * λ) / 2
            else:  # cubic through the last two trials
                r1 = φλ / 2 - φ0 / 2 - slope * λ
                r2 = φ_prev / 2 - φ0 / 2 - slope * λ_prev
                a = (r1 / λ**2 - r2 / λ_prev**2) / (λ - λ_prev)
                b = (-λ_prev * r1 / λ**2 + λ * r2 / λ_prev**2) / (λ - λ_prev)
                disc = b * b - 3 * a * slope
                if a == 0:
                    λ_new = -slope / (2 * b) if b else 0.5 * λ
                elif disc < 0:
                    λ_new = 0.5 * λ
                else:
                    λ_new = (-b + math.sqrt(disc)) / (3 * a)
            if not math.isfinite(λ_new):
                λ_new = 0.5 * λ
            λ_prev, φ_prev = λ, φλ
            λ = min(max(λ_new, 0.1 * λ), 0.5 * λ)
            φλ = None

    def solve(self, x: PETSc.Vec) -> NewtonResult:
        """Iterate from ``x`` (updated in place) to convergence or failure."""
        F, d = self.F, self._d
        result = NewtonResult(False, "", 0)
        ok = self.residual(x, F)
        result.residual_evaluations = 1
        f = F.norm() if ok else math.inf
        if self.monitor is not None:
            self.monitor(Iterate(0, f, 0.0, 0, False, 1))
        if not math.isfinite(f):
            result.reason = "DIVERGED_FNORM_NAN"
            return result
        f0 = f
        λ_last, f_last = 0.0, f
        while True:
            if f <= self.atol:
                result.converged, result.reason = True, "CONVERGED_FNORM_ABS"
                return result
            if f <= self.rtol * f0:
                result.converged, result.reason = True, "CONVERGED_FNORM_RELATIVE"
                return result
            if result.iterations >= self.max_it:
                result.reason = "DIVERGED_MAX_IT"
                return result
            self.jacobian(x)
            F.scale(-1.0)
            # Reuse a factor only where Newton converges fast (the Jacobian changes little).
            reuse = result.iterations > 0 and λ_last == 1.0 and f <= self.reuse_ratio * f_last
            try:
                solved, its, factorised = self.linear.solve(F, d, reuse)
            finally:
                F.scale(-1.0)
            result.iterations += 1
            result.krylov_iterations += its
            result.factorisations += factorised
            if not solved:
                result.reason = "DIVERGED_LINEAR_SOLVE"
                return result
            if self.predict is not None:
                for _ in range(self.rounds):
                    if not self.predict(x, d):
                        break
                    self.residual(x, self._G)
                    result.residual_evaluations += 1
                    self.jacobian(x)
                    self._G.scale(-1.0)
                    solved, its, factorised = self.linear.solve(self._G, d)
                    result.krylov_iterations += its
                    result.factorisations += factorised
                    self.predicted += 1
                self.release()
            f_last = f
            λ, f, evaluations = self._search(x, d, f)
            λ_last = λ
            result.residual_evaluations += evaluations
            if λ == 0.0:
                result.reason = "DIVERGED_LINE_SEARCH"
                return result
            x.axpy(λ, d)
            if self.updated is not None:
                self.updated(λ, d)
            self._G.copy(F)
            if self.first_release is not None and result.iterations == self.release_after:
                if self.first_release():
                    self.residual(x, F)
                    result.residual_evaluations += 1
                    f = F.norm()
            if self.monitor is not None:
                self.monitor(Iterate(result.iterations, f, λ, its, factorised, evaluations))
