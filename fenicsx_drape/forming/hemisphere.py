"""The paper's hemisphere forming case (section 4): the truss sheet, the tools, the run.

A square sheet (240 mm, the 4×4 twill prepreg of Table 2) lies on the blank holder at z = 0;
the punch rises 80 mm in 40 s (2 mm/s) through the holder's 170 mm opening and draws the
sheet over its hemispherical nose into the matched die, against the friction of the holder
(133 N). One call, :func:`run_hemisphere`, sets it up on the FE core and runs it; outputs are
in :mod:`fenicsx_drape.forming.outputs`. It is the convenience API of one forming case,
``meshes/hemisphere/case.toml``: :meth:`HemisphereCase.to_case` gives the
:class:`~fenicsx_drape.forming.case.FormingCase` (builtin closed-form tools) and the run is
:func:`~fenicsx_drape.forming.run.run_case`'s.

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
  with the whole F over the quarter's own nodes (``holder_force_share = "model"``, the
  default: the reading that reproduces the paper's numbers, README issue 15) or F/4 on a
  quarter model (``"symmetric_part"``),
- the out-of-plane stabilisation of the slack net (:mod:`~fenicsx_drape.forming.stabilisation`),
- symmetry conditions u_x = 0 on x = 0 and u_y = 0 on y = 0 for a quarter model; the full
  sheet needs none (the holder's friction bars hold it in its plane).

Load steps move the punch ``step_mm`` (1 mm); a step whose Newton solve fails is halved, and
steps grow back (×1.5, up to ``step_mm``) after solves of at most 15 iterations. The solver's
residual tolerance is 1e-6 N (forces on a node are 0.01-1 N).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.forming.case import (
    BUILTIN,
    BlankSpec,
    FormingCase,
    HolderSpec,
    ToolSpec,
    broken_planes,
    with_overrides,
)
from fenicsx_drape.forming.holder import check_force_share, part_force_N
from fenicsx_drape.forming.run import (  # noqa: F401 (re-exported: the hemisphere's API)
    FormingRun,
    contact_stiffness,
    draw_in,
    run_case,
    sheet_normal,
)
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
    # Eq. 1's reading (issue 15): "model" (the whole F over the model's own nodes under the
    # holder; the default, chosen on the paper's numbers: README) or "symmetric_part" (a
    # quarter carries F/4, symmetry-plane nodes count ½).
    holder_force_share: str = "model"
    # The set-up as placed (issue 27): the blank (and its net) moved by [x, y] mm on the tools,
    # and the punch moved by [x, y] mm off the die and holder. Off the axes: the full sheet.
    blank_offset_mm: tuple[float, float] = (0.0, 0.0)
    tool_offset_mm: tuple[float, float] = (0.0, 0.0)

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
        if self.quarter and broken_planes(self.setup):
            text = ", ".join(f"{k} = {v}" for k, v in self.setup.items())
            raise ParameterError(f"hemisphere: {text} breaks the quarter symmetry; model the "
                                 "full sheet (quarter=False, drape form --full)")
        check_force_share(self.holder_force_share, "hemisphere: holder_force_share")

    @property
    def setup(self) -> dict:
        """The set-up overrides that differ from the paper's (ply angle and offsets)."""
        out = {"ply_angle_deg": self.ply_angle_deg, "blank_offset_mm": self.blank_offset_mm,
               "tool_offset_mm": self.tool_offset_mm}
        return {k: v for k, v in out.items() if np.any(np.asarray(v) != 0.0)}

    @property
    def speed_mm_per_s(self) -> float:
        """Punch speed (mm/s)."""
        return self.tools.travel_mm / self.duration_s

    @property
    def part_force_N(self) -> float:
        """Holding force the modelled part carries (F; a quarter F/4 if "symmetric_part")."""
        return part_force_N(self.holder_force_N, 2 if self.quarter else 0,
                            self.holder_force_share)

    def to_case(self) -> FormingCase:
        """The hemisphere as a forming case: builtin tools, the square sheet, the holder."""
        params = tuple((f.name, float(getattr(self.tools, f.name)))
                       for f in dataclasses.fields(HemisphereTools))
        tools = [ToolSpec("punch", "punch", BUILTIN, parameters=params)]
        if self.die:
            tools.append(ToolSpec("die", "die", BUILTIN, parameters=params))
        tools.append(ToolSpec("holder", "holder", BUILTIN, parameters=params))
        side = self.tools.sheet_mm
        blank = BlankSpec("rectangle", cell_mm=self.cell_mm, size_mm=(side, side),
                          ply_angle_deg=self.ply_angle_deg,
                          symmetry=("x", "y") if self.quarter else ())
        case = FormingCase(
            name="hemisphere", duration_s=self.duration_s, blank=blank, tools=tuple(tools),
            holder=HolderSpec("holder", self.holder_force_N,
                              force_share=self.holder_force_share),
            description="the paper's hemisphere (section 4)", step_mm=self.step_mm,
            penalty_factor=self.penalty_factor,
            stabilisation_N_per_mm=self.stabilisation_N_per_mm)
        offsets = {k: v for k, v in self.setup.items() if k != "ply_angle_deg"}
        return with_overrides(case, **offsets) if offsets else case


@dataclasses.dataclass
class HemisphereRun(FormingRun):
    """A finished hemisphere run (a :class:`~fenicsx_drape.forming.run.FormingRun`).

    Its ``case`` is the :class:`HemisphereCase`, ``forming_case`` the case it ran.
    """

    forming_case: FormingCase | None = None

    @property
    def travel_mm(self) -> float:
        """Punch travel reached (mm): the full travel unless the run stopped short."""
        return self.case.speed_mm_per_s * self.problem.t


def run_hemisphere(case: HemisphereCase | None = None, model=None, options=None, *,
                   progress: Callable[[str], None] | None = None,
                   on_step: Callable[[object], None] | None = None, comm=None,
                   allow_incomplete: bool = False, failure_dir=None) -> HemisphereRun:
    """Form the hemisphere: build the sheet, tools and terms, then step to full travel.

    The run is :func:`~fenicsx_drape.forming.run.run_case` of :meth:`HemisphereCase.to_case`.

    Args:
        case: The forming conditions (default: the paper's, on a 10 mm quarter model).
        model: The material :class:`~fenicsx_drape.model.Model` (default: the paper's).
        options: :class:`~fenicsx_drape.fe.solver.SolverOptions` of the truss.
        progress: Called with a line of text after every load step (rank 0 only).
        on_step: Called with the problem after every converged step (e.g. field output).
        comm: MPI communicator (default ``COMM_WORLD``).
        allow_incomplete: When a step fails at the smallest step, return the sheet at the
            last converged step (``stopped`` says why) instead of raising ``SolverError``.
        failure_dir: Where the last converged state is saved when a step fails.

    Returns:
        The formed sheet and the run's statistics.
    """
    from fenicsx_drape.model import default_model

    case = case or HemisphereCase()
    forming = case.to_case()
    run = run_case(forming, model or default_model(), options, progress=progress,
                   on_step=on_step, comm=comm, allow_incomplete=allow_incomplete,
                   failure_dir=failure_dir)
    fields = {f.name: getattr(run, f.name) for f in dataclasses.fields(FormingRun)}
    fields["case"] = case
    return HemisphereRun(**fields, forming_case=forming)


