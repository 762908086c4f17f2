"""The implicit truss solver: one load step by PETSc SNES around DOLFINx assembly.

:class:`TrussProblem` owns the displacement, the material state at the quadrature points, the
Dirichlet conditions and the nodal terms (contact, blank holder: :mod:`fenicsx_drape.nodal`).
SNES, set up by :mod:`~fenicsx_drape.fe.newton`, evaluates the material laws at every iterate
and assembles the residual and the consistent Jacobian; a converged step commits the history of
the laws and of the nodal terms, a failed one reverts both. Load stepping with cut-back is in
:mod:`~fenicsx_drape.fe.stepping`, outputs in :mod:`~fenicsx_drape.fe.output`.

Two choices make the Newton iteration of forming robust without changing its solution
(the residual is exact, only the path to its zero changes):

- **The geometric stiffness is limited** to the largest bar force of the last converged step
  (``limit_geometric_stiffness``). A Newton step that straightens a buckled tow or rotates a
  stiff one stretches it, and the stretched tow carries tens of newtons for one iterate
  (l_t E_o = 2.4 kN per unit strain) where converged tows carry 1-3 N; its geometric stiffness
  S/L then pins its nodes in every direction and slows the next iterations. Near convergence
  no bar exceeds the limit and the Jacobian is exact: Newton converges quadratically. On the
  hemisphere it saves 12 % of the iterations at Δ = 10 mm, 22 % at 5 mm.
- **The predictor** extrapolates the last increment and lets the nodal terms project it
  (contact keeps pressed nodes on their gap, :mod:`~fenicsx_drape.forming.terms.contact`).

A nodal term with a ``pattern`` (the ply contact of a stack, :mod:`~fenicsx_drape.fe.plies`)
couples nodes: its 3 × 3 blocks (``values``) go to the Jacobian on that pattern (rows the owned
nodes, columns global node indices, so partners on other ranks too), added to the matrix's
once.

Nodes are the blocks of the vector P1 space in its local order (owned nodes first, then
ghosts); that is the order of every nodal array this module hands out or takes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import time
from collections.abc import Callable, Mapping, Sequence

from mpi4py import MPI
from petsc4py import PETSc

import dolfinx
import dolfinx.fem.petsc as fem_petsc
import numpy as np

from fenicsx_drape import nodal
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.fe.bending import TowBending
from fenicsx_drape.fe.constraints import Constraints
from fenicsx_drape.fe.coupling import ShearTensionCoupling
from fenicsx_drape.fe.grid import NODE_FLAGS, WARP, WEFT
from fenicsx_drape.fe.kinematics import truss_forms
from fenicsx_drape.fe.mesh import Sheet
from fenicsx_drape.fe.newton import LINE_SEARCHES, Iterate, Newton, NewtonResult
from fenicsx_drape.fe.plies import ply_of, sheet_grids
from fenicsx_drape.fe.state import MaterialState, StrainError
from fenicsx_drape.fe.stepping import StepReport, run
from fenicsx_drape.materials.base import MaterialLaw

_ids = itertools.count()
_default_monitors: list[Callable] = []  # monitors given to problems built inside monitoring()


@contextlib.contextmanager
def monitoring(monitor: Callable[[TrussProblem, Iterate], None]):
    """Hand ``monitor(problem, iterate)`` every Newton iterate of the problems built inside.

    A diagnostic hook (``benchmarks/diagnose_stepping.py``) that needs no change where the
    problem is built (a forming case)::

        with monitoring(probe):
            run_case(load_case("hemisphere"))
    """
    _default_monitors.append(monitor)
    try:
        yield monitor
    finally:
        _default_monitors.remove(monitor)


SINGLE_PRECISION_FACTOR = {
    "pc_precision": "single", "ksp_type": "gmres", "ksp_pc_side": "right",
    "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-3, "ksp_atol": 0.0, "ksp_max_it": 30}
"""``petsc_options`` that factorise the Jacobian in single precision (PETSc's mixed-precision
MUMPS) and solve to 10⁻³ with GMRES on that factor: 7-15 % faster on the hemisphere
(docs/solver-notes.md). Alone the single factor solves the forming Jacobians to
about 10⁻¹."""


BENDING_JACOBIANS = ("auto", "full", "diagonal", "preconditioner")
STACK_SOLVERS = ("plies", "direct")
"""``SolverOptions.stack_solver``: how a stack's linear solves go (fe/stack_solver.py)."""
"""``SolverOptions.bending_jacobian``: how the tow bending's stencils enter Newton's solve."""

