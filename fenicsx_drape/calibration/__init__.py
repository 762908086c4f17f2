"""Where a model is fitted to measurements: coupon simulation, features, fit, sensitivity.

The public API (:data:`__all__`)::

    from fenicsx_drape.calibration import fit
    result = fit(load_bundle("demos/bundles/twill-table2"))  # the paper's model by default

- :mod:`~fenicsx_drape.calibration.fitting`: the fit itself (:func:`fit`, :class:`FitResult`,
  :func:`write_fit`, :func:`plot_fit`);
- :mod:`~fenicsx_drape.calibration.coupons`: tensile, bias-extension and picture-frame tests as
  least squares sees them (the unit-cell forward model, per-row noise weights, variables and
  residuals);
- :mod:`~fenicsx_drape.calibration.features`: starting values from curve features (section 3.2;
  :func:`shear_curve`);
- :mod:`~fenicsx_drape.calibration.global_stage`: the search from several starts;
- :mod:`~fenicsx_drape.calibration.identifiability`: what the tests cannot determine;
- :mod:`~fenicsx_drape.calibration.sensitivity`: the paper's Table 2 and the uncertainties
  (:func:`table2`, :func:`format_table`);
- :mod:`~fenicsx_drape.calibration.synthetic`: bundles made by the forward model plus noise
  (:func:`synthetic_bundle`, :func:`standard_tests`, the tests' makers);
- :mod:`~fenicsx_drape.calibration.agreement`: one parameter set for every test, lab, size
  and kind? (leave one group out, refit, predict it: :func:`consistency`, by
  :func:`lab_of`, :func:`size_of`);
- :mod:`~fenicsx_drape.calibration.interply`: the inter-ply law fitted to inter-ply friction
  tests (:func:`fit_interply`).
"""


from fenicsx_drape._lazy import lazy_exports
from fenicsx_drape._moved import keep_old_paths

# The public names, each from its module, imported on first use.
_PUBLIC = {
    "FitResult": "fitting",
    "InterplyFit": "interply",
    "bias_test": "synthetic",
    "consistency": "agreement",
    "fit": "fitting",
    "fit_interply": "interply",
    "format_table": "sensitivity",
    "lab_of": "agreement",
    "picture_frame_test": "synthetic",
    "plot_fit": "fitting",
    "shear_curve": "features",
    "simulate_interply": "interply",
    "size_of": "agreement",
    "standard_tests": "synthetic",
    "synthetic_bundle": "synthetic",
    "table2": "sensitivity",
    "tensile_test": "synthetic",
    "write_fit": "fitting",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _PUBLIC)


# Modules renamed so that no public function is hidden by a module of its name (CHANGELOG.md):
# the old paths work for one release.
keep_old_paths(__name__, {"fit": ("fitting",), "consistency": ("agreement",)})
