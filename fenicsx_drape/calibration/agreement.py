"""Do all coupon tests of a bundle share one parameter set? Leave-one-group-out refits.

A bundle may hold tests of several kinds (bias extension, picture frame, tension), specimen
sizes and labs. The joint fit (:func:`fenicsx_drape.calibration.fitting.fit`) weighs every test
by its noise; a test that cannot be reconciled with the others would still pull all
parameters. :func:`consistency` asks, for every group of tests -- one test, one lab, one
specimen size, one kind -- how the others alone predict it:

- the model is refitted to the **rest** (a warm start from the joint fit, no global stage:
  the joint optimum is a good start for a subset), and the left-out group is **predicted**;
- per group: its error in the joint fit, its **held-out** normalised error (√ of the mean
  over its tests of (RMSE / noise)², the measurement spec's measure), the rest's error after
  the refit, the least-squares **scale** between its measured and predicted forces (a lab's
  force calibration or normalisation shows as a scale), and how far the parameters moved;
- a group **disagrees** when its held-out error exceeds :data:`DISAGREE` (twice its noise);
  it **explains** the misfit when, left out, the rest is fitted at :data:`ADEQUATE` (the
  spec's 1.5) while the joint fit was not.

Groups: ``test`` (its id), ``lab`` (the test key ``lab = "..."``, a string the bundle keeps
as a note of the test; a numeric ``lab`` condition is read too), ``size`` (bias extension
``L×W``, picture frame ``frame/fabric``, tension ``gauge×width`` in mm) and ``kind``.

**Verdict** (fixed rules, not tuned per bundle): ``consistent`` when the joint fit is
adequate and no group disagrees; else the group whose removal brings the rest closest to
its noise, among the smallest groups that explain the misfit, names it -- ``lab_offset`` (a lab),
``size_effect`` (a specimen size), ``kind_mismatch`` (a test kind, e.g. a normalisation
that differs between picture frame and bias extension), ``single_test``; with the same
tests in a lab and a size group (each lab used its own frame) the verdict says both
(``lab_or_size``). When no single group explains it but the held-out force scales of three
or more sizes of one kind change monotonically with the specimen's shape (L/W, fabric/frame)
by more than twice their noise, it is a ``size_effect`` too (a trend; the report says when
the sizes' strain rates differ, as a rate effect would look the same). Otherwise the
model itself lacks something all tests share: ``missing_physics`` (see ``diagnose``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from fenicsx_drape.calibration.coupons import COUPON_KINDS, simulate, test_noise
from fenicsx_drape.measurements.bundle import Bundle, Test

DISAGREE = 2.0  # held-out normalised error beyond which a group disagrees with the rest
ADEQUATE = 1.5  # the spec's adequacy of a fit (normalised error)
GROUPINGS = ("test", "lab", "size", "kind")
_VERDICT = {"lab": "lab_offset", "size": "size_effect", "kind": "kind_mismatch",
            "test": "single_test"}


def lab_of(test: Test) -> str | None:
    """The lab of a test: its ``lab`` key (kept as a note, or a numeric condition)."""
    lab = test.notes.get("lab", test.conditions.get("lab"))
    return None if lab is None else f"{lab:g}" if isinstance(lab, float) else str(lab)


def size_of(test: Test) -> str:
    """The specimen's size as a label (mm): ``L×W``, ``frame/fabric`` or ``gauge×width``."""
    if test.kind == "picture_frame":
        return f"frame {test.frame_side_mm:g}/fabric {test.fabric_side_mm:g}"
    if test.kind == "bias_extension":
        return f"{test.length_mm:g}x{test.width_mm:g}"
    return f"{test.gauge_length_mm:g}x{test.width_mm or 0:g}"


def size_measure(test: Test) -> float:
    """The shape that sets a coupon's kinematics: L/W, L_fabric/L_frame or gauge/width."""
    if test.kind == "picture_frame":
        return test.fabric_side_mm / test.frame_side_mm
    if test.kind == "bias_extension":
        return test.length_mm / test.width_mm
    return test.gauge_length_mm / (test.width_mm or 1.0)


def groups(tests: Sequence[Test], by: str) -> dict[str, list[str]]:
    """Test ids by group label (tests without a lab are left out of the ``lab`` groups)."""
    key = {"test": lambda t: t.id, "lab": lab_of, "size": size_of, "kind": lambda t: t.kind}[by]
    out: dict[str, list[str]] = {}
    for test in tests:
        label = key(test)
        if label is not None:
            out.setdefault(label, []).append(test.id)
    return out


