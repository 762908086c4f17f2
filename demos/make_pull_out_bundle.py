# # The pull-out bundle: inter-ply friction tests from the pull-out's closed form
#
# Writes `demos/bundles/pull-outs/`: four pull-out tests (one ply pulled between two,
# `interfaces = 2`, over a 100 × 50 mm overlap) at 50 and 200 kPa and 10 and 100 mm/min,
# 3 mm of pulling each, from the closed form of the inter-ply law (`materials/interply.py`)
# at constant speed v and pressure p:
#
#     F = 2 A (τ₀ + μ p) min(d / ε, 1) + 2 A η_f v,
#
# the steady F = 2 A (τ₀ + μ p + η_f v) of ten Thije & Akkerman (2009) once the slip d passes
# the law's regularisation ε = 0.1 mm, with τ₀ = 0.004 MPa, μ = 0.22, η_f = 0.003 MPa·s/mm,
# plus Gaussian noise of 0.5 N (seed 53), stated in the `force_sd_N` column.
#
# Run from the repository root: `python3 demos/make_pull_out_bundle.py`.

from pathlib import Path

import numpy as np

TRUE = {"tau0_MPa": 0.004, "mu_ply": 0.22, "eta_f_MPa_s_per_mm": 0.003}
AREA_MM2 = 100.0 * 50.0  # the overlap: contact_length_mm × contact_width_mm
EPS_MM = 0.1  # the law's regularisation slip (its default)
NOISE_N = 0.5
SEED = 53
ROWS = 41

out = Path(__file__).parent / "bundles" / "pull-outs"
out.mkdir(parents=True, exist_ok=True)
rng = np.random.default_rng(SEED)
toml = ["# pull-out tests from the closed form of the inter-ply law + Gaussian noise "
        f"(force_sd_N), seed {SEED}: demos/make_pull_out_bundle.py",
        '[bundle]\nname = "pull-outs"\nmaterial = "prepreg plies (synthetic: '
        'tau0 0.004 MPa, mu 0.22, eta_f 0.003 MPa s/mm + noise)"\n']
for p in (50.0, 200.0):  # kPa
    for v in (10.0, 100.0):  # mm/min
        name = f"ipf-{p:g}kPa-{v:g}"
        t = np.linspace(0.0, 3.0 * 60.0 / v, ROWS)
        d = v / 60.0 * t
        coulomb = TRUE["tau0_MPa"] + TRUE["mu_ply"] * p / 1000.0
        film = TRUE["eta_f_MPa_s_per_mm"] * v / 60.0
        f = 2 * AREA_MM2 * (coulomb * np.minimum(d / EPS_MM, 1.0) + film * (t > 0))
        f += NOISE_N * rng.standard_normal(t.size)
        toml.append(f'[[test]]\nid = "{name}"\nkind = "interply_friction"\nfile = "{name}.csv"\n'
                    "contact_length_mm = 100.0\ncontact_width_mm = 50.0\ninterfaces = 2\n"
                    f"pressure_kPa = {p}\nspeed_mm_per_min = {v}\n")
        rows = "\n".join(f"{a:.6f},{b:.6f},{c:.4f},{NOISE_N}" for a, b, c in zip(t, d, f))
        (out / f"{name}.csv").write_text("time_s,displacement_mm,force_N,force_sd_N\n"
                                         + rows + "\n")
        print(f"{name:16s} {ROWS} rows, steady force {2 * AREA_MM2 * (coulomb + film):7.2f} N")
(out / "bundle.toml").write_text("\n".join(toml))
print(f"wrote {out}")
