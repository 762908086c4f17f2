"""The paper's hemisphere: its numbers and its studies (Figs. 9-12), run by ``demos/study_*``.

- :mod:`~fenicsx_drape.forming.paper.numbers`: every number the paper states, and the
  comparison ``drape form hemisphere`` prints;
- :mod:`~fenicsx_drape.forming.paper.studies`: sweeps of the hemisphere (duration, force,
  mesh), cached, tabulated and plotted.
"""

from fenicsx_drape._lazy import lazy_exports

# Their public names, from the package (``from fenicsx_drape.forming import paper``;
# ``paper.TARGETS``, ``paper.sweep``), each imported on first use.
_PUBLIC = {
    "DURATIONS_S": "studies",
    "DURATION_RANGE_S": "numbers",
    "DURATION_SHEAR_SPAN_DEG": "numbers",
    "DURATION_WRINKLING": "numbers",
    "FORCES_N": "studies",
    "FORCE_RANGE_N": "numbers",
    "FORCE_SHEAR_PEAK_N": "numbers",
    "FORCE_WRINKLING": "numbers",
    "MAX_SHEAR_EXPERIMENT_DEG": "numbers",
    "MAX_SHEAR_KINEMATIC_DEG": "numbers",
    "MAX_SHEAR_MODEL_DEG": "numbers",
    "MEAN_DISTANCE_10MM_MM": "numbers",
    "MESH_CELLS_MM": "studies",
    "METRICS": "studies",
    "MIN_WRINKLING_EXPERIMENT": "numbers",
    "MIN_WRINKLING_MODEL": "numbers",
    "MU_LITERATURE": "studies",
    "PAPER_CONDITIONS": "numbers",
    "READINGS": "studies",
    "SHEAR_PLATEAU_FROM_NODES": "numbers",
    "STATS": "studies",
    "SUMMARY": "numbers",
    "TARGETS": "numbers",
    "TOTAL_WRINKLING_MODEL": "numbers",
    "TOW_STRAIN_800N": "numbers",
    "Variant": "studies",
    "WRINKLING_PLACE": "numbers",
    "WRINKLING_STABLE_FROM_NODES": "numbers",
    "default_options": "studies",
    "mesh_distances": "studies",
    "metrics": "studies",
    "misfit": "numbers",
    "paper_case": "studies",
    "paper_comparison": "numbers",
    "paper_differences": "numbers",
    "paper_numbers": "studies",
    "plot_trend": "studies",
    "run_key": "studies",
    "run_variants": "studies",
    "source_tag": "studies",
    "sweep": "studies",
    "write_rows": "studies",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _PUBLIC)
