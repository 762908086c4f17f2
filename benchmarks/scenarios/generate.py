"""The scenario generator: from a seed, lab-style bundles with a hidden truth.

Each scenario is one slot of :func:`slots` (its truth class and, for some, which effect or
set-up is hidden), the rest drawn from ``numpy.random.default_rng([seed, index, attempt])``:

- the **part** (hemisphere, octagon, double dome, square box, the user's cup; a stack on the
  hemisphere), the **truth's net** against the lab case's (finer: half the cell and step;
  the same; coarser: 1.5 × the cell), one or two **trials** (two speeds, two holding forces or
  two temperatures), the **kinds** measured (any mix of grid, shear at cell centres or by
  finite differences, scan, edge, force curve), the **noise** and how the lab states it (a
  column, a test key, or nothing: the diagnosis's own model-free estimate);
- the **hidden truth**: nothing; a catalogue effect; a set-up error; a set-up error with an
  effect; discretisation only (shear by finite differences, or a finer truth); data of
  another part; a stack whose plies slide (or are bonded).

The truth is formed (:mod:`truth`) with the truth's model (the paper's model at Table 2, plus
the hidden effect when it is not the paper's), and so is the **counterfactual**: the model
handed to the diagnosis at the set-up as stated (on the truth's own sheet: where the truth's
set-up error drops a symmetry plane, so does the counterfactual). A hidden effect or set-up
error is kept only when it *can show* (:func:`shows`): the lab's measures of the truth and of
the counterfactual differ by at least :data:`SHOW` times the noise (normalised as the diagnosis
normalises: the root mean square over measurements of RMS difference / noise); a set-up error
with an effect only when each part shows on its own by the same measure as well — the **set-up
error alone** (the truth against the truth's model at the set-up as stated) and the **effect
alone** (the truth against the model handed, at the truth's set-up). Otherwise another part, net
and mix of kinds is drawn (:data:`ATTEMPTS` in all), and a slot whose truth never shows is
reported as such. The truth's model is also formed on the lab case's own net: the **net error**
says how far the case's net alone moves the lab's measures.

The lab's measures are :mod:`lab`'s, written by hand into the bundle (``bundle.toml``, one CSV
per measurement, the lab's case with its STL tools); the model handed (``model.toml``) and the
scenario's record (``truth.json``, with the answers that count as right) lie beside it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
from pathlib import Path

import lab
import numpy as np
import parts
import truth as truths

PAPER = ("rate_dependence", "strain_dependent_viscosity", "decrimping", "tow_buckling",
         "holder_friction")
NOT_PAPER = ("tool_friction", "temperature_dependence", "shear_tension_coupling")
SETUPS = ("ply_angle_deg", "blank_offset_mm", "holder_force_N", "mu", "tool_offset_mm")
KINDS = ("grid", "shear", "scan", "edge", "force")
SHOW = 3.0  # a hidden effect or set-up error must move the lab's measures this far (× noise)
ATTEMPTS = 4  # draws of part, net and kinds before a slot is given up
RECORD = 5  # version of a scenario's record and bundle (its truths are kept apart: truth.py)
ETA_O = 1.37  # Table 2 (N·s/tow)
T_REF_C = 20.0
R_GAS = 8.314  # J/(mol K)

CLASSES = ("nothing", "effect", "setup", "setup+effect", "discretisation", "other part",
           "stack: sliding", "stack: bonded")


def slots() -> list[tuple[str, str | None]]:
    """The benchmark's slots in order: the first eight one of each class, then the rest."""
    first = [("nothing", None), ("effect", "tow_buckling"), ("setup", "ply_angle_deg"),
             ("setup+effect", None), ("discretisation", "fd"), ("other part", None),
             ("stack: sliding", None), ("stack: bonded", None)]
    rest = [("effect", "rate_dependence"), ("setup", "blank_offset_mm"),
            ("effect", "tool_friction"), ("discretisation", "finer"), ("nothing", None),
            ("effect", "holder_friction"), ("setup", "holder_force_N"),
            ("effect", "strain_dependent_viscosity"), ("setup", "mu"),
            ("effect", "shear_tension_coupling"), ("setup", "tool_offset_mm"),
            ("effect", "temperature_dependence"), ("other part", None),
            ("effect", "decrimping"), ("setup+effect", None), ("nothing", None),
            ("effect", "tow_buckling"), ("setup", "ply_angle_deg"),
            ("discretisation", "fd"), ("effect", "rate_dependence"),
            ("setup", "blank_offset_mm"), ("effect", "tool_friction"),
            ("stack: sliding", None), ("discretisation", "finer"), ("nothing", None),
            ("effect", "holder_friction"), ("setup", "holder_force_N"),
            ("effect", "strain_dependent_viscosity"), ("setup+effect", None),
            ("setup", "mu"), ("effect", "shear_tension_coupling"),
            ("setup", "tool_offset_mm"), ("other part", None), ("nothing", None),
            ("discretisation", "fd"), ("setup+effect", None), ("discretisation", "finer"),
            ("nothing", None), ("effect", "tow_buckling"), ("effect", "tool_friction")]
    return first + rest


