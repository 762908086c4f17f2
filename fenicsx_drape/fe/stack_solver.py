"""The linear solve of a stack of plies: each ply's own factor and the stack moving as one.

A stack's Jacobian couples its plies only through the inter-ply contact (fe/plies.py), but
that coupling is as stiff as a tow along the normal: one factorisation of the whole stack
puts every ply's unknowns at each place into the same separators, and its cost grows about
as the cube of the number of plies. Factoring each ply alone (block Jacobi) costs a ply per
ply, but leaves each ply tied to the ground by the penalty that ties it to its neighbours:
the stack's common motion, soft, is what it gets most wrong. So the preconditioner of the
Krylov solve (GMRES on the full Jacobian) has two levels:

- **the stack moving as one** (the coarse level): the displacements of ply 1 carried to every
  ply by the point of ply 1 under each node (bilinear weights W, the plies' pairing made
  direct), ``u = R u₁``; the coarse matrix is Rᵀ J R, the stack's stiffness with its plies
  bonded, on ply 1's net (the size of one ply);
- **each ply on its own**: the ply's diagonal block of the Jacobian (its net, tools, holder
  and its share of the inter-ply penalty), factored alone.

Applied multiplicatively: z = R A_c⁻¹ Rᵀ r, then z += B⁻¹ (r − J z) with B the plies' blocks.
Each level factors matrices of one ply's size: k + 1 factorisations of a ply for k plies.

Measured (benchmarks/bench_laminates.py, the double dome's quarter at 10 mm, plies at 0°,
docs/laminates-internals.md): the factors' flops grow as the plies (10.6 and 14.2 Mflop for
two and four plies, against 14.4 and 125 for the stack's factor), but the Krylov iterations
grow too (5.6 and 21 a Newton iteration, against 2.1 and 2.2 on the stack's factor; eight
plies do not converge): the plies' friction holds them to each other more stiffly than a
woven ply resists its own shear (the trellis mode), so the plies' relative shear modes are a
stiff coupling across the stack that neither level resolves (sweeping the plies as symmetric
block Gauss-Seidel instead: 13.5 Krylov iterations a Newton iteration for four plies, each
dearer, and more CPU time). Its CPU time is 4.5 and 14.2 times one ply's for two and four
plies (the stack's factor: 3.0 and 7.3). It is the solver of
``SolverOptions(stack_solver="plies")``, not the default.
"""

from __future__ import annotations

from mpi4py import MPI
from petsc4py import PETSc

import numpy as np

from fenicsx_drape.fe.plies import ply_of


