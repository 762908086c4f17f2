# # Why the maximum shear moves with forming speed: every lead measured
#
# Over 8-240 s the paper's maximum shear moves by about 3° (Fig. 12a); ours moved by 22°
# with the "symmetric_part" reading of eq. 1. This study runs each candidate explanation at
# 8, 40 and 240 s (10 mm quarter, 133 N, μ = 0.3) under both readings of eq. 1's force share
# and reports the spread of the maximum shear (240 s minus 8 s) and of the total wrinkling:
#
# - the force share (the two readings themselves);
# - the model's own regularisations, which the paper's Marc model does not have: the
#   out-of-plane stabilisation halved and quartered (removed, the solve stalls at 13.6 mm),
#   the tow bending removed and halved, the buckled tows' residual stiffness removed and
#   halved;
# - the die (left out, with the stabilisation it then needs, against the same stabilisation
#   with the die);
# - the time step against the viscous time: the punch step halved and quartered;
# - the unit-cell scaling of the diagonal bars (n_t / A_e, section 4): the diagonals' force
#   halved and doubled (all stress-like shear parameters scaled, which scales the bar force
#   exactly), to show what a factor-2 slip in the convention would do;
# - the rate dependence itself: the shear law without its Maxwell branch (rate-independent);
# - the tool geometry: the cap's centre on the base plane instead of 20 mm above it.
#
# Writes `rate_leads.csv` (every run), `rate_leads.md` (the spread per lead) and `law_rate.md`
# (the shear law alone: a diagonal's stress at 24°, 37° and 53° of shear when strained at the
# rate of each forming time).
#
#     ./drape exec python3 demos/study_rate.py --out results/study_rate [--quick]

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from fenicsx_drape.forming.paper import (
    READINGS,
    Variant,
    default_options,
    paper_case,
    run_variants,
    write_rows,
)
from fenicsx_drape.forming.tools import HemisphereTools
from fenicsx_drape.model import default_model
from fenicsx_drape.provenance import atomic_write_text, write_provenance

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("results/study_rate"))
parser.add_argument("--cache", type=Path, default=Path("results/study_cache"))
parser.add_argument("--quick", action="store_true", help="20 mm cells, three leads")
args = parser.parse_args()

cell = 20.0 if args.quick else 10.0
durations = (8.0, 40.0, 240.0)
model = default_model()
shear_stress = ("sigma_o", "eta_o", "E_v", "E_p")


def scaled_diagonals(k):
    """The shear law with its bar force scaled by k (every stress-like parameter times k)."""
    return model.with_parameters(**{n: k * float(model.parameters[n]) for n in shear_stress})


def leads(base):
    """(name, case, model, options) of every lead for one base case."""
    R = dataclasses.replace
    c = base.stabilisation_N_per_mm
    out = [("baseline", base, None, None),
           ("stabilisation × ½", R(base, stabilisation_N_per_mm=c / 2), None, None),
           ("stabilisation × ¼", R(base, stabilisation_N_per_mm=c / 4), None, None),
           ("tow bending EI = 0", base, None, default_options(model, tow_bending_EI_Nmm2=0.0)),
           ("tow bending EI × ½", base, None, default_options(model, tow_bending_EI_Nmm2=1.0)),
           ("buckled-tow stiffness 0", base, None,
            default_options(model, buckled_tow_stiffness_N=0.0)),
           ("buckled-tow stiffness × ½", base, None,
            default_options(model, buckled_tow_stiffness_N=0.02)),
           ("stabilisation × 4 (die)", R(base, stabilisation_N_per_mm=4 * c), None, None),
           ("no die (stabilisation × 4)", R(base, die=False, stabilisation_N_per_mm=4 * c),
            None, None),
           ("punch step × ½", R(base, step_mm=base.step_mm / 2), None, None),
           ("punch step × ¼", R(base, step_mm=base.step_mm / 4), None, None),
           ("diagonal bars × ½", base, scaled_diagonals(0.5), None),
           ("diagonal bars × 2", base, scaled_diagonals(2.0), None),
           ("rate-independent shear law", base, model.without_effects("rate_dependence"), None),
           # A 60 mm punch: travel 60 mm at the same speed (the same motion once it touches).
           ("cap centre on the base plane",
            R(base, duration_s=0.75 * base.duration_s,
              tools=HemisphereTools(cap_centre_drop_mm=20.0, travel_mm=60.0)), None, None)]
    return out[:3] if args.quick else out