# --------------------------------------------------------------------------------------------
# Drawing a scenario


@dataclasses.dataclass
class Draw:
    """What a scenario is, before it is formed (JSON-ready through ``vars``)."""

    id: str
    cls: str
    detail: str | None
    part: str
    net: str  # finer | same | coarser
    case_cell_mm: float
    case_step_mm: float
    truth_cell_mm: float
    truth_step_mm: float
    trials: list[dict]
    kinds: list[str]
    shear_mode: str | None  # cells | fd
    noise: dict
    stated_mu: float | None  # the holder's μ the lab case states
    truth_effects: list[str]
    truth_parameters: dict
    model_effects: list[str]
    hidden_effect: str | None
    effect_parameters: dict
    setup: dict | None  # {"parameter", "value", "stated"}
    stack: str | None  # sliding | bonded
    other_part: dict | None  # {"part", "kind"}
    plan: dict  # where and how much the lab measures


def _pick(rng, seq):
    return seq[int(rng.integers(len(seq)))]


def _kinds(rng, must: tuple[str, ...] = ()) -> list[str]:
    """A random mix of kinds (one to four), holding those it ``must``."""
    n = max(int(rng.choice([1, 2, 3, 4], p=[0.2, 0.35, 0.3, 0.15])), len(must))
    rest = [str(k) for k in rng.permutation(KINDS) if k not in must]
    chosen = set(must) | set(rest[:n - len(must)])
    return [k for k in KINDS if k in chosen]


def _plan(rng, part: str, kinds: list[str], stack: bool) -> dict:
    """Where and how much the lab measures (lines, spacings, counts, holes, seeds)."""
    size = np.array(parts.PARTS[part]["blank"].get("size_mm") or np.ptp(
        np.array(parts.PARTS[part]["blank"]["points_mm"]), axis=0))
    half = size / 2
    reach = float(np.hypot(*half))
    lines = []
    names = list(rng.permutation(["warp", "weft", "bias"])[:int(rng.integers(2, 4))])
    for name in sorted(names):
        if name == "warp":
            off = float(rng.uniform(0.1, 0.35) * half[1])
            lines.append((name, (-reach, off), (1.0, 0.0)))
        elif name == "weft":
            off = float(rng.uniform(0.1, 0.35) * half[0])
            lines.append((name, (off, -reach), (0.0, 1.0)))
        else:
            lines.append((name, (-reach / math.sqrt(2), -reach / math.sqrt(2)), (1.0, 1.0)))
    holes = [(float(rng.uniform(-0.4, 0.4) * half[0]), float(rng.uniform(-0.4, 0.4) * half[1]),
              float(rng.uniform(15.0, 30.0))) for _ in range(int(rng.integers(0, 3)))]
    return {
        "lines": lines, "line_spacing_mm": 10.0, "line_reach_mm": 2 * reach,
        "grid_mm": float(_pick(rng, [10.0, 20.0])), "fd_h_mm": float(_pick(rng, [5.0, 10.0])),
        "scan_points": int(rng.integers(400, 1201)), "holes": holes,
        "edge_points": int(rng.integers(40, 101)), "edge_z": bool(rng.random() < 0.3),
        "draw_in": bool(rng.random() < 0.4), "force_rows": int(rng.integers(20, 41)),
        "flat_shear": bool(rng.random() < 0.25), "ply": (
            {k: 1 for k in kinds if k != "force" and rng.random() < 0.3} if stack else {}),
        "sample_seed": int(rng.integers(2**31)),
    }


def _noise(rng) -> dict:
    return {"shear_sd_deg": round(float(rng.uniform(0.5, 1.5)), 1),
            "position_sd_mm": round(float(rng.uniform(0.1, 0.4)), 2),
            "force_sd_rel": round(float(rng.uniform(0.015, 0.04)), 3),
            "stated": str(rng.choice(["key", "column", "none"], p=[0.5, 0.3, 0.2]))}