class PlyPreconditioner:
    """A petsc4py PCPYTHON context: the two levels of the module docstring.

    Args:
        problem: The :class:`~fenicsx_drape.fe.solver.TrussProblem` of a stack.
        contact: Its :class:`~fenicsx_drape.fe.plies.PlyContact` (the map to ply 1).
        solver: The LU package of the factors (``mumps``, ``petsc``, ...).
    """

    def __init__(self, problem, contact, solver: str = "mumps") -> None:
        self.problem, self.contact, self.solver = problem, contact, solver
        comm = problem.comm
        first = problem.V.dofmap.index_map.local_range[0]
        which = ply_of(problem.sheet.plies, problem.X[: problem.num_owned])
        self.plies = len(problem.sheet.plies)
        nodes = [first + np.flatnonzero(which == k) for k in range(self.plies)]
        self.sets = [PETSc.IS().createGeneral(
            (3 * n[:, None] + np.arange(3)).ravel().astype(PETSc.IntType), comm=comm)
            for n in nodes]
        self._blocks: list = [None] * self.plies
        self._solvers = [self._lu(f"ply{k}") for k in range(self.plies)]
        self._coarse_solver = self._lu("coarse")
        self._R = self._Ac = None
        self._version = None
        self.applications = 0  # times the preconditioner was applied (Krylov iterations)

    def _lu(self, name: str) -> PETSc.KSP:
        ksp = PETSc.KSP().create(self.problem.comm)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType(self.solver)
        return ksp

    def _prolongation(self) -> PETSc.Mat:
        """R (stack dofs × ply 1's dofs): ply 1 itself, every other node by its point on ply 1."""
        problem, comm = self.problem, self.problem.comm
        rows, cols, weights = self.contact.first_ply_map()  # global nodes; ply 1's (p, 4)
        start, end = problem.V.dofmap.index_map.local_range
        mine = (rows >= start) & (rows < end)
        rows, cols, weights = rows[mine], cols[mine], weights[mine]
        ply1 = self.contact.first_ply_nodes()  # global node indices of ply 1, in order
        coarse = np.full(int(ply1.max()) + 1 if len(ply1) else 0, -1)
        coarse[ply1] = np.arange(len(ply1))
        n1_local = int(np.count_nonzero((ply1 >= start) & (ply1 < end)))
        n_local = end - start
        indptr = np.zeros(n_local + 1, dtype=PETSc.IntType)
        width = np.zeros(n_local, dtype=int)
        width[rows - start] = 4
        own = (ply1 >= start) & (ply1 < end)
        width[ply1[own] - start] = 1
        indptr[1:] = np.cumsum(width)
        indices = np.zeros(indptr[-1], dtype=PETSc.IntType)
        values = np.zeros(indptr[-1])
        at = indptr[rows - start]
        for c in range(4):
            indices[at + c] = coarse[cols[:, c]]
            values[at + c] = weights[:, c]
        indices[indptr[ply1[own] - start]] = coarse[ply1[own]]
        values[indptr[ply1[own] - start]] = 1.0
        # Blocks of 3 × 3 (w I): node r's component c is row 3r + c, column 3 coarse + c.
        R = PETSc.Mat().createBAIJ(((3 * n_local, None), (3 * n1_local, None)), 3,
                                   csr=(indptr, indices, (values[:, None, None] * np.eye(3))
                                        .ravel()), comm=comm)
        return R.convert("aij")

    def setUp(self, pc: PETSc.PC) -> None:
        """Factor every ply's block and the coarse matrix Rᵀ P R (P: the assembled Jacobian)."""
        _, P = pc.getOperators()
        self.P = P
        version = self.contact.map_version
        # Made on every rank from the same gathered positions; R is made collectively, so
        # every rank remakes it if any saw the map change.
        changed = self._R is None or version != self._version
        if self.problem.comm.allreduce(changed, op=MPI.LOR):
            self._R = self._prolongation()
            self._version = version
            self._Ac = None
            self._blocks = [None] * self.plies
        for k, rows in enumerate(self.sets):
            self._blocks[k] = P.createSubMatrix(rows, rows, submat=self._blocks[k])
            self._solvers[k].setOperators(self._blocks[k])
            self._solvers[k].setUp()
        self._Ac = P.ptap(self._R, result=self._Ac)
        self._coarse_solver.setOperators(self._Ac)
        self._coarse_solver.setUp()
        if not hasattr(self, "_rc"):
            self._rc, self._zc = self._Ac.createVecs()
        if self._rc.getSize() != self._Ac.getSize()[0]:
            self._rc, self._zc = self._Ac.createVecs()
        self._t = P.createVecLeft()

    def apply(self, pc: PETSc.PC, r: PETSc.Vec, z: PETSc.Vec) -> None:
        """The coarse level, then the plies (module docstring)."""
        self.applications += 1
        self._R.multTranspose(r, self._rc)
        self._coarse_solver.solve(self._rc, self._zc)
        self._R.mult(self._zc, z)
        self.P.mult(z, self._t)
        self._t.aypx(-1.0, r)
        for rows, ksp in zip(self.sets, self._solvers):
            t = self._t.getSubVector(rows)
            y = t.duplicate()
            ksp.solve(t, y)
            self._t.restoreSubVector(rows, t)
            z.isaxpy(rows, 1.0, y)
            y.destroy()