from mpi4py import MPI

rank0 = MPI.COMM_WORLD.rank == 0
table, all_rows, first = [], [], {"reading": [], "lead": [], "duration_s": []}
for reading in READINGS:
    by_lead = {}
    for d in durations:
        for name, case, m, options in leads(paper_case(reading, cell_mm=cell, duration_s=d)):
            by_lead.setdefault(name, []).append(Variant(f"{reading}: {name}, {d:g} s", case, m,
                                                        options))
    for name, variants in by_lead.items():
        rows, _ = run_variants(variants, cache=args.cache)
        all_rows += rows
        first["reading"] += [reading] * len(rows)
        first["lead"] += [name] * len(rows)
        first["duration_s"] += list(durations)
        shear = [r.get("max_shear_deg", np.nan) for r in rows]
        wrink = [r.get("total_wrinkling_strain", np.nan) for r in rows]
        table.append((reading, name, shear, wrink, rows))



def diagonal_stress(rate_per_s, strains=(0.2, 0.3, 0.4), steps=400):
    """Stress per tow of a shear diagonal (Table 2) loaded at a constant rate, at ``strains``.

    The law alone (eqs. 5-9), integrated in ``steps`` steps up to the largest strain.
    """
    law = model.laws()["shear"]
    end = max(strains)
    dt = end / rate_per_s / steps
    state, eps, sig = law.initial_state(1), [0.0], [0.0]
    for k in range(1, steps + 1):
        σ, _, state = law.update(np.array([end * k / steps]), dt, state)
        eps.append(end * k / steps)
        sig.append(float(σ[0]))
    return np.interp(strains, eps, sig)


# The law's own rate sensitivity: a diagonal strained to 0.4 (53° of shear) over the forming
# time, for each duration (ε_d = sin γ / 2 for inextensible tows).
law_lines = ["| forming time | diagonal strain rate | stress at 24° / 37° / 53° of shear |",
             "| --- | --- | --- |"]
for d in durations:
    σ = diagonal_stress(0.4 / d)
    law_lines.append(f"| {d:g} s | {0.4 / d:.4f} /s | "
                     + " / ".join(f"{v:.3f}" for v in σ) + " N/tow |")

if rank0:
    atomic_write_text(args.out / "law_rate.md", "\n".join(law_lines) + "\n")
    print("\n".join(law_lines))
    write_rows(args.out / "rate_leads.csv", all_rows, first,
               f"hemisphere quarter, {cell:g} mm cells, 133 N, mu 0.3: leads of the rate spread")
    md = ["| reading | lead | max shear 8 / 40 / 240 s | spread 8 → 240 s | total wrinkling "
          "8 / 40 / 240 s | bias-line max shear 8 / 240 s |",
          "| --- | --- | --- | --- | --- | --- |"]
    for reading, name, shear, wrink, rows in table:
        failed = [r["failed"] for r in rows if "failed" in r]
        md.append(f"| {reading} | {name} | " + " / ".join(f"{s:.1f}°" for s in shear)
                  + f" | {shear[-1] - shear[0]:+.1f}° | "
                  + " / ".join(f"{-100 * w:.2f} %" for w in wrink)
                  + " | " + " / ".join(f"{r.get('diagonal_max_shear_deg', np.nan):.1f}°"
                                       for r in (rows[0], rows[-1]))
                  + (f" (stopped: {failed[0]})" if failed else "") + " |")
    atomic_write_text(args.out / "rate_leads.md", "\n".join(md) + "\n")
    write_provenance(args.out, study="rate spread leads", durations_s=list(durations),
                     cell_mm=cell)
    print("\n".join(md))
    print(f"wrote {args.out / 'rate_leads.md'} and {args.out / 'rate_leads.csv'}")
