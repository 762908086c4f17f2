"""PETSc SNES for one load step: its set-up, the ``full-l2`` line search and the tests.

The problem supplies its residual ``F(x)`` and Jacobian ``J(x)`` as callbacks that fill PETSc
objects; SNES drives the iteration (``newtonls`` with a direct factorisation by default) and
:class:`Newton` only sets it up, with SNES's own hooks:

- **The line search** ``full-l2`` (default) is SNES's ``basic`` line search with a pre-check
  that takes the step: the full Newton step when it lowers ‖F‖ (one residual evaluation, most
  iterations), else the step to the minimum of the parabola through ‖F(x + λd)‖² at λ = 0, ½
  and 1, whatever ‖F‖ is there (PETSc's ``l2``, one secant iteration). Backtracking (``bt``)
  crawls at λ = 0.1 for tens of iterations where the Newton step straightens a buckled tow
  (eq. 4) or drives a node into a tool: the residual of such a step is large but cheap to
  correct at the next iteration (on the full 2.5 mm sheet ``bt`` cut fifteen steps
  back, ``full-l2`` two). The residual at the point taken is handed to the line search, not
  evaluated twice. Any PETSc line search can be chosen instead (``line_search``, or
  ``-snes_linesearch_type``).
- **The convergence test** (``setConvergenceTest``) is SNES's ``‖F‖ ≤ atol`` or
  ``‖F‖ ≤ rtol ‖F₀‖`` plus ``node_atol``: converged when no unknown carries an out-of-balance
  force above it, ‖F‖∞ ≤ ``node_atol`` (reported as ``CONVERGED_FNORM_NODE``). Unlike the
  2-norm it does not tighten as the mesh is refined (the forming cases use 1e-3 N).
  There is no step-length test (``snes_stol`` 0) and ``DIVERGED_MAX_IT`` after ``max_it``.
- **A hook per iterate** (``setMonitor``) hands an :class:`Iterate` to a monitor, for
  diagnostics (``benchmarks/diagnose_stepping.py``); it costs nothing when unused.
- **Options**: the defaults here, then ``SolverOptions.petsc_options``, then the user's
  (``PETSC_OPTIONS``, ``--petsc-option`` on the command line, :func:`set_petsc_options`), each
  overriding the last: ``-snes_type newtontr``, ``-snes_type qn -npc_snes_type newtonls``,
  factor reuse (``-snes_lag_preconditioner 2 -ksp_type gmres``), profiling (``-log_view``).
  ``docs/solver.md`` measures them: none beats the default on the hemisphere.

A residual that cannot be evaluated (a bar collapsed, a law failed) is a vector of NaN for SNES
(petsc4py has no domain-error call): the pre-check halves the step until it is finite, and at
the starting point the solve fails (``DIVERGED_FUNCTION_NANORINF``).
"""

from __future__ import annotations

import dataclasses
import math
import shlex
import weakref
from collections.abc import Callable, Mapping, Sequence

from petsc4py import PETSc

from fenicsx_drape.errors import DrapeInputError

LINE_SEARCHES = ("full-l2", "l2", "bt", "basic", "cp", "nleqerr")
"""``full-l2`` (default, see the module docstring) and PETSc's own line searches."""

SOLVER_PREFIXES = ("snes_", "ksp_", "pc_", "mat_", "npc_", "sub_")
"""Options of the load step's solver: given without prefix, they reach every truss problem."""

KEPT_OPTIONS = ("mat_mumps_", "mat_superlu_dist_")
"""Options read by the factor each time it is made, kept while their solver lives."""


def _kept(key: str) -> bool:
    return any(name in key for name in KEPT_OPTIONS)


def _forget(keys: list[str]) -> None:
    db = PETSc.Options()
    for key in keys:
        db.delValue(key)


_REUSE_REDUCTION = 0.1  # Newton converges fast after a full step that cut ‖F‖ this much ...
_GLOBAL_ITERATIONS = 6  # ... or after this many iterations: the exact Jacobian is asked
_REASONS = {v: k for k, v in vars(PETSc.SNES.ConvergedReason).items()
            if k.startswith(("CONVERGED_", "DIVERGED_"))}