def draw(seed: int, index: int, attempt: int, cls: str, detail: str | None,
         fixed: dict | None = None) -> Draw:
    """One scenario's draw (module doc); ``fixed`` sets some choices (the tests' small
    scenarios): ``part``, ``net``, ``kinds``, ``shear_mode``, ``trials``, ``stated``,
    ``setup`` (its value), ``hidden`` (the effect of a set-up with an effect), ``other``,
    ``case_cell``, ``case_step`` (the lab case's net), ``noise`` (sds), ``stated_mu`` (the
    holder's μ the lab case states, None: none), ``lab_tools`` (the truth formed on the lab's
    copy of the tools)."""
    fixed = fixed or {}
    rng = np.random.default_rng([seed, index, attempt])
    stack = cls.startswith("stack")
    part = "hemisphere" if stack else _pick(rng, list(parts.PARTS))
    part = fixed.get("part", part)
    p = parts.PARTS[part]
    case_cell = fixed.get("case_cell", parts.STACK["cell_mm"] if stack else p["cell_mm"])
    case_step = fixed.get("case_step", parts.STACK["step_mm"] if stack else p["step_mm"])
    duration = parts.STACK["duration_s"] if stack else p["duration_s"]
    hidden = detail if cls == "effect" else None
    setup_name = detail if cls == "setup" else None
    if cls == "setup+effect":
        setup_name = _pick(rng, ["ply_angle_deg", "blank_offset_mm", "holder_force_N"])
        hidden = _pick(rng, ["tow_buckling", "tool_friction", "strain_dependent_viscosity"])
        hidden = fixed.get("hidden", hidden)
    # the truth's net
    if cls == "nothing" or (cls == "discretisation" and detail == "fd"):
        net = "same"
    elif cls == "discretisation":
        net = "finer"
    elif stack:
        net = _pick(rng, ["same", "finer"])
    else:
        net = _pick(rng, ["finer", "same", "coarser"])
    net = fixed.get("net", net)
    finer = 20.0 if stack else case_cell / 2  # a finer stack: 20 mm (30 mm for the lab)
    truth_cell = {"finer": finer, "same": case_cell, "coarser": 1.5 * case_cell}[net]
    truth_step = case_step / 2 if net == "finer" else case_step
    # the trials
    force = p["force_N"]
    if hidden == "rate_dependence":
        trials = [{"duration_s": 8.0}, {"duration_s": 240.0}]
    elif hidden == "temperature_dependence":
        trials = [{"temperature_C": 20.0}, {"temperature_C": float(_pick(rng, [40.0, 60.0]))}]
    elif rng.random() < 0.45:
        if rng.random() < 0.5:
            trials = [{"duration_s": duration}, {"duration_s": round(duration * 6.0, 1)}]
        else:
            trials = [{"holder_force_N": force}, {"holder_force_N": 2.0 * force}]
    else:
        trials = [{}]
    trials = [dict(t) for t in fixed.get("trials", trials)]
    for k, t in enumerate(trials, 1):
        t.setdefault("duration_s", duration)
        t.setdefault("holder_force_N", force)
        t["id"] = f"t{k}"
    # the kinds
    shear_mode = None
    if cls == "discretisation" and detail == "fd":
        kinds = _kinds(rng, must=("shear",))
        shear_mode = "fd"
    else:
        kinds = _kinds(rng)
    kinds = list(fixed.get("kinds", kinds))
    if "shear" in kinds and shear_mode is None:
        shear_mode = "cells" if cls == "nothing" or rng.random() < 0.6 else "fd"
    shear_mode = fixed.get("shear_mode", shear_mode)
    # the models
    truth_effects = list(PAPER)
    truth_parameters: dict = {}
    effect_parameters: dict = {}
    if stack:
        truth_effects += ["interply_friction"] if cls == "stack: sliding" else []
        hidden = "interply_friction" if cls == "stack: sliding" else None
    if hidden in NOT_PAPER:
        truth_effects.append(hidden)
        if hidden == "tool_friction":
            effect_parameters = {"mu_tool": round(float(rng.uniform(0.2, 0.6)), 3)}
        elif hidden == "shear_tension_coupling":
            effect_parameters = {"k_st": round(float(rng.uniform(0.3, 1.5)), 3)}
        else:
            effect_parameters = {"Ea_kJ_per_mol": round(float(rng.uniform(40.0, 80.0)), 1)}
        truth_parameters.update(effect_parameters)
    model_effects = [e for e in truth_effects if e != hidden]
    # the set-up
    setup = None
    stated_mu = 0.3 if rng.random() < 0.5 else None
    if setup_name in ("holder_force_N", "mu"):
        stated_mu = 0.3  # else the baseline's fit of the holder's μ takes the error up
    stated_mu = fixed.get("stated_mu", stated_mu)
    if setup_name == "ply_angle_deg":
        setup = {"value": round(float(rng.uniform(3.0, 6.0) * _pick(rng, [-1, 1])), 2),
                 "stated": 0.0}
    elif setup_name == "blank_offset_mm":
        r, phi = rng.uniform(5.0, 12.0), rng.uniform(0.0, 2 * np.pi)
        setup = {"value": [round(float(r * np.cos(phi)), 2), round(float(r * np.sin(phi)), 2)],
                 "stated": [0.0, 0.0]}
    elif setup_name == "holder_force_N":
        factor = float(_pick(rng, [rng.uniform(0.35, 0.55), rng.uniform(1.8, 2.6)]))
        setup = {"factor": round(factor, 3), "stated": force}
    elif setup_name == "mu":
        setup = {"value": round(float(_pick(rng, [rng.uniform(0.1, 0.18),
                                                  rng.uniform(0.5, 0.75)])), 3),
                 "stated": 0.3}
    elif setup_name == "tool_offset_mm":
        r, phi = rng.uniform(0.5, 1.0), rng.uniform(0.0, 2 * np.pi)
        setup = {"value": [round(float(r * np.cos(phi)), 2), round(float(r * np.sin(phi)), 2)],
                 "stated": [0.0, 0.0]}
    if setup is not None:
        setup["parameter"] = setup_name
        if "setup" in fixed:
            setup["factor" if "factor" in setup else "value"] = fixed["setup"]
    other = None
    if cls == "other part":
        if len(kinds) < 2:
            kinds = _kinds(rng, must=("grid", "edge"))
        pool = [k for k in kinds if k != "force"]
        other = {"part": _pick(rng, [q for q in parts.PARTS if q != part]),
                 "kind": _pick(rng, pool)}
        other = fixed.get("other", other)
    noise = {**_noise(rng), **fixed.get("noise", {})}
    if "stated" in fixed:
        noise["stated"] = fixed["stated"]
    return Draw(
        id=f"s{index + 1:02d}", cls=cls, detail=detail, part=part, net=net,
        case_cell_mm=case_cell, case_step_mm=case_step, truth_cell_mm=truth_cell,
        truth_step_mm=truth_step, trials=trials, kinds=kinds, shear_mode=shear_mode,
        noise=noise, stated_mu=stated_mu, truth_effects=truth_effects,
        truth_parameters=truth_parameters, model_effects=model_effects, hidden_effect=hidden,
        effect_parameters=effect_parameters, setup=setup,
        stack=(cls.split(": ")[1] if stack else None), other_part=other,
        plan={**_plan(rng, part, kinds, stack), "lab_tools": bool(fixed.get("lab_tools"))})


