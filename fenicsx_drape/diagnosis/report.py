"""The diagnosis report: the contract's fields formatted from the stages' results, written.

:func:`format_report` only formats what the stages returned (:mod:`~fenicsx_drape.diagnosis.
results`): it fits, forms and decides nothing. :func:`summary` is its text,
:func:`write_diagnosis` writes ``REPORT.json`` and, with an output folder, the pictures, the
ledger of versions and the provenance.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.comparison import (
    error_record,
    model_record,
    noise_record,
    normalised_error,
    trends,
    where,
)
from fenicsx_drape.diagnosis.cost import cost_line
from fenicsx_drape.diagnosis.decision import (
    ADEQUATE,
    MISSING_RULE,
    RANKING_RULE,
    SIGNIFICANCE_RULE,
)
from fenicsx_drape.diagnosis.kinds import kind_of
from fenicsx_drape.diagnosis.ledger import record_history
from fenicsx_drape.diagnosis.resolution import sentence as resolution_sentence
from fenicsx_drape.diagnosis.setup_fit import DISTINCT_SD as SETUP_DISTINCT_SD
from fenicsx_drape.diagnosis.setup_words import (
    setup_fields,
    setup_sentence,
    setup_summary,
    value_text,
)
from fenicsx_drape.diagnosis.words import (
    conclusion,
    explain,
    groups_conclusion,
    groups_sentence,
    noise_notes,
    pattern_of,
    unjudged,
)

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds import Comparison
    from fenicsx_drape.diagnosis.results import (
        Baseline,
        Candidate,
        DataCheck,
        Decision,
        Effects,
        Entry,
        HeldOut,
        Resolution,
    )
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

CONTRACT = 4  # the measurement spec's version (docs/measurements.md), which the report follows


class Report(dict):
    """The diagnosis report: a dict with the contract's fields (JSON-ready).

    It also carries, outside the dict (not written to JSON), the fitted models and their
    comparisons with the tests: ``models`` and ``comparisons``, keyed by ``"baseline"`` and
    by each ranked candidate's ``effect``.
    """

    models: dict[str, Model]
    comparisons: dict[str, list[Comparison]]
    tests: tuple[Test, ...]  # the tests compared (without the outliers' rows)


def candidate_record(c: Candidate, explanation: str) -> dict[str, Any]:
    """A ranked candidate's entry in the report."""
    out = {"effect": c.effect, "effects": list(c.effects), "acts_on": c.acts_on,
           "summary": c.summary, "parameters": dict(c.parameters),
           "error_after": c.error_after, "heldout_normalised": c.heldout_normalised,
           "evidence": c.evidence, "significant": c.significant,
           "sensitivity": c.sensitivity, "where_after": list(c.where_after)}
    if c.setup_refitted is not None:
        out["setup_refitted"] = c.setup_refitted.record()
    if c.resolution_after is not None:
        out["resolution_after"] = list(c.resolution_after)
    if c.finer_net is not None:
        out["finer_net"] = dict(c.finer_net)
    out["explanation"] = explanation
    return out