def set_petsc_options(options: str | Sequence[str]) -> dict[str, str]:
    """Give PETSc options to every later load-step solve of this process.

    The one call of ``--petsc-option`` (``drape form``, ``compare``, ``diagnose``); options in
    the environment variable ``PETSC_OPTIONS`` act the same way. They override the solver's
    defaults and ``SolverOptions.petsc_options``, and ``provenance.json`` records them.

    Args:
        options: Options as on PETSc's command line, e.g. ``"-snes_type newtontr"`` or
            ``["-snes_type qn", "-npc_snes_type newtonls"]``: solver options (``-snes_*``,
            ``-ksp_*``, ``-pc_*``, ``-mat_*``, ``-npc_*``, ``-sub_*``) or ``-log_view``.

    Returns:
        The options given, by name (without the dash).

    Raises:
        DrapeInputError: An option that is not a solver option, or a value without a name.
    """
    text = options if isinstance(options, str) else " ".join(options)
    given: dict[str, str] = {}
    name = None
    for token in shlex.split(text):
        if token.startswith("-") and not _is_number(token):
            name = token.lstrip("-")
            if not (name.startswith(SOLVER_PREFIXES) or name.startswith("log_")):
                raise DrapeInputError(f"PETSc option {token!r}: not an option of the solver "
                                      "(-snes_*, -ksp_*, -pc_*, -mat_*, -npc_*, -sub_*, "
                                      "-log_view)")
            given[name] = ""
        elif name is None or given[name]:
            raise DrapeInputError(f"PETSc options {text!r}: value {token!r} follows no option")
        else:
            given[name] = token
    if "log_view" in given:
        PETSc.Log.begin()  # PETSc prints the log at exit when -log_view is in the database
    db = PETSc.Options()
    for key, value in given.items():
        db[key] = value
    return given


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


@dataclasses.dataclass(frozen=True)
class Iterate:
    """One Newton iterate, as handed to a monitor."""

    iteration: int  # 0 for the starting point
    residual_norm: float  # ‖F‖₂ at the iterate (N)
    step_length: float  # λ of the full-l2 search that led here (0 at the start; NaN: other)
    krylov_iterations: int  # Krylov iterations of the solve that led here (0: a factor alone)
    residual_evaluations: int  # residuals evaluated since the last iterate


@dataclasses.dataclass
class NewtonResult:
    """How one solve went: SNES's reason and counters."""

    converged: bool
    reason: str  # SNES's reason, e.g. CONVERGED_FNORM_ABS, DIVERGED_MAX_IT
    iterations: int  # SNES iterations (Newton: linear solves and updates)
    jacobians: int = 0  # each factorised, unless -snes_lag_preconditioner keeps a factor
    krylov_iterations: int = 0
    residual_evaluations: int = 0


