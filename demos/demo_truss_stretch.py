# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# # Stretching a woven patch in the bias direction at three speeds
#
# A scripted study through the FE API: a 60 × 60 mm patch of 10 mm unit cells, turned by 45°
# so that its tows lie at ±45° to x, is stretched along x at the three crosshead speeds of
# the paper's bias-extension tests (10, 40 and 160 mm/min on the 210 × 70 mm specimen). The
# rate-dependent shear law (eqs. 5-9) makes the force rise with the speed; the patch follows
# the unit-cell solution of section 2.2 (eqs. 18-20). Writes a CSV table, a PNG plot, the
# ParaView fields of the fastest run and ``provenance.json`` to ``results/demo_truss_stretch``
# (or the folder given as the first argument).
#
# Run it with `./drape exec python3 demos/demo_truss_stretch.py` (any number of ranks).

import sys
from pathlib import Path

from mpi4py import MPI

import numpy as np

from fenicsx_drape.fe import FieldWriter, TrussProblem, truss_sheet
from fenicsx_drape.model import default_model
from fenicsx_drape.provenance import atomic_write_text, save_figure, write_provenance
from fenicsx_drape.unitcell import bias_extension

comm = MPI.COMM_WORLD
# As a page of the docs the demo is a notebook run in demos/, without arguments.
SCRIPT = "__file__" in globals()
args = sys.argv[1:] if SCRIPT else []
out = Path(args[0] if args else "results/demo_truss_stretch")
model = default_model()

# ## The patch and its loading
#
# The border nodes follow the homogeneous stretch along x of the full-shear region of the
# specimen, whose length is L − W = 140 mm; across the load (y) they are free, so the tows
# find their own strain as in eq. 19. The corners on the x axis are held in y, and the patch
# stays in its plane.

SIZE, CELL = 60.0, 10.0
LENGTH, WIDTH = 210.0, 70.0
D = SIZE * np.sqrt(2.0)  # diagonal of the patch along the load
N = SIZE / CELL  # unit cells along a side
TOWS = (N - 0.5) * 0.71 * CELL  # tows of one family carried across the minor diagonal


def stretch(speed_mm_per_min, crosshead_mm=35.0, steps=35, fields_path=None):
    """Force per tow and shear angle of the patch, stepped like the unit cell."""
    sheet = truss_sheet(SIZE, CELL, rotation_deg=45.0)
    problem = TrussProblem(sheet, model)
    speed = speed_mm_per_min / 60.0  # mm/s
    problem.fix("all", (2,))
    problem.fix("border", (0,), lambda t, X: speed * t / (LENGTH - WIDTH) * X[:, [0]])
    problem.fix(lambda X: np.isclose(np.abs(X[:, 0]), D / 2), (1,))
    writer = FieldWriter(problem, fields_path) if fields_path else None
    time_s = np.linspace(0.0, crosshead_mm / speed, steps + 1)
    force, shear = [0.0], [0.0]
    for t in time_s[1:]:
        problem.step(t)
        res = problem.results()
        force.append(problem.reaction_force(lambda X: X[:, 0] > 1e-9)[0] / TOWS)
        shear.append(-res.shear_deg.mean())  # the tows' angle opens: γ < 0 in our convention
        if writer is not None:
            writer.write(res)
    if writer is not None:
        writer.close()
    curve = bias_extension(model, time_s, speed * time_s, length_mm=LENGTH, width_mm=WIDTH)
    return time_s, np.array(force), np.array(shear), curve


# ## Three speeds

rows = ["speed_mm_per_min,time_s,crosshead_mm,shear_deg,force_per_tow_N,unit_cell_N"]
runs = {}
for speed in (10.0, 40.0, 160.0):
    fields = out / "patch_160mm_per_min.xdmf" if speed == 160.0 else None
    time_s, force, shear, curve = stretch(speed, fields_path=fields)
    runs[speed] = (shear, force, curve)
    for t, g, f, f_uc in zip(time_s, shear, force, curve.force_per_tow_N):
        rows.append(f"{speed:g},{t:.4f},{speed / 60 * t:.4f},{g:.4f},{f:.6f},{f_uc:.6f}")
    error = np.abs(force - curve.force_per_tow_N).max() / curve.force_per_tow_N.max()
    if comm.rank == 0:
        print(f"{speed:5.0f} mm/min: shear {shear[-1]:5.1f}°, force {force[-1]:.3f} N/tow, "
              f"largest difference from the unit cell {100 * error:.1e} %")

# ## Table, plot and provenance (rank 0 writes)

if comm.rank == 0:
    import matplotlib.pyplot as plt

    atomic_write_text(out / "bias_patch.csv", "\n".join(rows) + "\n")
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for speed, (shear, force, curve) in runs.items():
        line, = ax.plot(shear, force, "o", ms=3, label=f"FE patch, {speed:g} mm/min")
        ax.plot(curve.shear_deg, curve.force_per_tow_N, "-", color=line.get_color(), lw=1)
    ax.set_xlabel("shear angle (°)")
    ax.set_ylabel("force per tow (N)")
    ax.set_title("Bias stretch: FE patch (dots) and unit cell (lines)")
    ax.legend(frameon=False, fontsize=8)
    save_figure(fig, out / "bias_patch.png")
    write_provenance(out, model={"effects": list(model.effects)},
                     patch={"size_mm": SIZE, "cell_mm": CELL, "rotation_deg": 45.0})
    print(f"wrote {out}/bias_patch.csv, bias_patch.png, patch_160mm_per_min.xdmf")

# ## The pictures

if not SCRIPT:  # as a page of the docs: the pictures inline
    from IPython.display import Image, display

    for png in [out / "bias_patch.png"]:
        display(Image(filename=str(png)))
