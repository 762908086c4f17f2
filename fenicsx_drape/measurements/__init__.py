"""Where a measurement enters: the bundle format (load, check, write) and noise estimates.

A bundle (``bundle.toml`` plus one CSV per test, ``docs/measurements.md``) is read into
typed, validated :class:`Bundle` and :class:`Test` objects by :func:`load_bundle`
(:mod:`~fenicsx_drape.measurements.bundle`); :mod:`~fenicsx_drape.measurements.noise` gives
the noise floor of a test from its own data. Nothing here knows of a model, a fit or DOLFINx.
"""

from fenicsx_drape.measurements.bundle import Bundle, BundleError, Test, load_bundle, write_bundle

__all__ = ["Bundle", "BundleError", "Test", "load_bundle", "write_bundle"]
