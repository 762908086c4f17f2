"""Run any forming case: the blank's truss, the tools, the holder, the load steps.

:func:`run_case` sets a :class:`~fenicsx_drape.forming.case.spec.FormingCase` up on the FE
core and steps it to the end of its motion (the paper's hemisphere is the case
``meshes/hemisphere/case.toml``). The terms of the model, for any case:

- the blank's structured net (:meth:`~fenicsx_drape.forming.case.spec.BlankSpec.grid`), with the
  symmetry conditions u_x = 0 on x = 0 and/or u_y = 0 on y = 0 of a half or quarter model,
  and u_x = u_y = 0 at the net's node at ``origin_mm`` when the blank holds it
  (``hold_origin``: a part symmetric in both planes modelled without them);
- penalty contact with every punch, die and surface (:mod:`~fenicsx_drape.forming.terms.contact`)
  of stiffness k = ``penalty_factor`` · l_t E_o (l_t E_o: the axial stiffness of one tow bar),
  with ``tool_friction`` when the model has it;
- the blank holder (:mod:`~fenicsx_drape.forming.terms.holder`) on the clamping tool's surface:
  clamping with the same k and eq. 1 friction bars, the force shared as ``force_share`` says;
- on a sheet that neither symmetry planes in both x and y nor ``hold_origin`` hold, the
  stick of the punch's first point of contact (:mod:`~fenicsx_drape.forming.terms.stick`;
  on a stack, each ply's point there): without it a frictionless punch leaves the whole
  sheet free to slide over it;
- the out-of-plane stabilisation of the slack net
  (:mod:`~fenicsx_drape.forming.terms.stabilisation`) along the nearest tool's normal.

Before anything is built the run's length is checked (load steps, nodes, time:
:func:`~fenicsx_drape.forming.case.size.check_run_size`; the estimate is the first progress
line), and before the first step where the blank and the tools are
(:mod:`~fenicsx_drape.forming.running.geometry`); the progress lines then give the time left
at the rate so far.

Load steps move the fastest tool ``step_mm``; a step whose Newton solve fails is halved, and
steps grow back (×1.5, up to ``step_mm``) after solves of at most 15 iterations. A step has
converged when ‖F‖ ≤ 1e-6 N or no node carries more than :data:`NODE_ATOL_N` out of balance
(forces on a node are 0.01-1 N). The Jacobian is symmetric unless
tool friction or the shear-tension coupling acts or the holder's surface is curved: it is then
factored with MUMPS's symmetric LDLᵀ (about 20 % less time than LU).
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable, Mapping

import numpy as np

from fenicsx_drape.errors import InputFileError as CaseError
from fenicsx_drape.errors import SolverError
from fenicsx_drape.forming.case import FormingCase, case_key, check_run_size
from fenicsx_drape.forming.case.size import size_text
from fenicsx_drape.forming.case.spec import where
from fenicsx_drape.forming.running.geometry import geometry_problems
from fenicsx_drape.forming.running.post import FormedGrid
from fenicsx_drape.forming.terms.contact import PenaltyContact
from fenicsx_drape.forming.terms.holder import BlankHolder, StackHolder
from fenicsx_drape.forming.terms.stabilisation import ExtrapolationSpring
from fenicsx_drape.forming.terms.stick import ApexStick, PlyStick
from fenicsx_drape.forming.tools.build import build_tools

CONTACT_ROLES = ("punch", "die", "surface")
# The geometry checks of the cases formed in this process, by content (the latest few): a
# diagnosis forms the same part for many models, and the check took a sixth of a small run.
_GEOMETRY: dict[str, tuple[list[str], list[str]]] = {}
_GEOMETRY_SIZE = 64

NODE_ATOL_N = 1e-3
"""A step has converged when no node carries an out-of-balance force above this (N).

