"""What each stage of a diagnosis returns: frozen values, passed forward and never edited.

:func:`~fenicsx_drape.diagnosis.pipeline.diagnose` calls its stages in order, each with the
values of the stages before it, and the report (:mod:`~fenicsx_drape.diagnosis.report`) only
formats them:

- the data check: :class:`DataCheck`;
- the tests prepared (noise, regions, held-out folds): :class:`Prepared`;
- the baseline fitted, its outliers left out (and again at a fitted set-up): :class:`Baseline`;
- the set-up stage: :class:`SetupResult` (its chosen set-up :class:`SetupBest`);
- the baseline's held-out error: :class:`HeldOut`; the net's own error: :class:`Resolution`;
- each candidate effect refitted and judged: :class:`Candidate` (or an untestable entry),
  all of them ranked: :class:`Effects`;
- the decision: :class:`Decision`.

Entries that go into the report as they are (a set-up candidate, an outlier, a resolution
check) are plain dicts of the contract's fields, made once by their stage.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.comparison import compare_tests, normalised_error

if TYPE_CHECKING:
    from fenicsx_drape.calibration.fitting import FitResult
    from fenicsx_drape.diagnosis.folds import Fold
    from fenicsx_drape.diagnosis.kinds import Comparison, Region
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

Entry = Mapping[str, Any]  # an entry of the report, with the contract's fields only


@dataclasses.dataclass(frozen=True)
class DataCheck:
    """Each forming measurement against its case (spec version 4), before any fit."""

    entries: tuple[Entry, ...]  # the report's ``data_check``: one per forming measurement
    suspect: frozenset[str]  # ids of the tests whose measurement cannot be of its case
    bundle: Bundle  # what is diagnosed: the bundle less its suspect tests (all, when all are)

    @property
    def suspects(self) -> tuple[Entry, ...]:
        """The entries of the measurements that cannot be of their case."""
        return tuple(e for e in self.entries if e["suspect"])


@dataclasses.dataclass(frozen=True)
class Prepared:
    """The bundle in canonical order and what does not depend on the model."""

    bundle: Bundle  # comparable tests only, sorted by id (the result is order-independent)
    tests: tuple[Test, ...]  # the same tests
    noise: Mapping[str, tuple[float, str]]  # each test's noise (its unit) and its source
    regions: Mapping[str, list[Region]]  # each test's regions (its kind's)
    folds: tuple[Fold, ...]  # the held-out folds (folds.folds_of)
    scheme: str  # the folds in words (the report's ``heldout_scheme``)
    notes: tuple[str, ...]  # tests left out or read on a chosen ply, in words

    def compare(self, simulated: Mapping[str, np.ndarray]) -> list[Comparison]:
        """Simulated values (by test id) against the tests."""
        return compare_tests(self.tests, simulated, self.regions, self.noise)


@dataclasses.dataclass(frozen=True)
class Baseline:
    """The model as given, fitted to the bundle less its outliers."""

    data: Prepared  # the bundle compared (without the outliers' rows)
    model: Model  # fitted
    compared: tuple[Comparison, ...]  # the fitted model against every test
    outliers: tuple[Entry, ...]  # the rows left out (file, line, residual in noise units)
    error_with_outliers: Entry  # the first fit's error record, the outliers still in
    optimiser: Entry  # how the coupon fit knows it is at its best (before the outliers' refit)
    coupons: FitResult | None  # the coupon fit (its blocks, noise, groups); None: no coupon

    @property
    def normalised(self) -> float:
        """The baseline's normalised error."""
        return normalised_error(self.compared)


@dataclasses.dataclass(frozen=True)
class HeldOut:
    """The baseline's held-out error: every row predicted by the fold that held it out."""

    compared: tuple[Comparison, ...]  # the predictions against the tests

    @property
    def normalised(self) -> float:
        """The held-out normalised error."""
        return normalised_error(self.compared)


@dataclasses.dataclass(frozen=True)
class Resolution:
    """The model's own discretisation error on each forming measurement it misses."""

    entries: tuple[Entry, ...]  # the report's ``resolution`` entries (resolution.py)
    explained: frozenset[str]  # the measurements whose residual the net explains


@dataclasses.dataclass(frozen=True)
class SetupBest:
    """The set-up the stage chose: applied to the bundle for what follows."""

    parameter: str  # e.g. "ply_angle_deg", "blank_offset_mm"
    p: tuple[float, ...]  # its fitted point, internal units (setup_parameters.stated_point)


