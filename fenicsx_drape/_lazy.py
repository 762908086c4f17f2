"""Packages whose public names are imported from their modules when first asked for.

A package lists its public names and the module of each; importing the package imports none of
them (a command that forms a part does not load the diagnosis, nor a worker DOLFINx before its
MPI is set up).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping


def lazy_exports(package: str, public: Mapping[str, str]
                 ) -> tuple[list[str], Callable[[str], object], Callable[[], list[str]]]:
    """``__all__``, ``__getattr__`` and ``__dir__`` of ``package``.

    Args:
        package: The package's ``__name__``.
        public: Each public name and the module it lives in, relative to ``package``.
    """
    def attribute(name: str) -> object:
        if name in public:
            return getattr(importlib.import_module(f"{package}.{public[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def names() -> list[str]:
        return sorted({*vars(sys.modules[package]), *public})

    return sorted(public), attribute, names
