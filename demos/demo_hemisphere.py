# ---
# jupyter:
#   jupytext:
#     formats: py:light
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

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

from fenicsx_drape.forming import form_case, load_case
from fenicsx_drape.model import default_model

# As a page of the docs the demo is a notebook run in demos/, without arguments.
SCRIPT = "__file__" in globals()
args = sys.argv[1:] if SCRIPT else []
out = Path(args[0]) if args else Path("results/hemisphere")
# -

# ## The case
#
# The hemisphere is a case file like any part's, `meshes/hemisphere/case.toml`, read here by
# its name; keyword arguments override its values (a finer net: `cell_mm=5.0`). Its tools are
# exact closed-form surfaces (`geometry = "builtin:hemisphere"`), its blank a symmetric
# quarter. Eq. 1 shares the holding force over the nodes under the holder; the paper does not
# say how its quarter model did, and the file's `holder_force_share = "model"` chooses
# (docs/paper.md, "Eq. 1's force share and μ"). The material is the paper's model: its four
# coupon effects plus the blank-holder friction bars.

case = load_case("hemisphere", cell_mm=10.0, duration_s=40.0, holder_force_N=133.0)
print(f"{case.name}: {case.description}; tools {', '.join(t.name for t in case.tools)}")
model = default_model()
print("effects:", ", ".join(model.effects))

# ## Form it
#
# `form_case` runs the load steps (as a script printing step, travel and Newton iterations
# of each) and writes the summary, the ParaView fields, the forming bundle and the pictures.

rank0 = MPI.COMM_WORLD.rank == 0
run, summary = form_case(out, case, model, progress=print if SCRIPT and rank0 else None)
if rank0:
    print(f"{summary['steps']} load steps ({summary['cutbacks']} cut back), "
          f"{summary['snes_iterations']} Newton iterations, {summary['wall_time_s']:.0f} s")

# ## Compare with the paper and with the kinematic drape (Fig. 11)
#
# `paper_comparison` sets the run's numbers beside the paper's model and experiment (all the
# paper's hemisphere numbers are in `fenicsx_drape.forming.paper.numbers`; the studies that compare
# them all are `demos/study_*.py`).

if rank0:
    from fenicsx_drape.forming.paper import paper_comparison

    print(paper_comparison(summary))  # the kinematic drape's maximum shear included

# ## The pictures
#
# The formed sheet coloured by shear angle (the quarter mirrored to the whole part), the
# wrinkled tows, the paper's Figs. 10-11 (shear along the diagonal path and wrinkling along
# the normal path, with the kinematic drape beside the FE result) and the press's force.

if not SCRIPT:  # as a page of the docs: the pictures inline
    from IPython.display import Image, display

    for name in ("shear.png", "wrinkling.png", "paths.png", "tool_forces.png"):
        display(Image(filename=str(out / name)))
