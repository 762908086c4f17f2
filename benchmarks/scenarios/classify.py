"""What the diagnosis answered, and whether that is right (the rule of docs/scenarios.md).

The answer is read from ``REPORT.json`` as a user reads it: ``data_check`` (measurements
named suspect), ``setup_error``, ``missing_effect`` (and ``add_effects``), and the
conclusion's words: "write it as a user law", "the net's own discretisation error", "No
single candidate brings the error ... to the noise floor".

**Right**, by the scenario's truth (``expected`` in its record):

- *nothing hidden* (nothing; discretisation only; a bonded stack): no data suspect, no
  set-up error, no effect, no "write a user law";
- *an effect E*: E is among the effects the report adds, and no set-up error is named;
- *a set-up error S*: ``setup_error`` is S (the holder's force and μ act only as their
  product, eq. 1: either names a wrong force or μ), no effect, no "write a user law";
- *a set-up error S with an effect E*: both named;
- *data of another part*: the replaced measurement named suspect, no effect, no "write a
  user law";
- where the lab case's own net moves the measures by at least half as much as a hidden part
  (the effect, the set-up error) does on its own (``net_hides``: the truth's model formed on
  the case's net against the truth, set against each part's own signal), that part may go
  unnamed when the conclusion puts the rest down to "the net's own error" (and says no "write
  a user law"); ``resolution_ok``: the net hides every hidden part, so "the net's own error"
  with nothing named is right.

Everything else is wrong, and :func:`judge` says why from the report's own entries.
"""

from __future__ import annotations

LABELS = ("nothing", "the net's error", "the hidden effect", "another effect",
          "effect short of the noise", "the set-up error", "another set-up error",
          "set-up and effect", "data suspect", "write a user law")


def answer(report: dict) -> dict:
    """The report's answer: suspects, set-up error, effects, and the conclusion's verdict."""
    conclusion = report.get("conclusion", "")
    suspects = [f"{e['test']}/{e['measurement']}" for e in report.get("data_check", [])
                if e.get("suspect")]
    effects = list(report.get("add_effects") or ([report["missing_effect"]]
                                                 if report.get("missing_effect") else []))
    setup = report.get("setup_error")
    value = None
    for entry in report.get("setup", []):
        if entry.get("parameter") == setup:
            value = {"fitted": entry.get("fitted"), "sd": entry.get("sd")}
    return {"data": suspects, "setup": setup, "setup_value": value,
            "effect": report.get("missing_effect"), "effects": effects,
            "user_law": "user law" in conclusion,
            "net": "net's own discretisation error" in conclusion,
            "short": "No single candidate" in conclusion,
            "conclusion": conclusion}


def label(ans: dict, expected: dict) -> str:
    """The answer's column of the confusion table."""
    if ans["data"]:
        return "data suspect"
    if ans["user_law"]:
        return "write a user law"
    if ans["effects"] and ans["setup"]:
        return "set-up and effect"
    if ans["effects"]:
        return ("the hidden effect" if expected.get("effect") in ans["effects"]
                else "another effect")
    if ans["setup"]:
        return ("the set-up error" if ans["setup"] in (expected.get("setup") or ())
                else "another set-up error")
    if ans["short"]:
        return "effect short of the noise"
    if ans["net"]:
        return "the net's error"
    return "nothing"


def _num(v) -> str:
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_num(x) for x in v) + "]"
    return f"{v:.3g}" if isinstance(v, (int, float)) else str(v)


def _candidate(report: dict, effect: str) -> str:
    for c in report.get("candidates", []):
        if effect in c.get("effects", [c["effect"]]):
            after = c["error_after"]["normalised"]
            sig = "significant" if c["significant"] else "not significant"
            return (f"{c['effect']} refitted to {after:.3g} × the noise (evidence "
                    f"{c['evidence']:.3g}, {sig})")
    for u in report.get("untestable", []):
        if effect in u.get("effects", [u["effect"]]):
            return f"{u['effect']} untestable: {u['reason']}"
    return f"{effect} not tried"


def _setup_entry(report: dict, parameter: str) -> str:
    for s in report.get("setup", []):
        if s.get("parameter") == parameter:
            return (f"{parameter} fitted {_num(s.get('fitted'))} ± {_num(s.get('sd'))} "
                    f"(stated {_num(s.get('stated'))}, evidence {_num(s.get('evidence'))}, "
                    f"{'significant' if s.get('significant') else 'not significant'})")
    for u in report.get("untestable", []):
        if u.get("effect") == parameter or u.get("parameter") == parameter:
            return f"{parameter} untestable: {u.get('reason')}"
    return f"{parameter} not tried"


def net_hidden(expected: dict) -> set[str]:
    """The hidden parts ("effect", "setup") the case's net may be blamed for: ``net_hides``,
    or, in a record without it, every hidden part when ``resolution_ok``."""
    if "net_hides" in expected:
        return set(expected["net_hides"])
    hidden = {k for k in ("effect", "setup") if expected.get(k)}
    return hidden if expected.get("resolution_ok") else set()


def judge(record: dict, report: dict) -> tuple[bool, str]:
    """Whether the report's answer is right for the scenario, and why not when it is not."""
    exp = record["expected"]
    ans = answer(report)
    base = report.get("baseline", {}).get("error", {}).get("normalised")
    why = []
    want_effect, want_setup, want_data = exp.get("effect"), exp.get("setup"), exp.get("data")
    if want_data:
        hit = [s for s in ans["data"] if s.split("/")[-1] == want_data]
        if not hit:
            why.append(f"the {want_data} of another part was not named suspect")
    elif ans["data"]:
        why.append(f"data_check named {', '.join(ans['data'])} suspect, of the case's own part")
    if ans["user_law"]:
        why.append(f"the conclusion says to write a user law (baseline {_num(base)} × noise)")
    named = ans["effects"]
    hides = net_hidden(exp)

    def excused(part: str, other_named) -> bool:
        # the case's net moves the measures as much as this part does: unnamed is right too
        return part in hides and not other_named and ans["net"] and not ans["user_law"]

    if want_effect:
        if want_effect not in named and not excused("effect", named):
            what = f"named {ans['effect']}" if named else "named no effect"
            why.append(f"{what}; {_candidate(report, want_effect)}")
    elif named:
        c = next((c for c in report.get("candidates", []) if c["effect"] == ans["effect"]), {})
        after = c.get("error_after", {}).get("normalised")
        why.append(f"named {ans['effect']} where no effect is missing (baseline {_num(base)} → "
                   f"{_num(after)} × noise, evidence {_num(c.get('evidence'))})")
    if want_setup:
        if ans["setup"] not in want_setup and not excused("setup", ans["setup"]):
            what = f"named {ans['setup']}" if ans["setup"] else "named no set-up error"
            why.append(f"{what}; {_setup_entry(report, want_setup[0])}")
    elif ans["setup"]:
        why.append(f"named set-up error {_setup_entry(report, ans['setup'])} where the set-up "
                   "was as stated")
    return (not why), "; ".join(why)
