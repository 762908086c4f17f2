"""Forming cases (any part; the paper's hemisphere is one): the case, its tools, the terms, runs.

A case is a file (``case.toml``, or a case of the repository by name: ``"hemisphere"`` is
``meshes/hemisphere/case.toml``); :func:`load_case` reads it, :func:`run_case` forms it and
:func:`form_case` writes its outputs::

    from fenicsx_drape.forming import form_case, load_case

    run, summary = form_case("out", load_case("hemisphere", cell_mm=5.0))

The parts, one subpackage each:

- :mod:`~fenicsx_drape.forming.case`: the case and its file format (reading, checking,
  overrides, writing);
- :mod:`~fenicsx_drape.forming.tools`: tool geometry (closed-form tools, meshed surfaces
  from Gmsh/CAD/STL as smooth signed distance fields) and tool motion;
- :mod:`~fenicsx_drape.forming.terms`: the nodal terms of the residual besides the truss
  (penalty contact with tool friction, the blank holder of eq. 1, the out-of-plane
  stabilisation);
- :mod:`~fenicsx_drape.forming.running`: a run and its outputs (the load steps, summary,
  fields, bundle, pictures), the formed sheet's post-processing and the kinematic drape;
- :mod:`~fenicsx_drape.forming.paper`: the paper's numbers and its studies (run by
  ``demos/study_*.py``).

Everything but the runs is plain NumPy; :func:`run_case` and :func:`form_case` import DOLFINx
when called, and Gmsh is imported when a meshed tool is read.
"""

from fenicsx_drape.forming.case import (
    FormingCase,
    case_file,
    case_for_test,
    load_case,
    with_overrides,
    write_case,
)
from fenicsx_drape.forming.running.kinematic import kinematic_drape
from fenicsx_drape.forming.running.outputs import form_case
from fenicsx_drape.forming.running.post import FormedGrid, mean_distance
from fenicsx_drape.forming.running.run import FormingRun, run_case
from fenicsx_drape.forming.terms.contact import PenaltyContact
from fenicsx_drape.forming.terms.holder import BlankHolder, FlatHolder
from fenicsx_drape.forming.terms.stabilisation import ExtrapolationSpring
from fenicsx_drape.forming.tools.motion import RigidMotion
from fenicsx_drape.forming.tools.shapes import HemisphereTools, MeshedTool, RevolvedTool
from fenicsx_drape.forming.tools.surfaces import TriangleSurface, load_surface

__all__ = [
    "BlankHolder",
    "ExtrapolationSpring",
    "FlatHolder",
    "FormedGrid",
    "FormingCase",
    "FormingRun",
    "HemisphereTools",
    "MeshedTool",
    "PenaltyContact",
    "RevolvedTool",
    "RigidMotion",
    "TriangleSurface",
    "case_file",
    "case_for_test",
    "form_case",
    "kinematic_drape",
    "load_case",
    "load_surface",
    "mean_distance",
    "run_case",
    "with_overrides",
    "write_case",
]