The 2-norm test ‖F‖ ≤ 1e-6 N alone spent about one Newton iteration per step
polishing an equilibrium that no longer moved: on the hemisphere at Δ = 10, 5 and 2.5 mm
(quarter) stopping at 1e-3 N per node moves no node by more than 1e-4 mm. Holder friction puts
F μ / n_s ≥ 0.008 N on a node even on the full 2.5 mm sheet, eight times this.
"""


@dataclasses.dataclass
class FormingRun:
    """A finished run: the formed sheet and how it went."""

    case: FormingCase
    grid: FormedGrid  # the formed sheet (the modelled part) on its structured grid
    problem: object  # the TrussProblem at the end (fields, reactions)
    steps: int  # converged load steps
    cutbacks: int  # failed (halved) steps
    iterations: int  # Newton iterations of all attempts
    wall_time_s: float
    max_penetration_mm: float  # deepest penetration into any contact tool at the end
    draw_in_mm: dict[str, float] | None  # rectangle blanks: mid-side and corner draw-in
    edge_displacement_mm: dict[str, float]  # in-plane displacement of the free edge
    contact: list[PenaltyContact]
    holder: BlankHolder | None
    tools: dict[str, object] = dataclasses.field(default_factory=dict)  # built tools by name
    stopped: str | None = None  # why the run stopped short of full travel (allow_incomplete)
    # Per converged step: time_s, travel_mm and the force (N) of every tool along its motion
    # on the whole part (:func:`record_tool_forces`).
    tool_forces: list[dict[str, float]] = dataclasses.field(default_factory=list)
    # A stack: every ply's formed sheet (ply 1 on the punch side; ``grid`` is the last, the
    # side a camera sees) and the inter-ply contact (fe.plies.PlyContact).
    plies: list[FormedGrid] = dataclasses.field(default_factory=list)
    interply: object | None = None

    @property
    def travel_mm(self) -> float:
        """Travel of the fastest tool reached (mm): the full travel unless stopped short."""
        return self.case.travel_mm(self.problem.t)


def contact_stiffness(model, options, factor: float = 1.0) -> float:
    """Penalty stiffness k = factor · l_t E_o (N/mm): the axial stiffness of one tow bar."""
    E_o = float(np.max(model.parameters["E_o"]))
    return factor * options.tows_per_mm * E_o


def case_model(case: FormingCase):
    """The case's material model: its MODEL.toml, else the paper's (Table 2).

    A stack whose plies all name one model and whose ``[case]`` names none takes that one.
    The paper's model of a stack adds ``interply_friction`` (its plies slide; a model of the
    user's that lacks it bonds them, spec version 4).
    """
    from fenicsx_drape.model import default_model, load_model

    path = _stack_model_path(case)
    if path is None:
        model = default_model()
        return model.with_effects("interply_friction") if case.stack else model
    return load_model(path, origin=_model_origin(case))


def _stack_model_path(case: FormingCase):
    if case.model is None and case.plies:
        named = {p.model for p in case.plies}
        if len(named) == 1:
            return named.pop()
    return case.model


def ply_models(case: FormingCase) -> list | None:
    """Per ply of a stack, its own model (a ``[[ply]] model`` other than the case's) or None.

    None for a blank of one ply, or when no ply has a model of its own. A ply's own model
    gives its tow and shear laws; the run's model (the case's, or the one a command or the
    diagnosis gives) the rest: the other plies, the holder, the tools, the inter-ply switch.
    """
    from fenicsx_drape.model import load_model

    if not case.stack:
        return None
    common = _stack_model_path(case)
    models = [load_model(p.model, origin=_model_origin(case))
              if p.model not in (None, common) else None for p in case.plies]
    return models if any(models) else None


def _model_origin(case: FormingCase) -> str:
    """Where a model a case names comes from: data, whose plugins run only when trusted."""
    return case.origin or f"the case {case.path or case.name}"


def tool_friction(model) -> float:
    """The Coulomb coefficient μ_t of tool contact: ``mu_tool`` with ``tool_friction``, else 0."""
    return float(model.parameters.get("mu_tool", 0.0)) if "tool_friction" in model.effects else 0.0


def forming_options(model, *, flat_holder: bool = True, stack: bool = False, **changes):
    """The forming cases' solver options, with ``changes`` (SolverOptions fields).

    Residual tolerances of 1e-6 N (2-norm) and :data:`NODE_ATOL_N` per node. The Jacobian is
    symmetric unless tool friction, the shear-tension coupling or a curved clamping surface
    (``flat_holder`` False) acts: it is then factorised with MUMPS's symmetric indefinite
    LDLᵀ, about 20 % less time than LU; a stack of plies (``stack``: inter-ply friction
    depends on the pressure) is never symmetric. ``petsc_options`` given in ``changes`` are
    added to that choice (e.g. :data:`~fenicsx_drape.fe.solver.SINGLE_PRECISION_FACTOR`).
    """
    from fenicsx_drape.fe.solver import SolverOptions

    symmetric = (tool_friction(model) == 0.0 and "shear_tension_coupling" not in model.effects
                 and flat_holder and not stack)
    petsc = {"pc_type": "cholesky"} if symmetric else {}
    petsc.update(changes.pop("petsc_options", {}))
    return SolverOptions(snes_atol=1e-6, node_atol_N=NODE_ATOL_N, petsc_options=petsc, **changes)


def _checked_geometry(case: FormingCase, built: dict, known: bool
                      ) -> tuple[list[str], list[str]]:
    """:func:`geometry_problems` of the case, remembered by content when ``known``.

    Tools given in Python (``known`` False) are not in the case's content: checked each time.
    """
    key = case_key(case) if known else None
    if key not in _GEOMETRY:
        found = geometry_problems(case, built, case.blank.grid().nodes)
        if key is None:
            return found
        if len(_GEOMETRY) >= _GEOMETRY_SIZE:
            del _GEOMETRY[next(iter(_GEOMETRY))]
        _GEOMETRY[key] = found
    return _GEOMETRY[key]


def run_case(case: FormingCase, model=None, options=None, *,
             tools: Mapping[str, object] | None = None,
             progress: Callable[[str], None] | None = None,
             on_step: Callable[[object], None] | None = None, comm=None,
             allow_incomplete: bool = False, failure_dir=None) -> FormingRun:
    """Form a case: build the blank's truss, tools and terms, then step to the end.

    Args:
        case: The forming case (:func:`~fenicsx_drape.forming.case.reading.load_case`).
        model: The material :class:`~fenicsx_drape.model.Model` (default: the case's
            ``model``, else the paper's); the holder's ``mu``, if given, replaces its μ.
        options: :class:`~fenicsx_drape.fe.solver.SolverOptions` of the truss (default: the
            forming defaults above).
        tools: Built tools by name that replace those the case would build (e.g. a surface
            given in Python); each must be a tool of the case.
        progress: Called with a line of text after every load step (rank 0 only).
        on_step: Called with the problem after every converged step (e.g. field output).
        comm: MPI communicator (default ``COMM_WORLD``).
        allow_incomplete: When a step fails at the smallest step, return the sheet at the
            last converged step (``stopped`` says why) instead of raising ``SolverError``.
        failure_dir: Where the last converged state is saved when a step fails (default: a
            new temporary folder); the commands give their ``--out``.

    Returns:
        The formed sheet and the run's statistics.
    """
    from mpi4py import MPI

    from fenicsx_drape.fe.mesh import grid_to_sheet
    from fenicsx_drape.fe.solver import TrussProblem
    from fenicsx_drape.fe.stepping import RunReport
    from fenicsx_drape.limits import duration_text

    size = check_run_size(case)  # a run past the limits stops before anything is built
    if progress is not None and (comm or MPI.COMM_WORLD).rank == 0:  # before any work
        progress(size_text(case, size))
    model = model or case_model(case)
    if case.holder is not None and case.holder.mu is not None:
        model = model.with_parameters(mu=case.holder.mu)
    given = dict(tools or {})
    for name in given:
        if name not in {t.name for t in case.tools}:
            raise CaseError([f"{where(case)}: run_case: tool {name!r} is not a tool of the case "
                             f"({', '.join(t.name for t in case.tools)})"])
    built = {**build_tools(case, skip=tuple(given)), **given}
    built = {t.name: built[t.name] for t in case.tools}  # in the case's order
    errors, warns = _checked_geometry(case, built, known=not given)
    if errors:  # before the first step, in the user's terms
        raise CaseError([f"{where(case)}: {e}" for e in errors])
    for text in warns:
        warnings.warn(f"{where(case)}: {text}", stacklevel=2)
    holder_surface = built[case.holder.tool] if case.holder is not None else None
    μ_t = tool_friction(model)
    if options is None:
        flat = holder_surface is None or bool(getattr(holder_surface, "flat", False))
        options = forming_options(model, flat_holder=flat, stack=case.stack)
    comm = comm or MPI.COMM_WORLD
    start = time.perf_counter()
    planes = case.planes

    k = contact_stiffness(model, options, case.penalty_factor)
    slip = float(model.parameters.get("tool_slip_mm", 0.1))
    # Every ply against every tool: the punch on ply 1 only and the die on the last ply took
    # 13 % less CPU on four plies, none on two, and let the die squeeze a stack whose gap is
    # one ply's (docs/laminates.md, Speed).
    contact = [PenaltyContact(built[t.name], k, friction=μ_t, slip_regularisation_mm=slip)
               for t in case.tools if t.role in CONTACT_ROLES]
    plies = interply = None
    if case.stack:  # every ply its own net, laid on ply 1 (z = 0) from the punch side
        from fenicsx_drape.fe.plies import PlyContact, stack_plies, stack_sheet

        grids = [b.grid() for b in case.ply_blanks()]
        plies = stack_plies(grids, [p.thickness_mm for p in case.plies])
        interply = PlyContact(plies, case.interply_law(model), k)
    holder = None
    if case.holder is not None:
        h = case.holder
        axes = tuple({"x": 0, "y": 1}[p] for p in planes)
        if plies is None:
            holder = BlankHolder(model.laws()["friction"], surface=holder_surface,
                                 force_N=h.force_N, force_share=h.force_share,
                                 clamp_stiffness_N_per_mm=k, symmetry_axes=axes)
        else:
            holder = StackHolder(model.laws()["friction"], heights_mm=[p.z_mm for p in plies],
                                 surface=holder_surface, force_N=h.force_N,
                                 force_share=h.force_share, clamp_stiffness_N_per_mm=k,
                                 symmetry_axes=axes)
    if plies is None:
        grid = case.blank.grid()  # the same on every rank (plain NumPy)
        sheet = grid_to_sheet(grid, comm)
    else:
        grid = plies[0].grid
        sheet = stack_sheet(plies, comm)
    terms = [*contact, *([holder] if holder is not None else [])]
    punches = [c.tool for c, t in zip(contact, (t for t in case.tools if t.role in CONTACT_ROLES))
               if t.role == "punch"]
    if planes != ("x", "y") and not case.blank.hold_origin and len(punches) == 1:
        # The sheet's sliding mode held (stick.py): one ply's node, or each ply's point, at
        # the punch's first contact.
        terms.append(ApexStick(punches[0], k) if plies is None
                     else PlyStick(punches[0], k, plies))
    if interply is not None:
        terms.append(interply)
    if case.stabilisation_N_per_mm:
        terms.append(ExtrapolationSpring(case.stabilisation_N_per_mm, sheet_normal(contact)))
    problem = TrussProblem(sheet, model, terms, options, ply_models=ply_models(case))
    if planes == ("x", "y"):
        problem.symmetry()
    elif planes:
        problem.fix(f"symmetry_{planes[0]}", ({"x": 0, "y": 1}[planes[0]],))
    if case.blank.hold_origin:
        origin = np.hypot(*(problem.X[:, :2] - case.blank.origin_mm).T) <= 1e-6 * grid.cell_mm
        if comm.allreduce(int(origin[: problem.num_owned].sum())) != len(plies or [0]):
            raise CaseError([f"{where(case)}: hold_origin: no node of the net at "
                             f"origin_mm = {list(case.blank.origin_mm)} (inside the blank)"])
        problem.fix(origin, (0, 1))

    def report(step) -> None:
        if progress is not None and comm.rank == 0:
            travel = case.travel_mm(step.time_s)
            state = "ok" if step.converged else f"cut back ({step.reason})"
            # Time left at the rate so far (wall time per mm of travel).
            spent = time.perf_counter() - stepping
            left = (f"  ~{duration_text(spent * (size['travel_mm'] - travel) / travel)} left"
                    if travel > 0 and step.converged else "")
            progress(f"step {len(problem.steps):4d}  t = {step.time_s:7.3f} s  travel = "
                     f"{travel:6.2f} mm  Newton {step.iterations:2d}  {state}{left}")

    touched = False  # whether a node ever touched a punch, die or surface
    forces_of_tools = record_tool_forces(case, problem, contact, holder)

    def after_step(problem) -> None:
        nonlocal touched
        forces_of_tools(problem)
        if not touched:
            x = problem.positions()[: problem.num_owned]
            touched = any(bool(np.any(c.penetration(x, problem.t) > 0.0)) for c in contact)
        if on_step is not None:
            on_step(problem)

    dt = case.step_mm / case.max_speed_mm_per_s
    stopped = None
    stepping = time.perf_counter()
    try:
        problem.run(case.duration_s, dt, dt_max_s=dt, easy_iterations=15, progress=report,
                    on_step=after_step, failure_dir=failure_dir)
    except SolverError as error:
        if not allow_incomplete:
            raise
        stopped = str(error)
    if contact and stopped is None and not comm.allreduce(touched, op=MPI.LOR):
        names = ", ".join(repr(t.name) for t in case.tools if t.role in CONTACT_ROLES)
        warnings.warn(f"{where(case)}: no node of the blank touched {names} in "
                      f"{case.travel_mm(problem.t):g} mm of travel; check the tools' start "
                      "positions and motions", stacklevel=2)
    both = planes == ("x", "y")
    symmetry = None if both or not planes else planes
    if plies is None:
        res = problem.results()
        formed = FormedGrid(res.X, res.x, both, symmetry)
        formed_plies = []
    else:
        from fenicsx_drape.fe.output import ply_results

        formed_plies = [FormedGrid(r.X, r.x, both, symmetry)
                        for r in (ply_results(problem, j) for j in range(len(plies)))]
        # The ply away from the punch (the side a camera sees), carrying every ply's sheet.
        formed = dataclasses.replace(formed_plies[-1], plies=tuple(formed_plies))
    x = problem.positions()[: problem.num_owned]
    t = problem.t
    depth = max((float(c.penetration(x, t).max(initial=0.0)) for c in contact), default=0.0)
    run = RunReport(problem.steps)  # every attempt, also when the run stopped short
    return FormingRun(
        case=case, grid=formed, problem=problem, steps=len(run.accepted), cutbacks=run.cutbacks,
        iterations=run.iterations, wall_time_s=time.perf_counter() - start,
        max_penetration_mm=comm.allreduce(depth, op=MPI.MAX),
        draw_in_mm=draw_in(formed) if case.blank.outline == "rectangle" else None,
        edge_displacement_mm=edge_displacement(formed), contact=contact, holder=holder,
        tools=built, stopped=stopped, tool_forces=forces_of_tools.rows, plies=formed_plies,
        interply=interply)


def tool_direction(case: FormingCase, name: str) -> np.ndarray:
    """The unit direction a tool moves (its motion from start to end), else the case's travel.

    A fixed tool (die, holder) is measured along the travel of the case's fastest tool.
    """
    specs = {t.name: t for t in case.tools}
    order = sorted(case.tools, key=lambda t: -case.speed_mm_per_s(t))
    for spec in ([specs[name]] if name in specs else []) + order:
        m = spec.motion
        if m is not None:
            d = m.translation(m.time_s[-1]) - m.translation(m.time_s[0])
            if np.linalg.norm(d) > 0:
                return d / np.linalg.norm(d)
    return np.array([0.0, 0.0, 1.0])


def record_tool_forces(case: FormingCase, problem, contact, holder):
    """A step callback recording the force of every tool along its motion (whole part, N).

    The force a tool exerts on the sheet is the sum of its nodal term's forces at the
    converged state (the last evaluation of a step); its component along the tool's motion
    (:func:`tool_direction`) is the press force that drives it (the punch's is positive).
    A quarter or half model's sum is weighted by node (½ on a symmetry plane, ¼ on both)
    and multiplied by the number of parts, so the figure is the whole part's. The callback's
    ``rows`` hold one dict per converged step: ``time_s``, ``travel_mm`` and each tool's name.
    """
    from mpi4py import MPI

    planes = case.planes
    X = problem.X[: problem.num_owned]
    weight = np.ones(len(X))
    for p in planes:
        weight *= np.where(np.abs(X[:, {"x": 0, "y": 1}[p]]) < 1e-9, 0.5, 1.0)
    weight *= 2 ** len(planes)
    terms = {c.tool.name: c for c in contact}
    if holder is not None and case.holder is not None:
        terms[case.holder.tool] = holder
    last: dict[str, np.ndarray] = {}
    for name, term in terms.items():
        forces = term.forces

        def recorded(x, t, dt, _forces=forces, _name=name):
            f, K = _forces(x, t, dt)
            last[_name] = f
            return f, K

        term.forces = recorded
    directions = {name: tool_direction(case, name) for name in terms}

    def callback(problem) -> None:
        row = {"time_s": float(problem.t), "travel_mm": float(case.travel_mm(problem.t))}
        for name, d in directions.items():
            f = last.get(name)
            local = 0.0 if f is None else float((weight * (f[: len(X)] @ d)).sum())
            row[name] = problem.comm.allreduce(local, op=MPI.SUM)
        callback.rows.append(row)

    callback.rows = []
    return callback


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
    x = max, y = max (for a ply at an angle, on its ragged edge).
    """
    X, x = grid.X[..., :2], grid.x[..., :2]
    a, b = np.nanmax(X[..., 0]), np.nanmax(X[..., 1])

    def inward(target: tuple[float, float]) -> float:
        d = np.linalg.norm(X - target, axis=-1)
        k = np.unravel_index(np.nanargmin(d), d.shape)
        return float(np.linalg.norm(X[k]) - np.linalg.norm(x[k]))

    return {"mid_side_mm": inward((a, 0.0)), "corner_mm": inward((a, b))}


def free_edge(grid: FormedGrid) -> np.ndarray:
    """Mask (n_i, n_j) of the nodes on the blank's free edge (not on a symmetry plane)."""
    cells = np.pad(np.isfinite(grid.shear_deg()), 1)
    if "x" in grid.planes:
        cells[0, :] = cells[1, :]
    if "y" in grid.planes:
        cells[:, 0] = cells[:, 1]
    whole = cells[:-1, :-1] & cells[1:, :-1] & cells[:-1, 1:] & cells[1:, 1:]
    return grid.present & ~whole


def edge_displacement(grid: FormedGrid) -> dict[str, float]:
    """In-plane displacement (mm) of the blank's free edge: largest and mean (draw-in)."""
    edge = free_edge(grid)
    u = np.linalg.norm((grid.x - grid.X)[..., :2][edge], axis=-1)
    if not len(u):
        return {"max_mm": 0.0, "mean_mm": 0.0}
    return {"max_mm": float(u.max()), "mean_mm": float(u.mean())}
