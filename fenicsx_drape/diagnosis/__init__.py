"""Where a model is judged against measurements: compare, diagnose, the ledger of versions.

- :mod:`~fenicsx_drape.diagnosis.kinds`: what a test kind is (how it is measured, simulated,
  fitted, located and pictured);
- :mod:`~fenicsx_drape.diagnosis.coupon_kind`, :mod:`~fenicsx_drape.diagnosis.forming_kind`:
  the built-in kinds (tensile and bias extension; formed parts);
- :mod:`~fenicsx_drape.diagnosis.lab_kind`: a forming test's lab measurements (shear points,
  scan, outline, force curve; spec version 3);
- :mod:`~fenicsx_drape.diagnosis.forming_fit`: the forming kind (grid or lab) and the fit of
  its friction coefficients;
- :mod:`~fenicsx_drape.diagnosis.compare`: how far, and where, a model misses a bundle (and
  the table of kinds, :data:`~fenicsx_drape.diagnosis.compare.KINDS`);
- :mod:`~fenicsx_drape.diagnosis.diagnose`: which physical effect the model is missing;
- :mod:`~fenicsx_drape.diagnosis.ledger`: the history of model versions and their errors.
- :mod:`~fenicsx_drape.diagnosis.forming_runs`: the forming runs of compare and diagnose,
  through :mod:`concurrent.futures` on every core (:mod:`~fenicsx_drape.diagnosis.mpi_pool`:
  on the ranks of an MPI job) and remembered on disk
  (:mod:`~fenicsx_drape.diagnosis.run_store`).
"""
