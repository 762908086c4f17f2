"""The catalogue of physical effects a model can include, by the names of the measurement spec.

Each :class:`Effect` says what physics it adds, its parameters (with units, see
:func:`fenicsx_drape.model.parameter_info`), where it acts (``tow``, ``shear``, ``friction``
or ``contact``), which test kinds can exercise it and which effects it needs. Registered user
laws are effects too: :func:`effect_names` and :func:`describe_effect` include them.

Dependencies (measurement spec, "Dependencies and limits"):

- ``strain_dependent_viscosity`` and ``temperature_dependence`` act on the viscous branch.
  Without ``rate_dependence`` the diagonal is rate-independent: the elastic-plastic branch
  (E_p, σ_o) plus a non-linear elastic lock-up term of the eq. 8 shape in the total diagonal
  strain (the viscous stress at the reference rate ``rate_ref_per_s``, see
  :mod:`~fenicsx_drape.materials.shear`), which ``strain_dependent_viscosity`` switches on.
  So ``strain_dependent_viscosity`` needs nothing, while ``temperature_dependence`` lists
  ``rate_dependence`` as its prerequisite: a temperature-dependent viscosity is meant on the
  Maxwell branch (without it, the factor only scales the lock-up term).
- Without ``decrimping`` the tow is linear (modulus E_∞); without ``tow_buckling`` tows carry
  compression with their tension law mirrored.
- An effect whose prerequisite is missing is tried as a candidate together with it.

``shear_tension_coupling`` (our choice of where it acts): the shear resistance of a unit
cell rises with the tension of its tows,

    τ → (1 + k_st max(σ̄_t, 0)) τ,

with σ̄_t the mean stress (N/tow) of the cell's tow bars and ``k_st`` in tow/N. It is a
property of the cell, not of one bar, because it needs the tow stress: the shear law itself is
unchanged (its state evolves with its own strain) and the factor multiplies the diagonal
stresses where the cell is assembled, by :func:`shear_tension_factor` — in the unit-cell
solutions (:mod:`fenicsx_drape.unitcell`) and in the FE cell. Physically: tow tension presses
the crossing tows together and raises the friction at the crossovers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

COUPON_KINDS = ("tensile", "bias_extension", "picture_frame")
TEST_KINDS = (*COUPON_KINDS, "forming")


@dataclass(frozen=True)
class ParameterInfo:
    """A model parameter: unit, allowed range, meaning and default value."""

    name: str
    unit: str
    bounds: tuple[float, float]
    description: str
    default: float | None = None


@dataclass(frozen=True)
class Effect:
    """One physical effect of the catalogue."""

    name: str
    summary: str  # one line
    physics: str  # one paragraph
    acts_on: str  # "tow" | "shear" | "friction" | "contact"
    parameters: tuple[str, ...] = ()  # its own parameters (see model.parameter_info)
    conditions: tuple[str, ...] = ()  # test conditions it reads
    test_kinds: tuple[str, ...] = ()  # test kinds that can exercise it
    prerequisites: tuple[str, ...] = ()  # effects it needs to act as meant
    in_paper: bool = False
    equations: str = ""  # where in the paper (or "beyond the paper")


EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in (
        Effect(
            "rate_dependence",
            "viscous (Maxwell) branch of the shear law",
            "The prepreg's resin makes the shear resistance depend on the rate: a Maxwell "
            "branch (spring E_v, dashpot η) in parallel with the elastic-plastic branch gives "
            "stress that grows with the shear rate, relaxes at constant strain and recovers "
            "on reloading. Without it the diagonal is rate-independent (elastic-plastic plus "
            "the lock-up term at the reference rate).",
            "shear", ("eta_o", "E_v"), (), ("bias_extension", "picture_frame", "forming"), (),
            True, "eqs. 5-7, 9"),
        Effect(
            "strain_dependent_viscosity",
            "viscosity grows with viscous strain (lock-up)",
            "As the shear angle grows, tow bending gives way to crossover friction and then "
            "to lateral compression of the tows, which locks the weave: the viscosity rises "
            "along a smooth bilinear curve of the viscous strain (slopes s_o, s_∞, "
            "transition ε̄_v, breadth 1/α_v) while the dashpot is loading, and returns to η_o "
            "in unloading. Without rate_dependence the same shape is a non-linear elastic "
            "lock-up term in the total diagonal strain.",
            "shear", ("s_o", "s_inf", "alpha_v", "eps_v_bar"), (),
            ("bias_extension", "picture_frame", "forming"), (), True, "eq. 8"),
        Effect(
            "decrimping",
            "non-linear (bilinear) tow law",
            "A woven tow first straightens (crimp interchange, tow compression) with a low "
            "modulus E_o, then stretches its fibres with the high modulus E_∞; the smooth "
            "bilinear law joins them at the transition strain ε̄ with breadth 1/α. Without "
            "it the tow is linear with modulus E_∞.",
            "tow", ("E_o", "eps_bar", "alpha"), (), ("tensile", "forming"), (), True,
            "eqs. 2-3"),
        Effect(
            "tow_buckling",
            "tow bars carry no compression (wrinkling)",
            "A group of tows under compression buckles out of plane at almost no load: the "
            "tow bar is deactivated while compressed and reactivated in tension, which is "
            "how the model shows wrinkling. Without it tows carry compression with their "
            "tension law mirrored.",
            "tow", (), (), ("tensile", "bias_extension", "forming"), (), True, "eq. 4"),
        Effect(
            "holder_friction",
            "perfectly plastic friction bars at the blank holder",
            "The blank holder clamps the sheet with force F_tot; each node under it is "
            "restrained by a bar that sticks elastically and slides at μ F_tot / n_s "
            "(along the node's total displacement, as in the paper).",
            "friction", ("mu", "holder_slip_mm"), ("holder_force_N", "holder_nodes"),
            ("forming",), (), True, "eq. 1"),
        Effect(
            "tool_friction",
            "Coulomb friction between ply and punch/die",
            "Where the sheet touches the punch or the die, a tangential traction opposes the "
            "slip increment, at most μ_tool times the contact pressure (regularised over the "
            "slip tool_slip_mm). The paper leaves it out; it restrains draw-in over the "
            "punch and shifts shear and wrinkling.",
            "contact", ("mu_tool", "tool_slip_mm"), (), ("forming",), (), False,
            "beyond the paper"),
        Effect(
            "temperature_dependence",
            "Arrhenius dependence of the shear viscosity on temperature",
            "The resin's viscosity falls with temperature: η_o is multiplied by "
            "exp(E_a/R (1/T − 1/T_ref)), T_ref = 20 °C, T the test's temperature_C. Tests at "
            "several temperatures expose it; at one temperature it is absorbed in η_o.",
            "shear", ("Ea_kJ_per_mol",), ("temperature_C",),
            ("bias_extension", "picture_frame", "forming"),
            ("rate_dependence",), False, "beyond the paper"),
        Effect(
            "shear_tension_coupling",
            "shear stiffness rising with tow tension",
            "Tow tension presses crossing tows together and raises crossover friction: the "
            "diagonal stresses of a cell are multiplied by (1 + k_st max(σ̄_t, 0)), σ̄_t the "
            "mean tow stress of the cell (see this module's docstring for where it acts).",
            "shear", ("k_st",), (), ("bias_extension", "forming", "tensile"), (), False,
            "beyond the paper"),
        Effect(
            "interply_friction",
            "plies of a stack slide on each other under an inter-ply friction law",
            "The plies of a stack slide against each other under τ = τ₀ + μ p + η_f v (tack, "
            "Coulomb regularised over a small slip, a viscous resin film; "
            "materials/interply.py), with the values of the case's [interply] table (fitted "
            "from interply_friction tests by drape fit); μ, η_f and τ₀ that the table does "
            "not give are the model's mu_ply, eta_f_MPa_s_per_mm and tau0_MPa, which "
            "interply_friction tests fit (and a forming fit μ and η_f). Without it adjacent "
            "plies are bonded: they move together, and a pull-out cannot slide. It acts on a "
            "stack of plies and in inter-ply friction tests.",
            "contact", ("mu_ply", "eta_f_MPa_s_per_mm", "tau0_MPa"), (),
            ("forming", "interply_friction"), (), False, "beyond the paper"),
    )
}

EXTRA_PARAMETERS: dict[str, ParameterInfo] = {
    p.name: p
    for p in (
        ParameterInfo("k_st", "tow/N", (0.0, math.inf),
                      "shear-tension coupling: relative rise of the shear stress per N/tow "
                      "of mean tow tension"),
        ParameterInfo("mu_tool", "-", (0.0, 10.0),
                      "Coulomb friction coefficient between ply and punch/die"),
        ParameterInfo("tool_slip_mm", "mm", (1e-12, math.inf),
                      "regularisation slip of the tool friction (sticking below it)"),
        # The inter-ply law's (materials/interply.py: the same bounds and defaults). A model
        # has them only with interply_friction (Model: an effect's extra parameters).
        ParameterInfo("mu_ply", "-", (0.0, 10.0),
                      "inter-ply Coulomb coefficient μ of τ = τ₀ + μp + η_f v (0.1-0.3)", 0.2),
        ParameterInfo("eta_f_MPa_s_per_mm", "MPa·s/mm", (0.0, 100.0),
                      "inter-ply film viscosity over its thickness η_f = η/h "
                      "(0.0005-0.01 MPa·s/mm)", 0.002),
        ParameterInfo("tau0_MPa", "MPa", (0.0, 10.0),
                      "inter-ply tack τ₀ of τ = τ₀ + μp + η_f v: shear strength at zero "
                      "pressure", 0.0),
    )
}
"""Parameters of effects that act outside the material laws (contact, the unit cell)."""


def shear_tension_factor(tow_stress, k_st) -> tuple[np.ndarray, np.ndarray]:
    """The factor (1 + k_st max(σ̄_t, 0)) on a cell's diagonal stresses and its derivative.

    Args:
        tow_stress: Mean stress of the cell's tow bars σ̄_t (N/tow).
        k_st: Coupling coefficient (tow/N).

    Returns:
        ``(factor, d factor / d σ̄_t)``.
    """
    tension = np.asarray(tow_stress) > 0.0
    return 1.0 + k_st * np.where(tension, tow_stress, 0.0), np.where(tension, k_st, 0.0)


def _user_laws() -> dict:
    from fenicsx_drape.materials import BUILT_IN_LAWS, registered_laws

    built_in = set(BUILT_IN_LAWS.values())
    return {n: c for n, c in registered_laws().items() if n not in built_in}


def effect_names() -> tuple[str, ...]:
    """Every effect name a model may use: the catalogue plus the registered user laws."""
    return (*EFFECTS, *(n for n in _user_laws() if n not in EFFECTS))


def describe_effect(name: str) -> Effect:
    """The catalogue entry of an effect, or one built from a registered user law."""
    if name in EFFECTS:
        return EFFECTS[name]
    law = _user_laws().get(name)
    if law is None:
        from fenicsx_drape.errors import DrapeInputError

        raise DrapeInputError(f"unknown effect {name!r} (known: {', '.join(effect_names())})")
    from fenicsx_drape.materials import fields_of

    kinds = {"tow": ("tensile", "bias_extension", "forming"),
             "shear": ("bias_extension", "tensile", "forming"), "friction": ("forming",)}
    doc = (law.__doc__ or "").strip()
    return Effect(name, doc.splitlines()[0] if doc else f"user {law.role} law", doc,
                  law.role, tuple(f.name for f in fields_of(law, "parameter")),
                  tuple(f.name for f in fields_of(law, "condition")), kinds[law.role],
                  (), False, f"user law {law.__module__}.{law.__qualname__}")
