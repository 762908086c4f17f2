"""The diagnosis walkthrough demo runs as a script and tells its story in numbers."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_demo_diagnosis(tmp_path):
    out = tmp_path / "demo"
    env = os.environ | {"MPLBACKEND": "Agg",
                        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH",
                                                                                 "")])}
    run = subprocess.run([sys.executable, str(ROOT / "demos" / "demo_diagnosis.py"), str(out)],
                         env=env, capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0, run.stderr[-3000:]

    def report(name):
        return json.loads((out / name / "REPORT.json").read_text())

    # The catalogued effect is found, the unknown physics is not, until written as a law.
    assert report("diagnose-v1")["missing_effect"] == "decrimping"
    assert report("diagnose-v2-wide")["missing_effect"] is None
    assert report("diagnose-v2-wide")["where"]
    assert report("diagnose-v2-plugin")["missing_effect"] == "power_law_viscosity"
    # The history: each added effect brings the error from well above to the noise floor.
    history = json.loads((out / "history" / "history.json").read_text())
    errors = [v["normalised"] for v in history]
    assert errors[0] > 2.0 and errors[1] <= 1.5
    assert errors[2] > 2.0 and errors[3] <= 1.5
    for name in ("history/history.png", "v1/where.png", "v1/residual_tensile.png",
                 "diagnose-v1/candidates.png", "diagnose-v2-plugin/residual_bias-1.png"):
        assert (out / name).stat().st_size > 1000
    for folder in ("v1", "v2", "v2-wide", "v3-wide", "diagnose-v1", "history"):
        assert (out / folder / "provenance.json").is_file()
    assert "missing_effect: decrimping" in run.stdout