# --------------------------------------------------------------------------------------------
# Can it show?

PARTS = {"setup": "setup_alone", "effect": "effect_alone"}  # a part: its counterfactual's runs
PLANES_BROKEN = ("ply_angle_deg", "blank_offset_mm", "tool_offset_mm")  # set-ups off the planes


def compound(d: Draw) -> bool:
    """Whether the draw hides a set-up error with an effect (two parts that must each show)."""
    return bool(d.hidden_effect and d.setup)


def shows(signal: float, parts: dict[str, float] | None = None) -> bool:
    """Whether a hidden truth can show: the truth against the counterfactual (``signal``) and,
    for a set-up error with an effect, each part on its own (``parts``: the set-up error
    alone, the effect alone), all at least :data:`SHOW` × the noise."""
    return signal >= SHOW and all(v >= SHOW for v in (parts or {}).values())


def part_signals(d: Draw, signal: float, parts: dict[str, float] | None = None
                 ) -> dict[str, float]:
    """Each hidden part's own signal: a set-up error with an effect has both of ``parts``, a
    single effect or set-up error the truth's ``signal`` (its counterfactual differs from the
    truth by that part alone); nothing hidden, none."""
    if compound(d):
        return dict(parts or {})
    if d.hidden_effect:
        return {"effect": signal}
    return {"setup": signal} if d.setup else {}


def net_hides(signals: dict[str, float], net_error: float | None) -> list[str]:
    """The hidden parts the lab case's own net moves the measures at least half as much as
    the part does (``net_error`` >= signal / 2): the diagnosis may put those down to the net."""
    if net_error is None:
        return []
    return [k for k, v in signals.items() if net_error >= 0.5 * v]


# --------------------------------------------------------------------------------------------
# The runs a scenario needs


def _run_spec(d: Draw, trial: dict, *, effects, parameters, setup: bool, cell_mm, step_mm,
              part=None) -> dict:
    spec = {"part": part or d.part, "stack": d.stack is not None and part is None,
            "cell_mm": cell_mm, "step_mm": step_mm, "duration_s": trial["duration_s"],
            "holder_force_N": trial["holder_force_N"], "effects": sorted(effects),
            "parameters": dict(parameters)}
    if d.stated_mu is not None:
        spec["mu"] = d.stated_mu
    if spec["stack"]:
        spec["die"] = False  # parts.STACK: no die
    if d.plan.get("lab_tools") and part is None:
        spec["lab_tools"] = True
    params = spec["parameters"]
    if "temperature_dependence" in effects:
        # Forming runs read no test temperature: the truth at T is the model whose viscosity
        # amplitude is η_o(T) = η_o exp(E_a/R (1/T − 1/T_ref)) (the effect's definition).
        T = trial.get("temperature_C", T_REF_C) + 273.15
        Ea = params.pop("Ea_kJ_per_mol") * 1e3
        params["eta_o"] = ETA_O * math.exp(Ea / R_GAS * (1.0 / T - 1.0 / (T_REF_C + 273.15)))
        spec["effects"] = sorted(e for e in effects if e != "temperature_dependence")
    if setup and d.setup is not None:
        s = d.setup
        if s["parameter"] == "holder_force_N":
            spec["holder_force_N"] = trial["holder_force_N"] * s["factor"]
        else:
            spec[s["parameter"]] = s["value"]
    elif d.setup is not None and d.setup["parameter"] in PLANES_BROKEN:
        # At the stated set-up on the truth's own sheet: the truth's set-up drops symmetry
        # planes, and a quarter model mirrored differs from the whole sheet through its net
        # and holds, not through the set-up error.
        spec["symmetry_of"] = {d.setup["parameter"]: d.setup["value"]}
    return spec