def informative(tests: Sequence[Test]) -> tuple[str, ...]:
    """The groupings that can tell something about these tests.

    Several labs; several sizes of one kind; several kinds that identify one law (bias
    extension and picture frame).
    """
    from fenicsx_drape.calibration.coupons import BLOCK_ROLE

    by = []
    if len(groups(tests, "lab")) > 1:
        by.append("lab")
    kinds = {t.kind for t in tests}
    if any(len(groups([t for t in tests if t.kind == k], "size")) > 1 for k in kinds):
        by.append("size")
    roles = [BLOCK_ROLE[k] for k in kinds if k in BLOCK_ROLE]
    if len(roles) > len(set(roles)):
        by.append("kind")
    return tuple(by)


def _normalised(tests: Sequence[Test], model) -> tuple[float, float, dict[str, float]]:
    """Normalised error, least-squares force scale (measured/predicted), per-test errors."""
    per, num, den = {}, 0.0, 0.0
    for test in tests:
        sim = np.ravel(simulate(test, model))
        _, noise, _ = test_noise(test)
        per[test.id] = float(np.sqrt(np.mean((sim - test.force_N) ** 2)) / noise)
        num += float(np.dot(sim, test.force_N)) / noise**2
        den += float(np.dot(sim, sim)) / noise**2
    value = float(np.sqrt(np.mean([v**2 for v in per.values()])))
    return value, num / den if den > 0 else math.nan, per


def consistency(bundle: Bundle, result=None, *, model=None, by: Sequence[str] = GROUPINGS,
                progress=None) -> dict[str, Any]:
    """Leave each group of tests out, refit the rest, predict the group (module docstring).

    Args:
        bundle: The measurements (only coupon tests are used).
        result: The joint :class:`~fenicsx_drape.calibration.fitting.FitResult`; fitted here
            (from ``model``, or the default model) when None.
        model: The model to fit when ``result`` is None.
        by: The groupings to try, among :data:`GROUPINGS`.
        progress: Called with a line of text per refit.

    Returns:
        A JSON-ready report: ``joint`` (normalised error and per test), ``groups`` (one
        record per left-out group), ``verdict`` and ``says``, and the rules used.
    """
    from fenicsx_drape.calibration.fitting import fit

    say = progress or (lambda line: None)
    unknown = set(by) - set(GROUPINGS)
    if unknown:
        raise ValueError(f"unknown grouping(s) {sorted(unknown)} (known: {GROUPINGS})")
    if result is None:
        result = fit(bundle, model, analyse=False, progress=progress)
    tests = [t for t in result.bundle.tests if t.kind in COUPON_KINDS and t.id in result.errors]
    joint = result.normalised
    fitted = list(result.fitted)
    records = []
    for key in by:
        parts = groups(tests, key)
        if len(parts) < 2:
            continue
        for label, ids in parts.items():
            rest = [t.id for t in tests if t.id not in ids]
            say(f"leaving out {key} {label!r} ({', '.join(ids)}): refitting {len(rest)} tests")
            refit = fit(result.bundle, result.model, tests=rest, analyse=False,
                        initial_guess_from_features=False, global_stage=False,
                        parameters=fitted)
            left = [t for t in tests if t.id in ids]
            held, scale, per = _normalised(left, refit.model)
            in_joint = float(np.sqrt(np.mean([result.errors[i].normalised ** 2 for i in ids])))
            moves = {n: float(math.log(float(refit.model.parameters[n])
                                       / float(result.model.parameters[n])))
                     for n in refit.fitted if float(result.model.parameters[n]) > 0
                     and float(refit.model.parameters[n]) > 0}
            noise_rel = float(np.median([test_noise(t)[1] / np.max(np.abs(t.force_N))
                                         for t in left]))
            records.append({
                "by": key, "group": label, "tests": list(ids), "kind": left[0].kind,
                "size_measure": size_measure(left[0]), "rate_per_s": _rate(left[0]),
                "noise_rel": noise_rel, "in_joint_fit": in_joint,
                "held_out": held, "held_out_per_test": per, "rest_after": refit.normalised,
                "scale": scale, "disagrees": held > DISAGREE,
                "explains": held > DISAGREE and refit.normalised <= ADEQUATE < joint,
                "parameter_moves_log": moves})
            say(f"  held-out {held:.3g} (joint {in_joint:.3g}), rest {refit.normalised:.3g}, "
                f"measured/predicted {scale:.3g}")
    verdict, says = _verdict(joint, records)
    from fenicsx_drape.calibration.fitting import _strict

    return _strict({"scheme": "leave one group out; the rest refitted from the joint optimum "
                      "(warm start, no global stage); the group predicted",
            "rules": {"disagrees": f"held-out normalised error > {DISAGREE:g}",
                      "explains": f"disagrees, and the rest refitted without it reaches "
                                  f"normalised <= {ADEQUATE:g} while the joint fit does not"},
            "joint": {"normalised": joint,
                      "per_test": {i: e.normalised for i, e in result.errors.items()}},
            "groups": records, "verdict": verdict, "says": says})


