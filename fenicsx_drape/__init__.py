"""fenicsx_drape: forming and wrinkling of woven prepregs with a rate-dependent truss model.

The model is that of Skordos, Monroy Aceves & Sutcliffe, "A simplified rate dependent model of
forming and wrinkling of pre-impregnated woven composites". The material laws and the
unit-cell solutions are plain NumPy; the finite-element layer (``fenicsx_drape.fe``) needs
DOLFINx >= 0.10 and is imported only when used.
"""

__version__ = "0.1.0"

# The public API, imported on first use so that ``drape --help`` stays fast and the NumPy
# parts work without DOLFINx. Each package exports its own (``from fenicsx_drape.calibration
# import fit``, ``from fenicsx_drape.diagnosis import compare, diagnose``).
_LAZY = {
    "Model": "fenicsx_drape.model",
    "default_model": "fenicsx_drape.model",
    "load_model": "fenicsx_drape.model",
    "load_bundle": "fenicsx_drape.measurements.bundle",
    "synthetic_bundle": "fenicsx_drape.calibration.synthetic",
    "history": "fenicsx_drape.diagnosis.ledger",
}

__all__ = ["__version__", *sorted(_LAZY)]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'fenicsx_drape' has no attribute {name!r}")
