# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# # The paper's material laws and the unit-cell tests
#
# This demo walks through the material side of fenicsx_drape (no DOLFINx needed): the model
# with Table 2, the tow and shear laws, the unit-cell tensile and bias-extension tests, a
# model without rate dependence, and a user law registered by name. Run it as a script:
#
#     python3 demos/demo_material_laws.py [OUT_DIR]

# +
import sys
from pathlib import Path

import numpy as np

from fenicsx_drape import default_model, unitcell
from fenicsx_drape.curves import write_curves
from fenicsx_drape.model import Model, parameter_info

# As a page of the docs the demo is a notebook run in demos/, without arguments.
SCRIPT = "__file__" in globals()
args = sys.argv[1:] if SCRIPT else []
out = Path(args[0] if args else "results/demo_material_laws")
model = default_model()
print("effects:", ", ".join(model.effects))
for name in model.active_parameters(("tensile", "bias_extension")):
    info = parameter_info(name)
    print(f"  {name:10s} = {model.parameters[name]:<10g} {info.unit:8s} {info.description}")
# -

# ## Laws at one point
#
# A law is a dataclass with a vectorised update: strain (Green-Lagrange) and time step in,
# stress (N/tow), consistent tangent and new state out. Here a shear diagonal is loaded at the
# middle effective rate of the paper's bias tests, then held.

# +
shear = model.laws()["shear"]
state = shear.initial_state(1)
rate, dt = 0.0055, 1.0
for step in range(1, 101):
    strain = np.array([min(rate * step * dt, 0.4)])
    stress, tangent, state = shear.update(strain, dt, state)
    if step % 20 == 0:
        print(f"t = {step * dt:5.0f} s  strain {strain[0]:.3f}  stress {stress[0]:.4f} N/tow  "
              f"tangent {tangent[0]:.3f} N/tow")
# -

# ## Bias extension at the paper's three speeds
#
# The effective strain rates of eq. 23, and the force per tow at a few diagonal strains.

# +
L, W = 210.0, 70.0
u = np.linspace(0.0, 52.9, 200)
for speed in (10.0, 40.0, 160.0):
    curve = unitcell.bias_extension(model, u / (speed / 60.0), u, length_mm=L, width_mm=W)
    at = np.interp([0.1, 0.3, 0.45], curve.diagonal_strain, curve.force_per_tow_N)
    print(f"{speed:5g} mm/min ({unitcell.effective_strain_rate(speed, L, W):.6f} 1/s): "
          f"force per tow at ε_d = 0.1, 0.3, 0.45: {np.round(at, 3)} N "
          f"(× 35.3 tows = {np.round(35.3 * at, 1)} N)")
# -

# ## Without rate dependence
#
# The rate-independent limit: elastic-plastic branch plus the lock-up term at the reference
# rate. It cannot tell the three speeds apart.

# +
rate_free = model.without_effects("rate_dependence")
for speed in (10.0, 160.0):
    curve = unitcell.bias_extension(rate_free, u / (speed / 60.0), u, length_mm=L, width_mm=W)
    print(f"rate-independent, {speed:5g} mm/min: force per tow at ε_d = 0.3: "
          f"{np.interp(0.3, curve.diagonal_strain, curve.force_per_tow_N):.4f} N")
# -

# ## A user law
#
# `demos/user_laws/power_law_viscosity.py` registers a shear law with a power-law viscosity.
# Naming it among the effects (and the file among the plugins) replaces the paper's shear law.

# +
here = Path(__file__).resolve().parent if SCRIPT else Path.cwd()
plugin = here / "user_laws" / "power_law_viscosity.py"
user = Model(("power_law_viscosity", "decrimping", "tow_buckling"),
             {**model.parameters, "n_power": 0.5}, plugins=(plugin,))
print("shear law of the user model:", type(user.laws()["shear"]).__name__)
for speed in (10.0, 160.0):
    curve = unitcell.bias_extension(user, u / (speed / 60.0), u, length_mm=L, width_mm=W)
    print(f"power law n = 0.5, {speed:5g} mm/min: force per tow at ε_d = 0.3: "
          f"{np.interp(0.3, curve.diagonal_strain, curve.force_per_tow_N):.4f} N")
# -

# ## The curves of the paper's Figs. 6 and 2b
#
# The same as `./drape curves --out DIR`.

files = write_curves(model, out)
print("wrote", ", ".join(str(out / name) for name in files))

# ## The pictures

if not SCRIPT:  # as a page of the docs: the pictures inline
    from IPython.display import Image, display

    for png in (out / name for name in files if name.endswith(".png")):
        display(Image(filename=str(png)))
