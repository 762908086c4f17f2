"""The diagnosis in words: why untestable, where the residual is, explanations, conclusion.

Also the coupon fit's records in the report (how the optimiser knows it is at its best, the
noise of each test).

Plain functions of the stages' results (:mod:`~fenicsx_drape.diagnosis.results`): nothing
here fits or forms.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from fenicsx_drape.diagnosis.comparison import locate, normalised_error, trends
from fenicsx_drape.diagnosis.decision import ADEQUATE, EVIDENCE_THRESHOLD, UNTESTABLE_BELOW
from fenicsx_drape.diagnosis.resolution import finer_net, judged_text

if TYPE_CHECKING:
    from collections.abc import Sequence

    from fenicsx_drape.diagnosis.kinds import Comparison
    from fenicsx_drape.diagnosis.results import Candidate, Prepared


def untestable_reason(effect, data: Prepared, change: float, per_test: dict[str, float]) -> str:
    """Why an effect is untestable: how little it changes which tests, and what they lack."""
    kinds = sorted({t.kind for t in data.tests})
    if change == 0.0:
        text = "adding it at its default strength changes none of the simulated tests"
    else:
        largest = max(per_test, key=per_test.get)
        text = (f"adding it at its default strength changes the simulated tests by only "
                f"{change:.2g} × their noise (at most {per_test[largest]:.2g} in {largest}; "
                f"testable from {UNTESTABLE_BELOW})")
    if not set(kinds) & set(effect.test_kinds):
        return (f"{text}: it acts on the {effect.acts_on} in {' and '.join(effect.test_kinds)} "
                f"tests, and the bundle has only {' and '.join(kinds)} tests")
    fixed = [c for c in effect.conditions if len({t.conditions.get(c) for t in data.tests}) < 2]
    if fixed:
        return f"{text}: {', '.join(fixed)} does not vary across the tests"
    return f"{text}: these tests do not exercise it"


def pattern_of(base: Sequence[Comparison]) -> str:
    """One clause on where the baseline's residual is, from trends and regions."""
    normalised = normalised_error(base)
    if normalised <= 1.2:
        return f"the residual is at the noise floor (normalised {normalised:.2f})"
    for trend in trends(base):
        if trend["says"]:
            return trend["says"]
    regions = [e for e in locate(base) if "region" in e]
    if not regions:
        return f"the residual is {normalised:.3g} × the noise"
    top = max(regions, key=lambda e: e["share_of_error"])  # a kind's sum beats its parts
    tests = (f"the {top['kind'].replace('_', ' ')} tests" if len(top["tests"]) > 1
             else f"test {top['test']}")
    return (f"{100 * top['share_of_error']:.0f} % of the residual sits in the {top['region']} "
            f"region of {tests}")


def addition(c: Candidate) -> str:
    """How a candidate changes the model, in words."""
    from fenicsx_drape.effects import EFFECTS

    if all(e in EFFECTS for e in c.effects):
        return f"the model gets {c.effect} ({c.summary})"
    summary = c.summary.rstrip(".")
    return (f"the user law {c.effect} replaces the {c.acts_on} law "
            f"({summary[:1].lower() + summary[1:]})")


def explain(c: Candidate, pattern: str, base_norm: float, base_ho: float) -> str:
    """A candidate's ``explanation``: the residual's pattern, and what adding it does."""
    after = c.error_after["normalised"]
    gain = (f"error {base_norm:.3g} → {after:.3g} × noise, held-out {base_ho:.3g} → "
            f"{c.heldout_normalised:.3g} (evidence {c.evidence:.3g})")
    what = addition(c)
    if c.significant and after <= ADEQUATE:
        return f"{pattern[:1].upper() + pattern[1:]}, and it vanishes when {what}: {gain}."
    if c.significant and c.finer_net is not None:
        f = c.finer_net
        return (f"{pattern[:1].upper() + pattern[1:]}; it shrinks when {what}: {gain}, on a "
                f"net that cannot judge it; on the {f['cell_mm']:g} mm net it brings the "
                f"error from {f['baseline_normalised']:.3g} to {f['normalised']:.3g} × noise "
                f"(evidence {f['evidence']:.3g} there).")
    if c.significant:
        remains = c.where_after[0] if c.where_after else None
        rest = (f"; what remains sits in {remains['test']} ({remains['says']})"
                if remains else "")
        return (f"{pattern[:1].upper() + pattern[1:]}; it shrinks but stays above {ADEQUATE} × "
                f"noise when {what}: {gain}{rest}.")
    return (f"{pattern[:1].upper() + pattern[1:]}; no real gain when {what}: {gain}, "
            f"evidence below {EVIDENCE_THRESHOLD}.")


