"""The truss finite-element core on DOLFINx (section 2.1 and section 4 of the paper).

One call per task::

    sheet = truss_sheet(size_mm=240, cell_mm=10, quarter=True)   # mesh (Gmsh → DOLFINx)
    problem = TrussProblem(sheet, model, nodal_terms=[...])      # laws, options
    problem.symmetry(); problem.fix("border", (0,), lambda t: 0.1 * t)
    problem.run(duration_s=10.0, dt_s=0.5)                       # adaptive load stepping
    res = problem.results()                                      # shear, wrinkling, totals

PETSc SNES solves each load step; ``set_petsc_options("-snes_type newtontr")`` changes it
(:mod:`fenicsx_drape.fe.newton`).
"""

from fenicsx_drape.fe.grid import TrussGrid, read_grid, sheet_grid, write_grid
from fenicsx_drape.fe.mesh import Sheet, load_sheet, truss_mesh, truss_sheet
from fenicsx_drape.fe.newton import set_petsc_options
from fenicsx_drape.fe.output import FieldWriter, Results, grid_points, write_grid_csv
from fenicsx_drape.fe.solver import SolverOptions, TrussProblem
from fenicsx_drape.fe.stepping import RunReport, StepReport, run

__all__ = [
    "FieldWriter",
    "Results",
    "RunReport",
    "Sheet",
    "SolverOptions",
    "StepReport",
    "TrussGrid",
    "TrussProblem",
    "grid_points",
    "load_sheet",
    "read_grid",
    "run",
    "set_petsc_options",
    "sheet_grid",
    "truss_mesh",
    "truss_sheet",
    "write_grid",
    "write_grid_csv",
]
