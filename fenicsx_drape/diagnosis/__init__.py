"""Where a model is judged against measurements: compare, diagnose, the ledger of versions.

- :mod:`~fenicsx_drape.diagnosis.kinds`: the registry of test kinds (how each kind is
  measured, simulated, fitted, located and pictured);
- :mod:`~fenicsx_drape.diagnosis.coupon_kind`, :mod:`~fenicsx_drape.diagnosis.forming_kind`:
  the built-in kinds (tensile and bias extension; formed parts);
- :mod:`~fenicsx_drape.diagnosis.lab_kind`: a forming test's lab measurements (shear points,
  scan, outline, force curve; spec version 3), handed over by the forming kind;
- :mod:`~fenicsx_drape.diagnosis.compare`: how far, and where, a model misses a bundle;
- :mod:`~fenicsx_drape.diagnosis.diagnose`: which physical effect the model is missing;
- :mod:`~fenicsx_drape.diagnosis.ledger`: the history of model versions and their errors.

Importing the package registers the built-in kinds, coupons first (their fit fixes the
material before a forming fit holds it), so ``compare`` and ``diagnose`` never import a kind.
"""

from fenicsx_drape.diagnosis import (  # noqa: F401  (registration)
    coupon_kind,
    forming_kind,
    lab_kind,
)
