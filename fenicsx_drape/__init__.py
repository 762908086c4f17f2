"""fenicsx_drape: forming and wrinkling of woven prepregs with a rate-dependent truss model.

The model is that of Skordos, Monroy Aceves & Sutcliffe, "A simplified rate dependent model of
forming and wrinkling of pre-impregnated woven composites". The material laws and the
unit-cell solutions are plain NumPy; the finite-element layer (``fenicsx_drape.fe``) needs
DOLFINx >= 0.10 and is imported only when used.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
