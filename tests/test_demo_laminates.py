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
    run = subprocess.run([sys.executable, str(ROOT / "demos" / "demo_laminates.py"),
                          str(tmp_path)], env=env, capture_output=True, text=True, timeout=1200,
                         cwd=ROOT)
    assert run.returncode == 0, run.stderr[-3000:]
    with open(tmp_path / "layups.csv") as f:
        rows = list(csv.DictReader(f))
    sliding = {r["layup"]: float(r["max_sliding_mm"]) for r in rows}
    shear = {(r["layup"], int(r["ply"])): float(r["max_shear_deg"]) for r in rows}
    # More friction, or a thicker film, holds the plies together: they slide less.
    assert sliding["[0/90, ±45], μ = 0.3"] < sliding["[0/90, ±45]"] < sliding[
        "[0/90, ±45], μ = 0.1"]
    assert sliding["[0/90, ±45], η_f = 0.01"] < sliding["[0/90, ±45]"]
    # Plies at the same angle hardly slide; the ply at 45° shears more than the one at 0°.
    assert sliding["[0/90, 0/90]"] < 0.1 * sliding["[0/90, ±45]"]
    assert shear[("[0/90, ±45]", 2)] > shear[("[0/90, ±45]", 1)] + 5.0
    assert (tmp_path / "shear_ply2.png").stat().st_size > 0
