# # Forming a woven prepreg hemisphere (the paper's section 4)
#
# This demo forms the paper's hemisphere with the truss model: a 240 mm square sheet of the
# 4×4 twill prepreg of Table 2 is drawn by a hemispherical punch (radius 60 mm, 20 mm fillet)
# through a blank holder with a 170 mm opening, 80 mm in 40 s, against 133 N of holding force.
# It is the same as
#
#     ./drape form hemisphere --out results/hemisphere
#
# and runs serially or under MPI (`./drape --np 2 exec python3 demos/demo_hemisphere.py`).

# +
import sys
from pathlib import Path

from mpi4py import MPI

from fenicsx_drape.forming import HemisphereTools, kinematic_drape
from fenicsx_drape.forming.hemisphere import HemisphereCase
from fenicsx_drape.forming.outputs import form_hemisphere
from fenicsx_drape.model import default_model

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("results/hemisphere")
# -

# ## The case
#
# The tools are exact surfaces built from their parameters; the quarter model carries a
# quarter of the holding force (eq. 1 with symmetry weights). The material is the paper's
# model: its four coupon effects plus the blank-holder friction bars.

tools = HemisphereTools()
case = HemisphereCase(cell_mm=10.0, duration_s=40.0, holder_force_N=133.0, quarter=True,
                      tools=tools)
model = default_model()
print("effects:", ", ".join(model.effects))

# ## Form it
#
# `form_hemisphere` runs the load steps (printing step, travel and Newton iterations) and
# writes the summary, the ParaView fields, the forming bundle and the pictures.

run, summary = form_hemisphere(out, case, model,
                               progress=print if MPI.COMM_WORLD.rank == 0 else None)

# ## Compare with the paper and with the kinematic drape (Fig. 11)

if MPI.COMM_WORLD.rank == 0:
    net = kinematic_drape(tools, 10.0)
    print(f"max shear angle  {summary['max_shear_deg']:.1f}° (paper: model 51.4°, "
          "experiment 50.2°)")
    print(f"total wrinkling  {100 * summary['total_wrinkling_strain']:.2f} % (paper: 0.55 %)")
    print(f"min wrinkling    {summary['min_wrinkling_strain']:.3f} (paper: model -0.21, "
          "experiment -0.31)")
    print(f"kinematic drape  max shear {abs(net.shear_deg()).max():.1f}° (paper: 61°)")
    print(f"pictures in {out}: shear.png, wrinkling.png, paths.png")
