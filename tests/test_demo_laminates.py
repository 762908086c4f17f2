"""The layup demo runs as a script and its stacks form as inter-ply friction says."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_demo_laminates(tmp_path):
    env = os.environ | {"MPLBACKEND": "Agg",
                        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH",
                                                                                 "")])}
    # The layups checked below (the double dome's single ply and four-ply stack, and the
    # hemisphere's single ply, are the table's only: docs/laminates.md).
    names = [f"double dome/{n}" for n in ("[0/90, 0/90]", "[0/90, ±45]", "[0/90, ±45], μ = 0.1",
                                           "[0/90, ±45], μ = 0.3", "[0/90, ±45], η_f = 0.0005",
                                           "[0/90, ±45], η_f = 0.01")] + ["hemisphere/[0/90, ±45]"]
    run = subprocess.run([sys.executable, str(ROOT / "demos" / "demo_laminates.py"),
                          str(tmp_path), *names], env=env, capture_output=True, text=True,
                         timeout=1200, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-3000:]
    with open(tmp_path / "layups.csv") as f:
        rows = list(csv.DictReader(f))
    dome = [r for r in rows if r["part"] == "double dome"]
    sliding = {r["layup"]: float(r["max_sliding_mm"]) for r in dome}
    draw_in = {(r["layup"], int(r["ply"])): float(r["draw_in_x_mm"]) for r in dome}
    assert {r["layup"] for r in rows} == {n.split("/", 1)[1] for n in names}
    assert all(float(r["travel_mm"]) == pytest.approx(40.0) for r in dome)
    # More friction, or a thicker film, holds the plies together: they slide less.
    assert sliding["[0/90, ±45], μ = 0.3"] < sliding["[0/90, ±45]"] < sliding[
        "[0/90, ±45], μ = 0.1"]
    assert sliding["[0/90, ±45], η_f = 0.01"] < sliding["[0/90, ±45]"] < sliding[
        "[0/90, ±45], η_f = 0.0005"]
    # Plies at the same angle hardly slide; the 0/90 ply, its tows across the side, draws in
    # more at the middle of the blank's side than the ±45 ply (the tip of its ragged edge).
    assert sliding["[0/90, 0/90]"] < 0.2 * sliding["[0/90, ±45]"]
    for name in sliding:
        if name.startswith("[0/90, ±45]"):
            assert draw_in[(name, 1)] > draw_in[(name, 2)] + 2.0, name
    hemisphere = [r for r in rows if r["part"] == "hemisphere"]
    assert max(float(r["max_sliding_mm"]) for r in hemisphere) > 1.0
    for name in ("double_dome_shear_ply2.png", "double_dome_interply.png",
                 "hemisphere_shear_ply2.png"):
        assert (tmp_path / name).stat().st_size > 0
