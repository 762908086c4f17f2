"""Forming of the paper's hemisphere (section 4): tools, contact, blank holder, drapes.

The tools (closed-form, or meshed surfaces from Gmsh/CAD/STL with a smooth distance field),
contact and holder terms, the kinematic drape and the post-processing are plain NumPy (Gmsh
is imported when a surface is read); the forming run itself (:func:`run_hemisphere`,
:func:`form_hemisphere`) imports DOLFINx when called.
"""

from fenicsx_drape.forming.contact import PenaltyContact
from fenicsx_drape.forming.hemisphere import HemisphereCase, HemisphereRun, run_hemisphere
from fenicsx_drape.forming.holder import BlankHolder
from fenicsx_drape.forming.kinematic import kinematic_drape
from fenicsx_drape.forming.motion import RigidMotion
from fenicsx_drape.forming.outputs import form_hemisphere
from fenicsx_drape.forming.post import FormedGrid, mean_distance
from fenicsx_drape.forming.stabilisation import ExtrapolationSpring
from fenicsx_drape.forming.surfaces import TriangleSurface, load_surface
from fenicsx_drape.forming.tools import HemisphereTools, MeshedTool, RevolvedTool

__all__ = [
    "BlankHolder",
    "ExtrapolationSpring",
    "FormedGrid",
    "HemisphereCase",
    "HemisphereRun",
    "HemisphereTools",
    "MeshedTool",
    "PenaltyContact",
    "RevolvedTool",
    "RigidMotion",
    "TriangleSurface",
    "form_hemisphere",
    "kinematic_drape",
    "load_surface",
    "mean_distance",
    "run_hemisphere",
]
