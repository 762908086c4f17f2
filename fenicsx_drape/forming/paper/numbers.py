"""The paper's hemisphere numbers (section 4) and how a run compares with them.

Every number the paper states about the hemisphere, with where it states it, so that studies
and ``make demo`` print the paper beside this model. Wrinkling strains are Green-Lagrange and,
as everywhere in this package, negative (the paper quotes magnitudes).

:func:`paper_comparison` formats a run's summary (``summary.json`` of
:func:`~fenicsx_drape.forming.running.outputs.form_case` of the hemisphere) against them, and
only for a run under the paper's conditions (:func:`paper_differences`: the paper's tools,
blank and model, 10 mm cells, 133 N, 40 s, one ply at 0°); another run is said not to be
compared, with what differs.
"""

from __future__ import annotations

from collections.abc import Mapping

from fenicsx_drape.forming.running.conditions import (
    PAPER_CONDITIONS,
    paper_differences,
)

# Section 4.3 (Fig. 10) and 4.2 (Fig. 9): the default case, 10 mm cells, 133 N, 40 s.
MAX_SHEAR_MODEL_DEG = 51.4
MAX_SHEAR_EXPERIMENT_DEG = 50.2
MAX_SHEAR_KINEMATIC_DEG = 61.0  # Fig. 11a, the pin-jointed net
TOTAL_WRINKLING_MODEL = -0.0055  # Fig. 9: "stabilises to a value of about 0.55 %"
MIN_WRINKLING_MODEL = -0.21
MIN_WRINKLING_EXPERIMENT = -0.31
MEAN_DISTANCE_10MM_MM = 0.25  # Fig. 9: mean node distance from the finest model at 10 mm
WRINKLING_PLACE = ("on the tow axes at the base of the hemisphere (fillet), four places, "
                   "compressing along the sheet's sides (Figs. 7, 8, 10)")

# Fig. 9: maximum shear reaches a plateau beyond 100 nodes of the quarter; total wrinkling
# stabilises below 10 mm cells (169 nodes).
SHEAR_PLATEAU_FROM_NODES = 100
WRINKLING_STABLE_FROM_NODES = 169

# Fig. 12a: 8-240 s at 133 N. Total wrinkling 1.1 % (fast) → 0.3 % (slow), plateau beyond
# 100 s; maximum shear rises when slower, within about 3°.
DURATION_RANGE_S = (8.0, 240.0)
DURATION_WRINKLING = (-0.011, -0.003)
DURATION_SHEAR_SPAN_DEG = 3.0

# Fig. 12b: 70-800 N at 40 s. Total wrinkling 0.7 % → 0.25 %, nearly constant beyond 500 N;
# maximum shear rises up to about 200 N, then falls slowly; tow strain near 0.5 % at 800 N.
FORCE_RANGE_N = (70.0, 800.0)
FORCE_WRINKLING = (-0.007, -0.0025)
FORCE_SHEAR_PEAK_N = 200.0
TOW_STRAIN_800N = 0.005

# Every number the paper states, as (key of
# :func:`~fenicsx_drape.forming.paper.studies.paper_numbers`, value, what and where).
# Strains are negative, as here.
TARGETS = (
    ("max_shear_deg", MAX_SHEAR_MODEL_DEG, "maximum shear, paper's model (Fig. 10)"),
    ("max_shear_deg", MAX_SHEAR_EXPERIMENT_DEG, "maximum shear, experiment (Fig. 10)"),
    ("total_wrinkling_strain", TOTAL_WRINKLING_MODEL, "total wrinkling, 10 mm (Fig. 9)"),
    ("min_wrinkling_strain", MIN_WRINKLING_MODEL, "minimum wrinkling strain, paper's model"),
    ("min_wrinkling_strain", MIN_WRINKLING_EXPERIMENT, "minimum wrinkling strain, experiment"),
    ("distance_10mm_mm", MEAN_DISTANCE_10MM_MM, "mean distance from the finest model, 10 mm"),
    ("wrinkling_8s", DURATION_WRINKLING[0], "total wrinkling at 8 s (Fig. 12a)"),
    ("wrinkling_240s", DURATION_WRINKLING[1], "total wrinkling at 240 s (Fig. 12a)"),
    ("shear_span_duration_deg", DURATION_SHEAR_SPAN_DEG, "maximum shear span over 8-240 s"),
    ("wrinkling_70N", FORCE_WRINKLING[0], "total wrinkling at 70 N (Fig. 12b)"),
    ("wrinkling_800N", FORCE_WRINKLING[1], "total wrinkling at 800 N (Fig. 12b)"),
    ("tow_strain_800N", TOW_STRAIN_800N, "tow strain at 800 N (Fig. 12b)"),
)


