"""Runs bounded before they start: load steps, nodes and a time estimate from the
case; past the step limit the command stops at once; long runs print the time left."""

from __future__ import annotations

import re

import pytest

from fenicsx_drape.cli import main
from fenicsx_drape.forming.case.format import CaseError, load_case, run_size
from fenicsx_drape.forming.running.run import run_case
from fenicsx_drape.limits import run_seconds


@pytest.fixture
def no_limit_set(monkeypatch):
    """DRAPE_MAX_STEPS as the test sets it, put back afterwards (the CLI option sets it)."""
    monkeypatch.setenv("DRAPE_MAX_STEPS", "5000")
    monkeypatch.delenv("DRAPE_MAX_STEPS")
    return monkeypatch


def test_the_run_size_is_known_from_the_case():
    # The hemisphere at 40 mm cells: 80 mm of travel in 1 mm steps; a quarter of 240 mm in
    # 3 × 3 cells (Δ = 40 mm): 4 × 4 nodes.
    size = run_size(load_case("hemisphere", cell_mm=40.0))
    assert size["steps"] == 80 and size["nodes"] == 16 and size["travel_mm"] == 80.0
    assert size["seconds"] == pytest.approx(run_seconds(80, 16))
    # The double dome: 40 mm in steps of 0.3 mm.
    assert run_size(load_case("double_dome", step_mm=0.3))["steps"] == 134


def test_a_run_past_the_step_limit_stops_at_once_with_the_numbers(tmp_path, capsys,
                                                                   no_limit_set):
    out = tmp_path / "out"
    assert main(["form", "double_dome", "--step-mm", "0.001", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert re.search(r"the run would take 40000 load steps \(40 mm of travel at step_mm = "
                     r"0\.001\) on 176 nodes, about \d+ min: more than the limit of 5000 "
                     r"steps \(the default\); give a larger step_mm, or raise the limit with "
                     r"--max-steps N \(or DRAPE_MAX_STEPS=N\)", err), err
    assert not out.exists()
    # The limit set directly: 80 steps of the hemisphere.
    no_limit_set.setenv("DRAPE_MAX_STEPS", "79")
    with pytest.raises(CaseError, match=r"80 load steps .* limit of 79 steps \(set by "
                                        r"DRAPE_MAX_STEPS\)"):
        load_case("hemisphere", cell_mm=40.0)
    no_limit_set.setenv("DRAPE_MAX_STEPS", "80")
    load_case("hemisphere", cell_mm=40.0)
    # The option of every forming command.
    for command in (["form", "hemisphere", "--out", str(out)], ["compare", str(tmp_path)],
                    ["diagnose", str(tmp_path)]):
        with pytest.raises(SystemExit):
            main([*command, "--help"])
        assert "--max-steps" in capsys.readouterr().out
    assert main(["form", "hemisphere", "--cell-mm", "40", "--max-steps", "10", "--out",
                 str(out)]) == 2
    assert "limit of 10 steps (set by DRAPE_MAX_STEPS)" in capsys.readouterr().err


def test_a_run_prints_its_estimate_and_the_time_left():
    lines = []
    run = run_case(load_case("hemisphere", cell_mm=40.0), progress=lines.append)
    assert lines[0] == ("hemisphere: about 80 load steps (80 mm at 1 mm) on 16 nodes, about "
                        f"{run_seconds(80, 16):.2g} s (estimate)")
    left = [float(m.group(1)) for line in lines[1:]
            if (m := re.search(r"~(\S+) s left$", line))]
    assert len(left) == run.steps and left[-1] == 0.0
    assert left[len(left) // 2] < left[1]  # the time left goes down as the travel grows