def run_specs(d: Draw) -> dict[str, list[dict]]:
    """The truth, the counterfactual and the truth on the case's net, one run per trial; for a
    set-up error with an effect, also each part's own counterfactual (:data:`PARTS`)."""
    truth, counter, on_case = [], [], []
    alone: dict[str, list[dict]] = {"setup": [], "effect": []}
    net = {"cell_mm": d.truth_cell_mm, "step_mm": d.truth_step_mm}
    for t in d.trials:
        truth.append(_run_spec(d, t, effects=d.truth_effects, parameters=d.truth_parameters,
                               setup=True, **net))
        counter.append(_run_spec(d, t, effects=d.model_effects, parameters={}, setup=False,
                                 **net))
        on_case.append(_run_spec(d, t, effects=d.truth_effects, parameters=d.truth_parameters,
                                 setup=True, cell_mm=d.case_cell_mm, step_mm=d.case_step_mm))
        # the set-up error alone: the truth's own model (the effect kept) at the stated set-up
        alone["setup"].append(_run_spec(d, t, effects=d.truth_effects,
                                        parameters=d.truth_parameters, setup=False, **net))
        # the effect alone: the model handed at the truth's set-up
        alone["effect"].append(_run_spec(d, t, effects=d.model_effects, parameters={},
                                         setup=True, **net))
    out = {"truth": truth, "counterfactual": counter, "case_net": on_case}
    if compound(d):
        out.update({PARTS[k]: v for k, v in alone.items()})
    if d.other_part:
        o = d.other_part["part"]
        q = parts.PARTS[o]
        out["other"] = [{"part": o, "stack": False, "cell_mm": q["cell_mm"],
                         "step_mm": q["step_mm"], "duration_s": q["duration_s"],
                         "holder_force_N": q["force_N"], "effects": sorted(PAPER),
                         "parameters": {}} for _ in d.trials]
    return out


# --------------------------------------------------------------------------------------------
# Measuring


def _sheet_for(sheets: list[lab.Sheet], d: Draw, kind: str) -> lab.Sheet:
    ply = d.plan["ply"].get(kind)
    return sheets[ply - 1] if ply else sheets[-1]


def measure(d: Draw, trial_index: int, sheets: list[lab.Sheet], forces: dict, noisy: bool,
            kinds=None) -> dict[str, dict]:
    """The lab's measures of one trial's formed sheets: a table per kind (``noisy``: with the
    trial's noise, else exact), each with its material points (``_flat``) and noise
    (``_sd``)."""
    plan, noise = d.plan, d.noise
    rng = np.random.default_rng([plan["sample_seed"], trial_index, 1 if noisy else 0])
    sample = np.random.default_rng([plan["sample_seed"], trial_index, 7])
    f = 1.0 if noisy else 0.0
    offset = tuple(d.setup["value"]) if d.setup and d.setup["parameter"] == \
        "blank_offset_mm" else (0.0, 0.0)
    out = {}
    for kind in kinds or d.kinds:
        if kind == "force":
            table, _ = lab.force_curve(forces, plan["force_rows"], rng,
                                       noise["force_sd_rel"] * f)
            peak = float(np.max(np.abs(forces["punch"])))
            out[kind] = {**table, "_sd": noise["force_sd_rel"] * peak}
            continue
        sheet = _sheet_for(sheets, d, kind)
        pos_sd, shear_sd = noise["position_sd_mm"], noise["shear_sd_deg"]
        if kind == "grid":
            table = lab.grid(sheet, plan["grid_mm"], rng, pos_sd * f, offset=offset)
            table["_flat"] = np.column_stack([table["x0_mm"], table["y0_mm"]]) + offset
            table["_sd"] = pos_sd
        elif kind == "shear" and d.shear_mode == "fd":
            table, _ = lab.shear_differences(sheet, plan["lines"], plan["line_spacing_mm"],
                                             plan["line_reach_mm"], plan["fd_h_mm"], rng,
                                             pos_sd * f)
            # the lab's own estimate of the noise: the position noise propagated (sd/h rad)
            table["_sd"] = math.degrees(pos_sd / plan["fd_h_mm"])
        elif kind == "shear":
            flat = plan["flat_shear"] and offset == (0.0, 0.0)
            table = lab.shear_cells(sheet, plan["lines"], plan["line_spacing_mm"],
                                    plan["line_reach_mm"], rng, shear_sd * f, flat=flat)
            table["_sd"] = shear_sd
        elif kind == "scan":
            table = lab.scan(sheet, plan["scan_points"], sample, pos_sd * f,
                             holes=plan["holes"])
            table["_sd"] = pos_sd
        elif kind == "edge":
            table = lab.edge(sheet, plan["edge_points"], sample, pos_sd * f,
                             with_z=plan["edge_z"], draw_in=plan["draw_in"])
            table["_sd"] = pos_sd
        out[kind] = table
    return out


