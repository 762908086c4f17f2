"""Forming of the paper's hemisphere (section 4): tools, contact, blank holder, drapes.

The tools, contact and holder terms, the kinematic drape and the post-processing are plain
NumPy; the forming run itself (:func:`run_hemisphere`, :func:`form_hemisphere`) imports
DOLFINx when called.
"""

from fenicsx_drape.forming.contact import PenaltyContact
from fenicsx_drape.forming.hemisphere import HemisphereCase, HemisphereRun, run_hemisphere
from fenicsx_drape.forming.holder import BlankHolder
from fenicsx_drape.forming.kinematic import kinematic_drape
from fenicsx_drape.forming.outputs import form_hemisphere
from fenicsx_drape.forming.post import FormedGrid, mean_distance
from fenicsx_drape.forming.stabilisation import ExtrapolationSpring
from fenicsx_drape.forming.tools import HemisphereTools, RevolvedTool

__all__ = [
    "BlankHolder",
    "ExtrapolationSpring",
    "FormedGrid",
    "HemisphereCase",
    "HemisphereRun",
    "HemisphereTools",
    "PenaltyContact",
    "RevolvedTool",
    "form_hemisphere",
    "kinematic_drape",
    "mean_distance",
    "run_hemisphere",
]