def optimiser_record(coupons) -> dict[str, Any]:
    """How the baseline's coupon fit knows it is at its best (the global stage's record).

    ``at_best`` is true when every block's best minimum was reached from at least two of the
    independent starts (curve features, Table 2, MODEL.toml, Sobol points); the
    ``statement`` says so in words, block by block.
    """
    if coupons is None:
        return {"global_stage": False, "at_best": None, "blocks": [],
                "statement": "no coupon fit (the baseline has no coupon test)"}
    blocks = [{"label": b["label"], **{k: b["global"][k] for k in
                                       ("best_found_by", "n_best", "spread_normalised",
                                        "statement")},
               "starts": len(b["global"]["starts"])} for b in coupons.blocks if "global" in b]
    at_best = bool(blocks) and all(b["n_best"] >= 2 for b in blocks)
    parts = [f"{b['label']}: {b['statement']}" for b in blocks]
    head = ("the baseline is at the best minimum the global stage found from independent "
            "starts" if at_best else "the baseline's best minimum was reached from a single "
            "start only, so the optimiser may have stopped short of the model's best")
    undetermined = [u["parameter"] for u in coupons.undetermined]
    tail = (f"; held (undetermined by these tests): {', '.join(undetermined)}"
            if undetermined else "")
    return {"global_stage": bool(blocks), "at_best": at_best, "blocks": blocks,
            "undetermined": coupons.undetermined,
            "statement": f"{head} ({'; '.join(parts)}){tail}"}


def noise_notes(coupons) -> dict[str, Any]:
    """Where each coupon test's noise came from and, if so, why its estimate is implausible."""
    if coupons is None:
        return {}
    notes = {k: v["says"] for k, v in coupons.noise.items()}
    implausible = sorted(k for k, v in coupons.noise.items() if v["source"] == "relative_floor")
    return {"says": notes, "implausible": implausible}


def groups_conclusion(groups: dict[str, Any] | None, missing) -> str:
    """The conclusion when no effect is missing but one lab, size or kind explains the misfit.

    The rest fit at the noise without it: that group, not the physics, is the suspect.
    """
    if missing or not groups or groups["verdict"] in ("consistent", "missing_physics"):
        return ""
    return (f"Not missing physics but a {groups['verdict'].replace('_', ' ')}: "
            f"{groups['says']}. Check that group's set-up (load cell, normalisation, "
            "specimen, conditioning) or leave it out, and diagnose again.")


def groups_sentence(groups: dict[str, Any] | None) -> str:
    """A lab offset, size effect or kind mismatch, said beside the physics' conclusion."""
    if not groups or groups["verdict"] in ("consistent", "missing_physics"):
        return ""
    return (f" Before physics, the tests' groups: {groups['verdict']}: {groups['says']} "
            "(consistency).")


def conclusion(missing: Candidate | None, best: Candidate | None, base: Sequence[Comparison],
               pattern: str, optimiser: dict[str, Any] | None = None, coupons=None,
               resolution: Sequence[dict[str, Any]] = (), setup_fitted: str | None = None
               ) -> str:
    """The conclusion on the physics; its first sentence says how good the best model is.

    The missing effect (at the noise, or how far above it and why), none, or why none was
    found. ``resolution``: the baseline's net checked (its entries); a measurement whose
    residual is within the net's own error is one the net cannot judge, and no physics is
    concluded from it (:func:`~fenicsx_drape.diagnosis.decision.judged`).
    ``setup_fitted``: the set-up parameter named and fitted (the model is at it).
    """
    from fenicsx_drape.diagnosis.decision import judged

    normalised = normalised_error(base)
    noise = _noise_words(coupons)
    if missing:
        return _missing_words(missing, normalised, setup_fitted)
    model = f"with {setup_fitted} fitted, the model" if setup_fitted else "the model"
    if normalised <= ADEQUATE:
        return (f"No effect is missing: {model} is at {normalised:.3g} × the noise "
                f"(adequate at ≤ {ADEQUATE}).{noise}")
    unjudged = [e for e in resolution if e["explains"]]
    rest = judged(base, resolution)
    rest_norm = normalised_error(rest) if rest else None
    if unjudged and (rest_norm is None or rest_norm <= ADEQUATE):
        cells = " and ".join(f"{c:g}" for c in sorted({e["cell_mm"] for e in unjudged}))
        on_rest = (f"; on the rest it is at {rest_norm:.3g}" if rest_norm is not None else "")
        return (f"No missing physics is concluded: {model} is at {normalised:.3g} × the noise, and "
                f"what it misses is within the {cells} mm net's own discretisation error on "
                f"{', '.join(e['measurement'] for e in unjudged)}, which that net cannot "
                f"judge{on_rest}.{noise}")
    over = (f" ({rest_norm:.3g} on the measurements its net can judge)"
            if unjudged and rest_norm is not None else "")
    if best and best.significant:
        return (f"No single candidate brings the error to the noise floor: the best, "
                f"{best.effect}, is a real gain (evidence {best.evidence:.3g}) but brings it "
                f"only from {normalised:.3g} to {best.error_after['normalised']:.3g} × the "
                f"noise{over}. More than one effect may be missing: add it and diagnose again.")
    closest = (f" The closest candidate, {best.effect}, reaches "
               f"{best.error_after['normalised']:.3g} × noise (evidence "
               f"{best.evidence:.3g}).") if best else ""
    if optimiser is not None and optimiser.get("at_best") is False:
        return (f"None of the candidates explains the residual: {model} stays at "
                f"{normalised:.3g} × the noise{over}: {pattern}. But {optimiser['statement']}: "
                f"the residual may be the optimiser's, not missing physics; give better "
                f"starting values in MODEL.toml and diagnose again.{closest}{noise}")
    how = (f" How the baseline is known to be at its best: {optimiser['statement']}."
           if optimiser is not None and optimiser.get("at_best") else "")
    return (f"None of the candidates explains the residual: {model} stays at "
            f"{normalised:.3g} × the noise{over}: {pattern}. The missing physics is not in "
            f"the catalogue; write it as a user law (plugins in MODEL.toml) and diagnose "
            f"again.{closest}{how}{noise}")


