"""The module names before the package had subpackages, kept importable (issue 16).

Until version 0.1 the measurement side sat flat in the package (``fenicsx_drape.fit``,
``fenicsx_drape.bundle``, ...). Scripts written against those names keep working: an import
of an old name gives the module at its new place, the very same module object (not a copy),
so its functions, classes, private helpers and module state are all there and setting an
attribute through either name is seen through both. One table says where each went
(:data:`OLD_NAMES`); :func:`install`, called by ``fenicsx_drape/__init__.py``, puts the finder
that reads it on :data:`sys.meta_path`. New code uses the new names.

Why a finder rather than one thin re-export file per old name: re-export files would put ten
flat modules back beside the subpackages (the tree would again hide the architecture), would
copy names (``from x import *`` leaves out private helpers and module state such as the cache
of forming runs) and would have to be kept in step with their targets.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

OLD_NAMES: dict[str, str] = {
    "fenicsx_drape.bundle": "fenicsx_drape.measurements.bundle",
    "fenicsx_drape.noise": "fenicsx_drape.measurements.noise",
    "fenicsx_drape.features": "fenicsx_drape.calibration.features",
    "fenicsx_drape.fit": "fenicsx_drape.calibration.fit",
    "fenicsx_drape.sensitivity": "fenicsx_drape.calibration.sensitivity",
    "fenicsx_drape.synthetic": "fenicsx_drape.calibration.synthetic",
    "fenicsx_drape.compare": "fenicsx_drape.diagnosis.compare",
    "fenicsx_drape.forming_compare": "fenicsx_drape.diagnosis.forming_kind",
    "fenicsx_drape.diagnose": "fenicsx_drape.diagnosis.diagnose",
    "fenicsx_drape.ledger": "fenicsx_drape.diagnosis.ledger",
    # forming/ before its subpackages (issue 28; forming.case, .tools and .paper are
    # packages now: their modules are forming.case.format, forming.tools.shapes and
    # forming.paper.numbers, and fenicsx_drape.forming exports the API)
    "fenicsx_drape.forming.motion": "fenicsx_drape.forming.tools.motion",
    "fenicsx_drape.forming.surfaces": "fenicsx_drape.forming.tools.surfaces",
    "fenicsx_drape.forming.distance": "fenicsx_drape.forming.tools.distance",
    "fenicsx_drape.forming.tool_models": "fenicsx_drape.forming.tools.drawing",
    "fenicsx_drape.forming.contact": "fenicsx_drape.forming.terms.contact",
    "fenicsx_drape.forming.holder": "fenicsx_drape.forming.terms.holder",
    "fenicsx_drape.forming.stabilisation": "fenicsx_drape.forming.terms.stabilisation",
    "fenicsx_drape.forming.run": "fenicsx_drape.forming.running.run",
    "fenicsx_drape.forming.outputs": "fenicsx_drape.forming.running.outputs",
    "fenicsx_drape.forming.post": "fenicsx_drape.forming.running.post",
    "fenicsx_drape.forming.measure": "fenicsx_drape.forming.running.measure",
    "fenicsx_drape.forming.plots": "fenicsx_drape.forming.running.plots",
    "fenicsx_drape.forming.kinematic": "fenicsx_drape.forming.running.kinematic",
    "fenicsx_drape.forming.studies": "fenicsx_drape.forming.paper.studies",
}


class _AliasLoader(importlib.abc.Loader):
    """Loads an old name as the module of its new name."""

    def __init__(self, target: str):
        self.target = target
        self._spec = None

    def create_module(self, spec):
        """The module at its new name (imported if it is not yet)."""
        module = importlib.import_module(self.target)
        self._spec = module.__spec__
        return module

    def exec_module(self, module) -> None:
        """Nothing to run; give the module back its own spec (the import system set ours)."""
        module.__spec__ = self._spec


class _OldNames(importlib.abc.MetaPathFinder):
    """Finds the old names of :data:`OLD_NAMES`."""

    def find_spec(self, fullname, path=None, target=None):
        """A spec loading ``fullname`` as its new module, or None for any other name."""
        if fullname not in OLD_NAMES:
            return None
        return importlib.util.spec_from_loader(fullname, _AliasLoader(OLD_NAMES[fullname]))


def install() -> None:
    """Put the finder of old names first on ``sys.meta_path`` (once).

    First, so that no other finder answers an old name with a stale file (an installed copy
    of an older version, e.g. through an editable install's finder).
    """
    if not any(isinstance(f, _OldNames) for f in sys.meta_path):
        sys.meta_path.insert(0, _OldNames())
