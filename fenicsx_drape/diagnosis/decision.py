"""The diagnosis's fixed rules, and what it names from the stages' results.

The rules are the same for every bundle:

- **significant**: a candidate's ``evidence`` (baseline held-out / candidate held-out
  normalised error, on the tests of the kinds it acts on: :func:`evidence`) is at least
  :data:`EVIDENCE_THRESHOLD` (1.2: it predicts unseen data with an error at least 17 %
  lower);
- **ranked** by ``heldout_normalised``; among those within :data:`PARSIMONY` (5 %) of the
  best, the one adding the fewest parameters first (:func:`rank`);
- **missing**: the first candidate if it is significant and its refit reaches ``normalised
  <= ADEQUATE`` (1.5), the measurements its net's own error excuses left out
  (:func:`adequate`);
- a set-up error fitted again with the missing effect back within :data:`~fenicsx_drape.
  diagnosis.setup_fit.DISTINCT_SD` sd of its stated value is **withdrawn**: the effect, not
  the set-up, was missing (:func:`setup_as_reported`);
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
from fenicsx_drape.diagnosis.setup_fit import DISTINCT_SD

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds import Comparison
    from fenicsx_drape.diagnosis.results import Candidate, DataCheck, Effects, SetupResult

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
                f"normalised <= {ADEQUATE} (on the measurements whose residual "
                "its net does not explain or is within its net's own error, "
                "resolution_after)")


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
             effects: Sequence[str], resolved: frozenset[str] = frozenset()) -> float:
    """Baseline / candidate held-out normalised error on the tests the effects act on.

    Tests of other kinds (coupons, for a forming effect) are predicted alike by both and
    would only dilute the ratio; with none of them, all tests count. The measurements whose
    residual the net explains (``resolved``) are no evidence: with nothing else, the evidence
    is 1.
    """
    from fenicsx_drape.effects import describe_effect

    kinds = {k for name in effects for k in describe_effect(name).test_kinds}
    pick = [i for i, c in enumerate(baseline) if c.kind in kinds] or range(len(baseline))
    pick = [i for i in pick if baseline[i].id not in resolved]
    if not pick:
        return 1.0
    after = normalised_error([candidate[i] for i in pick])
    return normalised_error([baseline[i] for i in pick]) / after if after > 0 else math.inf


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


def adequate(candidate: Candidate) -> bool:
    """Whether a candidate's refit reaches the noise floor, its net's own error excused.

    ``normalised <= ADEQUATE`` on every test; else the measurements it still misses were
    checked for resolution as the baseline's were (``resolution_after``), and it is adequate
    when those its net does not excuse are within ``ADEQUATE``. A measurement is excused when
    the net explains it (the baseline's rule), or when what the candidate leaves beyond the
    noise is within its net's own error e_Δ (``within_net_error``): the candidate's
    parameters were refitted on that net, so the finer net need not come nearer, and no net
    this coarse can tell that residual from the truth.
    """
    if candidate.error_after["normalised"] <= ADEQUATE:
        return True
    checked = candidate.resolution_after
    if not checked:  # not checked (no formed part), or nothing it misses to check
        return False
    excused = {e["measurement"] for e in checked if e["explains"] or e["within_net_error"]}
    rest = [c for c in candidate.after if c.id not in excused]
    return not rest or normalised_error(rest) <= ADEQUATE


def setup_as_reported(setup: SetupResult | None, missing: Candidate | None
                      ) -> SetupResult | None:
    """The set-up error as it stands once the missing effect is in.

    A missing effect can be taken up by a set-up parameter when the set-up is fitted alone
    (a holding force that lowers a hidden friction's error); refitted with the effect, it
    goes back to the stated value. The set-up entry records its value with the effect
    (``fitted_with_effect``), and the set-up error is withdrawn when that value lies within
    :data:`~fenicsx_drape.diagnosis.setup_fit.DISTINCT_SD` of its sd from the stated one.
    """
    if not (missing and missing.setup_refitted and setup and setup.setup_error):
        return setup
    entry = {**setup.entries[0], "fitted_with_effect": missing.setup_refitted.fitted}
    fitted, stated, sd = (np.atleast_1d(np.asarray(v, float)) for v in
                          (entry["fitted_with_effect"], entry["stated"], entry["sd"]))
    within = bool(np.all(np.abs(fitted - stated) <= DISTINCT_SD * sd))
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