SPLIT_FROM_NODES = 500
"""``bending_jacobian = "auto"``: a sheet of more nodes than this, or a stack of plies, solves
with ``"preconditioner"``, a smaller one with ``"full"``. On the hemisphere, idle machine:
1.8 s either way at 169 nodes, 5.7 → 4.5 s at 625, 23.8 → 18.9 s at 2401, 111.1 → 85.3 s at
9409; two and four plies of the double dome 10 and 26 % faster (docs/solver-notes.md)."""

BENDING_PRECONDITIONER = {
    "ksp_type": "gmres", "ksp_pc_side": "right", "ksp_norm_type": "unpreconditioned",
    "ksp_rtol": 1e-5, "ksp_atol": 0.0, "ksp_max_it": 100, "ksp_gmres_restart": 100,
    "ksp_gmres_modifiedgramschmidt": ""}
"""The Krylov solve of ``bending_jacobian = "preconditioner"`` (``petsc_options`` override
it): GMRES on the full Jacobian to 10⁻⁵ of the residual, right-preconditioned by the factor of
the plain net's matrix, so that Newton's step is the full Jacobian's to that accuracy.
Modified Gram-Schmidt: with GMRES's default (classical, its dot products in one VecMDot) the
same run gave different last digits from one time to the next (1 in 4 on the 10 mm quarter
hemisphere); a few Krylov iterations a solve make the cost of the sequential dots nil."""


@dataclasses.dataclass
class SolverOptions:
    """Options of the truss model and of its solver.

    The first five are part of the *model* (they change results); halving the last three and
    reporting the change is how their effect is stated (see ``benchmarks/bench_fe.py``).
    """

    tows_per_mm: float = 0.71  # l_t, tows per mm in warp and weft (Table 1: 7.1 tows/cm)
    # Tow bars on a free edge or a symmetry edge stand for half a strip of tows, so a sheet
    # of width W holds l_t·W tows (a patch pulled along the tows gives the tensile force).
    edge_tow_factor: float = 0.5
    buckled_tow_stiffness_N: float = 0.04  # residual stiffness of buckled tows (N/tow), state.py
    tow_bending_EI_Nmm2: float = 2.0  # bending stiffness of one tow (N·mm²), bending.py
    drag_N_per_mm: float = 0.0  # pseudo-viscous drag c (u - u_n) per node: numerical damping
    snes_atol: float = 1e-8  # absolute residual tolerance (N)
    snes_rtol: float = 1e-9  # relative residual tolerance
    # Converged also when no unknown carries an out-of-balance force above this (N; 0: off);
    # fe/newton.py. Unlike snes_atol it does not tighten as the mesh is refined.
    node_atol_N: float = 0.0
    snes_max_it: int = 25  # Newton iterations before a step is cut back
    line_search: str = "full-l2"  # full-l2 or a PETSc line search (l2, bt, ...): fe/newton.py
    linear_solver: str = "mumps"  # LU factorisation package (mumps, superlu_dist, petsc)
    # The geometric stiffness takes the bar forces limited to the largest force of the last
    # converged step (solver docstring); the residual, hence the solution, is unchanged.
    limit_geometric_stiffness: bool = True
    predictor: bool = True  # extrapolate the last increment, then let nodal terms project
    # The tow bending's part of the Jacobian (the residual, hence the solution, keeps the full
    # term): "full" (its stencils, factored), "diagonal" (K's diagonal only: a plain net's
    # pattern), or "preconditioner" (the full Jacobian as GMRES's operator, preconditioned by
    # the factor of the plain net's matrix with K's neighbour couplings, the couplings two
    # nodes apart lumped on the diagonal: BENDING_PRECONDITIONER); "auto" chooses between the
    # last and "full" by the sheet's size (SPLIT_FROM_NODES).
    bending_jacobian: str = "auto"
    # A stack of plies: "direct" factors the whole stack (its Jacobian); "plies" solves with
    # GMRES preconditioned by each ply's own factor and the stack moving as one
    # (fe/stack_solver.py: fewer flops, more time, docs/laminates-internals.md).
    stack_solver: str = "direct"
    # Extra SNES/KSP/PC options (those of the command line, fe.newton.set_petsc_options, win).
    petsc_options: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        for name in ("tows_per_mm", "snes_atol"):
            if not getattr(self, name) > 0:
                raise DrapeInputError(f"solver option {name} = {getattr(self, name)} must be > 0")
        if self.bending_jacobian not in BENDING_JACOBIANS:
            raise DrapeInputError(f"solver option bending_jacobian = {self.bending_jacobian!r}: "
                                  f"choose from {', '.join(BENDING_JACOBIANS)}")
        if self.stack_solver not in STACK_SOLVERS:
            raise DrapeInputError(f"solver option stack_solver = {self.stack_solver!r}: choose "
                                  f"from {', '.join(STACK_SOLVERS)}")
        if self.line_search not in LINE_SEARCHES:
            raise DrapeInputError(f"solver option line_search = {self.line_search!r}: choose "
                                  f"from {', '.join(LINE_SEARCHES)}")
        for name in ("edge_tow_factor", "buckled_tow_stiffness_N", "tow_bending_EI_Nmm2",
                     "drag_N_per_mm", "node_atol_N"):
            if not getattr(self, name) >= 0:
                raise DrapeInputError(f"solver option {name} = {getattr(self, name)} must be "
                                      ">= 0")


