"""Material laws of the truss: the user-material interface and the paper's laws.

Public API for users writing their own law (see ``demos/user_laws/``)::

    from fenicsx_drape.materials import MaterialLaw, parameter, condition, effect, register_law

The built-in laws are registered as ``"paper_tow"`` (eqs. 2-4), ``"paper_shear"``
(eqs. 5-9) and ``"paper_friction"`` (eq. 1). :class:`InterplyLaw` is the friction between
the plies of a stack (tack, Coulomb, viscous film).
"""

from fenicsx_drape.materials.base import (
    ROLES,
    MaterialLaw,
    build_law,
    condition,
    effect,
    fields_of,
    get_law,
    parameter,
    register_law,
    registered_laws,
)
from fenicsx_drape.materials.friction import FrictionLaw
from fenicsx_drape.materials.interply import InterplyLaw
from fenicsx_drape.materials.shear import ShearLaw
from fenicsx_drape.materials.tow import TowLaw

BUILT_IN_LAWS: dict[str, str] = {"tow": "paper_tow", "shear": "paper_shear",
                                 "friction": "paper_friction"}
"""The law of each role used unless a registered user law in a model's effects replaces it."""

__all__ = [
    "BUILT_IN_LAWS",
    "ROLES",
    "FrictionLaw",
    "InterplyLaw",
    "MaterialLaw",
    "ShearLaw",
    "TowLaw",
    "build_law",
    "condition",
    "effect",
    "fields_of",
    "get_law",
    "parameter",
    "register_law",
    "registered_laws",
]
