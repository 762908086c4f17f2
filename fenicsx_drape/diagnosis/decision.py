"""The diagnosis's fixed rules, and what it names from the stages' results.

The rules are the same for every bundle:

- **what the net can judge**: a measurement whose residual is within its net's own error
  (:func:`~fenicsx_drape.diagnosis.resolution.within_net`: at the noise floor once that
  error is weighed as noise) is one the net cannot judge: no physics is concluded from it,
  neither an effect nor missing physics (:func:`judged`). One rule for the baseline's
  residual (``resolution``) and for what a candidate leaves (``resolution_after``); a
  measurement a candidate predicts at the noise on held-out rows is one its net does judge
  (the data then follow a model on this net to within their noise), and so is every
  measurement of a candidate whose refit reaches the noise on them together
  (:func:`follows`: an effect that brings the model to the noise on the case's own net is
  not withheld for that net's error);
- **significant**: a candidate's ``evidence`` (baseline held-out / candidate held-out
  normalised error, on the tests of the kinds it acts on that the net can judge:
  :func:`evidence`) is at least :data:`EVIDENCE_THRESHOLD` (1.2: it predicts unseen data
  with an error at least 17 % lower);
- **ranked** by ``heldout_normalised``; among those within :data:`PARSIMONY` (5 %) of the
  best, the one adding the fewest parameters first (:func:`rank`);
- **missing**: the first candidate if it is significant and its refit reaches ``normalised
  <= ADEQUATE`` (1.5) on the measurements its net can judge (:func:`adequate`); when what
  it leaves elsewhere keeps its overall error above, the conclusion's first sentence says so;
- a set-up parameter is named when the first of the set-up candidates is significant or
  **set apart** (fitted away from its stated value with evidence, whatever the leftover of
  other measurements: :mod:`~fenicsx_drape.diagnosis.setup_stage`, 5.);
- a set-up error fitted again with the missing effect back within :data:`~fenicsx_drape.
  diagnosis.setup_fit.DISTINCT_SD` sd of its stated value (one named as set apart only:
  within :data:`~fenicsx_drape.diagnosis.setup_fit.SET_APART_SD` of its fit's own sd) is
  **withdrawn**: the effect, not the set-up, was missing (:func:`setup_as_reported`);
- on data that cannot be of their case (the data check) no effect is **named**.

:func:`decide` applies them; :class:`Rules` carries those the set-up stage shares.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from fenicsx_drape.diagnosis.comparison import normalised_error
from fenicsx_drape.diagnosis.results import Decision
from fenicsx_drape.diagnosis.setup_fit import DISTINCT_SD, SET_APART_SD

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds import Comparison
    from fenicsx_drape.diagnosis.results import (
        Candidate,
        DataCheck,
        Effects,
        Entry,
        SetupResult,
    )

EVIDENCE_THRESHOLD = 1.2  # significant: evidence at least this (fixed for every bundle)
ADEQUATE = 1.5  # a model within this many times the noise floor explains the data
UNTESTABLE_BELOW = 0.3  # an effect changing the tests by less (× noise) is untestable
PARSIMONY = 0.05  # candidates this close to the best held-out error count as ties
BASELINE_ITERATIONS = 100  # the iteration cap of the baseline's fit (and the stated model's)

SIGNIFICANCE_RULE = (f"significant when evidence (baseline held-out normalised error / "
                     f"candidate held-out normalised error, on the tests of the kinds the "
                     f"candidate acts on) >= {EVIDENCE_THRESHOLD}")
RANKING_RULE = (f"by heldout_normalised; among candidates within {100 * PARSIMONY:g} % of "
                "the best, the one adding the fewest parameters first")
MISSING_RULE = (f"the first candidate if significant and its refit reaches "
                f"normalised <= {ADEQUATE} on the measurements its net can judge (those "
                f"whose residual is not within the net's own error: residual > {ADEQUATE} × "
                "√(noise² + discretisation_error²), resolution_after)")


@dataclasses.dataclass(frozen=True)
class Rules:
    """The diagnosis's fixed rules the set-up stage shares (:func:`setup_rules`)."""

    evidence: float  # significant: evidence at least this
    parsimony: float  # held-out errors this close count as ties
    untestable_below: float  # a change (× noise) below this: untestable
    iterations: int  # the coupon fit's iteration cap (the stated model's material)
    # a measurement within this × its noise has nothing to explain (no resolution check);
    # None: no resolution check of the stated set-up
    adequate: float | None = None


def setup_rules(iterations: int = BASELINE_ITERATIONS) -> Rules:
    """The rules the set-up stage shares with the effects (``iterations``: the coupon fits')."""
    return Rules(EVIDENCE_THRESHOLD, PARSIMONY, UNTESTABLE_BELOW, iterations, ADEQUATE)


def evidence(baseline: Sequence[Comparison], candidate: Sequence[Comparison],
             effects: Sequence[str], resolved: frozenset[str] = frozenset(),
             refit: Sequence[Comparison] | None = None) -> float:
    """Baseline / candidate held-out normalised error on the tests the effects act on.

    Tests of other kinds (coupons, for a forming effect) are predicted alike by both and
    would only dilute the ratio; with none of them, all tests count. The measurements whose
    residual is within the net's own error (``resolved``) are no evidence, unless a model on
    this net follows the data there to within their noise, and the net's error is not in the
    way: the candidate predicts one at the noise (``ADEQUATE``) on its held-out rows, or its
    ``refit`` (the candidate fitted to every row, same order) reaches the noise on all the
    tests its kinds give (:func:`follows`: then every one of them counts). With nothing
    left, the evidence is 1.
    """
    from fenicsx_drape.effects import describe_effect

    kinds = {k for name in effects for k in describe_effect(name).test_kinds}
    pick = [i for i, c in enumerate(baseline) if c.kind in kinds] or range(len(baseline))
    if refit is None or not follows([refit[i] for i in pick]):
        pick = [i for i in pick if baseline[i].id not in resolved
                or candidate[i].normalised <= ADEQUATE]
    if not pick:
        return 1.0
    after = normalised_error([candidate[i] for i in pick])
    return normalised_error([baseline[i] for i in pick]) / after if after > 0 else math.inf


