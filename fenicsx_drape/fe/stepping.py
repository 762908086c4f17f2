"""Load stepping with cut-back: adaptive time steps around a problem's ``step(t)``.

A step whose Newton solve fails is reverted (the laws' and nodal terms' history stay at the last
converged step), halved and retried; after ``easy_iterations`` or fewer Newton iterations the
next step grows by ``growth`` up to ``dt_max_s``. A step cut below ``dt_min_s`` stops the run
with a :class:`~fenicsx_drape.errors.SolverError` that says where the last converged state was
saved.

Steps never cross the run's grid of ``dt_max_s`` (its start plus whole steps): after a cut-back
the steps come back onto it. A run that cut one step back then takes the same steps as one
that did not everywhere else, so that its result does not jump when a parameter moves the
cut-back in or out (a blank moved by 0.01 mm cut the hemisphere's first contact step
back; the shifted steps after it moved the formed grid by 0.02 mm, as much as the fit's sd).
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from fenicsx_drape.errors import SolverError


@dataclasses.dataclass(frozen=True)
class StepReport:
    """How one load step went."""

    time_s: float  # time at the end of the step
    dt_s: float  # step length
    converged: bool
    iterations: int  # Newton iterations (linear solves)
    reason: str  # SNES's converged/diverged reason (fe/newton.py)
    # Jacobians assembled: each factorised, unless -snes_lag_preconditioner keeps a factor.
    factorisations: int = 0
    krylov_iterations: int = 0  # Krylov iterations (0: a factorisation alone)
    residual_evaluations: int = 0  # residuals assembled (line searches included)


class Steppable(Protocol):
    """What load stepping drives: a problem at its last converged time ``t``.

    :class:`~fenicsx_drape.fe.solver.TrussProblem` is one; this module does not import it,
    so the solver may import the stepping and not the other way round.
    """

    t: float  # time (s) of the last converged step
    comm: Any  # MPI communicator (save_state gathers the nodes over it)

    def step(self, t: float) -> StepReport:
        """Solve one step to time ``t`` (s); revert to the last converged state on failure."""


@dataclasses.dataclass
class RunReport:
    """What a run did: its accepted steps and how many were cut back."""

    steps: list[StepReport]  # every attempted step, in order (failed ones included)

    @property
    def accepted(self) -> list[StepReport]:
        """The converged steps."""
        return [s for s in self.steps if s.converged]

    @property
    def cutbacks(self) -> int:
        """Number of failed (cut-back) step attempts."""
        return sum(not s.converged for s in self.steps)

    @property
    def iterations(self) -> int:
        """Newton iterations of all attempts, failed ones included."""
        return sum(s.iterations for s in self.steps)


def run(problem: Steppable, t_end: float, dt_s: float, *, dt_min_s: float | None = None,
        dt_max_s: float | None = None, growth: float = 1.5, easy_iterations: int = 5,
        progress: Callable[[StepReport], None] | None = None,
        on_step: Callable[[Steppable], None] | None = None,
        failure_dir: str | os.PathLike | None = None) -> RunReport:
    """Step ``problem`` from its current time to ``t_end`` (s).

    Args:
        problem: The problem, at its last converged state.
        t_end: Time to reach (s).
        dt_s: First step length (s).
        dt_min_s: Smallest step before giving up (default ``dt_s / 1024``).
        dt_max_s: Largest step (default ``dt_s``).
        growth: Factor on the step after an easy step.
        easy_iterations: Newton iterations at or below which a step counts as easy.
        progress: Called with the report of every attempted step (converged or not).
        on_step: Called with the problem after every converged step (outputs).
        failure_dir: Where the last converged state is saved when the run fails (default a
            new temporary folder).

    Raises:
        SolverError: a step failed at the floor ``dt_min_s``.
    """
    if not dt_s > 0:
        raise ValueError(f"dt_s = {dt_s} must be > 0")
    dt_min = dt_s / 1024 if dt_min_s is None else dt_min_s
    dt_max = dt_s if dt_max_s is None else dt_max_s
    dt = dt_s
    t0 = problem.t
    report = RunReport([])
    while t_end - problem.t > 1e-9 * max(1.0, abs(t_end)):
        remaining = t_end - problem.t
        # A last step up to 1 % longer than dt is taken whole (no sliver after it).
        dt_try = remaining if remaining < 1.01 * dt else dt
        # The next point of the grid (module doc), unless the step ends the run anyway.
        grid = t0 + (math.floor((problem.t - t0) / dt_max + 1e-6) + 1) * dt_max
        if grid < min(problem.t + dt_try, t_end - 0.01 * dt_max):
            dt_try = grid - problem.t
        step = problem.step(problem.t + dt_try)
        report.steps.append(step)
        if progress is not None:
            progress(step)
        if step.converged:
            if on_step is not None:
                on_step(problem)
            if step.iterations <= easy_iterations:
                dt = min(dt * growth, dt_max)
            continue
        dt = dt_try / 2
        if dt < dt_min:
            path = save_state(problem, failure_dir)
            raise SolverError(
                f"the step from t = {problem.t:g} s to {problem.t + dt_try:g} s did not converge "
                f"({step.reason} after {step.iterations} iterations) and the step cannot be cut "
                f"below dt_min = {dt_min:g} s; the last converged state (t = {problem.t:g} s) "
                f"is saved in {path}")
    return report


def save_state(problem: Steppable, folder: str | os.PathLike | None = None) -> Path:
    """Save the node positions of the last converged state as ``state.npz`` (rank 0 writes).

    The file holds ``time_s`` and ``X``, ``x``: the reference and current positions (mm) of
    every node of the sheet, shaped (nx + 1, ny + 1, 3) by grid index ((n, 3) for a stack).
    """
    from fenicsx_drape.fe.output import gather_nodes
    from fenicsx_drape.provenance import atomic_write_bytes

    if folder is None:
        folder = problem.comm.bcast(
            tempfile.mkdtemp(prefix="drape_failed_") if problem.comm.rank == 0 else None)
    path = Path(folder) / "state.npz"
    X, x = gather_nodes(problem)
    if problem.comm.rank == 0:
        import io

        buf = io.BytesIO()
        np.savez(buf, time_s=problem.t, X=X, x=x)
        atomic_write_bytes(path, buf.getvalue())
    problem.comm.Barrier()  # the file exists on return, on every rank
    return path
