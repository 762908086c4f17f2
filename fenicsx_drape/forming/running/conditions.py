"""Whether a run had the conditions of the paper's section 4 (its hemisphere's numbers).

A run's outputs compare it with the paper (:mod:`fenicsx_drape.forming.paper.numbers`) only
under those conditions; the check lives here, below the paper's numbers, so that the outputs
(:mod:`~fenicsx_drape.forming.running.outputs`) can ask it.
"""

from __future__ import annotations

from collections.abc import Mapping

from fenicsx_drape.forming.case.spec import OLD_HOLDER_KEYS

PAPER_CONDITIONS = ("the paper's tools, 240 mm sheet and model (Table 2), 10 mm cells, "
                    "133 N, 40 s, one ply at 0°")
"""The conditions of section 4's numbers, as :func:`paper_comparison` says them."""

_IGNORED_CASE_KEYS = ("name", "description", "step_mm", "penalty_factor",
                      "stabilisation_N_per_mm")  # names and numerical choices, not conditions


def _paper_case() -> dict:
    from fenicsx_drape.forming.case import case_dict, load_case

    return case_dict(load_case("hemisphere"))


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return str(value)


def paper_differences(summary: Mapping, model=None) -> list[str]:
    """How a run's conditions differ from those of the paper's section 4 ([] when none do).

    Args:
        summary: A run's ``summary.json``: ``case`` (the case's tables, as
            :func:`~fenicsx_drape.forming.case.writing.case_dict` writes them) and ``cell_mm``
            (the net's own cell; else the case's).
        model: The run's material model (its effects and parameters against the paper's,
            Table 2); None: not checked.

    Returns:
        Short phrases (``"cell 20 mm"``, ``"8 s"``, ``"a stack of 2 plies"``, ...). Symmetry
        planes, load steps and contact stiffness are numerical choices and are not listed.
    """
    paper = _paper_case()
    case = summary.get("case") or {}
    out = []
    run, ref = case.get("case", {}), paper["case"]
    cell = summary.get("cell_mm", case.get("blank", {}).get("cell_mm"))
    if cell is None or abs(float(cell) - paper["blank"]["cell_mm"]) > 1e-9:
        out.append(f"cell {_fmt(cell)} mm")
    holder, ref_holder = case.get("holder") or {}, paper["holder"]
    holder = {OLD_HOLDER_KEYS.get(k, k): v for k, v in holder.items()}  # an earlier summary
    if holder.get("holder_force_N") != ref_holder["holder_force_N"]:
        out.append(f"holder_force_N {_fmt(holder.get('holder_force_N'))}")
    if run.get("duration_s") != ref["duration_s"]:
        out.append(f"{_fmt(run.get('duration_s'))} s")
    if len(case.get("ply", [])) > 1:
        out.append(f"a stack of {len(case['ply'])} plies")
    blank, ref_blank = case.get("blank", {}), paper["blank"]
    for key, phrase in (("ply_angle_deg", "ply at {}°"), ("size_mm", "sheet {} mm"),
                        ("centre_mm", "blank centre {} mm"), ("outline", "outline {}")):
        if blank.get(key) != ref_blank.get(key):
            out.append(phrase.format(_fmt(blank.get(key))))
    for key in ("holder_force_share", "mu", "tool"):
        if holder.get(key) != ref_holder.get(key):
            out.append(f"{'holder tool' if key == 'tool' else key} {_fmt(holder.get(key))}")
    tools = {t["name"]: t for t in case.get("tool", [])}
    for ref_tool in paper["tool"]:
        tool = tools.pop(ref_tool["name"], None)
        if tool is None:
            out.append(f"no {ref_tool['name']}")
            continue
        for key in ("role", "geometry", "motion"):
            if tool.get(key) != ref_tool.get(key):
                out.append(f"{ref_tool['name']} {key} {_fmt(tool.get(key))}")
        given, ref_params = tool.get("parameters", {}), ref_tool.get("parameters", {})
        out += [f"{ref_tool['name']} {k} {_fmt(given.get(k))}"
                for k in sorted(set(given) | set(ref_params)) if given.get(k) != ref_params.get(k)]
    out += [f"another tool {name!r}" for name in tools]
    for key in sorted(set(run) - set(_IGNORED_CASE_KEYS) - {"duration_s"}):
        out.append(f"{key} {_fmt(run[key])}")
    if model is not None:
        import numpy as np

        from fenicsx_drape.model import PAPER_EFFECTS, default_parameters

        effects = set(model.effects)
        out += [f"without {e}" for e in PAPER_EFFECTS if e not in effects]
        out += [f"with {e}" for e in model.effects if e not in PAPER_EFFECTS]
        paper_values = default_parameters()
        out += [f"{k} {_fmt(float(np.max(v)))}" for k, v in model.parameters.items()
                if k in paper_values and not np.allclose(v, paper_values[k], rtol=1e-12)]
    return out
