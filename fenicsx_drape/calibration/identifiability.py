"""What a bundle's coupon tests can determine, and starting values inside the laws' ranges.

**Undetermined by the kinds and conditions of the tests** (judged before fitting, from the
bundle alone; such a parameter is held at its starting value -- the MODEL.toml value or the
default of Table 2 -- and listed with the reason, rather than being driven to a bound by
whatever else it can mimic):

- the tow law (E_o, E_inf, eps_bar, alpha) without a tensile test: bias extension barely
  loads the tows (Table 2: bias sensitivities of 1e-3 and below), so a fit of bias curves
  alone moves them only to mimic something else (a real glass weave's lock-up drove E_o
  from 3410 to 0.34 N/tow, four decades, before this rule);
- ``eta_o`` (with ``rate_dependence``) when all bias tests run at one strain rate -- their
  effective rates (eq. 23, from the tables) span less than a factor :data:`RATE_SPREAD` --
  and none holds, unloads or changes speed: the viscous amplitude then trades off exactly
  against the rate-independent response (σ_o, and s_o, s_inf which scale the viscosity);
- ``Ea_kJ_per_mol`` (with ``temperature_dependence``) when all tests run at one temperature.

Parameters the data turn out not to determine once fitted are flagged afterwards by
:mod:`fenicsx_drape.calibration.sensitivity` (their relative uncertainty).

**Starting values** outside a law's allowed range (e.g. a curve-feature guess of η_o = 6e-14
from bias curves at one rate, below the law's 1e-12) are brought inside: to the default when
that is inside, else to the nearest bound; each change is reported.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

RATE_SPREAD = 1.5  # bias tests whose effective strain rates span less than this: one rate
_T_DEFAULT_C = 20.0  # temperature of a test that gives none (Table 2's room temperature)


def strain_rate(test) -> float:
    """The effective diagonal strain rate of a shear test from its table (1/s).

    Bias extension: eq. 23. Picture frame: the initial rate of ε_d = sin γ / 2,
    ḋ/(√2 L_frame) (from cos(π/4 − γ/2) = (√2 L_frame + d)/(2 L_frame)).
    """
    from fenicsx_drape.unitcell import EFFECTIVE_RATE_FACTOR

    rate = np.abs(np.diff(test.displacement_mm) / np.diff(test.time_s))
    moving = rate[rate > 1e-3 * rate.max()] if rate.max() > 0 else rate
    speed = float(np.median(moving)) if moving.size else 0.0
    if test.kind == "picture_frame":
        return speed / (np.sqrt(2.0) * test.frame_side_mm)
    return speed / (test.length_mm - test.width_mm) * EFFECTIVE_RATE_FACTOR


def history_varies(test) -> bool:
    """True when a test holds, unloads or changes its crosshead speed by more than 50 %."""
    rate = np.diff(test.displacement_mm) / np.diff(test.time_s)
    top = np.abs(rate).max()
    if top == 0:
        return True
    moving = np.abs(rate) > 1e-3 * top
    forward = rate[moving]
    return bool((~moving).any() or (forward < 0).any()
                or np.ptp(forward) > 0.5 * np.median(np.abs(forward)))


def undetermined(model, tests: Sequence, names: Sequence[str]) -> dict[str, str]:
    """The parameters among ``names`` the tests cannot determine, with the reason each."""
    out: dict[str, str] = {}
    kinds = {t.kind for t in tests}
    laws = model.law_classes()
    if "tensile" not in kinds:
        for name in laws["tow"].active_parameters(model.effects):
            if name in names:
                out[name] = ("no tensile test in the bundle: bias extension barely loads the "
                             "tows (a picture frame holds them at their length), so the tow "
                             "law is not determined")
    bias = [t for t in tests if t.kind in ("bias_extension", "picture_frame")]
    if "rate_dependence" in model.effects and "eta_o" in names:
        if not bias:
            out["eta_o"] = ("no bias-extension or picture-frame test: the viscous amplitude "
                            "is not exercised")
        elif not any(history_varies(t) for t in bias):
            rates = [strain_rate(t) for t in bias]
            if max(rates) < RATE_SPREAD * min(rates):
                speeds = sorted({t.speed_mm_per_min for t in bias
                                 if t.speed_mm_per_min is not None})
                at = (f" ({', '.join(f'{s:g}' for s in speeds)} mm/min)" if speeds else "")
                out["eta_o"] = (f"all shear tests (bias extension, picture frame) run at one "
                                f"strain rate"
                                f"{at}, {min(rates):.3g}-{max(rates):.3g} 1/s (a spread below "
                                f"{RATE_SPREAD:g}x), with no hold, unloading or change of "
                                "speed: the viscous amplitude cannot be told from the "
                                "rate-independent response")
    if "Ea_kJ_per_mol" in names:
        temperatures = {float(t.conditions.get("temperature_C", _T_DEFAULT_C)) for t in tests}
        if len(temperatures) < 2:
            out["Ea_kJ_per_mol"] = (f"all tests at one temperature ({temperatures.pop():g} "
                                    "°C): the activation energy is not exercised")
    return out


def inside_ranges(values: dict[str, float], names: Sequence[str], what: str
                  ) -> tuple[dict[str, float], list[str]]:
    """Starting ``values`` of ``names`` brought inside the laws' allowed ranges.

    Args:
        values: Parameter values by name (all of a model's, or some).
        names: The parameters to check.
        what: Where the values come from, for the notes ("curve features", "MODEL.toml").

    Returns:
        The corrected values (only those that changed) and a note for each change.
    """
    from fenicsx_drape.model import default_parameters, parameter_info

    defaults = default_parameters()
    changed, notes = {}, []
    for name in names:
        if name not in values:
            continue
        value = float(values[name])
        info = parameter_info(name)
        lo, hi = info.bounds
        # A law's lower bound of 1e-12 marks "positive", not a value to start from.
        ok = np.isfinite(value) and lo <= value <= hi and not (lo > 0 and value < 1e3 * lo)
        if ok:
            continue
        new = defaults.get(name, info.default)
        if new is None or not lo <= new <= hi:
            new = float(min(max(value, lo), hi)) if np.isfinite(value) else lo
        changed[name] = float(new)
        notes.append(f"start {name} = {value:.3g} {info.unit} from {what} is outside its "
                     f"allowed range [{lo:g}, {hi:g}]: started from {new:.4g} instead")
    return changed, notes
