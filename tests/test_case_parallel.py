"""Forming cases on meshed tools: every rank count forms the same part."""

from pathlib import Path

import pytest

pytest.importorskip("dolfinx")
from mpi4py import MPI

import numpy as np

from fenicsx_drape.forming.case.format import load_case
from fenicsx_drape.forming.running.run import run_case

MESHES = Path(__file__).resolve().parents[1] / "meshes"


@pytest.mark.parallel
@pytest.mark.compares_ranks
@pytest.mark.slow
@pytest.mark.parametrize("case_file", ["double_dome/case.toml", "square_box/case.toml"])
def test_serial_and_parallel_runs_agree(case_file, tight_solver):
    """The coarse quarter on meshed tools on all ranks equals the run on one process."""
    case = load_case(MESHES / case_file, cell_mm=20.0)
    parallel = run_case(case, options=tight_solver, comm=MPI.COMM_WORLD)
    serial = run_case(case, options=tight_solver, comm=MPI.COMM_SELF)
    assert parallel.stopped is None and serial.stopped is None
    np.testing.assert_allclose(parallel.grid.x, serial.grid.x, atol=1e-5)
    assert parallel.max_penetration_mm == pytest.approx(serial.max_penetration_mm, rel=1e-3)
