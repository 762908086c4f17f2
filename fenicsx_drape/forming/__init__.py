"""Forming of the paper's hemisphere (section 4): tools, contact, blank holder, drapes.

The tools, contact and holder terms, the kinematic drape and the post-processing are plain
NumPy; the forming run itself (:mod:`fenicsx_drape.forming.hemisphere`) needs DOLFINx.
"""

from fenicsx_drape.forming.contact import PenaltyContact
from fenicsx_drape.forming.holder import BlankHolder
from fenicsx_drape.forming.kinematic import kinematic_drape
from fenicsx_drape.forming.post import FormedGrid, mean_distance
from fenicsx_drape.forming.tools import HemisphereTools, RevolvedTool

__all__ = [
    "BlankHolder",
    "FormedGrid",
    "HemisphereTools",
    "PenaltyContact",
    "RevolvedTool",
    "kinematic_drape",
    "mean_distance",
]
