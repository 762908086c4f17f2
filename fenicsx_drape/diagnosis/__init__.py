"""Where a model is judged against measurements: compare, diagnose, the ledger of versions.

The public API (:data:`__all__`)::

    from fenicsx_drape.diagnosis import compare, diagnose, write_diagnosis
    report = diagnose(bundle, model)        # which effect the model misses (a Report)
    write_diagnosis(report, "REPORT.json")  # the contract's JSON

Its modules:

- :mod:`~fenicsx_drape.diagnosis.kinds`: the measurement kinds, one module each (how each is
  measured, simulated, fitted, located, pictured and checked), and their table;
- :mod:`~fenicsx_drape.diagnosis.comparison`: how far, and where, a model misses a bundle;
- :mod:`~fenicsx_drape.diagnosis.pipeline`: which physical effect the model is missing, its
  stages in order (what each returns: :mod:`~fenicsx_drape.diagnosis.results`; the rules and
  the decision: :mod:`~fenicsx_drape.diagnosis.decision`; the report:
  :mod:`~fenicsx_drape.diagnosis.report`, its words :mod:`~fenicsx_drape.diagnosis.words`;
  the fits the stages share: :mod:`~fenicsx_drape.diagnosis.refits`; the held-out folds:
  :mod:`~fenicsx_drape.diagnosis.folds`);
- :mod:`~fenicsx_drape.diagnosis.data_check`: is each measurement one of its case?
- :mod:`~fenicsx_drape.diagnosis.resolution`: the model's own discretisation error;
- :mod:`~fenicsx_drape.diagnosis.setup_stage`: the process set-up before physics (the
  parameters :mod:`~fenicsx_drape.diagnosis.setup_parameters`, their fit
  :mod:`~fenicsx_drape.diagnosis.setup_fit`, words :mod:`~fenicsx_drape.diagnosis.
  setup_words`);
- :mod:`~fenicsx_drape.diagnosis.ledger`: the history of model versions and their errors;
- :mod:`~fenicsx_drape.diagnosis.synthetic`, :mod:`~fenicsx_drape.diagnosis.lab_synthetic`:
  bundles made by the project's simulator (demos, tests, studies);
- :mod:`~fenicsx_drape.runs`: the forming runs of compare and diagnose,
  through :mod:`concurrent.futures` on every core (:mod:`~fenicsx_drape.diagnosis.mpi_pool`:
  on the ranks of an MPI job) and remembered on disk
  (:mod:`~fenicsx_drape.diagnosis.run_store`).
"""


from fenicsx_drape._lazy import lazy_exports
from fenicsx_drape._moved import keep_old_paths

# The public names, each from its module, imported on first use (the diagnosis's modules
# import DOLFINx through the forming runs: ``import fenicsx_drape.diagnosis`` stays light).
_PUBLIC = {
    "CompareResult": "comparison",
    "Report": "report",
    "compare": "comparison",
    "confirm": "pipeline",
    "diagnose": "pipeline",
    "evaluate": "comparison",
    "fit_setup": "setup_stage",
    "history": "ledger",
    "history_table": "ledger",
    "lab_tables": "lab_synthetic",
    "setup_rules": "decision",
    "summary": "report",
    "synthetic_case_test": "synthetic",
    "synthetic_forming_test": "synthetic",
    "write_case_bundle": "synthetic",
    "write_compare": "comparison",
    "write_diagnosis": "report",
    "write_lab_bundle": "lab_synthetic",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _PUBLIC)


# Modules that moved (CHANGELOG.md): their old paths work for one release.
keep_old_paths(__name__, {
    "compare": ("comparison",),
    "coupon_kind": ("kinds.coupon", "kinds.tensile", "kinds.bias_extension",
                    "kinds.picture_frame"),
    "forming_kind": ("synthetic", "kinds.grid", "kinds.forming", "kinds.part"),
    "lab_kind": ("kinds.lab", "kinds.shear_points", "kinds.surface", "kinds.outline",
                 "kinds.punch_force"),
    "forming_fit": ("kinds.forming", "kinds.grid"),
    "diagnose": ("pipeline", "report", "decision", "refits", "folds", "words", "results"),
    "setup": ("setup_stage", "setup_fit", "setup_parameters", "setup_words", "ledger",
              "decision", "results"),
})
