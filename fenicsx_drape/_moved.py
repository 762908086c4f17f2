"""Old import paths of modules that moved, kept working for one release.

A moved module's old dotted name is put in :data:`sys.modules` as a :class:`MovedModule`:
``from old.path import name`` finds ``name`` in the modules it moved to (in the order given)
and warns with a :class:`DeprecationWarning` naming where it lives now. Nothing is imported
until a name is asked for. ``CHANGELOG.md`` lists what moved where.
"""

from __future__ import annotations

import importlib
import sys
import types
import warnings
from collections.abc import Mapping, Sequence


class MovedModule(types.ModuleType):
    """A module's old path: its names looked up, on first use, where they moved."""

    def __init__(self, name: str, targets: Sequence[str]):
        super().__init__(name, f"Moved: the names of {name} now live in {', '.join(targets)}.")
        self._targets = tuple(targets)

    def __getattr__(self, attr: str):
        if attr.startswith("__"):
            raise AttributeError(attr)
        for target in self._targets:
            module = importlib.import_module(target)
            if hasattr(module, attr):
                value = getattr(module, attr)
                home = getattr(value, "__module__", None)
                home = home if home in self._targets else target
                warnings.warn(f"{self.__name__}.{attr} moved to {home}.{attr}; the old path "
                              "goes in the next release", DeprecationWarning, stacklevel=2)
                return value
        raise AttributeError(f"module {self.__name__!r} (moved to "
                             f"{', '.join(self._targets)}) has no attribute {attr!r}")

    def __dir__(self) -> list[str]:
        return sorted({n for t in self._targets for n in dir(importlib.import_module(t))})


def keep_old_paths(package: str, moved: Mapping[str, Sequence[str]]) -> None:
    """Register the old module paths ``package.<old>`` of ``moved``.

    ``moved`` maps an old module name to the modules its names moved to, both relative to
    ``package``; a module of the old name loaded already is kept.
    """
    for old, targets in moved.items():
        name = f"{package}.{old}"
        sys.modules.setdefault(name, MovedModule(name, [f"{package}.{t}" for t in targets]))
