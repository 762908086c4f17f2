"""Forming a scenario's truth with the project's forming API, remembered by its parameters.

A truth run is a dict (JSON): the part, the net (``cell_mm``, ``step_mm``), the process
(``duration_s``, ``holder_force_N``, the holder's ``mu`` when stated), the set-up as it was
(``ply_angle_deg``, ``blank_offset_mm``, ``tool_offset_mm``), the stack or not, the model
(``effects``, ``parameters``), and ``symmetry_of``: a set-up whose sheet the run is formed on
(the symmetry planes that set-up keeps; a counterfactual at the stated set-up formed on the
truth's own sheet, not on the case's quarter). :func:`form_all` writes each run's case file (the
real tools, :mod:`parts`) and model file into a folder named by the SHA-256 of that dict, and
forms it in a process of its own (``python3 truth.py FOLDER``: ``load_case`` with the overrides,
``load_model``, ``form_case`` without pictures), two at a time. A folder that holds a finished
run is not formed again: a rerun of the benchmark reuses its truths.

The process reads nothing of the diagnosis: the lab code (:mod:`lab`) reads the run's output
files afterwards.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
VERSION = 1  # of the way truths are formed: a new version forms them again
OVERRIDES = ("cell_mm", "step_mm", "duration_s", "holder_force_N", "mu", "ply_angle_deg",
             "blank_offset_mm", "tool_offset_mm")


def key_of(spec: dict) -> str:
    """The folder name of a truth run: SHA-256 of its parameters."""
    text = json.dumps({"version": VERSION, **spec}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def model_toml(effects, parameters: dict) -> str:
    """A MODEL.toml: its effects and parameter values."""
    import lab

    text = f"effects = {lab.toml_value(list(effects))}\n"
    if parameters:
        text += "\n" + lab.toml_table("[parameters]", dict(sorted(parameters.items())))
    return text


def prepare(spec: dict, cache: Path) -> Path:
    """The truth's folder with its case and model written (not yet formed)."""
    import parts

    folder = cache / key_of(spec)
    if (folder / "run" / "summary.json").is_file():
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    # "lab_tools": the truth formed on the lab's own copy of the tools (a check of the lab's
    # measures against the diagnosis's reading of them, with nothing else apart).
    parts.write_case(folder / "case", spec["part"], truth=not spec.get("lab_tools"),
                     stack=spec.get("stack", False), stl_cache=cache / "stl")
    (folder / "model.toml").write_text(model_toml(spec["effects"], spec.get("parameters", {})))
    (folder / "spec.json").write_text(json.dumps(spec, indent=1, sort_keys=True))
    return folder


def overrides_of(folder: Path) -> dict:
    """The case overrides of the truth run in ``folder`` (its ``spec.json``)."""
    from fenicsx_drape.forming import load_case

    spec = json.loads((folder / "spec.json").read_text())
    overrides = {k: spec[k] for k in OVERRIDES if spec.get(k) is not None}
    if spec.get("symmetry_of"):
        # the planes the named set-up keeps (load_case drops those it breaks)
        like = load_case(folder / "case" / "case.toml", **spec["symmetry_of"])
        overrides["symmetry"] = list(like.blank.symmetry)
    return overrides


def form_one(folder: Path) -> dict:
    """Form the truth of ``folder`` (in this process): its summary."""
    from fenicsx_drape.forming import form_case, load_case
    from fenicsx_drape.model import load_model

    case = load_case(folder / "case" / "case.toml", **overrides_of(folder))
    model = load_model(folder / "model.toml")
    _, summary = form_case(folder / "run.partial", case, model, pictures=False)
    os.replace(folder / "run.partial", folder / "run")
    return summary


def form_all(specs: list[dict], cache: Path, workers: int = 2, say=print) -> list[Path]:
    """Form every truth not yet formed, ``workers`` at a time; their run folders, in order."""
    folders = [prepare(s, cache) for s in specs]
    todo = sorted({f for f in folders if not (f / "run" / "summary.json").is_file()})

    def run(folder: Path) -> None:
        start = time.perf_counter()
        log = folder / "form.log"
        with open(log, "w") as out:
            done = subprocess.run([sys.executable, str(HERE / "truth.py"), str(folder)],
                                  stdout=out, stderr=subprocess.STDOUT, check=False,
                                  env={**os.environ, "OMP_NUM_THREADS": "1"})
        if done.returncode != 0 or not (folder / "run" / "summary.json").is_file():
            tail = log.read_text().splitlines()[-5:]
            raise RuntimeError(f"truth {folder.name} failed: " + " | ".join(tail))
        say(f"    formed truth {folder.name} in {time.perf_counter() - start:.1f} s")

    if todo:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            list(pool.map(run, todo))
    return [f / "run" for f in folders]


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    summary = form_one(Path(sys.argv[1]))
    print(f"steps {summary['steps']}, travel {summary['travel_mm']} mm, "
          f"max shear {summary['max_shear_deg']:.2f}°")