def misfit(numbers: Mapping[str, float]) -> float:
    """Mean |ln(ours / paper's)| over :data:`TARGETS` (0: all reproduced).

    ln 2 ≈ 0.69 is "a factor of two off on average". A number of the wrong sign or missing
    counts as ln 10.
    """
    import math

    terms = []
    for key, target, _ in TARGETS:
        value = numbers.get(key)
        ok = value is not None and math.isfinite(value) and value * target > 0
        terms.append(abs(math.log(value / target)) if ok else math.log(10.0))
    return sum(terms) / len(terms)


# The numbers as ``summary.json`` keeps them (key → paper's model, experiment).
SUMMARY = {
    "max_shear_deg": (MAX_SHEAR_MODEL_DEG, MAX_SHEAR_EXPERIMENT_DEG),
    "total_wrinkling_strain": (TOTAL_WRINKLING_MODEL, None),
    "min_wrinkling_strain": (MIN_WRINKLING_MODEL, MIN_WRINKLING_EXPERIMENT),
    "kinematic_max_shear_deg": (MAX_SHEAR_KINEMATIC_DEG, None),
}


def _number(value, unit: str) -> str:
    if value is None:
        return "—"
    if unit == "%":
        return f"{100 * value:.2f} %"
    if unit == "°":
        return f"{value:.1f}°"
    return f"{value:.2f}"


def paper_comparison(summary: Mapping, model=None) -> str:
    """A run's numbers beside the paper's model and experiment, under the paper's conditions.

    Args:
        summary: A run's summary (``summary.json``): ``max_shear_deg``,
            ``total_wrinkling_strain``, ``min_wrinkling_strain`` and, when present,
            ``total_wrinkling_engineering`` (the literal measure, see
            :meth:`~fenicsx_drape.forming.running.post.FormedGrid.total_wrinkling_strain`),
            ``kinematic_max_shear_deg``, and the conditions: ``case``, ``cell_mm`` and
            ``paper_differences`` (:func:`paper_differences`, computed when absent).
        model: The run's model, for :func:`paper_differences` when the summary has no
            ``paper_differences``.

    Returns:
        Lines of text (no trailing newline): the table, titled with the paper's conditions;
        for a run under other conditions one line saying that it is not compared and what
        differs (the paper's numbers hold for its conditions only).
    """
    differs = summary.get("paper_differences")
    if differs is None:
        differs = paper_differences(summary, model)
    if differs:
        return (f"not compared with the paper: its section 4 numbers are for {PAPER_CONDITIONS}; "
                f"this run: {', '.join(differs)}")
    rows = [("maximum shear angle", "max_shear_deg", "°"),
            ("total wrinkling strain", "total_wrinkling_strain", "%"),
            ("  as length change / tow length", "total_wrinkling_engineering", "%"),
            ("minimum wrinkling strain (G-L)", "min_wrinkling_strain", ""),
            ("kinematic drape, maximum shear", "kinematic_max_shear_deg", "°")]
    lines = ["compared with the paper (section 4: 10 mm cells, 133 N, 40 s)",
             f"{'':34s}{'this run':>12s}{'paper model':>14s}{'experiment':>12s}"]
    for name, key, unit in rows:
        if key not in summary:
            continue
        model_value, experiment = SUMMARY.get(key, SUMMARY["total_wrinkling_strain"])
        lines.append(f"{name:34s}{_number(summary[key], unit):>12s}"
                     f"{_number(model_value, unit):>14s}{_number(experiment, unit):>12s}")
    return "\n".join(lines)