def _rate(test: Test) -> float:
    from fenicsx_drape.calibration.identifiability import strain_rate

    return strain_rate(test) if test.kind != "tensile" else math.nan


def _size_trend(records: list[dict]) -> str | None:
    """A size effect as a trend, in words; None when there is none.

    The held-out force scales of three or more sizes of one kind, ordered by the specimens'
    shape, change monotonically and spread beyond twice their noise.
    """
    for kind in sorted({r["kind"] for r in records}):
        sizes = sorted((r for r in records if r["by"] == "size" and r["kind"] == kind),
                       key=lambda r: r["size_measure"])
        if len(sizes) < 3:
            continue
        scales = np.array([r["scale"] for r in sizes])
        steps = np.diff(scales)
        spread = scales.max() / scales.min() - 1.0
        if not (np.all(steps > 0) or np.all(steps < 0)) or not spread > 2.0 * max(
                r["noise_rel"] for r in sizes):
            continue
        rates = [r["rate_per_s"] for r in sizes]
        caveat = (f" (their strain rates differ too, {min(rates):.2g}-{max(rates):.2g} 1/s: "
                  "a rate effect would look the same)" if max(rates) > 1.5 * min(rates) else "")
        return (f"the {kind} sizes' forces against the others' prediction change steadily with "
                f"the specimen's shape: " + ", ".join(f"{r['group']} {r['scale']:.3g}"
                                                       for r in sizes) + caveat)
    return None


def _verdict(joint: float, records: list[dict]) -> tuple[str, str]:
    disagree = [r for r in records if r["disagrees"]]
    if joint <= ADEQUATE and not disagree:
        return "consistent", (f"one parameter set explains every test at its noise (joint "
                              f"normalised error {joint:.3g}); no group's held-out error "
                              f"exceeds {DISAGREE:g}")
    # the smallest group that explains the misfit is the most specific explanation
    explains = sorted((r for r in records if r["explains"]),
                      key=lambda r: (len(r["tests"]), r["rest_after"]))
    if not explains and (trend := _size_trend(records)):
        return "size_effect", trend
    if not explains:
        best = min(records, key=lambda r: r["rest_after"], default=None)
        where = (f"; the largest disagreement is {best['by']} {best['group']!r}: without it "
                 f"the rest fit at {best['rest_after']:.3g}, its held-out error is "
                 f"{best['held_out']:.3g}, its forces {best['scale']:.3g} × the prediction"
                 if best else "")
        return "missing_physics", (
            f"no single test, lab, size or kind explains the misfit (joint normalised "
            f"{joint:.3g}; leaving any one out leaves the rest above {ADEQUATE:g}){where}: "
            "the model lacks something the tests share (see diagnose)")
    best = explains[0]
    tied = [r for r in explains if r is not best and set(r["tests"]) == set(best["tests"])]
    kinds = {best["by"], *(r["by"] for r in tied)}
    verdict = ("lab_or_size" if {"lab", "size"} <= kinds else
               _VERDICT[next(k for k in ("lab", "size", "kind", "test") if k in kinds)])
    also = f" (the same tests as {', '.join(sorted(kinds - {best['by']}))})" if tied else ""
    return verdict, (
        f"{best['by']} {best['group']!r}{also} disagrees with the rest: predicted by them at "
        f"{best['held_out']:.3g} × its noise, its forces {best['scale']:.3g} × the prediction; "
        f"without it the rest fit at {best['rest_after']:.3g} (joint {joint:.3g})")
