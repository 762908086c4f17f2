"""Newton's method for one load step, around PETSc assembly and a direct factorisation.

The problem supplies its residual ``F(x)`` and Jacobian ``J(x)`` as callbacks that fill PETSc
objects; :class:`Newton` drives the iteration, :class:`LinearSolver` solves ``J d = −F``.
It replaces PETSc SNES (issue 17), whose ``bt`` and ``l2`` line searches it reproduces
iterate for iterate, for three reasons:

- **The line search** ``full-l2`` takes the full Newton step when it lowers ‖F‖ (one residual
  evaluation, most iterations), and otherwise the step to the minimum of the parabola through
  ‖F(x + λd)‖² at λ = 0, ½, 1, whatever ‖F‖ is there (PETSc's ``l2``). Backtracking on ‖F‖²
  (``bt``) crawls at λ = 0.1 for tens of iterations where the Newton step straightens a
  buckled tow (eq. 4) or drives a node into a tool: the residual of such a step is large but
  cheap to correct at the next iteration. On the hemisphere ``bt`` cut five steps back at
  Δ = 10 mm and fifteen on the full 2.5 mm sheet; ``l2`` none and two. Asking the full step
  to halve ‖F‖, as this search first did, sent steps that only lowered it to the parabola:
  on the full 2.5 mm sheet 1020 iterations, 4 cut-backs and 2106 residuals against 875, 2
  and 1515 now (``benchmarks/bench_forming.py``).
- **Factorisation reuse** (``max_krylov`` > 0): once Newton converges fast (the last step was
  full and cut ‖F‖ tenfold) the Jacobian changes little, and the factor of an earlier one
  preconditions GMRES on it (right preconditioning: the Newton direction is that of the
  current Jacobian to ``krylov_rtol``); a GMRES solve that does not converge within
  ``max_krylov`` iterations is redone with a fresh factorisation.
- **A hook per iterate** (``monitor``) for diagnostics (``benchmarks/diagnose_stepping.py``)
  that costs nothing when unused.

Iterations, reasons and tolerances follow SNES: an iteration is one linear solve and update;
converged when ‖F‖ ≤ ``atol`` or ‖F‖ ≤ ``rtol`` ‖F₀‖; ``DIVERGED_MAX_IT`` after ``max_it``
iterations. A third test, not SNES's, is ``node_atol``: converged when no unknown carries an
out-of-balance force above it, ‖F‖∞ ≤ ``node_atol`` (``CONVERGED_FNORM_NODE``). Unlike the
2-norm it does not tighten as the mesh is refined (issue 17: the forming cases use 1e-3 N).
A residual that cannot be evaluated (a bar collapsed, a law failed) makes the line
search back off, or fails the solve (``DIVERGED_FNORM_NAN``) at the starting point.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping

from petsc4py import PETSc

LINE_SEARCHES = ("full-l2", "l2", "bt", "basic")
"""``full-l2`` (default), PETSc's ``l2`` and ``bt``, and the full step ``basic``."""

_REUSE_REDUCTION = 0.1  # a factor is reused after a full step that cut ‖F‖ at least this much
_GLOBAL_ITERATIONS = 6  # iterations after which the exact Jacobian is asked in any case


