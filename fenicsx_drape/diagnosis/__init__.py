"""Where a model is judged against measurements: compare, diagnose, the ledger of versions.

- :mod:`~fenicsx_drape.diagnosis.kinds`: the measurement kinds, one module each (how each is
  measured, simulated, fitted, located, pictured and checked), and their table;
- :mod:`~fenicsx_drape.diagnosis.compare`: how far, and where, a model misses a bundle;
- :mod:`~fenicsx_drape.diagnosis.diagnose`: which physical effect the model is missing;
- :mod:`~fenicsx_drape.diagnosis.data_check`: is each measurement one of its case?
- :mod:`~fenicsx_drape.diagnosis.resolution`: the model's own discretisation error;
- :mod:`~fenicsx_drape.diagnosis.setup`: the process set-up before physics;
- :mod:`~fenicsx_drape.diagnosis.ledger`: the history of model versions and their errors;
- :mod:`~fenicsx_drape.diagnosis.synthetic`, :mod:`~fenicsx_drape.diagnosis.lab_synthetic`:
  bundles made by the project's simulator (demos, tests, studies);
- :mod:`~fenicsx_drape.diagnosis.forming_runs`: the forming runs of compare and diagnose,
  through :mod:`concurrent.futures` on every core (:mod:`~fenicsx_drape.diagnosis.mpi_pool`:
  on the ranks of an MPI job) and remembered on disk
  (:mod:`~fenicsx_drape.diagnosis.run_store`).
"""

from fenicsx_drape._moved import keep_old_paths

# Modules that moved (CHANGELOG.md): their old paths work for one release.
keep_old_paths(__name__, {
    "coupon_kind": ("kinds.coupon", "kinds.tensile", "kinds.bias_extension",
                    "kinds.picture_frame"),
    "forming_kind": ("synthetic", "kinds.grid", "kinds.forming", "kinds.part"),
    "lab_kind": ("kinds.lab", "kinds.shear_points", "kinds.surface", "kinds.outline",
                 "kinds.punch_force"),
    "forming_fit": ("kinds.forming", "kinds.grid"),
})