@dataclasses.dataclass(frozen=True)
class SetupResult:
    """The set-up stage (spec version 3): each set-up candidate fitted and judged."""

    entries: tuple[Entry, ...]  # the report's ``setup``: candidates ranked, the error first
    setup_error: str | None  # the parameter named, or None
    untestable: tuple[Entry, ...]  # the set-up parameters these tests cannot exercise
    stated_error: Entry | None  # the stated set-up's error record (None: no forming test)
    stated_heldout_normalised: float | None  # its held-out error (it fits nothing: its error)
    scheme: str | None  # the held-out scheme in words
    rule: str | None  # the significance rule in words
    resolution: tuple[Entry, ...] | None  # the stated set-up's resolution (None: not checked)
    model_note: str | None  # when the stated set-up forms unlike the case's model on another
    best: SetupBest | None  # the chosen set-up when one is significant
    bundle: Bundle  # the stage's bundle (the baseline's, its outliers left out)
    stated_model: Model  # the model as stated: its material fitted to the coupons, if any
    corrected: Bundle  # the bundle with the best set-up applied (``bundle`` when none)
    given_model: Model | None = None  # the model diagnose was given (None: fit_setup alone)
    parameters: tuple[str, ...] = ()  # the parameters it was asked to try
    found_with_effect: str | None = None  # the effect it needed in to name its error
    withdrawn: str | None = None  # the error withdrawn: the effect, not the set-up, missing
    # the noise it judged with, where widened by the net's own error: ``measurements`` (the
    # net's error of each), ``normalised`` (the stated set-up's error on it); None: as stated
    widened: Entry | None = None
    # the forming parameters the stated model's fit moved (a diagnosis's baseline: the
    # holder's μ where no case states it); the set-up parameters they take up are untestable
    fitted: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class SetupRefit:
    """The set-up error fitted again with a candidate effect (a round of set-up and effect)."""

    parameter: str  # the set-up parameter
    fitted: float | list[float]  # its value with the effect (the report's units)
    fitted_alone: float | list[float]  # its value fitted alone (the set-up stage's)
    p: tuple[float, ...]  # the point with the effect, internal units

    def record(self) -> dict[str, Any]:
        """The candidate's ``setup_refitted`` entry."""
        return {"parameter": self.parameter, "fitted": self.fitted,
                "fitted_alone": self.fitted_alone}


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One candidate effect refitted and judged on held-out rows (the effects stage)."""

    effect: str  # its name, prerequisites first ("rate_dependence+temperature_dependence")
    effects: tuple[str, ...]  # the effects it adds to the model, in order
    acts_on: str  # the role of the law it acts on ("shear", "tow", "contact", ...)
    summary: str  # the catalogue's (or the user law's) summary
    parameters: Mapping[str, float]  # its own parameters as refitted
    error_after: Entry  # the refit's error record
    heldout_normalised: float  # the refit's held-out normalised error
    evidence: float  # baseline held-out / candidate held-out, on the tests it acts on
    significant: bool  # evidence at least the threshold (decision.EVIDENCE_THRESHOLD)
    sensitivity: float  # the change (× noise) it makes at its default strength
    where_after: tuple[Entry, ...]  # where the refit's error sits (the three largest)
    setup_refitted: SetupRefit | None  # the set-up fitted again with it, when there were rounds
    model: Model  # the refitted model
    after: tuple[Comparison, ...]  # the refit against the tests
    tests: tuple[Test, ...]  # the tests compared (a fitted set-up applied)
    n_parameters: int  # the parameters it adds (ties go to the fewest)
    # what it leaves checked against its net (the best candidate, when it needs it)
    resolution_after: tuple[Entry, ...] | None = None
    # the candidate and the baseline on the finer net, where the case's net judges none of
    # its measurements (pipeline.finer_net_stage): cell_mm, measurements, normalised,
    # baseline_normalised, evidence
    finer_net: Entry | None = None


@dataclasses.dataclass(frozen=True)
class Effects:
    """Every candidate effect tried: the testable ones ranked, the others with the reason."""

    ranked: tuple[Candidate, ...]  # by held-out error, the parsimonious near-best first
    untestable: tuple[Entry, ...]  # the report's ``untestable`` entries of the effects

    @property
    def best(self) -> Candidate | None:
        """The first ranked, if any."""
        return self.ranked[0] if self.ranked else None


@dataclasses.dataclass(frozen=True)
class Decision:
    """What the diagnosis names, from the stages' results (decision.decide)."""

    ranked: tuple[Candidate, ...]  # by held-out error, the parsimonious near-best first
    best: Candidate | None  # the first ranked, if any
    missing: Candidate | None  # the effect that explains the data: significant and adequate
    named: Candidate | None  # the effect the report names (none on suspect data)
    setup: SetupResult | None  # the set-up as reported (withdrawn when the effect took it)