def _surface_distance(sheet: lab.Sheet, points: np.ndarray) -> np.ndarray:
    """Distance of points (n, 3) to a formed sheet: to the tangent plane of its nearest
    sample (each cell sampled 6 × 6 on its bilinear patch)."""
    from scipy.spatial import cKDTree

    s = (np.arange(6) + 0.5) / 6
    S, T = (a.ravel()[None, :, None] for a in np.meshgrid(s, s, indexing="ij"))
    a, b, c, d = (sheet.x[sheet.cells[:, k]][:, None, :] for k in range(4))
    P = (1 - S) * (1 - T) * a + S * (1 - T) * b + (1 - S) * T * c + S * T * d
    du = (1 - T) * (b - a) + T * (d - c)
    dv = (1 - S) * (c - a) + S * (d - b)
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    P, n = P.reshape(-1, 3), n.reshape(-1, 3)
    _, k = cKDTree(P).query(points)
    return np.abs(np.einsum("ni,ni->n", points - P[k], n[k]))


def _edge_distance(sheet: lab.Sheet, points: np.ndarray) -> np.ndarray:
    """Distance in plan of points to the formed sheet's edge (its boundary sides)."""
    sides = sheet.boundary()
    A, B = sheet.x[sides[:, 0], :2], sheet.x[sides[:, 1], :2]
    P = points[:, None, :2]
    AB = (B - A)[None]
    t = np.clip(((P - A[None]) * AB).sum(-1) / np.maximum((AB * AB).sum(-1), 1e-12), 0, 1)
    return np.linalg.norm(P - (A[None] + t[..., None] * AB), axis=-1).min(axis=1)


def differences(d: Draw, exact: dict[str, dict], sheets: list[lab.Sheet], forces: dict
                ) -> dict[str, float]:
    """How far another run's sheets are from exact measures, per kind, in noise units."""
    out = {}
    for kind, table in exact.items():
        sd = table["_sd"]
        if kind == "force":
            other = np.interp(table["travel_mm"], forces["travel_mm"], forces["punch"])
            r = table["force_N"] - other
        elif kind == "grid":
            sheet = _sheet_for(sheets, d, kind)
            pos, ok = sheet.formed(table["_flat"])
            mine = np.column_stack([table["x_mm"], table["y_mm"], table["z_mm"]])
            r = np.where(ok[:, None], mine - pos, 0.0).ravel()
        elif kind == "shear":
            sheet = _sheet_for(sheets, d, kind)
            again = measure(d, 0, sheets, forces, noisy=False, kinds=["shear"])["shear"]
            # the same lines on the other net: compare along each line by s
            r = []
            for name in set(table["line"].tolist()):
                a, b = table["line"] == name, again["line"] == name
                if b.sum() < 2:
                    r.append(table["shear_deg"][a])
                    continue
                r.append(table["shear_deg"][a] - np.interp(table["s_mm"][a], again["s_mm"][b],
                                                           again["shear_deg"][b]))
            r = np.concatenate(r)
            del sheet
        elif kind == "scan":
            pts = np.column_stack([table["x_mm"], table["y_mm"], table["z_mm"]])
            r = _surface_distance(_sheet_for(sheets, d, kind), pts)
        else:
            pts = np.column_stack([table["x_mm"], table["y_mm"]])
            r = _edge_distance(_sheet_for(sheets, d, kind), pts)
        out[kind] = float(np.sqrt(np.mean(np.square(r))) / sd)
    return out


def normalised(per: dict[str, float]) -> float:
    """The root mean square of per-measurement errors (in noise units)."""
    return float(np.sqrt(np.mean(np.square(list(per.values()))))) if per else 0.0


# --------------------------------------------------------------------------------------------
# Writing the bundle


def _stated_noise(table: dict, kind: str, d: Draw, keys: dict) -> dict:
    """The table to write, its noise stated as the draw says (column, key or nothing)."""
    mode = d.noise["stated"]
    cols = {k: v for k, v in table.items() if not k.startswith("_")}
    n = len(next(iter(cols.values())))
    sd = table["_sd"]
    if kind == "force":
        if mode == "column":
            cols["force_sd_N"] = np.full(n, sd)
        elif mode == "key":
            keys["force_sd_N"] = round(sd, 4)
    elif kind == "shear":
        if mode == "column":
            cols["shear_sd_deg"] = np.full(n, sd)
        elif mode == "key":
            keys["shear_sd_deg"] = round(sd, 4)
    elif kind in ("grid", "edge"):
        if mode == "column":
            cols["position_sd_mm"] = np.full(n, sd)
    if kind in ("grid", "edge", "scan") and mode in ("key", "column"):
        keys["position_sd_mm"] = d.noise["position_sd_mm"]
    return cols


FILES = {"grid": ("file", "grid.csv"), "shear": ("shear_points", "shear.csv"),
         "scan": ("surface", "scan.csv"), "edge": ("outline", "edge.csv"),
         "force": ("punch_force", "force.csv")}