def follows(refit: Sequence[Comparison]) -> bool:
    """Whether a model on its net follows these measurements to the noise (``ADEQUATE``).

    Its normalised error on them together is within ``ADEQUATE``: the model as formed on
    this net explains the data, so the net's own error, however large against the
    baseline's residual, is not what the data show. What a lab would expect: an effect whose
    refit reaches the noise on the case's own net, with held-out evidence, is named; the
    net's error withholds physics only where no model on that net reaches the noise.
    """
    return bool(refit) and normalised_error(refit) <= ADEQUATE


def rank(candidates: Sequence[Candidate]) -> list[Candidate]:
    """Candidates by held-out error, the most parsimonious near-best first."""
    ranked = sorted(candidates, key=lambda c: (c.heldout_normalised, c.effect))
    if ranked:
        near = [c for c in ranked
                if c.heldout_normalised <= (1 + PARSIMONY) * ranked[0].heldout_normalised]
        first = min(near, key=lambda c: (c.n_parameters, c.heldout_normalised))
        ranked.remove(first)
        ranked.insert(0, first)
    return ranked


def judged(compared: Sequence[Comparison], checked: Sequence[Entry] | None
           ) -> list[Comparison]:
    """The comparisons of the measurements the net can judge (module doc).

    ``checked``: the model's resolution entries (None or empty: nothing checked, all count).
    """
    unjudged = {e["measurement"] for e in checked or () if e["explains"]}
    return [c for c in compared if c.id not in unjudged]


def adequate(candidate: Candidate) -> bool:
    """Whether a candidate's refit reaches the noise floor on what its net can judge.

    ``normalised <= ADEQUATE`` on every test; else the measurements it still misses were
    checked against its net (``resolution_after``: the candidate formed on half the cell),
    and those whose leftover is within the net's own error are left out (:func:`judged`):
    it is adequate when the rest are within ``ADEQUATE`` (or none is left). A candidate the
    finer net judged (``finer_net``: on the measurements its own net cannot judge, at the
    noise on half the cell) is adequate when the rest are within ``ADEQUATE``.
    """
    if candidate.error_after["normalised"] <= ADEQUATE:
        return True
    finer = candidate.finer_net
    if finer is not None and finer["normalised"] <= ADEQUATE:  # the finer net judged them
        rest = [c for c in candidate.after if c.id not in finer["measurements"]]
        return not rest or normalised_error(rest) <= ADEQUATE
    if not candidate.resolution_after:  # not checked (no formed part), or nothing to check
        return False
    rest = judged(candidate.after, candidate.resolution_after)
    return not rest or normalised_error(rest) <= ADEQUATE


def setup_as_reported(setup: SetupResult | None, missing: Candidate | None
                      ) -> SetupResult | None:
    """The set-up error as it stands once the missing effect is in.

    A missing effect can be taken up by a set-up parameter when the set-up is fitted alone
    (a holding force that lowers a hidden friction's error); refitted with the effect, it
    goes back to the stated value. The set-up entry records its value with the effect
    (``fitted_with_effect``), and the set-up error is withdrawn when that value lies within
    :data:`~fenicsx_drape.diagnosis.setup_fit.DISTINCT_SD` of its sd from the stated one (an
    error named as set apart only, within :data:`~fenicsx_drape.diagnosis.setup_fit.
    SET_APART_SD` of its fit's own sd: the basis it was named on).
    """
    if not (missing and missing.setup_refitted and setup and setup.setup_error):
        return setup
    entry = {**setup.entries[0], "fitted_with_effect": missing.setup_refitted.fitted}
    apart_only = entry.get("set_apart") and not entry["significant"]
    fitted, stated, sd = (np.atleast_1d(np.asarray(v, float)) for v in
                          (entry["fitted_with_effect"], entry["stated"],
                           entry["sd_fit" if apart_only else "sd"]))
    within = bool(np.all(np.abs(fitted - stated)
                         <= (SET_APART_SD if apart_only else DISTINCT_SD) * sd))
    return dataclasses.replace(setup, entries=(entry, *setup.entries[1:]),
                               setup_error=None if within else setup.setup_error,
                               withdrawn=entry["parameter"] if within else None)


def decide(effects: Effects, best: Candidate | None, setup: SetupResult | None,
           checked: DataCheck) -> Decision:
    """What the diagnosis names (module doc), from the candidates, the set-up and the data.

    Args:
        effects: The candidates, ranked (:func:`rank`).
        best: The first of them as the later stages left it (refitted at a set-up found with
            it, its net checked).
        setup: The set-up stage's result (None: not run).
        checked: The data check.
    """
    ranked = (best, *effects.ranked[1:]) if best is not None else effects.ranked
    missing = best if best is not None and best.significant and adequate(best) else None
    return Decision(ranked=ranked, best=best, missing=missing,
                    named=None if checked.suspects else missing,
                    setup=setup_as_reported(setup, missing))