@dataclasses.dataclass(frozen=True)
class Iterate:
    """One Newton iterate, as handed to a monitor."""

    iteration: int  # 0 for the starting point
    residual_norm: float  # ‖F‖₂ at the iterate (N)
    step_length: float  # λ of the line search that led here (0 at the start)
    krylov_iterations: int  # GMRES iterations of the solve that led here
    factorised: bool  # whether that solve factorised the Jacobian
    residual_evaluations: int  # residuals evaluated by the line search that led here


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
    """``J d = b`` by a direct factorisation, optionally reused as a GMRES preconditioner.

    Args:
        A: The Jacobian matrix (reassembled in place before every solve).
        comm: Its communicator.
        prefix: PETSc options prefix of the KSP.
        options: PETSc options (``pc_type``, ``pc_factor_mat_solver_type``, ``mat_mumps_*``)
            set under ``prefix`` until the first factorisation has read them.
        max_krylov: GMRES iterations allowed on a reused factor (0: factorise every
            Jacobian).
        krylov_rtol: Relative tolerance of GMRES.
    """

    def __init__(self, A: PETSc.Mat, comm, prefix: str, options: Mapping[str, object],
                 max_krylov: int = 0, krylov_rtol: float = 1e-10):
        self.A = A
        self.max_krylov = int(max_krylov)
        ksp = PETSc.KSP().create(comm)
        ksp.setOptionsPrefix(prefix)
        defaults: dict[str, object] = {"pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
        if self.max_krylov:
            # P holds the factorised Jacobian: PETSc refactorises when P changes.
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
            db[prefix + key] = value
            self._keys.append(prefix + key)
        ksp.setFromOptions()
        self.ksp = ksp
        self._factorised = False

    def release_options(self) -> None:
        """Remove our options from the database (the factor has read them)."""
        db = PETSc.Options()
        for key in self._keys:
            db.delValue(key)
        self._keys = []

    def _factorise(self) -> None:
        self.A.copy(self.P, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.ksp.setOperators(self.A, self.P)
        self._factorised = True

    def solve(self, b: PETSc.Vec, x: PETSc.Vec, reuse: bool = False) -> tuple[bool, int, bool]:
        """Solve ``A x = b`` for the Jacobian just assembled in ``A``.

        Args:
            b: Right-hand side.
            x: Solution.
            reuse: Whether the factor of an earlier Jacobian may precondition this solve.

        Returns:
            ``(ok, krylov_iterations, factorised)``.
        """
        if self.P is self.A:
            self.ksp.setOperators(self.A)  # the KSP sees a new matrix: refactorise
            self.ksp.solve(b, x)
            krylov = self.ksp.getType() != PETSc.KSP.Type.PREONLY  # e.g. on a single factor
            its = self.ksp.getIterationNumber() if krylov else 0
            return self.ksp.getConvergedReason() > 0, its, True
        factorised = not (reuse and self._factorised)
        if factorised:
            self._factorise()
        self.ksp.solve(b, x)
        its = self.ksp.getIterationNumber()
        ok = self.ksp.getConvergedReason() > 0
        if not ok and not factorised:  # the old factor no longer preconditions: refresh
            self._factorise()
            factorised = True
            self.ksp.solve(b, x)
            its += self.ksp.getIterationNumber()
            ok = self.ksp.getConvergedReason() > 0
        return ok, its, factorised


class Newton:
    """Newton's method with a line search on one PETSc vector of unknowns.

    Args:
        residual: ``residual(x, F) -> bool`` fills ``F(x)``; False (on every rank) when ``x``
            is outside the domain.
        jacobian: ``jacobian(x, local)`` assembles ``J(x)`` into the linear solver's matrix;
            ``local`` says that Newton converges fast (see :meth:`solve`), where the exact
            Jacobian is due.
        linear: The :class:`LinearSolver`.
        F: Work vector for the residual (the layout of ``x``); holds F at the last iterate.
        atol, rtol, max_it: Convergence test (see the module docstring).
        node_atol: Largest out-of-balance force of any unknown at convergence (0: unused).
        line_search: One of :data:`LINE_SEARCHES`.
        monitor: Called with an :class:`Iterate` at the start and after every iteration,
            when the problem's state is that of the iterate.
    """

    def __init__(self, residual: Callable[[PETSc.Vec, PETSc.Vec], bool],
                 jacobian: Callable[[PETSc.Vec, bool], None], linear: LinearSolver, F: PETSc.Vec,
                 *, atol: float, rtol: float, max_it: int, node_atol: float = 0.0,
                 line_search: str = "full-l2", monitor: Callable[[Iterate], None] | None = None):
        if line_search not in LINE_SEARCHES:
            raise ValueError(f"line search {line_search!r}: choose from "
                             f"{', '.join(LINE_SEARCHES)}")
        self.residual, self.jacobian, self.linear = residual, jacobian, linear
        self.F = F
        self.atol, self.rtol, self.max_it = float(atol), float(rtol), int(max_it)
        self.node_atol = float(node_atol)
        self.line_search = line_search
        self.monitor = monitor
        self._d = F.duplicate()
        self._y = F.duplicate()
        self._G = F.duplicate()

    def _norm_at(self, x: PETSc.Vec, d: PETSc.Vec, λ: float) -> float:
        """‖F(x + λd)‖ (inf outside the domain); leaves F(x + λd) in ``self._G``."""
        x.copy(self._y)
        self._y.axpy(λ, d)
        if not self.residual(self._y, self._G):
            return math.inf
        value = self._G.norm()
        return value if math.isfinite(value) else math.inf

    def _search(self, x: PETSc.Vec, d: PETSc.Vec, f0: float) -> tuple[float, float, int]:
        """Step length along ``d`` from ``x``, where ‖F‖ = f0: (λ, ‖F‖ there, evaluations).

        On return the problem's state and ``self._G`` are those at x + λd (λ = 0: failed).
        """
        φ0 = f0 * f0
        if self.line_search == "l2":
            return self._parabola(x, d, φ0, None)
        f1 = self._norm_at(x, d, 1.0)
        if self.line_search == "basic":
            return 1.0, f1, 1
        if self.line_search == "full-l2":
            if f1 < f0:
                return 1.0, f1, 1
            λ, f, evaluations = self._parabola(x, d, φ0, f1)
            return λ, f, evaluations + 1
        return self._backtrack(x, d, φ0, 1.0, 1, f1 * f1)

    def _parabola(self, x, d, φ0: float, f1: float | None) -> tuple[float, float, int]:
        """The step to the minimum of the parabola through ‖F‖² at λ = 0, ½ and 1.

        It is taken whatever ‖F‖ is there (PETSc's ``l2``, one secant iteration, steps up
        to 1). A parabola open downwards gives the step downhill from λ = 1. ``f1`` is
        ‖F(x + d)‖ if known; ``_norm_at`` is called in PETSc's order (½, then 1, then λ) so
        that the iterates equal SNES's.
        """
        evaluations = 0
        fh = self._norm_at(x, d, 0.5)
        evaluations += 1
        if f1 is None:
            f1 = self._norm_at(x, d, 1.0)
            evaluations += 1
        if not (math.isfinite(f1) and math.isfinite(fh)):
            λ, f, n = self._backtrack(x, d, φ0, 0.5 if math.isfinite(fh) else 0.25, 0)
            return λ, f, evaluations + n
        φ1, φh = f1 * f1, fh * fh
        slope1 = 3 * φ1 - 4 * φh + φ0  # dφ/dλ of the parabola at 1 ...
        slope0 = -3 * φ0 + 4 * φh - φ1  # ... and at 0
        curvature = slope1 - slope0
        λ = 1.0 - slope1 / curvature if curvature > 0 else 1.0 + slope1 / curvature
        if not math.isfinite(λ) or λ > 1.0:
            λ = 1.0
        elif λ < 1e-8:
            λ = 0.5
        f = self._norm_at(x, d, λ)
        evaluations += 1
        if not math.isfinite(f):
            λ, f, n = self._backtrack(x, d, φ0, 0.5 * λ, 0)
            evaluations += n
        return λ, f, evaluations

    def _backtrack(self, x, d, φ0: float, λ: float, evaluations: int,
                   φλ: float | None = None) -> tuple[float, float, int]:
        """Armijo backtracking on ‖F‖²/2 with quadratic, then cubic, models (PETSc's ``bt``).

        Along a Newton direction the slope of ‖F‖²/2 at λ = 0 is −‖F‖².
        """
        α, slope = 1e-4, -φ0
        λ_prev = φ_prev = None
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
        """Iterate from ``x`` (updated in place) to convergence or failure.

        The iteration is *local* from the first full step that cuts ‖F‖ tenfold (Newton
        converges fast: the Jacobian is asked exact) or after ``_GLOBAL_ITERATIONS``.
        """
        F, d = self.F, self._d
        result = NewtonResult(False, "", 0, residual_evaluations=1)
        f = F.norm() if self.residual(x, F) else math.inf
        f = f if math.isfinite(f) else math.inf
        if self.monitor is not None:
            self.monitor(Iterate(0, f, 0.0, 0, False, 1))
        if not math.isfinite(f):
            result.reason = "DIVERGED_FNORM_NAN"
            return result
        f0, fast, local = f, False, False
        while True:
            if f <= self.atol:
                result.converged, result.reason = True, "CONVERGED_FNORM_ABS"
                return result
            if f <= self.rtol * f0:
                result.converged, result.reason = True, "CONVERGED_FNORM_RELATIVE"
                return result
            if self.node_atol and F.norm(PETSc.NormType.INFINITY) <= self.node_atol:
                result.converged, result.reason = True, "CONVERGED_FNORM_NODE"
                return result
            if result.iterations >= self.max_it:
                result.reason = "DIVERGED_MAX_IT"
                return result
            local = local or fast or result.iterations >= _GLOBAL_ITERATIONS
            self.jacobian(x, local)
            F.scale(-1.0)
            try:
                solved, its, factorised = self.linear.solve(F, d, reuse=fast)
            finally:
                F.scale(-1.0)
            result.iterations += 1
            result.krylov_iterations += its
            result.factorisations += factorised
            if not solved:
                result.reason = "DIVERGED_LINEAR_SOLVE"
                return result
            λ, f_new, evaluations = self._search(x, d, f)
            result.residual_evaluations += evaluations
            if λ == 0.0:
                result.reason = "DIVERGED_LINE_SEARCH"
                return result
            fast = λ == 1.0 and f_new <= _REUSE_REDUCTION * f
            f = f_new
            x.axpy(λ, d)
            self._G.copy(F)
            if self.monitor is not None:
                self.monitor(Iterate(result.iterations, f, λ, its, factorised, evaluations))