def write_bundle(d: Draw, folder: Path, tables: list[dict[str, dict]], stl_cache: Path
                 ) -> Path:
    """The bundle a lab would send: ``bundle.toml``, a CSV per measurement, its case."""
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    parts.write_case(folder / "case", d.part, truth=False, stack=d.stack is not None,
                     mu=d.stated_mu, stl_cache=stl_cache, cell_mm=d.case_cell_mm,
                     step_mm=d.case_step_mm)
    text = (f"# A lab's forming trials of the {d.part.replace('_', ' ')}"
            f"{' stack' if d.stack else ''} (benchmarks/scenarios, scenario {d.id})\n\n")
    text += lab.toml_table("[bundle]", {"name": f"scenario-{d.id}",
                                        "material": "twill prepreg (Table 2 of the paper)"})
    for k, (trial, measured) in enumerate(zip(d.trials, tables, strict=True)):
        keys = {"id": trial["id"], "kind": "forming", "case": "case/case.toml",
                "duration_s": trial["duration_s"], "holder_force_N": trial["holder_force_N"]}
        files, noise_keys = {}, {}
        for kind in d.kinds:
            table = measured[kind]
            cols = _stated_noise(table, kind, d, noise_keys)
            key, name = FILES[kind]
            fname = f"{trial['id']}_{name}"
            lab.write_csv(folder / fname, cols, f"scenario {d.id}, trial {k + 1}: {kind}")
            files[key] = fname
            ply = d.plan["ply"].get(kind)
            if ply:
                files[f"{key}_ply"] = ply
        keys.update(files)
        if "grid" in d.kinds:
            keys["grid_mm"] = d.plan["grid_mm"]
        keys.update(noise_keys)
        text += "\n" + lab.toml_table("[[test]]", keys)
        if "temperature_C" in trial:
            text += lab.toml_table("[test.conditions]", {"temperature_C": trial["temperature_C"]})
    (folder / "bundle.toml").write_text(text)
    return folder


# --------------------------------------------------------------------------------------------
# One scenario, made


def expected(d: Draw, hides: list[str]) -> dict:
    """What counts as right for this scenario (the rule of docs/scenarios.md): ``hides``, the
    hidden parts ("effect", "setup") the case's net may be blamed for (:func:`net_hides`);
    ``resolution_ok`` when it is every hidden part."""
    setups = None
    if d.setup:
        p = d.setup["parameter"]
        setups = ["holder_force_N", "mu"] if p in ("holder_force_N", "mu") else [p]
    data = FILES[d.other_part["kind"]][0] if d.other_part else None
    hidden = [k for k, v in (("effect", d.hidden_effect), ("setup", d.setup)) if v]
    return {"effect": d.hidden_effect, "setup": setups, "data": data,
            "resolution_ok": bool(hidden) and set(hidden) <= set(hides),
            "net_hides": [k for k in hidden if k in hides]}


def _attempt(d: Draw, cache: Path, say) -> dict:
    """Form a draw's truth and counterfactuals; how far the hidden truth moves the measures,
    and each part of a set-up error with an effect on its own."""
    specs = run_specs(d)
    keys = [k for k in ("truth", "counterfactual", "other", *PARTS.values()) if k in specs]
    formed = iter(truths.form_all([s for k in keys for s in specs[k]], cache, say=say))
    runs = {k: [next(formed) for _ in specs[k]] for k in keys}
    sheets = {k: [lab.read_run(r) for r in v] for k, v in runs.items()}
    forces = {k: [lab.read_forces(r) for r in v] for k, v in runs.items()}
    exact = [measure(d, i, sheets["truth"][i], forces["truth"][i], noisy=False)
             for i in range(len(d.trials))]

    def against(key: str) -> dict[str, float]:
        per = {}
        for i, t in enumerate(d.trials):
            for k, v in differences(d, exact[i], sheets[key][i], forces[key][i]).items():
                per[f"{t['id']}/{k}"] = v
        return per

    per = against("counterfactual")
    parts_per = {part: against(key) for part, key in PARTS.items() if key in specs}
    return {"specs": specs, "sheets": sheets, "forces": forces, "exact": exact, "per": per,
            "signal": normalised(per), "parts_per": parts_per,
            "parts": {k: normalised(v) for k, v in parts_per.items()}}