Where = str | np.ndarray | Callable[[np.ndarray], np.ndarray]


class TrussProblem:
    """The truss sheet, its laws, constraints and nodal terms, solved step by step.

    Args:
        sheet: The mesh and its tags (:func:`~fenicsx_drape.fe.mesh.truss_sheet`).
        model: A :class:`~fenicsx_drape.model.Model` (its ``laws(conditions)`` gives the law
            of each role) or a mapping ``{"tow": law, "shear": law}``.
        nodal_terms: Contact, holder or other :class:`~fenicsx_drape.nodal.NodalTerm` s.
        options: Model and solver options.
        conditions: Test conditions handed to ``model.laws`` (e.g. ``temperature_C``).
        ply_models: A stack (``sheet.plies``): per ply, a model of its own (its tow and shear
            laws replace ``model``'s on that ply's bars) or None (``model``'s).

    Example::

        problem = TrussProblem(sheet, default_model())
        problem.symmetry()
        problem.fix("border", (0,), lambda t: 0.1 * t)
        problem.run(10.0, 0.5)
        res = problem.results()
    """

    def __init__(self, sheet: Sheet, model, nodal_terms: Sequence[nodal.NodalTerm] = (),
                 options: SolverOptions | None = None,
                 conditions: Mapping[str, float] | None = None,
                 ply_models: Sequence | None = None):
        self.sheet = sheet
        self.options = options = options or SolverOptions()
        laws: Mapping[str, MaterialLaw] = (model.laws(conditions) if hasattr(model, "laws")
                                           else dict(model))
        self.laws = laws
        mesh = sheet.mesh
        self.comm: MPI.Comm = mesh.comm
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
        self.V = V
        self.u = dolfinx.fem.Function(V, name="displacement_mm")
        self._u_n = self.u.x.array.copy()  # last converged displacement
        self._du_n: np.ndarray | None = None  # last converged increment (predictor)
        index_map = V.dofmap.index_map
        self.num_owned = index_map.size_local
        self.X = V.tabulate_dof_coordinates().copy()  # reference node positions (mm)
        self.owned = np.arange(len(self.X)) < self.num_owned
        self.node_flags = self._node_flags()

        kinds, tows = self._bars()
        own_laws = self._ply_laws(ply_models, conditions)
        self.state = MaterialState(self.u, kinds, tows, laws, options.buckled_tow_stiffness_N,
                                   own_laws)
        self._coupling = None
        if "shear_tension_coupling" in getattr(model, "effects", ()) or any(
                "shear_tension_coupling" in m.effects for m in ply_models or () if m):
            if own_laws:
                raise DrapeInputError("shear_tension_coupling acts with one model for the "
                                      "whole sheet, not with plies of their own models")
            if sheet.grid is None:
                raise DrapeInputError("shear_tension_coupling needs the unit cells of a "
                                      "structured sheet (truss_sheet)")
            self._coupling = ShearTensionCoupling(self, model.parameters["k_st"])
        residual, jacobian = truss_forms(self.u, self.state.S, self.state.dS,
                                         self.state.S_geometric)
        self.residual_form = dolfinx.fem.form(residual)
        self.jacobian_form = dolfinx.fem.form(jacobian)
        self.constraints = Constraints(V, self.X)

        self.nodal_terms = list(nodal_terms)
        for term in self.nodal_terms:
            term.bind(self.X.copy(), self.owned.copy(), self.comm)
        self.t = 0.0
        self.dt = 0.0
        self.steps: list[StepReport] = []
        # Wall time (s) spent in the parts of the solve, summed over all steps.
        self.timings = dict.fromkeys(("material", "nodal", "residual", "jacobian", "solve"), 0.0)
        self._evaluated_at: np.ndarray | None = None
        self._nodal_f = np.zeros((len(self.X), 3))
        self._nodal_K = np.zeros((len(self.X), 3, 3))
        self._geometric_limit_N = np.inf
        # Called with (problem, Iterate) at every Newton iterate (diagnostics; None: off).
        self.monitor: Callable[[TrussProblem, Iterate], None] | None = (
            _default_monitors[-1] if _default_monitors else None)
        self._A = fem_petsc.create_matrix(self.jacobian_form)
        self._b = fem_petsc.create_vector(self.V)
        self._x = fem_petsc.create_vector(self.V)
        # Terms whose stiffness couples nodes (plies of a stack): blocks on their pattern.
        self._couplings = [t for t in self.nodal_terms if hasattr(t, "pattern")]
        if self._couplings:
            self._setup_couplings()
        self._bending = None
        self._bending_in_A: tuple[PETSc.Mat, PETSc.Mat | PETSc.Vec] | None = None
        self.bending_jacobian = options.bending_jacobian  # "auto" resolved
        if self.bending_jacobian == "auto":
            large = self.comm.allreduce(self.num_owned) > SPLIT_FROM_NODES or bool(sheet.plies)
            self.bending_jacobian = "preconditioner" if large else "full"
        if options.tow_bending_EI_Nmm2 > 0 and (sheet.grid is not None or sheet.plies):
            self._setup_bending()
        self._setup_newton()

    # -- geometry and selections -------------------------------------------------------

    def _node_flags(self) -> np.ndarray:
        flags = np.zeros(len(self.X), dtype=np.int32)
        tags = self.sheet.node_tags
        if tags is not None:
            # locate_dofs_topological is collective: loop over the values of all ranks.
            values = set().union(*self.comm.allgather(set(np.unique(tags.values).tolist())))
            for value in sorted(values):
                vertices = tags.find(value)
                nodes = dolfinx.fem.locate_dofs_topological(self.V, 0, vertices)
                flags[nodes] |= int(value)
        return flags

    def _bars(self) -> tuple[np.ndarray, np.ndarray]:
        """Kind and number of tows ``n_t`` of every owned bar."""
        mesh, opts = self.sheet.mesh, self.options
        n = mesh.topology.index_map(1).size_local
        kinds = np.zeros(n, dtype=np.int32)
        tags = self.sheet.bar_tags
        owned = tags.indices < n
        kinds[tags.indices[owned]] = tags.values[owned]
        if (kinds == 0).any():
            raise DrapeInputError("the sheet has bars without a kind tag")
        # n_t = l_t Δ (NOTES.md: the printed l_t/Δ is a typo); half on edge tows, the tow
        # bars with a unit cell on one side only (sheet edges, symmetry edges, ragged edges
        # of a clipped net).
        tows = np.full(n, opts.tows_per_mm * self.sheet.cell_mm)
        nodes = mesh.geometry.dofmaps[0][:n]
        middle = mesh.geometry.x[nodes].mean(axis=1)
        for grid, on in sheet_grids(self.sheet, middle):  # each ply of a stack on its own
            ij = grid.grid_coordinates(middle)
            lo, near = np.floor(ij).astype(int), np.rint(ij).astype(int)  # a bar's (i, j)
            warp, weft = on & (kinds == WARP), on & (kinds == WEFT)
            warp_cells, weft_cells = grid.tow_bar_cells()
            sides = np.zeros(n, dtype=int)
            sides[warp] = warp_cells[lo[warp, 0], near[warp, 1]]
            sides[weft] = weft_cells[near[weft, 0], lo[weft, 1]]
            tows[sides == 1] *= opts.edge_tow_factor
        return kinds, tows

    def _ply_laws(self, ply_models: Sequence | None, conditions
                  ) -> list[tuple[np.ndarray, Mapping[str, MaterialLaw]]]:
        """The owned bars of each ply with a model of its own, and that model's laws."""
        if not ply_models or not any(ply_models):
            return []
        plies = self.sheet.plies
        if not plies or len(ply_models) != len(plies):
            raise DrapeInputError(f"ply_models: {len(ply_models)} models for a sheet of "
                                  f"{len(plies or [])} plies")
        mesh = self.sheet.mesh
        n = mesh.topology.index_map(1).size_local
        middle = mesh.geometry.x[mesh.geometry.dofmaps[0][:n]].mean(axis=1)
        which = ply_of(plies, middle)
        return [(which == k, m.laws(conditions)) for k, m in enumerate(ply_models) if m]

    def nodes(self, where: Where) -> np.ndarray:
        """Boolean mask of the local nodes selected by ``where``.

        ``where`` is ``"all"``, a node flag name (``"symmetry_x"``, ``"symmetry_y"``,
        ``"border"``), a boolean mask over the local nodes, or a function of the reference
        positions ``X`` (n, 3) returning such a mask.
        """
        if isinstance(where, str):
            if where == "all":
                return np.ones(len(self.X), dtype=bool)
            bits = {name: bit for bit, name in NODE_FLAGS.items()}
            if where not in bits:
                raise DrapeInputError(f"unknown node set {where!r} (choose from all, "
                                      f"{', '.join(bits)})")
            return (self.node_flags & bits[where]) != 0
        mask = np.asarray(where(self.X) if callable(where) else where, dtype=bool)
        if mask.shape != (len(self.X),):
            raise DrapeInputError(f"node selection shaped {mask.shape}, expected "
                                  f"({len(self.X)},) (the local nodes)")
        return mask

    def positions(self) -> np.ndarray:
        """Current positions ``x = X + u`` of the local nodes (n, 3) in mm."""
        return self.X + self.u.x.array.reshape(-1, 3)

    # -- Dirichlet conditions ----------------------------------------------------------

    def fix(self, where: Where, components: Sequence[int] = (0, 1, 2),
            value: float | Sequence[float] | Callable = 0.0) -> None:
        """Prescribe displacement components (0 = x, 1 = y, 2 = z) on a node set.

        Args:
            where: The nodes (see :meth:`nodes`).
            components: Which displacement components are prescribed.
            value: Displacement in mm: a number or one per component, or a function of time
                ``value(t)``, or of time and reference positions ``value(t, X)`` returning an
                array broadcastable to (n_selected, len(components)).
        """
        self.constraints.add(self.nodes(where), components, value)
        if self._bending is not None:
            self._bending.constrain(self)

    def symmetry(self) -> None:
        """The symmetry conditions of a quarter model: u_x = 0 on x = 0, u_y = 0 on y = 0."""
        self.fix("symmetry_x", (0,))
        self.fix("symmetry_y", (1,))

    @property
    def constrained(self) -> np.ndarray:
        """Which displacement components of the local nodes are prescribed, (n, 3)."""
        return self.constraints.constrained

    # -- SNES -----------------------------------------------------------------------------

    def _setup_newton(self) -> None:
        opts = self.options
        split = self._bending is not None and self.bending_jacobian == "preconditioner"
        contact = next((t for t in self._couplings if hasattr(t, "first_ply_map")), None)
        plies = opts.stack_solver == "plies" and contact is not None
        krylov = split or plies
        options = {"pc_factor_mat_solver_type": opts.linear_solver,
                   **(BENDING_PRECONDITIONER if krylov else {}), **opts.petsc_options}
        operator = self._operator() if split else self._A
        self.newton = Newton(self._residual, self._jacobian, operator, self._b,
                             P=self._A if krylov else None,
                             prefix=f"drape_truss_{next(_ids)}_", atol=opts.snes_atol,
                             rtol=opts.snes_rtol, max_it=opts.snes_max_it,
                             node_atol=opts.node_atol_N, line_search=opts.line_search,
                             options=options, monitor=self._monitor)
        self.stack_preconditioner = None
        if plies and "pc_type" not in opts.petsc_options:  # fe/stack_solver.py
            from fenicsx_drape.fe.stack_solver import PlyPreconditioner

            self.stack_preconditioner = PlyPreconditioner(self, contact, opts.linear_solver)
            pc = self.newton.snes.getKSP().getPC()
            pc.setType(PETSc.PC.Type.PYTHON)
            pc.setPythonContext(self.stack_preconditioner)

    def _monitor(self, iterate: Iterate) -> None:
        if self.monitor is not None:
            self.monitor(self, iterate)

    def _setup_couplings(self) -> None:
        """Add the coupling terms' patterns to the Jacobian's, once (zeros kept as entries).

        A coupling's ``pattern`` is CSR over the owned nodes, its columns global node
        indices (partners may live on any rank).
        """
        first = self.V.dofmap.index_map.local_range[0]
        self._owned_global = np.arange(first, first + self.num_owned, dtype=PETSc.IntType)
        A = self._A
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        fem_petsc.assemble_matrix(A, self.jacobian_form)
        A.assemble()
        for term in self._couplings:
            indptr, indices = term.pattern
            A.setValuesBlockedIJV(indptr, indices, np.zeros((len(indices), 3, 3)),
                                  PETSc.InsertMode.ADD_VALUES, rowmap=self._owned_global)
        A.assemble()
        A.zeroEntries()
        self._coupling_versions = [t.pattern_version for t in self._couplings]
        self._bending_in_A = None  # A's pattern changed: the bending's copy of it too

    def _couplings_grew(self) -> bool:
        """Whether a coupling term's pattern grew on any rank since the Jacobian took it.

        A pattern holds the rank's own rows, so it grows on the ranks whose rows the re-made
        pairs touch; taking it into the Jacobian assembles the matrix, which is collective,
        so every rank decides alike (a rank that alone re-allocated waited in the assembly
        while the others had gone on: the stack under mpirun hung).
        """
        grew = self._coupling_versions != [t.pattern_version for t in self._couplings]
        return self.comm.allreduce(grew, op=MPI.LOR) if self.comm.size > 1 else grew

    def _add_couplings(self, A: PETSc.Mat) -> None:
        """Add the coupling terms' blocks, without the rows and columns of constrained dofs."""
        free = ~self.constrained[: self.num_owned]
        free_all = free if self.comm.size == 1 else np.concatenate(self.comm.allgather(free))
        masks = self.__dict__.setdefault("_coupling_masks", {})  # by term: (key, mask)
        for k, term in enumerate(self._couplings):
            indptr, indices = term.pattern
            key = (term.pattern_version, free_all.tobytes())  # a mask per pattern
            if masks.get(k, (None,))[0] != key:
                rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
                masks[k] = (key, free[rows][:, :, None] & free_all[indices][:, None, :])
            values = term.values * masks[k][1]
            A.setValuesBlockedIJV(indptr, indices, values, PETSc.InsertMode.ADD_VALUES,
                                  rowmap=self._owned_global)

    def _setup_bending(self) -> None:
        """The tow bending term, and a Jacobian whose pattern also holds its stencils.

        The stencils couple nodes two apart along a tow line, outside the form's sparsity:
        the Jacobian gets the union of both patterns, allocated once.
        """
        self._bending = TowBending(self, self.options.tow_bending_EI_Nmm2)
        if self.bending_jacobian != "full":  # the form's pattern is enough
            return
        fem_petsc.assemble_matrix(self._A, self.jacobian_form)
        self._A.assemble()
        A = self._A.duplicate(copy=True)
        A.axpy(1.0, self._bending.matrix, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        A.setLGMap(*self._A.getLGMap())
        A.zeroEntries()
        self._A.destroy()
        self._A = A

    def _add_bending(self, A: PETSc.Mat) -> None:
        """Add the constant bending matrix to the Jacobian ``A``.

        It is kept in ``A``'s own pattern (rebuilt when the constraints change), so the sum
        is a plain pass over the values: ten times faster than adding it on its own pattern.
        """
        source = self._bending.constrained_matrix
        if self.bending_jacobian == "diagonal":
            if self._bending_in_A is None or self._bending_in_A[0] is not source:
                self._bending_in_A = (source, source.getDiagonal())
            A.setDiagonal(self._bending_in_A[1], addv=PETSc.InsertMode.ADD_VALUES)
            return
        if self.bending_jacobian == "preconditioner":
            A.axpy(1.0, self._bending_split()[0], PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            return
        if self._bending_in_A is None or self._bending_in_A[0] is not source:
            same = A.duplicate(copy=False)
            same.axpy(1.0, source, PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self._bending_in_A = (source, same)
        A.axpy(1.0, self._bending_in_A[1], PETSc.Mat.Structure.SAME_NONZERO_PATTERN)

    def _bending_split(self) -> tuple[PETSc.Mat, PETSc.Mat]:
        """K = near + far, constraints applied (``bending_jacobian = "preconditioner"``).

        ``near`` (in ``self._A``'s pattern) holds K's couplings of nodes that a bar joins (a
        tow line's neighbours) and, on the diagonal, each row's other entries lumped (so that
        near, like K, costs nothing under a rigid motion and is positive semidefinite: per
        stencil, twice the Laplacian of the path a-b-c); ``far`` the rest (the couplings of
        nodes two apart, less that lumping). Rebuilt when the constraints change.
        """
        K = self._bending.constrained_matrix
        parts = getattr(self, "_bending_parts", None)
        if self._bending_in_A is not None and self._bending_in_A[0] is K:
            return self._bending_in_A[1], self._bending_in_A[2]
        if parts is not None and parts[0] is K:
            # Only A's pattern grew (the coupling terms' blocks join nodes of two plies, K's
            # stencils nodes of one ply): the split stands, its copy in A's pattern is remade.
            near_in_A = self._A.duplicate(copy=False)
            near_in_A.axpy(1.0, parts[1], PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self._bending_in_A = (K, near_in_A, parts[2])
        else:
            first = K.getOwnershipRange()[0]
            ki, kj, kv = K.getValuesCSR()
            ai, aj, _ = self._A.getValuesCSR()
            n, width = len(ki) - 1, K.getSize()[1]
            rows = np.repeat(np.arange(n), np.diff(ki))
            in_A = np.isin(rows * width + kj,
                           np.repeat(np.arange(n), np.diff(ai)) * width + aj)
            diagonal = kj == rows + first
            lumped = np.bincount(rows, np.where(in_A, 0.0, kv), minlength=n)
            near = np.where(in_A, kv, 0.0) + np.where(diagonal, lumped[rows], 0.0)
            far = kv - near
            keep = in_A | diagonal
            indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[keep], minlength=n))])
            sizes = K.getSizes()
            own = PETSc.Mat().createAIJ(sizes, csr=(indptr.astype(PETSc.IntType), kj[keep],
                                                    near[keep]), comm=self.comm)
            near_in_A = self._A.duplicate(copy=False)
            near_in_A.axpy(1.0, own, PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            rest = PETSc.Mat().createAIJ(sizes, csr=(ki, kj, far), comm=self.comm)
            self._bending_parts = (K, own, rest)
            self._bending_in_A = (K, near_in_A, rest)
        return self._bending_in_A[1], self._bending_in_A[2]

    def _operator(self) -> PETSc.Mat:
        """The full Jacobian as an operator: the assembled net (with K's near part) + K's far.

        ``bending_jacobian = "preconditioner"``: ``self._A`` holds a plain net's pattern and is
        what is factored; the Krylov solve applies this sum, so Newton's step is the full
        Jacobian's. The sum is applied, never formed (one extra product with K's stencils).
        """
        problem = self

        class FullJacobian:
            def mult(self, mat, x, y):
                problem._A.mult(x, y)
                problem._bending_split()[1].multAdd(x, y, y)

        J = PETSc.Mat().createPython(self._A.getSizes(), FullJacobian(), comm=self.comm)
        J.setBlockSize(3)
        J.setUp()
        return J

    def _evaluate(self, x: PETSc.Vec) -> bool:
        """Displacement, material state and nodal terms at the iterate ``x``.

        Returns False on every rank when a bar collapsed or a law failed on any rank.
        """
        x.ghostUpdate(PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        with x.localForm() as xl:
            self.u.x.array[:] = xl.array_r
        self._evaluated_at = self.u.x.array.copy()
        with self._timed("material"):
            try:
                self.state.evaluate(self.dt)
                ok = True
            except (StrainError, ValueError):
                ok = False
        if not self.comm.allreduce(ok, op=MPI.LAND):
            self._evaluated_at = None
            return False
        if self._coupling is not None:
            ratio = self.dt / self._dt_n if self._du_n is not None else 0.0
            self.state.scale_shear(self._coupling.predict(ratio))
        with self._timed("nodal"):
            n = len(self.X)
            f, K = np.zeros((n, 3)), np.zeros((n, 3, 3))
            xpos = self.positions()
            for term in self.nodal_terms:
                ft, Kt = term.forces(xpos, self.t + self.dt, self.dt)
                f += ft
                K += Kt
            c = self.options.drag_N_per_mm
            if c:
                f -= c * (self.u.x.array - self._u_n).reshape(-1, 3)
                K += c * np.eye(3)
            free = ~self.constrained
            self._nodal_f = f * free
            self._nodal_K = K * free[:, :, None] * free[:, None, :]
        return True

    @contextlib.contextmanager
    def _timed(self, part: str):
        start = time.perf_counter()
        try:
            yield
        finally:
            self.timings[part] += time.perf_counter() - start

    def _residual(self, x: PETSc.Vec, b: PETSc.Vec) -> bool:
        """Assemble the residual at ``x`` into ``b``; False (all ranks) outside the domain."""
        if not self._evaluate(x):
            return False  # a bar collapsed or a law failed: the line search backs off
        with self._timed("residual"):
            with b.localForm() as bl:
                bl.set(0.0)
            fem_petsc.assemble_vector(b, self.residual_form)
            bcs = self.constraints.bcs
            fem_petsc.apply_lifting(b, [self.jacobian_form], [bcs], x0=[x], alpha=-1.0)
            b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
            b.array_w[:] -= self._nodal_f[: self.num_owned].ravel()
            if self._bending is not None:
                b.array_w[:] += self._bending.force(x)
            fem_petsc.set_bc(b, bcs, x, -1.0)
        return True

    def _stale(self, x: PETSc.Vec) -> bool:
        """Whether ``x`` differs from the last evaluated iterate on any rank."""
        n = 3 * self.num_owned
        last = self._evaluated_at
        changed = last is None or not np.array_equal(x.array_r[:n], last[:n])
        return self.comm.allreduce(changed, op=MPI.LOR)

    def _jacobian(self, x: PETSc.Vec, local: bool = True) -> None:
        """Assemble the Jacobian at ``x`` into ``self._A``.

        Away from convergence (``local`` False) its geometric stiffness takes the bar forces
        limited to the largest force of the last step (``limit_geometric_stiffness``).
        """
        if self._stale(x):
            self._evaluate(x)
        self.state.limit_geometric_force(np.inf if local else self._geometric_limit_N)
        A = self._A
        with self._timed("jacobian"):
            if self._couplings and self._couplings_grew():
                self._setup_couplings()  # the pairs followed the plies: a larger pattern
            A.zeroEntries()
            fem_petsc.assemble_matrix(A, self.jacobian_form, bcs=self.constraints.bcs)
            A.assemble()
            n = self.num_owned
            if self._bending is not None:
                self._add_bending(A)
            if self.nodal_terms or self.options.drag_N_per_mm:
                A.setValuesBlockedLocalCSR(np.arange(n + 1, dtype=PETSc.IntType),
                                           np.arange(n, dtype=PETSc.IntType),
                                           self._nodal_K[:n].ravel(),
                                           PETSc.InsertMode.ADD_VALUES)
            if self._couplings:
                self._add_couplings(A)
            A.assemble()

    # -- stepping -----------------------------------------------------------------------

    def step(self, t: float) -> StepReport:
        """Solve for the equilibrium at time ``t`` (s) from the last converged state.

        A converged step commits the history of the laws and nodal terms; a failed one
        restores the last converged state (nothing is committed) and reports it.
        """
        dt = t - self.t
        if not dt > 0:
            raise ValueError(f"step to t = {t} s is not after the current time {self.t} s")
        self.dt = dt
        u = self.u.x.array
        u[:] = self._u_n
        if self.options.predictor and self._du_n is not None:
            u += self._du_n * (dt / self._dt_n)
        self.constraints.apply(t, self.u.x.array)
        if self.options.predictor and self.nodal_terms:
            projected = nodal.predict(self.nodal_terms, self.positions(), t) - self.X
            free = ~self.constrained.ravel()
            u[free] = projected.ravel()[free]
        self.u.x.scatter_forward()
        with self._x.localForm() as xl:
            xl.array_w[:] = u
        if self.options.limit_geometric_stiffness:  # the largest force of the last step
            top = self.comm.allreduce(self.state.largest_force(), op=MPI.MAX)
            self._geometric_limit_N = top if top > 0 else np.inf
        try:
            with self._timed("solve"):
                result = self.newton.solve(self._x)
        except PETSc.Error:
            result = NewtonResult(False, "DIVERGED_LINEAR_SOLVE", self.options.snes_max_it)
        finally:
            self.newton.release_options()  # the factor has read them
        converged = result.converged
        if converged:
            if self._stale(self._x):
                self._evaluate(self._x)
            self.state.commit()
            for term in self.nodal_terms:
                term.commit()
            if self._coupling is not None:
                self._coupling.commit()
            self._du_n = self.u.x.array - self._u_n
            self._dt_n = dt
            self._u_n = self.u.x.array.copy()
            self.t = t
        else:
            self.revert()
        report = StepReport(t, dt, converged, result.iterations, result.reason,
                            factorisations=result.jacobians,
                            krylov_iterations=result.krylov_iterations,
                            residual_evaluations=result.residual_evaluations)
        self.steps.append(report)
        return report

    def revert(self) -> None:
        """Return to the last converged state (displacement, laws, nodal terms)."""
        self.u.x.array[:] = self._u_n
        self._evaluated_at = None
        self.state.revert()
        for term in self.nodal_terms:
            term.revert()

    def run(self, duration_s: float, dt_s: float, **kwargs):
        """Step to ``t + duration_s`` with adaptive steps; see :func:`~.stepping.run`."""
        return run(self, self.t + duration_s, dt_s, **kwargs)

    # -- forces and results -------------------------------------------------------------

    def reaction_force(self, where: Where) -> np.ndarray:
        """Total force (3,) in N that the constraints exert on the selected nodes.

        It is the internal force of the bars minus the nodal-term forces at those nodes, at
        the last evaluated state, summed over all ranks.
        """
        mask = self.nodes(where)[: self.num_owned]
        b = fem_petsc.assemble_vector(self.residual_form)
        b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        r = b.array_r.reshape(-1, 3) - self._nodal_f[: self.num_owned]
        if self._bending is not None:
            r = r + self._bending.force(self.u.x.petsc_vec).reshape(-1, 3)
        b.destroy()
        return self.comm.allreduce(r[mask].sum(axis=0), op=MPI.SUM)

    def results(self):
        """Node positions, shear per unit cell, wrinkling per tow and totals (all ranks).

        See :func:`~fenicsx_drape.fe.output.results`.
        """
        from fenicsx_drape.fe.output import results

        return results(self)