class Newton:
    """PETSc SNES on one vector of unknowns, set up for the load steps.

    Args:
        residual: ``residual(x, F) -> bool`` fills ``F(x)``; False (on every rank) when ``x``
            is outside the domain.
        jacobian: ``jacobian(x, local)`` assembles ``J(x)`` into ``A`` (into ``P`` when
            given); ``local`` says that Newton converges fast (see :meth:`solve`), where the
            exact Jacobian is due.
        A: The Jacobian matrix (the Krylov solve's operator).
        F: The residual vector (the layout of the unknowns); holds F at the last iterate.
        prefix: PETSc options prefix of this solver.
        atol, rtol, max_it: Convergence test (see the module docstring).
        node_atol: Largest out-of-balance force of any unknown at convergence (0: unused).
        line_search: One of :data:`LINE_SEARCHES`.
        options: PETSc options under ``prefix`` (e.g. ``pc_type``, ``snes_type``); they stay
            in PETSc's database until :meth:`release_options`.
        monitor: Called with an :class:`Iterate` at the start and after every iteration,
            when the problem's state is that of the iterate.
        P: The matrix the preconditioner is built from, when it is not ``A`` (SNES's J/P
            split); ``A`` then applies the Jacobian, built on ``P``'s values.
    """

    def __init__(self, residual: Callable[[PETSc.Vec, PETSc.Vec], bool],
                 jacobian: Callable[[PETSc.Vec, bool], None], A: PETSc.Mat, F: PETSc.Vec, *,
                 prefix: str, atol: float, rtol: float, max_it: int, node_atol: float = 0.0,
                 line_search: str = "full-l2", options: Mapping[str, object] | None = None,
                 monitor: Callable[[Iterate], None] | None = None, P: PETSc.Mat | None = None):
        if line_search not in LINE_SEARCHES:
            raise ValueError(f"line search {line_search!r}: choose from "
                             f"{', '.join(LINE_SEARCHES)}")
        self.residual, self.jacobian, self.F = residual, jacobian, F
        self.node_atol = float(node_atol)
        self.monitor = monitor
        db = PETSc.Options()
        user = {k: v for k, v in db.getAll().items() if k.startswith(SOLVER_PREFIXES)}
        settings: dict[str, object] = {
            "snes_type": "newtonls", "snes_atol": atol, "snes_rtol": rtol, "snes_stol": 0.0,
            "snes_max_it": max_it, "ksp_type": "preonly", "pc_type": "lu",
            "pc_factor_mat_solver_type": "mumps", **(options or {}), **user}
        # full-l2 is newtonls's basic line search with a pre-check; other methods keep theirs.
        if "snes_linesearch_type" not in settings and (line_search != "full-l2"
                                                       or settings["snes_type"] == "newtonls"):
            settings["snes_linesearch_type"] = ("basic" if line_search == "full-l2"
                                                else line_search)
        for key in user:  # PETSc would call them unused at exit: they were read here
            db.getString(key)
        self._keys = [prefix + key for key in settings]
        for key, value in settings.items():
            db[prefix + key] = value
        snes = PETSc.SNES().create(A.getComm())
        snes.setOptionsPrefix(prefix)
        snes.setFunction(self._function, F)
        snes.setJacobian(self._jacobian, A, P)
        snes.setConvergenceTest(self._converged)
        snes.setMonitor(self._monitor)
        snes.setFromOptions()
        self.rtol, self.atol, _, self.max_it = snes.getTolerances()
        self.full_l2 = (line_search == "full-l2" and snes.getType() == "newtonls"
                        and snes.getLineSearch().getType() == "basic")
        if self.full_l2:
            snes.setLineSearchPreCheck(self._precheck)
        self.snes = snes
        self._w, self._G = F.duplicate(), F.duplicate()
        self._trial = False  # F(w) in _G is that of the point the line search takes next
        self._reset()

    def release_options(self) -> None:
        """Remove this solver's options from PETSc's database (the factor has read them).

        The factor package's own options (``mat_mumps_*``, ...: :data:`KEPT_OPTIONS`) stay
        until the solver is gone: PETSc makes the factor again, reading them, whenever the
        Jacobian's pattern grows (a stack's pairs reaching new cells).
        """
        db = PETSc.Options()
        kept = [key for key in self._keys if _kept(key)]
        for key in self._keys:
            if not _kept(key):
                db.delValue(key)
        self._keys = []
        if kept and not getattr(self, "_kept", None):
            self._kept = weakref.finalize(self, _forget, kept)

    def _reset(self) -> None:
        self.evaluations = 0  # residuals evaluated in this solve
        self.jacobians = 0  # Jacobians assembled (by a nonlinear preconditioner too)
        self._since = 0  # evaluations since the last iterate
        self._its, self._f0, self._fnorm = 0, math.inf, math.inf
        self._λ = 0.0  # step of the last full-l2 search
        self._failed = self._fast = self._local = self._node = False

    # -- SNES callbacks ---------------------------------------------------------------------

    def _evaluate(self, x: PETSc.Vec, F: PETSc.Vec) -> float:
        """F(x) into ``F``; its norm, inf outside the domain (F is then NaN for SNES)."""
        self.evaluations += 1
        self._since += 1
        if not self.residual(x, F):
            F.set(math.nan)
            return math.inf
        value = F.norm()
        return value if math.isfinite(value) else math.inf

    def _function(self, snes, x: PETSc.Vec, F: PETSc.Vec) -> None:
        if self._trial and self._w.equal(x):  # the pre-check evaluated it last
            self._G.copy(F)
        else:
            self._evaluate(x, F)
        self._trial = False

    def _jacobian(self, snes, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        # Newton converges fast from the first full step that cut ‖F‖ tenfold, or after
        # _GLOBAL_ITERATIONS: from then on the Jacobian is exact (TrussProblem._jacobian).
        self._local = self._local or self._fast or self._its >= _GLOBAL_ITERATIONS
        self.jacobians += 1
        self.jacobian(x, self._local)

    def _converged(self, snes, its: int, norms: tuple[float, float, float]) -> int:
        fnorm = norms[2]
        R = PETSc.SNES.ConvergedReason
        if its == 0:
            self._f0 = fnorm
        else:
            λ = self._λ if self.full_l2 else 1.0  # other searches: the step is not known
            self._fast = λ == 1.0 and fnorm <= _REUSE_REDUCTION * self._fnorm
        self._its, self._fnorm = its, fnorm
        if not math.isfinite(fnorm):
            return R.DIVERGED_FUNCTION_NANORINF
        if self._failed:
            return R.DIVERGED_LINE_SEARCH
        if fnorm <= self.atol:
            return R.CONVERGED_FNORM_ABS
        if fnorm <= self.rtol * self._f0:
            return R.CONVERGED_FNORM_RELATIVE
        if self.node_atol and self.F.norm(PETSc.NormType.INFINITY) <= self.node_atol:
            self._node = True
            return R.CONVERGED_FNORM_ABS
        if its >= self.max_it:
            return R.DIVERGED_MAX_IT
        return R.CONVERGED_ITERATING

    def _monitor(self, snes, its: int, fnorm: float) -> None:
        if self.monitor is not None:
            ksp = snes.getKSP()
            krylov = 0 if its == 0 or ksp.getType() == "preonly" else ksp.getIterationNumber()
            λ = 0.0 if its == 0 else (self._λ if self.full_l2 else math.nan)
            self.monitor(Iterate(its, fnorm, λ, krylov, self._since))
        self._since = 0

    # -- the full-l2 line search ------------------------------------------------------------

    def _precheck(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """Take the step of ``full-l2`` along the Newton step ``y`` (SNES would take x − y).

        The point found, x − λy, becomes ``x`` and ``y`` zero, so that SNES's basic line
        search keeps it as computed (with its residual, evaluated once) rather than
        recomputing x − λy in other arithmetic.
        """
        λ, _ = self._search(x, y, self._fnorm)
        self._λ = λ
        self._failed = λ == 0.0
        if λ:
            self._w.copy(x)
            self._trial = True
        y.set(0.0)

    def _norm_at(self, x: PETSc.Vec, y: PETSc.Vec, λ: float) -> float:
        """‖F(x − λy)‖ (inf outside the domain); leaves x − λy in ``_w``, F there in ``_G``."""
        x.copy(self._w)
        self._w.axpy(-λ, y)
        return self._evaluate(self._w, self._G)

    def _search(self, x: PETSc.Vec, y: PETSc.Vec, f0: float) -> tuple[float, float]:
        """Step length along −y from ``x``, where ‖F‖ = f0: (λ, ‖F‖ there); λ = 0: failed.

        The full step if it lowers ‖F‖; else the minimum of the parabola through ‖F‖² at
        λ = 0, ½ and 1 (evaluated in PETSc's order, ½ after 1), taken whatever ‖F‖ is there;
        a parabola open downwards gives the step downhill from λ = 1. Where F cannot be
        evaluated the step is halved.
        """
        f1 = self._norm_at(x, y, 1.0)
        if f1 < f0:
            return 1.0, f1
        fh = self._norm_at(x, y, 0.5)
        if math.isfinite(f1) and math.isfinite(fh):
            φ0, φh, φ1 = f0 * f0, fh * fh, f1 * f1
            slope1 = 3 * φ1 - 4 * φh + φ0  # dφ/dλ of the parabola at 1 ...
            slope0 = -3 * φ0 + 4 * φh - φ1  # ... and at 0
            curvature = slope1 - slope0
            λ = 1.0 - slope1 / curvature if curvature > 0 else 1.0 + slope1 / curvature
            if not math.isfinite(λ) or λ > 1.0:
                λ = 1.0
            elif λ < 1e-8:
                λ = 0.5
        else:
            λ = 0.5 if math.isfinite(fh) else 0.25
        f = self._norm_at(x, y, λ)
        while not math.isfinite(f):
            λ *= 0.5
            if λ < 1e-10:
                return 0.0, f0
            f = self._norm_at(x, y, λ)
        return λ, f

    # -- the solve --------------------------------------------------------------------------

    def solve(self, x: PETSc.Vec) -> NewtonResult:
        """Iterate from ``x`` (updated in place) to convergence or failure.

        The Jacobian is *local* (exact) from the first full step that cuts ‖F‖ tenfold
        (Newton converges fast) or after ``_GLOBAL_ITERATIONS`` iterations.
        """
        self._reset()
        self.snes.solve(None, x)
        reason = self.snes.getConvergedReason()
        ksp = self.snes.getKSP()
        krylov = 0 if ksp.getType() == "preonly" else self.snes.getLinearSolveIterations()
        name = "CONVERGED_FNORM_NODE" if self._node and reason > 0 else _REASONS[reason]
        return NewtonResult(reason > 0, name, self.snes.getIterationNumber(),
                            jacobians=self.jacobians, krylov_iterations=krylov,
                            residual_evaluations=self.evaluations)
