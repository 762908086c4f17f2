"""The set-up stage in words: its fields in the report, its sentence, its lines of text."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.results import SetupResult


def value_text(v) -> str:
    """A fitted set-up value as text: a number, or ``[x, y]`` for an offset."""
    return f"[{v[0]:.3g}, {v[1]:.3g}]" if isinstance(v, list) else f"{v:.4g}"


def setup_fields(stage: SetupResult | None) -> dict[str, Any]:
    """The set-up stage's fields of a diagnosis report (spec version 3)."""
    if stage is None:
        return {"setup": [], "setup_error": None}
    stated = {"error": stage.stated_error,
              "heldout_normalised": stage.stated_heldout_normalised}
    if stage.widened is not None:
        stated["widened"] = dict(stage.widened)
    out = {"setup": list(stage.entries), "setup_error": stage.setup_error,
           "setup_stated": stated,
           "setup_scheme": stage.scheme, "setup_rule": stage.rule}
    if stage.resolution is not None:
        out["setup_resolution"] = list(stage.resolution)
    return out


def widened_text(stage: SetupResult | None) -> str:
    """Words on the noise the set-up stage judged with, when widened ("" when as stated)."""
    if stage is None or stage.widened is None:
        return ""
    ids = ", ".join(stage.widened["measurements"])
    return (f"judged with the noise of {ids} widened by the net's own error (the set-up as "
            f"stated {stage.widened['normalised']:.3g} on it)")


def setup_sentence(stage: SetupResult | None) -> str:
    """The conclusion's words on a named set-up error ("" when none).

    Its errors are on the stated noise; the widened noise the stage judged with, if any, is
    said in the same sentence.
    """
    if stage is None or stage.setup_error is None:
        return ""
    s = stage.entries[0]
    show = value_text
    also = (f" (equivalently {s['confounded_with']}: the holder's friction acts through μF)"
            if "confounded_with" in s else "")
    judged = widened_text(stage)
    judged = (f"; {judged}: {s['widened']['normalised']:.3g}" if judged and "widened" in s
              else "")
    apart = ""
    if s.get("set_apart") and not s["significant"]:
        apart = (f"; set apart, whatever the leftover of other measurements: "
                 f"{show(s['fitted'])} ± {show(s['sd_fit'])} by its fit alone, evidence "
                 f"{s['evidence_stated']:.3g} on the stated noise")
    return (f"Set-up error: {s['parameter']} fitted {show(s['fitted'])} ± {show(s['sd'])} "
            f"(stated {show(s['stated'])}){also}, bringing the forming tests' normalised "
            f"error from {stage.stated_error['normalised']:.3g} to "
            f"{s['error_after']['normalised']:.3g} (evidence {s['evidence']:.3g}{judged}"
            f"{apart}). "
            + (f"It shows once {stage.found_with_effect} is in (alone, that effect's "
               "error hid it). " if stage.found_with_effect else
               "The physics candidates were tried with it fitted. "))


def setup_summary(report: dict[str, Any]) -> list[str]:
    """Lines of text on the set-up candidates of a report."""
    lines = []
    if not report.get("setup"):
        return lines
    lines.append(f"{'set-up candidate':<20} {'stated':>12} {'fitted':>18} {'after':>7} "
                 f"{'held-out':>9} {'evidence':>9}  significant")
    show = value_text
    for s in report["setup"]:
        fitted = f"{show(s['fitted'])} ± {show(s['sd'])}"
        lines.append(f"{s['parameter']:<20} {show(s['stated']):>12} {fitted:>18} "
                     f"{s['error_after']['normalised']:>7.3g} {s['heldout_normalised']:>9.3g} "
                     f"{s['evidence']:>9.3g}  {'yes' if s['significant'] else 'no'}"
                     + (" (set apart)" if s.get("set_apart") and not s["significant"]
                        else ""))
    widened = report.get("setup_stated", {}).get("widened")
    if widened:
        lines.append(f"(errors on the stated noise; the stage judged with the noise of "
                     f"{', '.join(widened['measurements'])} widened by the net's own error: "
                     f"as stated {widened['normalised']:.3g}, "
                     + ", ".join(f"{s['parameter']} {s['widened']['normalised']:.3g}"
                                 for s in report["setup"] if "widened" in s) + ")")
    lines.append(f"setup_error: {report.get('setup_error')}")
    return lines