def unjudged(entries: Sequence[dict[str, Any]], missing: Candidate | None
             ) -> list[dict[str, Any]]:
    """The resolution entries no physics is concluded from.

    Those within the net's own error, less those the named effect predicts at the noise (its
    evidence: the net judges them), and none when its refit reaches the noise on all its
    tests together (:func:`~fenicsx_drape.diagnosis.decision.follows`).
    """
    from fenicsx_drape.diagnosis.decision import follows

    if missing and (follows(missing.after) or missing.finer_net is not None):
        return []
    at_noise = {c.id for c in (missing.after if missing else ()) if c.normalised <= ADEQUATE}
    return [e for e in entries if e["explains"] and e["measurement"] not in at_noise]


def _missing_words(missing: Candidate, normalised: float, setup_fitted: str | None) -> str:
    """The named effect: the error it brings, at the noise or how far above it and why."""
    from fenicsx_drape.diagnosis.decision import judged

    after = missing.error_after["normalised"]
    at = f" ({setup_fitted} fitted)" if setup_fitted else ""
    head = (f"Missing effect: {missing.effect} ({missing.summary.rstrip('.')}): adding it{at} "
            f"brings the normalised error from {normalised:.3g} to {after:.3g} × the noise")
    checked = missing.resolution_after or ()
    nets = [e for e in checked if e["explains"]]
    if after <= ADEQUATE:
        return f"{head}, at the noise (adequate at ≤ {ADEQUATE})."
    finer = missing.finer_net
    if finer is not None:
        return (f"{head}, still above it: the net it ran on cannot judge "
                f"{', '.join(finer['measurements'])} (its own error there is as large as "
                f"the residual). On the {finer['cell_mm']:g} mm net the effect brings "
                f"{'it' if len(finer['measurements']) == 1 else 'them'} "
                f"from {finer['baseline_normalised']:.3g} to {finer['normalised']:.3g} × the "
                f"noise (evidence {finer['evidence']:.3g}): that net judges it.")
    if not nets:
        return f"{head}, {after / ADEQUATE:.3g} × above the adequate {ADEQUATE}."
    rest = judged(missing.after, checked)
    on_rest = (f"; on the rest, which it can judge, it is at {normalised_error(rest):.3g}"
               if rest else "")
    cells = " and ".join(f"{c:g}" for c in sorted({e["cell_mm"] for e in nets}))
    return (f"{head}, still above it: what it leaves on "
            f"{', '.join(e['measurement'] for e in nets)} is within its {cells} mm net's own "
            f"discretisation error, which that net cannot judge{on_rest}. On "
            + "; on ".join(judged_text(e) for e in nets)
            + f": {finer_net(nets)}.")


def _noise_words(coupons) -> str:
    """The coupons' implausibly small noise estimates, in words ("" when none)."""
    floored = [k for k, v in (coupons.noise.items() if coupons is not None else ())
               if v["source"] == "relative_floor"]
    if not floored:
        return ""
    return (f" Noise: the model-free estimates of {', '.join(floored)} are implausibly "
            "small for the curves (smoothed or digitised), so their errors are measured "
            "against 2 % of each test's peak force; declare the noise (force_sd_N or "
            "force_sd_rel in bundle.toml, [noise] in MODEL.toml) to judge against the "
            "real one.")