def _finish(d: Draw, got: dict, folder: Path, cache: Path, record: dict, say) -> dict:
    """The net error, the noisy measures and the bundle of an accepted draw; its record."""
    per, signal, exact = got["per"], got["signal"], got["exact"]
    sheets, forces = got["sheets"], got["forces"]
    # The truth's model on the case's own net: how far the net alone moves the measures.
    if d.net == "same" and d.truth_step_mm == d.case_step_mm:
        net_per = {k: 0.0 for k in per}
    else:
        try:
            case_runs = truths.form_all(got["specs"]["case_net"], cache, say=say)
        except RuntimeError as err:  # the truth's model does not form on the case's net
            say(f"  {d.id}: the truth's model on the case's net failed: {err}")
            case_runs = None
        net_per = {}
        for i, t in enumerate(d.trials if case_runs else ()):
            other = [lab.read_run(case_runs[i]), lab.read_forces(case_runs[i])]
            for k, v in differences(d, exact[i], *other).items():
                net_per[f"{t['id']}/{k}"] = v
    net_error = normalised(net_per) if net_per or d.net == "same" else None
    noisy = [measure(d, i, sheets["truth"][i], forces["truth"][i], noisy=True)
             for i in range(len(d.trials))]
    if d.other_part:
        kind = d.other_part["kind"]
        for i in range(len(d.trials)):
            noisy[i][kind] = measure(d, i, sheets["other"][i], forces["other"][i], noisy=True,
                                     kinds=[kind])[kind]
    write_bundle(d, folder / "bundle", noisy, cache / "stl")
    (folder / "model.toml").write_text(
        f"# the model handed to the diagnosis (scenario {d.id})\n"
        + truths.model_toml(d.model_effects, {}))
    signals = part_signals(d, signal, got["parts"])
    parts = {"signal_parts": got["parts"], "signal_parts_per_measurement": got["parts_per"]
             } if compound(d) else {}
    record = {**record, "class": d.cls, "detail": d.detail,
              **{k: v for k, v in vars(d).items() if k not in ("id", "cls", "detail")},
              "signal": signal, "signal_per_measurement": per, **parts, "net_error": net_error,
              "net_error_per_measurement": net_per,
              "expected": expected(d, net_hides(signals, net_error))}
    (folder / "truth.json").write_text(json.dumps(record, indent=1, default=_plain))
    return record


def make(seed: int, index: int, work: Path, cache: Path, say=print) -> dict:
    """Draw, form and write scenario ``index`` of ``seed``; its record (``truth.json``)."""
    cls, detail = slots()[index % len(slots())]
    folder = work / f"s{index + 1:02d}"
    record_path = folder / "truth.json"
    if record_path.is_file():
        record = json.loads(record_path.read_text())
        if record.get("seed") == seed and record.get("generator") == [truths.VERSION, RECORD]:
            return record
    tried = []
    attempts = ATTEMPTS if cls in ("effect", "setup", "setup+effect", "stack: sliding") else 2
    for attempt in range(attempts):
        d = draw(seed, index, attempt, cls, detail)
        try:
            got = _attempt(d, cache, say)
        except RuntimeError as err:
            tried.append({"attempt": attempt, "part": d.part, "failed": str(err)})
            say(f"  {d.id} attempt {attempt}: a run failed ({err})")
            continue
        tried.append({"attempt": attempt, "part": d.part, "net": d.net, "kinds": d.kinds,
                      "signal": got["signal"],
                      **({"signal_parts": got["parts"]} if got["parts"] else {})})
        alone = ", ".join(f"{k} alone {v:.2f}" for k, v in got["parts"].items())
        say(f"  {d.id} attempt {attempt}: {d.part}, {d.net} net, {'+'.join(d.kinds)}: "
            f"signal {got['signal']:.2f} × noise" + (f" ({alone})" if alone else ""))
        if not (d.hidden_effect or d.setup) or d.stack == "bonded" or \
                shows(got["signal"], got["parts"]):
            break
    else:
        failed = all("failed" in t for t in tried)
        record = {"id": d.id, "seed": seed, "generator": [truths.VERSION, RECORD],
                  "class": cls, "detail": detail, "left_out": "its runs failed" if failed else
                  f"cannot show: below {SHOW} × the noise on {len(tried)} draws"
                  + (" (the set-up error and the effect each on its own)" if compound(d)
                     else ""),
                  "attempts": tried, "hidden_effect": d.hidden_effect, "setup": d.setup}
        folder.mkdir(parents=True, exist_ok=True)
        record_path.write_text(json.dumps(record, indent=1, default=_plain))
        say(f"  {d.id}: {detail or cls}: {record['left_out']}: left out")
        return record
    own = {"id": d.id, "seed": seed, "generator": [truths.VERSION, RECORD], "attempts": tried}
    return _finish(d, got, folder, cache, own, say)


def small(folder: Path, cache: Path, cls: str, detail: str | None = None, seed: int = 7,
          say=print, **fixed) -> dict:
    """One small scenario of a class (the tests'): ``fixed`` choices (:func:`draw`), by
    default the octagon on the lab case's own net, one trial, noise stated by keys. No
    "can show" redraw: the record's ``signal`` (and ``signal_parts``) say how far the hidden
    truth moves the measures."""
    fixed = {"part": "octagon", "net": "same", "trials": [{}], "stated": "key", **fixed}
    d = draw(seed, 0, 0, cls, detail, fixed)
    got = _attempt(d, cache, say)
    folder.mkdir(parents=True, exist_ok=True)
    return _finish(d, got, folder, cache, {"id": d.id, "seed": seed, "small": True}, say)


def _plain(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(type(v))