def format_report(bundle: Bundle, checked: DataCheck, base: Baseline, heldout: HeldOut,
                  resolution: Resolution, effects: Effects, decision: Decision,
                  groups: Entry | None, measures: Mapping[str, Any], *,
                  seconds: float, cost: Sequence[Entry] = ()) -> Report:
    """The contract's report from the stages' results: their fields and their words.

    Args:
        bundle: The bundle as given (its name).
        checked: The data check.
        base: The baseline (at the fitted set-up, when one was applied).
        heldout: The baseline's held-out error.
        resolution: The baseline's net checked against the forming measurements.
        effects: The effects tried (their untestable entries; the ranked ones are the
            decision's).
        decision: The ranked candidates, the effect named and the set-up as reported.
        groups: The coupon groups' consistency (None: nothing to compare).
        measures: The kinds' own measures by model label (``metrics``).
        seconds: How long the diagnosis took (wall clock).
        cost: Each stage's forming runs (asked, formed) and wall seconds, in order.
    """
    compared, coupons, missing, stage = base.compared, base.coupons, decision.missing, \
        decision.setup
    pattern = pattern_of(compared)
    models, comparisons = {"baseline": base.model}, {"baseline": list(compared)}
    candidates = []
    for c in decision.ranked:
        candidates.append(candidate_record(c, explain(c, pattern, normalised_error(compared),
                                                      heldout.normalised)))
        models[c.effect], comparisons[c.effect] = c.model, list(c.after)
    # The physics first: its first sentence says how good the best model is; then the
    # set-up error named, the measurements the net cannot judge, the coupon groups.
    fitted = stage.setup_error if stage is not None else None
    words = " ".join(w.strip() for w in (
        groups_conclusion(groups, missing)
        or conclusion(missing, decision.best, compared, pattern, base.optimiser, coupons,
                      resolution.entries, setup_fitted=fitted),
        setup_sentence(stage), resolution_sentence(unjudged(resolution.entries, missing)),
        "" if groups_conclusion(groups, missing) else groups_sentence(groups)) if w.strip())
    if stage and stage.withdrawn and stage.entries[0].get("withdrawn_for"):
        e = stage.entries[0]
        words += (f" {e['parameter']} fitted alone ({value_text(e['fitted'])}) is not needed "
                  f"with {e['withdrawn_for']}: at the stated set-up it predicts the held-out "
                  f"rows as well (evidence {e['evidence_with_effect']:.3g} for the set-up "
                  "fitted): the effect, not the set-up, was missing (setup_error "
                  "withdrawn).")
    if missing and missing.setup_refitted:
        j = missing.setup_refitted
        words += (f" With {missing.effect} added, {j.parameter} is fitted "
                  f"again: {value_text(j.fitted)}.")
        if stage and stage.withdrawn:
            words += (f" That is within {SETUP_DISTINCT_SD:g} sd of the stated "
                      f"set-up: the effect, not the set-up, was missing "
                      f"(setup_error withdrawn).")
    if checked.suspects:
        words = (
            "Check the data: " + "; ".join(f"{e['test']}/{e['measurement']}: {e['why']}"
                                           for e in checked.suspects)
            + ". No effect is named on the evidence of data that cannot be of the case; set "
            "them right (or leave them out) and diagnose again.")
    named = decision.named
    notes = [*base.data.notes, *([f"set-up: {stage.model_note}"]
                                 if stage and stage.model_note else []),
             *(f"{e['test']}/{e['measurement']}: {e['why']}" for e in checked.entries
               if not e["suspect"] and e["why"].startswith("chosen:"))]
    report = Report({
        "contract": CONTRACT,
        "bundle": bundle.name,
        "baseline": {**model_record(base.model), "error": error_record(compared),
                     "heldout_normalised": heldout.normalised, "optimiser": base.optimiser},
        "noise_floor": noise_record(compared) | noise_notes(coupons),
        "outliers": list(base.outliers),
        "error_with_outliers": base.error_with_outliers,
        "where": where(compared),
        "trends": trends(compared),
        "candidates": candidates,
        "untestable": [*effects.untestable, *(stage.untestable if stage else ())],
        "missing_effect": named.effect if named else None,
        "add_effects": list(named.effects) if named else [],
        "heldout_scheme": base.data.scheme,
        "significance": SIGNIFICANCE_RULE,
        "ranking": RANKING_RULE,
        "missing_rule": MISSING_RULE,
        "conclusion": words,
        "consistency": groups,
        "resolution": list(resolution.entries),
        "metrics": dict(measures),
        "notes": notes,
        **setup_fields(stage),
        "data_check": list(checked.entries),
        "seconds": seconds,
        "cost": list(cost),
    })
    report.models, report.comparisons = models, comparisons
    report.tests = base.data.tests
    return report


# --------------------------------------------------------------------------------------------
# Output


