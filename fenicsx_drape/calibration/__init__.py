"""Where a model is fitted to measurements: coupon simulation, features, fit, sensitivity.

- :mod:`~fenicsx_drape.calibration.coupons`: tensile, bias-extension and picture-frame tests as
  least squares sees them (the unit-cell forward model, per-row noise weights, variables and
  residuals);
- :mod:`~fenicsx_drape.calibration.features`: starting values from curve features (section 3.2);
- :mod:`~fenicsx_drape.calibration.fit`: the fit itself (``fit(bundle, model)``);
- :mod:`~fenicsx_drape.calibration.sensitivity`: the paper's Table 2 and the uncertainties;
- :mod:`~fenicsx_drape.calibration.synthetic`: bundles made by the forward model plus noise;
- :mod:`~fenicsx_drape.calibration.consistency`: one parameter set for every test, lab, size
  and kind? (leave one group out, refit, predict it).

Call the fit as ``from fenicsx_drape.calibration.fit import fit`` (a package attribute named
``fit`` would be replaced by the submodule of that name on its first import).
"""
