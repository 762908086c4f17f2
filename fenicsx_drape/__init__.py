"""fenicsx_drape: forming and wrinkling of woven prepregs with a rate-dependent truss model.

The model is that of Skordos, Monroy Aceves & Sutcliffe, "A simplified rate dependent model of
forming and wrinkling of pre-impregnated woven composites". The material laws and the
unit-cell solutions are plain NumPy; the finite-element layer (``fenicsx_drape.fe``) needs
DOLFINx >= 0.10 and is imported only when used.
"""

__version__ = "0.1.0"

__all__ = ["Model", "__version__", "default_model", "load_model"]

_LAZY = {"Model": "fenicsx_drape.model", "default_model": "fenicsx_drape.model",
         "load_model": "fenicsx_drape.model"}


def __getattr__(name: str):
    # The model API is imported on first use, so that ``drape --help`` stays fast.
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'fenicsx_drape' has no attribute {name!r}")
