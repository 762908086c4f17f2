"""The paper's hemisphere forming case (section 4): the truss sheet, the tools, the run.

A square sheet (240 mm, the 4×4 twill prepreg of Table 2) lies on the blank holder at z = 0;
the punch rises 80 mm in 40 s (2 mm/s) through the holder's 170 mm opening and draws the
sheet over its hemispherical nose into the matched die, against the friction of the holder
(133 N). One call, :func:`run_hemisphere`, sets it up on the FE core and runs it; outputs are
in :mod:`fenicsx_drape.forming.outputs`.

An optional initial ply angle θ (``ply_angle_deg``, issue 6; the paper blames small angle
variations for its asymmetric part) turns the tow net by θ inside the square sheet, whose
edges stay along x and y: the net is clipped to the square cell by cell (a ragged edge,
:func:`~fenicsx_drape.fe.grid.sheet_grid`), on the full sheet only. Its tow bars with a
cell on one side only carry half a strip of tows, as on a straight edge; the bending
stencils and the post-processing see the ragged edge too.

The parts of the model that are not the truss itself:

- the tools (:class:`~fenicsx_drape.forming.tools.HemisphereTools`: exact surfaces),
- penalty contact with the punch and the die (:mod:`~fenicsx_drape.forming.contact`) of
  stiffness k = ``penalty_factor`` · l_t E_o (l_t E_o: the axial stiffness of one tow bar),
- the blank holder (:mod:`~fenicsx_drape.forming.holder`): clamping and eq. 1 friction bars,
  with F/4 on a quarter model,
- the out-of-plane stabilisation of the slack net (:mod:`~fenicsx_drape.forming.stabilisation`),
- symmetry conditions u_x = 0 on x = 0 and u_y = 0 on y = 0 for a quarter model; the full
  sheet needs none (the holder's friction bars hold it in its plane).

Load steps move the punch ``step_mm`` (1 mm); a step whose Newton solve fails is halved, and
steps grow back (×1.5, up to ``step_mm``) after solves of at most 15 iterations. The solver's
residual tolerance is 1e-6 N (forces on a node are 0.01-1 N).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np

from fenicsx_drape.errors import ParameterError, SolverError
from fenicsx_drape.forming.contact import PenaltyContact
from fenicsx_drape.forming.holder import BlankHolder
from fenicsx_drape.forming.post import FormedGrid
from fenicsx_drape.forming.stabilisation import ExtrapolationSpring
from fenicsx_drape.forming.tools import HemisphereTools


@dataclasses.dataclass(frozen=True)
class HemisphereCase:
    """The conditions of a hemisphere forming run (defaults: the paper's experiment)."""

    cell_mm: float = 10.0  # unit-cell size Δ (mm)
    duration_s: float = 40.0  # forming time for the whole travel (s): 2 mm/s
    holder_force_N: float = 133.0  # total holding force on the whole sheet (N)
    quarter: bool = True  # model one symmetric quarter (else the full sheet)
    die: bool = True  # the matched die closes on the sheet (else the punch alone)
    penalty_factor: float = 0.3  # contact stiffness k in units of l_t E_o (contact.py)
    step_mm: float = 1.0  # punch travel per load step (mm); cut back when Newton fails
    stabilisation_N_per_mm: float = 1.25  # out-of-plane spring to the extrapolated motion
    ply_angle_deg: float = 0.0  # tow net turned by θ in the square sheet (full sheet only)
    tools: HemisphereTools = dataclasses.field(default_factory=HemisphereTools)

    def __post_init__(self) -> None:
        for name in ("cell_mm", "duration_s", "penalty_factor", "step_mm"):
            if not getattr(self, name) > 0:
                raise ParameterError(f"hemisphere: {name} = {getattr(self, name)} must be > 0")
        for name in ("holder_force_N", "stabilisation_N_per_mm"):
            if not getattr(self, name) >= 0:
                raise ParameterError(f"hemisphere: {name} = {getattr(self, name)} must be >= 0")
        if not np.isfinite(self.ply_angle_deg):
            raise ParameterError(f"hemisphere: ply_angle_deg = {self.ply_angle_deg} is not a "
                                 "number")
        if self.ply_angle_deg and self.quarter:
            raise ParameterError(f"hemisphere: ply_angle_deg = {self.ply_angle_deg} breaks the "
                                 "quarter symmetry; model the full sheet (quarter=False)")

    @property
    def speed_mm_per_s(self) -> float:
        """Punch speed (mm/s)."""
        return self.tools.travel_mm / self.duration_s

    @property
    def part_force_N(self) -> float:
        """Holding force carried by the modelled part (a quarter carries F/4)."""
        return self.holder_force_N / (4.0 if self.quarter else 1.0)


@dataclasses.dataclass
class HemisphereRun:
    """A finished run: the formed sheet and how it went."""

    case: HemisphereCase
    grid: FormedGrid  # the formed sheet on its structured grid
    problem: object  # the TrussProblem at the end (fields, reactions)
    steps: int  # converged load steps
    cutbacks: int  # failed (halved) steps
    iterations: int  # Newton iterations of all attempts
    wall_time_s: float
    max_penetration_mm: float  # deepest penetration into punch or die at the end
    draw_in_mm: dict[str, float]  # inward displacement of the sheet edge (mid-side, corner)
    contact: list[PenaltyContact]
    holder: BlankHolder
    stopped: str | None = None  # why the run stopped short of full travel (allow_incomplete)

    @property
    def travel_mm(self) -> float:
        """Punch travel reached (mm): the full travel unless the run stopped short."""
        return self.case.speed_mm_per_s * self.problem.t


def contact_stiffness(model, options, factor: float = 1.0) -> float:
    """Penalty stiffness k = factor · l_t E_o (N/mm): the axial stiffness of one tow bar."""
    E_o = float(np.max(model.parameters["E_o"]))
    return factor * options.tows_per_mm * E_o


def run_hemisphere(case: HemisphereCase | None = None, model=None, options=None, *,
                   progress: Callable[[str], None] | None = None,
                   on_step: Callable[[object], None] | None = None, comm=None,
                   allow_incomplete: bool = False) -> HemisphereRun:
    """Form the hemisphere: build the sheet, tools and terms, then step to full travel.

    Args:
        case: The forming conditions (default: the paper's, on a 10 mm quarter model).
        model: The material :class:`~fenicsx_drape.model.Model` (default: the paper's).
        options: :class:`~fenicsx_drape.fe.solver.SolverOptions` of the truss.
        progress: Called with a line of text after every load step (rank 0 only).
        on_step: Called with the problem after every converged step (e.g. field output).
        comm: MPI communicator (default ``COMM_WORLD``).
        allow_incomplete: When a step fails at the smallest step, return the sheet at the
            last converged step (``stopped`` says why) instead of raising ``SolverError``.

    Returns:
        The formed sheet and the run's statistics.
    """
    from mpi4py import MPI

    from fenicsx_drape.fe.mesh import truss_sheet
    from fenicsx_drape.fe.solver import SolverOptions, TrussProblem
    from fenicsx_drape.fe.stepping import RunReport
    from fenicsx_drape.model import default_model

    case = case or HemisphereCase()
    model = model or default_model()
    μ_t = float(model.parameters.get("mu_tool", 0.0)) if "tool_friction" in model.effects else 0.0
    if options is None:
        # The Jacobian is symmetric unless tool friction or the shear-tension coupling acts:
        # a symmetric (indefinite LDLᵀ) factorisation then costs about 20 % less time.
        symmetric = μ_t == 0.0 and "shear_tension_coupling" not in model.effects
        options = SolverOptions(snes_atol=1e-6,
                                petsc_options={"pc_type": "cholesky"} if symmetric else {})
    comm = comm or MPI.COMM_WORLD
    tools = case.tools
    start = time.perf_counter()

    k = contact_stiffness(model, options, case.penalty_factor)
    slip = float(model.parameters.get("tool_slip_mm", 0.1))
    contact = [PenaltyContact(tools.punch(case.duration_s), k, friction=μ_t,
                              slip_regularisation_mm=slip)]
    if case.die:
        contact.append(PenaltyContact(tools.die(), k, friction=μ_t, slip_regularisation_mm=slip))
    holder = BlankHolder(model.laws()["friction"], opening_radius_mm=tools.opening_radius_mm,
                         force_N=case.part_force_N, clamp_stiffness_N_per_mm=k,
                         symmetry_axes=(0, 1) if case.quarter else ())
    sheet = truss_sheet(tools.sheet_mm, case.cell_mm, quarter=case.quarter, comm=comm,
                        ply_angle_deg=case.ply_angle_deg)
    terms = [*contact, holder]
    if case.stabilisation_N_per_mm:
        terms.append(ExtrapolationSpring(case.stabilisation_N_per_mm, sheet_normal(contact)))
    problem = TrussProblem(sheet, model, terms, options)
    if case.quarter:
        problem.symmetry()

    def report(step) -> None:
        if progress is not None and comm.rank == 0:
            travel = case.speed_mm_per_s * step.time_s
            state = "ok" if step.converged else f"cut back ({step.reason})"
            progress(f"step {len(problem.steps):4d}  t = {step.time_s:7.3f} s  travel = "
                     f"{travel:6.2f} mm  Newton {step.iterations:2d}  {state}")

    dt = case.step_mm / case.speed_mm_per_s
    stopped = None
    try:
        problem.run(case.duration_s, dt, dt_max_s=dt, easy_iterations=15, progress=report,
                    on_step=on_step)
    except SolverError as error:
        if not allow_incomplete:
            raise
        stopped = str(error)
    res = problem.results()
    grid = FormedGrid(res.X, res.x, case.quarter)
    x = problem.positions()[: problem.num_owned]
    t = problem.t
    depth = max((float(c.penetration(x, t).max(initial=0.0)) for c in contact), default=0.0)
    run = RunReport(problem.steps)  # every attempt, also when the run stopped short
    return HemisphereRun(
        case=case, grid=grid, problem=problem, steps=len(run.accepted), cutbacks=run.cutbacks,
        iterations=run.iterations, wall_time_s=time.perf_counter() - start,
        max_penetration_mm=comm.allreduce(depth, op=MPI.MAX), draw_in_mm=draw_in(grid),
        contact=contact, holder=holder, stopped=stopped)


def sheet_normal(contact: list[PenaltyContact], near_mm: float = 3.0):
    """An estimate of the sheet's normal at every node, for the out-of-plane stabilisation.

    The normal of the nearest tool surface where a tool is within ``near_mm`` (the sheet
    lies on it, or will), else the z axis (the flat sheet and the holder). The sheet's own
    normal, from its grid, was tried: it cost 50 % more Newton iterations on the 2.5 mm mesh
    (wrinkled cells tilt it from node to node).
    """

    def direction(x: np.ndarray, t: float) -> np.ndarray:
        d = np.zeros_like(x)
        d[:, 2] = 1.0
        best = np.full(len(x), near_mm)
        for c in contact:
            g = c.tool.gap(x, t)
            closer = np.abs(g.phi) < best
            d[closer] = g.normal[closer]
            best = np.where(closer, np.abs(g.phi), best)
        return d

    return direction


def draw_in(grid: FormedGrid) -> dict[str, float]:
    """Inward in-plane displacement (mm) of the middle of a side and of a corner.

    The nodes of the flat sheet nearest the middle of the side x = max and the corner
    x = y = max (for a ply at an angle, on its ragged edge).
    """
    X, x = grid.X[..., :2], grid.x[..., :2]
    a = np.nanmax(X[..., 0])

    def inward(target: tuple[float, float]) -> float:
        d = np.linalg.norm(X - target, axis=-1)
        k = np.unravel_index(np.nanargmin(d), d.shape)
        return float(np.linalg.norm(X[k]) - np.linalg.norm(x[k]))

    return {"mid_side_mm": inward((a, 0.0)), "corner_mm": inward((a, a))}
