"""``drape compare BUNDLE --model MODEL.toml --out DIR``: how far, and where, a model misses."""

from __future__ import annotations

import argparse
import math
import sys

from fenicsx_drape.cli import forming_runs_arguments, petsc_option_argument
from fenicsx_drape.errors import DrapeInputError


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the command's arguments."""
    parser.add_argument("bundle", help="measurement bundle folder (or its bundle.toml)")
    parser.add_argument("--model", help="MODEL.toml (effects, plugins, starting parameters); "
                        "default: the paper's model with Table 2 parameters")
    parser.add_argument("--out", required=True, help="output folder (compare.json, plots, "
                        "the ledger of versions)")
    parser.add_argument("--no-fit", action="store_true",
                        help="compare the model as given, without fitting its parameters")
    parser.add_argument("--forming-cell-mm", type=float, default=None, metavar="MM",
                        help="unit cell of the forming simulations (default: a case's own "
                        "cell_mm; the hemisphere 10 mm, the paper's)")
    petsc_option_argument(parser)
    forming_runs_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Fit, compare, write the outputs and print the summary; returns the exit status."""
    from fenicsx_drape.cli import forming_runs_setting, load_bundle_reported
    from fenicsx_drape.diagnosis import compare, write_compare
    from fenicsx_drape.diagnosis.comparison import conclusion
    from fenicsx_drape.model import default_model, load_model

    bundle = load_bundle_reported(args.bundle)
    model = load_model(args.model) if args.model else default_model()
    if args.forming_cell_mm is not None and not args.forming_cell_mm > 0:
        raise DrapeInputError(f"--forming-cell-mm {args.forming_cell_mm} must be > 0 (mm)")
    with forming_runs_setting(args, cell_mm=args.forming_cell_mm):  # provenance: its runs'
        result = compare(bundle, model, fit=not args.no_fit,
                         progress=lambda line: print(line, file=sys.stderr))
        if not result.tests:
            raise DrapeInputError(f"{args.bundle}: nothing to compare")
        write_compare(result, bundle, args.out, model_path=args.model)
    if any(e["suspect"] for e in result.data_check or ()):
        print(conclusion(result))  # data that cannot be of the case, first
    print(summary(result))
    print(f"written to {args.out}")
    return 0


def summary(result) -> str:
    """The comparison as text: per-test errors, noise floor and where the error sits."""
    lines = [f"bundle {result.bundle!r}, effects: {', '.join(result.model.effects) or 'none'}",
             f"{'test':<16} {'RMSE':>10} {'mean|e|':>10} {'%':>6} {'noise':>10} "
             f"{'RMSE/noise':>10}"]
    for c in result.tests:
        lines.append(f"{c.id:<16} {c.rmse:>8.3g} {c.unit:<1} {c.mean_abs:>8.3g} {c.unit:<1} "
                     f"{percent_text(c.percent):>6} {c.noise:>8.3g} {c.unit:<1} "
                     f"{c.normalised:>10.2f}")
    if any(not math.isfinite(c.percent) for c in result.tests):
        lines.append("(% is the mean error over the mean measured value; left blank where the "
                     "measured values are all 0, as an outline's distances to the edge)")
    for test_id, m in (result.metrics or {}).items():
        if "sliding_shear_stress_MPa" in m:  # an inter-ply friction test
            lines.append(f"{test_id}: sliding shear stress {m['sliding_shear_stress_MPa']:.4g} "
                         f"MPa measured, {m['model_sliding_shear_stress_MPa']:.4g} MPa model")
            continue
        if "mean_distance_mm" not in m:  # a lab measurement (spec version 3)
            lines.append(lab_line(test_id, m))
            continue
        line = f"{test_id}: mean distance {m['mean_distance_mm']:.2f} mm"
        if math.isfinite(m.get("percent_of_displacement", math.nan)):
            line += f" ({m['percent_of_displacement']:.1f} % of the mean node displacement)"
        if "shear_rmse_deg" in m:
            line += f", shear error {m['shear_rmse_deg']:.2f}° RMS"
        if "stopped_at_travel_mm" in m:
            line += f"; stopped at {m['stopped_at_travel_mm']:.1f} mm of travel"
        lines.append(line)
    lines.append(f"normalised error {result.normalised:.3f} (1 = noise floor)")
    lines.append("where the error sits:")
    for e in result.where():
        lines.append(f"  {100 * e['share_of_error']:5.1f} %  {e['test']}: {e['says']} "
                     f"({e['variable']} {e['range'][0]:.3g} to {e['range'][1]:.3g})")
    for o in result.outliers:
        lines.append(f"outlier: {o['file']}:{o['line']} ({o['id']}), residual "
                     f"{o['residual']:.3g} × noise")
    if result.outliers:
        without = result.to_dict()["error_without_outliers"]["normalised"]
        lines.append(f"normalised error without the outliers {without:.3f}")
    lines += [f"note: {s}" for s in result.skipped]
    return "\n".join(lines)


def percent_text(percent: float) -> str:
    """A percentage with one decimal; "" when it is of nothing (not finite)."""
    return f"{percent:.1f}" if math.isfinite(percent) else ""


def lab_line(test_id: str, m: dict) -> str:
    """A lab measurement's own measures as text: unmatched rows, coverage, registration."""
    parts = [f"{m.get('unmatched', 0)} unmatched row(s)"]
    if m.get("unmatched_lines"):
        parts[0] += f" (lines {', '.join(map(str, m['unmatched_lines'][:5]))})"
    if "coverage" in m:
        parts.append(f"covers {100 * m['coverage']:.0f} % of the formed sheet")
    if (reg := m.get("registration")) is not None:
        parts.append("registered: rotation "
                     + ", ".join(f"{a:.2f}±{s:.2f}" for a, s in zip(reg["rotation_deg"],
                                                                 reg["sd_rotation_deg"]))
                     + " deg, translation "
                     + ", ".join(f"{a:.2f}±{s:.2f}" for a, s in zip(reg["translation_mm"],
                                                                 reg["sd_translation_mm"]))
                     + " mm" + (" (FAR from any registration)" if reg["far"] else ""))
    return f"{test_id}: " + "; ".join(parts)
