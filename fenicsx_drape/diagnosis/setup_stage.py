"""Process set-up before physics: the diagnosis's set-up stage (spec version 3).

When a formed part disagrees with the model, its set-up is the first suspect. Before any
physics effect is tried, :func:`setup_stage` fits each set-up parameter
(:mod:`~fenicsx_drape.diagnosis.setup_parameters`: the ply's angle, the blank's offset, the
holding force, the holder's μ, the punch's offset) to the forming tests of a bundle, as a
candidate of its own. The reference is the **stated set-up**: in a diagnosis, the baseline
as fitted (its material as given or fitted to the coupons, the friction no case states
fitted to the forming tests), so that the stated model has one error in a run, the
baseline's, on one noise; the stage fits nothing more to it. A set-up parameter that fit
takes up is untestable (:func:`taken_up`: the holding force and μ, where the baseline fits
μ). Alone (:func:`fit_setup`), the model as given.

Per candidate, the same definitions as an effect's (``diagnose``'s module doc): 1. the scan
and whether it is testable, 2. the fit, 3. the held-out error
(:mod:`~fenicsx_drape.diagnosis.setup_fit`, the folds :func:`~fenicsx_drape.diagnosis.folds.
node_folds`), and

4. **Decision**: ``evidence`` = stated held-out / candidate held-out on the forming tests
   (the stated set-up on the case's own model), ``evidence_on_model`` the same against the
   stated set-up on the model the candidate needs (a whole blank may form a little unlike the
   mirrored quarter: that difference is not the set-up's); significant when both are
   ``>= EVIDENCE_THRESHOLD`` (the effects' rule) and the fitted value lies more than
   :data:`DISTINCT_SD` sd from the stated one (a missing effect that a set-up parameter takes
   up by wandering within its own uncertainty names no set-up error). Ranked by held-out error;
   near-ties (``PARSIMONY``) go to the fewer parameters, then to the order of
   :data:`SETUP_PARAMETERS`. ``setup_error`` is the first if significant or set apart.

5. **Set apart**: a set-up parameter fitted away from its stated value with evidence is named
   whatever the leftover of other measurements. The honest ``sd`` grows with what the fit
   leaves (its lack of fit), and the evidence on the noise widened by the net's own error
   weighs the measurements it improves against edges the net cannot resolve: a stack's ply
   laid at 35° where the case says 45° is fitted 35.0 ± 4.0° (its fit alone ± 0.18°) with
   evidence 1.195 on the widened noise and 1.28 on the stated one, not significant. A
   candidate is **set apart** when all hold:

   - its value lies :data:`SET_APART_SD` (3) of its fit's own sd (``sd_fit``, the lack of fit
     left out) from the stated one, and as far from each bound of its range
     (:func:`~fenicsx_drape.diagnosis.setup_fit.set_apart`): a fit that ends at a bound, or a
     force or μ within 3 sd of zero, is a compensating fit with no value of its own (a hidden
     tow buckling took the octagon's holding force to 5 ± 14 N, the bound, for 100 N stated);
   - ``evidence_stated`` (the stated set-up's held-out error / the candidate's, on the noise
     as stated, against the stated set-up on the case's own model and on the model the
     candidate needs) is ``>= EVIDENCE_THRESHOLD``: the data as measured, at their own noise,
     are predicted better on held-out nodes;
   - ``evidence`` and ``evidence_on_model`` are above 1: on the noise widened by the net's
     own error, where the finer net shows a residual to be that error, the gain does not
     come from those measurements alone (the measurements the net can judge improve too).

   The report's entry says ``set_apart`` and ``evidence_stated``; the conclusion names the
   parameter with its value and sd (the honest one, and the fit's own).

``holder_force_N`` and ``mu`` act on the part only through their product μF (eq. 1: a
friction bar yields at F μ / n_s; the clamping does not depend on F), so the data cannot
tell them apart: when both are tried, ``mu`` is not formed again but reported from the
force's fit (μ · F'/F, the same errors and evidence, ``tied_to`` and ``confounded_with``).

Before the candidates, the stated set-up's own residual is checked against its net
(:mod:`~fenicsx_drape.diagnosis.resolution`): a measurement whose residual the finer net
shows to be the net's own error (:func:`~fenicsx_drape.diagnosis.resolution.shown`) still
counts, its noise widened by that error (:func:`widened`). The stage
judges its candidates (evidence, sd, significance) on that widened noise; the errors it
reports are on the stated noise, one scale with every other model of the report, and what it
judged with is kept beside them (``widened``: :func:`restated`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.comparison import error_record, normalised_error
from fenicsx_drape.diagnosis.decision import Rules
from fenicsx_drape.diagnosis.folds import NODE_SCHEME
from fenicsx_drape.diagnosis.kinds import is_formed, kind_of, row_sd
from fenicsx_drape.diagnosis.kinds.forming import forming_case_of
from fenicsx_drape.diagnosis.resolution import check_resolution, shown
from fenicsx_drape.diagnosis.results import SetupBest, SetupResult
from fenicsx_drape.diagnosis.setup_fit import (
    DISTINCT_SD,
    SET_APART_SD,
    SetupFit,
    SetupRuns,
    Untestable,
    distinct,
    first_runs,
    fit_candidate,
    set_apart,
)
from fenicsx_drape.diagnosis.setup_parameters import (
    PLY,
    SETUP_PARAMETERS,
    applied,
    base_parameter,
    corrected,
    fitted_of,
    forming_tests,
    sd_of,
    setup_names,
    show,
    stated,
    stated_point,
    why_not,
)
from fenicsx_drape.diagnosis.setup_words import value_text
from fenicsx_drape.errors import DrapeInputError, SolverError
from fenicsx_drape.runs import together

if TYPE_CHECKING:
    from fenicsx_drape.measurements.bundle import Bundle, Test
    from fenicsx_drape.model import Model

Progress = Callable[[str], None]

CONFOUNDED = {"holder_force_N": "mu", "mu": "holder_force_N"}
# The stated set-up on the model a candidate needs, this many times further from the data than
# on the case's own model (and beyond the noise): the two models differ, not the set-up.
MODELS_DIFFER = 2.0


def setup_candidate(name: str, tests: Sequence[Test], test0: Test, model: Model,
                    base_ho: float, rules: Rules, say: Progress, widened_noise: bool = False,
                    stated_noise: dict[str, float] | None = None,
                    stated_normalised: float | None = None
                    ) -> tuple[dict[str, Any], SetupFit | None]:
    """One set-up candidate: its report entry and its fit, or (its untestable entry, None).

    ``base_ho`` is the stated set-up's held-out error (its evidence's numerator);
    ``widened_noise``: the tests' noise is widened by the net's own error (said so);
    ``stated_noise`` (by test id) and ``stated_normalised``: the noise as stated and the
    stated set-up's error on it (``evidence_stated``; None: the tests' noise is as stated).
    """
    reason = why_not(name, tests)
    if reason is not None:
        return {"effect": name, "setup": True, "reason": reason}, None
    runs = SetupRuns(tests, model, name)
    start = stated_point(name, test0, model)
    say(f"set-up candidate {name}: from {show(name, start, test0, model)}")
    try:
        c = fit_candidate(runs, test0, rules.untestable_below, say)
    except (SolverError, DrapeInputError) as err:
        return {"effect": name, "setup": True,
                "reason": f"the part cannot be formed so: {err}"}, None
    if isinstance(c, Untestable):
        say(f"  untestable: {c.reason}")
        return {"effect": name, "setup": True, "reason": c.reason,
                "sensitivity": c.sensitivity}, None
    ratio = base_ho / c.heldout_normalised if c.heldout_normalised > 0 else math.inf
    on_stated = stated_evidence(c, stated_noise, stated_normalised, ratio)
    apart = bool(min(ratio, c.evidence) > 1.0 and on_stated >= rules.evidence
                 and set_apart(c, name))
    planes = planes_of(tests, name, c.p, model)
    entry = {"parameter": name, "stated": stated(test0, name, model),
             "fitted": fitted_of(name, c.p, test0, model),
             "sd": sd_of(name, c.sd_internal, test0, model),
             "sd_fit": sd_of(name, c.sd_fit, test0, model),
             "error_after": error_record(c.after),
             "heldout_normalised": c.heldout_normalised,
             "evidence": ratio,
             "evidence_on_model": c.evidence,
             "significant": bool(min(ratio, c.evidence) >= rules.evidence and distinct(c)),
             "evidence_stated": on_stated, "set_apart": apart,
             "sensitivity": c.sensitivity,
             "stated_on_model": c.stated_normalised,
             "n_parameters": len(c.p),
             "model": "full" if not planes else "/".join(planes) + " symmetry"}
    if name in CONFOUNDED:
        entry["confounded_with"] = CONFOUNDED[name]
    entry["runs"] = runs.formed
    say(f"  fitted {show(name, c.p, test0, model)} ± {value_text(entry['sd'])} "
        f"(fit alone ± {value_text(entry['sd_fit'])}), normalised "
        f"{entry['error_after']['normalised']:.3g}, held-out "
        f"{c.heldout_normalised:.3g}{' (the widened noise)' if widened_noise else ''}, "
        f"evidence {c.evidence:.3g}"
        + (f" ({on_stated:.3g} on the stated noise)" if stated_noise else "")
        + (", set apart" if apart else "") + "; "
        f"{runs.formed} forming runs ({c.folds_formed} for the folds)")
    return entry, c


def stated_evidence(c: SetupFit, noise: dict[str, float] | None, stated: float | None,
                    evidence: float) -> float:
    """A candidate's evidence on the noise as stated (module doc, 5.).

    The stated set-up's held-out error (its error: it fits nothing) on the case's own model,
    ``stated``, and on the model the candidate needs, each over the candidate's held-out
    error, all on ``noise``; the smaller. With ``noise`` None (the stage's noise is as
    stated) the stage's own ``evidence`` and ``evidence_on_model``.
    """
    if noise is None or stated is None or not c.heldout_rmse:
        return float(min(evidence, c.evidence))
    held = restated_error({"per_test": dict(c.heldout_rmse)}, noise)["normalised"]
    if not held > 0:
        return math.inf
    on_model = (restated_error({"per_test": dict(c.stated_rmse)}, noise)["normalised"]
                if c.stated_rmse else stated)
    return float(min(stated, on_model) / held)


def fit_setup(bundle: Bundle, model: Model, rules: Rules, *,
              parameters: Sequence[str] | None = None,
              progress: Progress | None = None, fitted: Sequence[str] = (),
              label: str = "") -> SetupResult:
    """Try every set-up candidate on the bundle's forming tests (module doc).

    Args:
        bundle: The measurements (only the forming tests count here).
        model: The model as stated: material as given or coupon-fitted, friction as given
            (in a diagnosis, the baseline as fitted: :func:`setup_stage`).
        rules: The diagnosis's fixed rules (:func:`~fenicsx_drape.diagnosis.decision.
            setup_rules`).
        parameters: The set-up parameters to try (default :data:`~fenicsx_drape.diagnosis.
            setup_parameters.SETUP_PARAMETERS`).
        progress: Called with a line of text per stage.
        fitted: The forming parameters ``model``'s fit moved (a diagnosis's baseline: the
            holder's μ where no case states it); a set-up parameter they take up is
            untestable (:func:`taken_up`).
        label: What the stated set-up is, in the console line (e.g. "the baseline").

    Returns:
        The candidates' entries ranked, the set-up error (or None), the untestable ones, the
        stated set-up's error and the chosen set-up (:class:`~fenicsx_drape.diagnosis.
        results.SetupResult`; the model as stated is ``model``, nothing applied yet).
    """
    say = progress or (lambda line: None)
    names = list(parameters if parameters is not None else SETUP_PARAMETERS)
    unknown = [n for n in names if base_parameter(n) not in SETUP_PARAMETERS]
    if unknown:
        raise DrapeInputError(f"set-up parameters {unknown}: not among "
                              f"{', '.join(SETUP_PARAMETERS)} (and {PLY}<k> on a stack)")
    tests = forming_tests(bundle)
    names = setup_names(names, tests)
    nothing = functools.partial(SetupResult, setup_error=None, best=None, bundle=bundle,
                                stated_model=model, corrected=bundle,
                                parameters=tuple(names))
    if not tests:
        return nothing(entries=(), untestable=tuple(
            {"effect": n, "setup": True, "reason": "no forming test in the bundle"}
            for n in names), stated_error=None, stated_heldout_normalised=None, scheme=None,
            rule=None, resolution=None, model_note=None)
    test0 = tests[0]
    base_cmp = stated_comparisons(tests, model)
    # The candidates are independent (but μ after the force: it is tied to it, eq. 1): tried
    # together, their runs formed in common batches; the outcomes taken in order.
    tied = "mu" in names and "holder_force_N" in names[:names.index("mu")]
    fitted_away = taken_up(names, tests, fitted)
    own = [n for n in names if not (n == "mu" and tied) and n not in fitted_away]
    resolution = None
    stated_noise = {c.id: c.noise for c in base_cmp}  # each test's noise as stated
    net_error: dict[str, float] = {}  # the net's own error, where it widens the noise
    if rules.adequate is not None:
        # Resolution before the set-up, too: a measurement whose residual at the stated
        # set-up is the net's own error is no evidence of a set-up error. Its verdict weighs
        # the candidates' runs, not which they are: their first batch is formed with its run.
        checked, *_ = together([
            functools.partial(check_resolution, tests, model, base_cmp, rules.adequate),
            *(functools.partial(first_runs, name, tests, test0, model) for name in own)], say)
        resolution = tuple(checked)
        # Widened where the finer net shows the residual to be the net's own error (it comes
        # nearer the data, within its own error): a residual the net's error could hide but
        # a finer net does not shrink (data of this very net) is left to the set-up's own
        # evidence: a blank 10 mm off is 20 × the noise and within a 20 mm net's error.
        resolved = {e["measurement"] for e in resolution if shown(e)}
        if resolved:
            # They still count: a set-up that moves the part far from them must pay for it.
            # Their noise is widened by the net's own error (what the net cannot resolve).
            say(f"  set-up stage: the finer net shows the residual of "
                f"{', '.join(sorted(resolved))} to be the net's own error; their noise is "
                "widened by it")
            net_error = {e["measurement"]: e["discretisation_error"] for e in resolution
                         if shown(e)}
            tests = [widened(t, net_error[t.id]) if t.id in net_error else t for t in tests]
            test0 = tests[0]
            base_cmp = stated_comparisons(tests, model)
    base_ho = normalised_error(base_cmp)  # nothing is fitted: held-out = the error
    stated_error = restated_error(error_record(base_cmp), stated_noise)
    say(f"set-up as stated{f' ({label})' if label else ''}: normalised error "
        f"{stated_error['normalised']:.3g} on {len(tests)} forming test(s)" + (
            f" ({base_ho:.3g} with the noise of {', '.join(sorted(net_error))} widened by "
            "the net's own error, as the set-up stage judges)" if net_error else ""))
    rule = (f"significant when evidence (stated held-out / candidate held-out, on "
            f"the forming tests) and evidence_on_model (the same with the stated "
            f"set-up on the model the candidate needs) are >= {rules.evidence} "
            f"and the fitted value lies more than {DISTINCT_SD:g} sd from the "
            f"stated one; set apart, whatever the leftover of other measurements, when "
            f"the fitted value lies {SET_APART_SD:g} sd_fit (the fit's own sd) from the "
            f"stated one and from each bound of its range, evidence_stated (the same "
            f"ratios on the noise as stated) is >= {rules.evidence} and evidence and "
            f"evidence_on_model are above 1; "
            f"ranked by held-out error, "
            f"near-ties ({100 * rules.parsimony:g} %) to fewer parameters, then to the "
            f"order {', '.join(SETUP_PARAMETERS)}; the first is named when significant or "
            f"set apart")
    outcomes = dict(zip(own, together([functools.partial(
        setup_candidate, name, tests, test0, model, base_ho, rules,
        widened_noise=bool(net_error), stated_noise=stated_noise if net_error else None,
        stated_normalised=stated_error["normalised"]) for name in own], say)))
    tried: list[tuple[dict[str, Any], SetupFit]] = []
    untestable: list[dict[str, Any]] = []
    for name in names:
        if name in fitted_away:
            untestable.append({"effect": name, "setup": True, "reason": fitted_away[name]})
            say(f"set-up candidate {name}: untestable ({fitted_away[name]})")
            continue
        if name in outcomes:
            entry, c = outcomes[name]
            if c is None:
                untestable.append(entry)
            else:
                tried.append((entry, c))
            continue
        reason = why_not(name, tests)
        force = [ec for ec in tried if ec[0]["parameter"] == "holder_force_N"]
        if reason is not None:
            untestable.append({"effect": name, "setup": True, "reason": reason})
        elif force:  # eq. 1: μ acts through μF only, as the force does
            tried.append(tied_mu(*force[0], test0, model))
            say(f"set-up candidate mu: tied to holder_force_N (μF, eq. 1), "
                f"{value_text(tried[-1][0]['fitted'])}, no runs of its own")
        else:  # the force was untestable: so is μ
            force_entry = [u for u in untestable if u["effect"] == "holder_force_N"]
            untestable.append({**force_entry[0], "effect": "mu", "reason": (
                f"as holder_force_N (μ acts through μF only, eq. 1): "
                f"{force_entry[0]['reason']}")})
    order = {n: i for i, n in enumerate(dict.fromkeys(setup_names(SETUP_PARAMETERS, tests)
                                                       + names))}
    tried.sort(key=lambda ec: (ec[0]["heldout_normalised"], order[ec[0]["parameter"]]))
    if tried:
        top = tried[0][0]["heldout_normalised"]
        near = [ec for ec in tried
                if ec[0]["heldout_normalised"] <= (1 + rules.parsimony) * top]
        first = min(near, key=lambda ec: (ec[0]["n_parameters"], order[ec[0]["parameter"]]))
        tried.remove(first)
        tried.insert(0, first)
    note = model_note(tried, base_ho)
    if note:
        say(note)
    best = None
    if tried and (tried[0][0]["significant"] or tried[0][0]["set_apart"]):
        entry, c = tried[0]
        best = SetupBest(entry["parameter"], tuple(float(v) for v in c.p))
    widening = None
    if net_error:
        widening = {"measurements": {k: net_error[k] for k in sorted(net_error)},
                    "normalised": base_ho}
        tried = [(restated(e, c, stated_noise), c) for e, c in tried]
    return nothing(entries=tuple(e for e, _ in tried),
                   setup_error=best.parameter if best else None,
                   untestable=tuple(untestable), stated_error=stated_error,
                   stated_heldout_normalised=stated_error["normalised"], scheme=NODE_SCHEME,
                   rule=rule, resolution=resolution, model_note=note, best=best,
                   widened=widening, fitted=tuple(fitted))


def taken_up(names: Sequence[str], tests: Sequence[Test], fitted: Sequence[str]
             ) -> dict[str, str]:
    """The set-up parameters the stated model's own fit takes up, with the reason.

    The holding force and the holder's μ act on the part only through μF (eq. 1). Where no
    forming test's case states μ, a diagnosis's baseline fits it (``fitted``), so the
    stated set-up already sits at the best μF: a factor on the force, or μ again, would
    only repeat that fit (fitted before physics, it would take up whatever restraint the
    model misses, as the baseline's μ may).
    """
    from fenicsx_drape.diagnosis.kinds.forming import holder_mu_free

    held = [t for t in tests if forming_case_of(t).holder is not None]
    if "mu" not in fitted or not held or not all(holder_mu_free(t) for t in held):
        return {}
    why = ("the holder's μ is not stated in the case: the baseline fits it, and the "
           "holding force acts through μF only (eq. 1), so the stated set-up is at its best "
           "μF already")
    return {n: why for n in names if n in ("holder_force_N", "mu")}


def restated_error(record: dict[str, Any], noise: dict[str, float]) -> dict[str, Any]:
    """An error record's ``normalised`` on the given noise of each test (its ``per_test``)."""
    ratios = [record["per_test"][k] / noise[k] for k in record["per_test"]]
    return {**record, "normalised": float(np.sqrt(np.mean(np.square(ratios))))}


def restated(entry: dict[str, Any], c: SetupFit, noise: dict[str, float]) -> dict[str, Any]:
    """A candidate's entry with its errors on the stated noise (one scale in the report).

    What the stage judged with, on the noise widened by the net's own error, is kept as
    ``widened`` (``normalised``, ``heldout_normalised``); ``evidence`` is its ratio.
    """
    held = restated_error({"per_test": dict(c.heldout_rmse)}, noise)["normalised"]
    return {**entry, "error_after": restated_error(entry["error_after"], noise),
            "heldout_normalised": held,
            "widened": {"normalised": entry["error_after"]["normalised"],
                        "heldout_normalised": entry["heldout_normalised"]}}


def model_note(tried: list, stated_ho: float) -> str | None:
    """A note when the stated set-up forms unlike the case's model on another.

    A whole blank on frictionless tools can slide on them as a whole: only the holder's
    friction holds it, and once that yields (eq. 1) the translation is free, so where it
    ends is set by small differences (a quarter's symmetry planes fix it). The candidates
    on that model are then judged against the stated set-up on it (``evidence_on_model``).
    """
    other = [e for e, _ in tried if e["stated_on_model"] > MODELS_DIFFER * max(1.0, stated_ho)]
    if not other:
        return None
    worst = max(other, key=lambda e: e["stated_on_model"])
    where = "whole-blank" if worst["model"] == "full" else worst["model"]
    return (f"the stated set-up on the {where} model is "
            f"{worst['stated_on_model']:.3g} × the noise from the forming tests, against "
            f"{stated_ho:.3g} on the case's own model: the models differ, not the set-up (a "
            "whole blank on frictionless tools may slide on them as a whole once the holder's "
            "friction yields); candidates on it are judged against the stated set-up on the "
            "same model too (evidence_on_model)")


def stated_comparisons(tests: Sequence[Test], model: Model):
    """The comparisons of the stated set-up with the tests (nothing fitted)."""
    runs = SetupRuns(tests, model, None)
    return runs.compare(runs.values([np.zeros(0)])[0])


def tied_mu(entry: dict[str, Any], c: SetupFit, test: Test, model: Model
            ) -> tuple[dict[str, Any], SetupFit]:
    """The ``mu`` candidate from the fitted ``holder_force_N`` one (μF fitted: no runs).

    Eq. 1: a friction bar yields at F μ / n_s and F acts nowhere else, so μ' = μ · (F'/F)
    forms the same part as F' with μ: the same errors and evidence, μ's sd scaled likewise.
    """
    mu = float(stated(test, "mu", model))
    factor, sd = float(c.p[0]), float(c.sd_internal[0])
    tied = {**entry, "parameter": "mu", "stated": mu, "fitted": mu * factor, "sd": mu * sd,
            "sd_fit": mu * float(c.sd_fit[0]),
            "confounded_with": "holder_force_N", "tied_to": "holder_force_N", "runs": 0}
    return tied, dataclasses.replace(c, p=np.array([mu * factor]), start=np.array([mu]),
                                     sd_internal=np.array([mu * sd]),
                                     sd_fit=np.array([mu * float(c.sd_fit[0])]))


def planes_of(tests: Sequence[Test], name: str, p, model: Model) -> tuple[str, ...]:
    """The symmetry planes of the model a set-up point needs."""
    return forming_case_of(applied(tests[0], name, p, model)[0]).planes


def widened(test: Test, extra: float) -> Test:
    """``test`` with ``extra`` (in its unit) added in quadrature to every row's noise.

    A model error of known size weighed as noise: the net's own error on a measurement whose
    residual it explains (:mod:`~fenicsx_drape.diagnosis.resolution`).
    """
    column = kind_of(test).sd_column(test)
    columns = dict(test.columns)
    columns[column] = np.hypot(np.asarray(row_sd(test), float), float(extra))
    return dataclasses.replace(test, columns=columns)


def setup_stage(bundle: Bundle, model: Model, parameters: Sequence[str] | None, rules: Rules,
                progress: Progress | None = None, *, baseline: Model | None = None,
                fitted: Sequence[str] | None = None, label: str = ""
                ) -> SetupResult | None:
    """The diagnosis's set-up stage: the candidates, and the bundle with the best applied.

    The set-up as stated is one model with one error: given ``baseline`` (the diagnosis's
    baseline, fitted to ``bundle``), that model as fitted, the same nuisance values (the
    material fitted to the coupons, the friction the cases do not state fitted to the
    forming tests), so that the set-up as stated is the baseline, its error the baseline's;
    without it, ``model`` with its material fitted to the bundle's coupon tests (if any), its
    friction as given. ``fitted``: the forming parameters that model's fit moved (default:
    the baseline's, :func:`~fenicsx_drape.diagnosis.kinds.forming.free_parameters`; none
    without a baseline). Returns None when nothing is to be tried (no parameters, or no
    forming test); else the stage's result, whose ``corrected`` bundle has the chosen set-up
    applied (the bundle itself when none is significant).
    """
    from fenicsx_drape.diagnosis.comparison import fit_bundle
    from fenicsx_drape.diagnosis.kinds.forming import free_parameters

    if not parameters or not any(is_formed(t) for t in bundle.tests):
        return None
    say = progress or (lambda line: None)
    stated_model = model
    coupons = tuple(t for t in bundle.tests if not is_formed(t))
    if baseline is not None:
        stated_model = baseline
        if fitted is None:
            fitted = free_parameters(baseline, forming_tests(bundle))
        label = label or "the baseline"
    elif coupons:
        say("set-up: the material fitted to the coupon tests first")
        stated_model = fit_bundle(dataclasses.replace(bundle, tests=coupons), model,
                                  max_iterations=rules.iterations, from_features=True)
    stage = fit_setup(bundle, stated_model, rules, parameters=parameters, progress=say,
                      fitted=tuple(fitted or ()), label=label)
    stage = dataclasses.replace(stage, given_model=model, parameters=tuple(parameters))
    if stage.best is None:
        return stage
    best = stage.best
    say(f"set-up error: {best.parameter}; the physics candidates are tried with it fitted")
    return dataclasses.replace(stage, corrected=corrected(bundle, best.parameter, best.p,
                                                          stated_model))
