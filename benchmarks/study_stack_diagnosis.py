"""A lab's stack bundle of the double dome, and the three diagnoses of it (``--print``).

    ./drape exec python3 benchmarks/study_stack_diagnosis.py results/stack-lab

Writes, under the folder given:

- ``sliding/``: the bundle of a [0/90, ±45] stack formed with sliding plies (the paper's model
  with ``interply_friction``, μ = 0.2, η_f = 0.002 MPa·s/mm) on the double dome (the whole
  blank, 10 mm cells, frictionless tools): shear along two lines on the outer ply (1° sd), a
  scan of the outer ply (0.15 mm) and each ply's edge after forming (0.3 mm); its case is the
  lab's copy: punch and die as STL, 20 mm cells (``demos/make_lab_bundle.py``);
- ``ply35/``: the same, the stack formed with its second ply laid at 35° where the case says
  45°;
- ``sliding.toml`` (the model that made them) and ``bonded.toml`` (the paper's model: the
  plies bonded).

It prints the ``drape diagnose`` commands that judge them: the model that made the data, the
bonded model, and the model that made the data on the bundle whose ply was laid wrong.
"""

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "demos"))

import make_lab_bundle

from fenicsx_drape.diagnosis.lab_synthetic import lab_tables, write_lab_bundle
from fenicsx_drape.forming.case import load_case
from fenicsx_drape.forming.running.run import run_case
from fenicsx_drape.model import default_model

EFFECTS = ["rate_dependence", "strain_dependent_viscosity", "decrimping", "tow_buckling",
           "holder_friction"]


def bundle(out: Path, case_path: Path, truth_path: Path, model, seed: int) -> Path:
    """Form the truth and write the lab's bundle of it with the lab's case."""
    truth = run_case(load_case(truth_path, cell_mm=10.0), model)
    tables = lab_tables(truth.grid, {"travel_mm": np.zeros(1), "punch": np.zeros(1)},
                        seed=seed, points_per_line=20, scan_points=800, edge_points=40)
    edges = [lab_tables(g, {"travel_mm": np.zeros(1), "punch": np.zeros(1)}, seed=seed + k,
                        edge_points=40)["outline"] for k, g in enumerate(truth.plies, 1)]
    tables["outline"] = {key: np.concatenate([e[key] for e in edges])
                         for key in ("x_mm", "y_mm", "position_sd_mm")}
    tables["outline"]["ply"] = np.repeat(np.arange(1, len(edges) + 1), [len(e["x_mm"])
                                                                         for e in edges])
    write_lab_bundle(out, load_case(case_path), tables, name=out.name,
                     measurements=("shear_points", "surface", "outline"),
                     comment="A lab's trial of a [0/90, ±45] stack on the double dome "
                             "(benchmarks/study_stack_diagnosis.py)")
    return out


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    sliding = default_model().with_effects("interply_friction")
    (out / "sliding.toml").write_text(f"effects = {[*EFFECTS, 'interply_friction']}\n"
                                      .replace("'", '"'))
    (out / "bonded.toml").write_text(f"effects = {EFFECTS}\n".replace("'", '"'))
    lab = make_lab_bundle.stack_stl_case(out / "lab-case")
    truth45 = make_lab_bundle.stack_stl_case(out / "truth-45")
    truth35 = make_lab_bundle.stack_stl_case(out / "truth-35", angles=(0.0, 35.0))
    for name, truth, seed in (("sliding", truth45, 52), ("ply35", truth35, 53)):
        bundle(out / name, lab, truth, sliding, seed)
    for name, bundle_name in (("sliding", "sliding"), ("bonded", "sliding"),
                              ("sliding", "ply35")):
        print(f"./drape diagnose {out / bundle_name} --model {out / name}.toml "
              f"--json {out / f'{bundle_name}-{name}.json'}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "results" / "stack-lab")