def plot_candidates(report: dict[str, Any], path: str | Path) -> Path:
    """Bars: each model's normalised and held-out error, one error per model.

    The set-up as stated is the baseline (one bar) unless a set-up error was fitted: then
    the stated set-up's bar (on the forming tests) is drawn above the baseline at the
    fitted set-up.
    """
    import matplotlib.pyplot as plt

    from fenicsx_drape.provenance import save_figure

    stated = report.get("setup_stated") or {}
    fitted = report.get("setup_error")
    rows = []
    if fitted and stated.get("error"):
        rows.append(("set-up as stated", stated["error"]["normalised"],
                     stated["heldout_normalised"], False))
    label = (f"baseline, {fitted} fitted" if fitted else
             "baseline (the set-up as stated)" if stated else "baseline")
    rows.append((label, report["baseline"]["error"]["normalised"],
                 report["baseline"]["heldout_normalised"], False))
    rows += [(c["effect"], c["error_after"]["normalised"], c["heldout_normalised"],
              c["effect"] == report["missing_effect"]) for c in report["candidates"]]
    y = np.arange(len(rows))[::-1]
    fig, ax = plt.subplots(figsize=(8, 0.6 * len(rows) + 1.5))
    ax.barh(y + 0.18, [r[1] for r in rows], height=0.35, label="fitted (error_after)",
            color=["C3" if r[3] else "C0" for r in rows])
    ax.barh(y - 0.18, [r[2] for r in rows], height=0.35, label="held-out", color="0.6")
    ax.axvline(1.0, color="k", ls="--", lw=1, label="noise floor")
    ax.axvline(ADEQUATE, color="0.4", ls=":", lw=1, label=f"adequate ({ADEQUATE})")
    ax.set_xscale("log")
    ax.set_yticks(y, [r[0] for r in rows], fontsize=8)
    ax.set_xlabel("normalised error (RMSE / noise)")
    ax.set_title(found_text(report), fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    return save_figure(fig, path)


def found_text(report: dict[str, Any]) -> str:
    """What the run found, in a few words (the candidates picture's title)."""
    suspects = [f"{e['test']}/{e['measurement']}" for e in report.get("data_check", ())
                if e["suspect"]]
    if suspects:
        return f"check the data: {', '.join(suspects)}"
    found = []
    if report.get("setup_error"):
        found.append(f"set-up error {report['setup_error']}")
    if report["missing_effect"]:
        found.append(f"missing effect {report['missing_effect']}")
    return "found: " + " and ".join(found) if found else "found: no set-up error, no effect"


def summary(report: dict[str, Any]) -> str:
    """The report as text: baseline, ranked candidates, untestable effects, conclusion.

    The conclusion is printed once: first when data are suspect, else last.
    """
    base = report["baseline"]
    suspect = any(e["suspect"] for e in report.get("data_check", ()))
    lines = [report["conclusion"]] if suspect else []
    at = (f" with {report['setup_error']} fitted" if report.get("setup_error") else
          " (the set-up as stated)" if report.get("setup_stated") else "")
    lines += [f"baseline ({', '.join(base['effects']) or 'no effects'}){at}: normalised "
              f"{base['error']['normalised']:.3g}, held-out {base['heldout_normalised']:.3g} "
              f"(noise floor 1; from {report['noise_floor']['source']})"]
    if base.get("optimiser", {}).get("statement"):
        lines.append(f"optimiser: {base['optimiser']['statement']}")
    lines += [f"noise of {k}: {v}" for k, v in report["noise_floor"].get("says", {}).items()
              if k in report["noise_floor"].get("implausible", ())]
    lines.append("where the error sits:")
    lines += [f"  {100 * e['share_of_error']:5.1f} %  {e['test']}: {e['says']}"
              for e in report["where"][:5]]
    lines += setup_summary(report)
    lines.append(f"{'candidate':<44} {'after':>7} {'held-out':>9} {'evidence':>9}  significant")
    for c in report["candidates"]:
        lines.append(f"{c['effect']:<44} {c['error_after']['normalised']:>7.3g} "
                     f"{c['heldout_normalised']:>9.3g} {c['evidence']:>9.3g}  "
                     f"{'yes' if c['significant'] else 'no'}")
        lines.append(f"    {c['explanation']}")
    lines += [f"not testable from these tests: {u['effect']} ({u['reason']})"
              for u in report["untestable"]]
    for label, tests in report.get("metrics", {}).items():
        for test, m in tests.items():
            if "stopped_at_travel_mm" in m:
                lines.append(f"note: {label} could not form {test} to full travel (stopped at "
                             f"{m['stopped_at_travel_mm']:.1f} mm); compared as far as it got")
    for o in report.get("outliers", []):
        lines.append(f"outlier left out: {o['file']}:{o['line']} ({o['id']}), residual "
                     f"{o['residual']:.3g} × noise")
    if report.get("cost"):
        lines.append(cost_line(report["cost"]))
    lines.append(f"missing_effect: {report['missing_effect']}")
    if not suspect:
        lines.append(report["conclusion"])
    return "\n".join(lines)


def write_diagnosis(report: dict[str, Any], json_path: str | Path,
                    out_dir: str | Path | None = None, *, bundle: Bundle | None = None) -> Path:
    """Write ``REPORT.json`` (atomically); with ``out_dir``, the plots and provenance too.

    ``out_dir`` gets ``candidates.png`` (each candidate's fitted and held-out error),
    ``ledger.jsonl`` (the model versions: set-up as stated, fitted, effect added; ``drape
    history``),
    ``where.png`` (the baseline's error by region) and, given the ``bundle`` and a
    :class:`Report`, ``residual_<test>.png`` (the baseline and the best candidate against
    each test), plus ``provenance.json``.
    """
    from fenicsx_drape.diagnosis.comparison import locate, plot_where, safe_name
    from fenicsx_drape.provenance import write_json, write_provenance
    from fenicsx_drape.runs import execution_record

    path = write_json(json_path, report)
    if out_dir is None:
        return path
    out = Path(out_dir)
    plot_candidates(report, out / "candidates.png")
    plot_where(report["where"], out / "where.png",
               f"{report['bundle']}: baseline error by region")
    comparisons = getattr(report, "comparisons", None)
    if bundle is not None and comparisons:
        best = report["candidates"][0]["effect"] if report["candidates"] else None
        tests = {t.id: t for t in getattr(report, "tests", None) or bundle.tests}
        regions = locate(comparisons["baseline"])
        for i, base in enumerate(comparisons["baseline"]):
            shown = {"baseline": base} | ({best: comparisons[best][i]} if best else {})
            kind_of(tests[base.id]).plot(shown, tests[base.id],
                                         out / f"residual_{safe_name(base.id)}.png",
                                         [e for e in regions if e["tests"] == [base.id]])
    record_history(report, out, bundle)  # the versions, for drape history
    write_provenance(out, bundle=report["bundle"], report=str(Path(json_path).resolve()),
                     effects=report["baseline"]["effects"],
                     parameters=report["baseline"]["parameters"],
                     missing_effect=report["missing_effect"], seed=None,
                     forming_runs=execution_record())
    return path
