"""The characterisation curves of a model, as the paper's Figs. 2b and 6 (``drape curves``).

:func:`write_curves` writes into a folder:

- ``tensile.csv``, ``bias_extension.csv`` and ``fig6_characterisation.png``: the tensile test
  (25 mm wide, 100 mm gauge, 2 mm/min, 17.8 tows) and the bias-extension test (210 × 70 mm,
  10, 40 and 160 mm/min, 35.3 tows) simulated with the unit-cell solutions (section 3);
- ``shear_law.csv`` and ``fig2b_shear_law.png``: one shear diagonal through loading,
  relaxation, reloading and unloading at 0.0055 s⁻¹ (Fig. 2b);
- ``provenance.json``.

``drape curves --out DIR`` is this one call.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

from fenicsx_drape import unitcell
from fenicsx_drape.model import Model
from fenicsx_drape.provenance import atomic_write_text, save_figure, write_provenance

TOWS_PER_MM = 0.713  # the paper's 17.8 tows on 25 mm and 35.3 on 70 mm / √2
TENSILE = {"gauge_length_mm": 100.0, "width_mm": 25.0, "speed_mm_per_min": 2.0,
           "displacement_mm": 0.3}
BIAS = {"length_mm": 210.0, "width_mm": 70.0, "speeds_mm_per_min": (10.0, 40.0, 160.0),
        "diagonal_strain": 0.45}
FIG2B_RATE = 0.0055  # 1/s

__all__ = ["BIAS", "TENSILE", "effective_rate", "fig2b_history", "paper_tests", "write_curves"]


def paper_tests(model: Model, rows: int = 300) -> dict:
    """Simulate the paper's tensile test and bias tests at its three speeds.

    Returns:
        ``{"tensile": UnitCellCurve, "bias": {speed: UnitCellCurve}, "tows": {...}}``.
    """
    u = np.linspace(0.0, TENSILE["displacement_mm"], rows)
    tensile = unitcell.tensile(model, u / (TENSILE["speed_mm_per_min"] / 60.0), u,
                               gauge_length_mm=TENSILE["gauge_length_mm"])
    L, W = BIAS["length_mm"], BIAS["width_mm"]
    u_end = (L - W) * (math.sqrt(1.0 + 2.0 * BIAS["diagonal_strain"]) - 1.0)
    bias = {}
    for speed in BIAS["speeds_mm_per_min"]:
        u = np.linspace(0.0, u_end, rows)
        bias[speed] = unitcell.bias_extension(model, u / (speed / 60.0), u, length_mm=L,
                                              width_mm=W)
    tows = {"tensile": TOWS_PER_MM * TENSILE["width_mm"], "bias": TOWS_PER_MM * W / math.sqrt(2)}
    return {"tensile": tensile, "bias": bias, "tows": tows}


def fig2b_history(rate: float = FIG2B_RATE) -> tuple[np.ndarray, np.ndarray]:
    """Loading to 0.3, relaxation for 60 s, reloading to 0.4, unloading to −0.1 (Fig. 2b)."""
    legs = [(0.0, 0.3), (0.3, 0.3), (0.3, 0.4), (0.4, -0.1)]
    times, strains, t0 = [0.0], [0.0], 0.0
    for start, end in legs:
        duration = 60.0 if start == end else abs(end - start) / rate
        n = max(int(duration / 0.5), 2)
        times.extend(t0 + np.linspace(0.0, duration, n + 1)[1:])
        strains.extend(np.linspace(start, end, n + 1)[1:])
        t0 += duration
    return np.array(times), np.array(strains)


def _csv(header: list[str], columns: list[np.ndarray], comment: str) -> str:
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack(columns), delimiter=",", fmt="%.10g",
               header=",".join(header), comments="")
    return "".join(f"# {line}\n" for line in comment.splitlines()) + buf.getvalue()


def write_curves(model: Model, out_dir: str | Path) -> dict[str, Path]:
    """Write the curves, tables and pictures of the module docstring into ``out_dir``.

    Returns:
        The written files by name.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tests = paper_tests(model)
    ten, tows = tests["tensile"], tests["tows"]
    files = {"tensile.csv": atomic_write_text(out / "tensile.csv", _csv(
        ["time_s", "displacement_mm", "tow_strain", "force_per_tow_N", "force_N"],
        [ten.time_s, ten.displacement_mm, ten.tow_strain, ten.force_per_tow_N,
         ten.force_per_tow_N * tows["tensile"]],
        f"tensile test: gauge 100 mm, width 25 mm, 2 mm/min, {tows['tensile']:.1f} tows"))}
    rows = []
    for speed, c in tests["bias"].items():
        rows.append([np.full_like(c.time_s, speed), c.time_s, c.displacement_mm,
                     c.diagonal_strain, c.shear_deg, c.force_per_tow_N,
                     c.force_per_tow_N * tows["bias"]])
    files["bias_extension.csv"] = atomic_write_text(out / "bias_extension.csv", _csv(
        ["speed_mm_per_min", "time_s", "displacement_mm", "diagonal_strain", "shear_deg",
         "force_per_tow_N", "force_N"], [np.concatenate(col) for col in zip(*rows)],
        f"bias extension: 210 x 70 mm, {tows['bias']:.1f} tows; effective rates (eq. 23): "
        + ", ".join(f"{v:g} mm/min -> {effective_rate(v):.6f} 1/s" for v in tests["bias"])))

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    ax1.plot(100 * ten.tow_strain, ten.force_per_tow_N * tows["tensile"], "k-")
    ax1.set(xlabel="tow strain (%)", ylabel="force (N)", title="(a) tension, 2 mm/min")
    for speed, c in tests["bias"].items():
        ax2.plot(c.diagonal_strain, c.force_per_tow_N * tows["bias"],
                 label=f"{speed:g} mm/min ({effective_rate(speed):.4g} s⁻¹)")
    ax2.set(xlabel="diagonal strain", ylabel="force (N)", title="(b) bias extension")
    ax2.legend()
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.suptitle(f"Characterisation tests of the model ({', '.join(model.effects) or 'none'})",
                 fontsize=9)
    files["fig6_characterisation.png"] = save_figure(fig, out / "fig6_characterisation.png")

    t, strain = fig2b_history()
    stress = unitcell.diagonal_response(model, t, strain)
    files["shear_law.csv"] = atomic_write_text(out / "shear_law.csv", _csv(
        ["time_s", "strain", "stress_N_per_tow"], [t, strain, stress],
        f"shear diagonal: loading, relaxation, reloading, unloading at {FIG2B_RATE} 1/s"))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    ax1.plot(t, stress, "k-")
    ax1.set(xlabel="time (s)", ylabel="stress (N/tow)", title="stress history")
    ax1b = ax1.twinx()
    ax1b.plot(t, strain, "C0--", lw=0.8)
    ax1b.set_ylabel("strain", color="C0")
    ax2.plot(strain, stress, "k-")
    ax2.set(xlabel="strain", ylabel="stress (N/tow)", title="stress-strain")
    ax2.grid(alpha=0.3)
    fig.suptitle("Shear diagonal: loading-relaxation-reloading-unloading (Fig. 2b)",
                 fontsize=9)
    files["fig2b_shear_law.png"] = save_figure(fig, out / "fig2b_shear_law.png")
    files["provenance.json"] = write_provenance(out, model={
        "effects": list(model.effects), "parameters": model.parameters,
        "plugins": [str(p) for p in model.plugins]})
    return files


def effective_rate(speed_mm_per_min: float) -> float:
    """The effective shear strain rate (1/s, eq. 23) of the bias test at a crosshead speed."""
    return unitcell.effective_strain_rate(speed_mm_per_min, BIAS["length_mm"],
                                          BIAS["width_mm"])
