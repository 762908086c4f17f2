"""Forming cases (any part; the paper's hemisphere is one): tools, contact, holder, runs.

A case is a file (``case.toml``, :func:`load_case`); :func:`run_case` forms it and
:func:`form_case` writes its outputs. The tools, contact and holder terms, the case, the
kinematic drape and the post-processing are plain NumPy; the forming runs
(:func:`run_case`, :func:`run_hemisphere`, :func:`form_case`, :func:`form_hemisphere`) import
DOLFINx when called. Tools are closed-form, or meshed surfaces from Gmsh/CAD/STL held as a
smooth signed distance field (Gmsh is imported when one is read). Importing the package lets
the bundle loader read the case files that measured forming tests name (:func:`case_for_test`).
"""

from fenicsx_drape.forming.case import (
    FormingCase,
    case_for_test,
    load_case,
    with_overrides,
    write_case,
)
from fenicsx_drape.forming.contact import PenaltyContact
from fenicsx_drape.forming.hemisphere import HemisphereCase, HemisphereRun, run_hemisphere
from fenicsx_drape.forming.holder import BlankHolder, FlatHolder
from fenicsx_drape.forming.kinematic import kinematic_drape
from fenicsx_drape.forming.motion import RigidMotion
from fenicsx_drape.forming.outputs import form_case, form_hemisphere
from fenicsx_drape.forming.post import FormedGrid, mean_distance
from fenicsx_drape.forming.run import FormingRun, run_case
from fenicsx_drape.forming.stabilisation import ExtrapolationSpring
from fenicsx_drape.forming.surfaces import TriangleSurface, load_surface
from fenicsx_drape.forming.tools import HemisphereTools, MeshedTool, RevolvedTool

__all__ = [
    "BlankHolder",
    "ExtrapolationSpring",
    "FlatHolder",
    "FormedGrid",
    "FormingCase",
    "FormingRun",
    "HemisphereCase",
    "HemisphereRun",
    "HemisphereTools",
    "MeshedTool",
    "PenaltyContact",
    "RevolvedTool",
    "RigidMotion",
    "TriangleSurface",
    "case_for_test",
    "form_case",
    "form_hemisphere",
    "kinematic_drape",
    "load_case",
    "load_surface",
    "mean_distance",
    "run_case",
    "run_hemisphere",
    "with_overrides",
    "write_case",
]
