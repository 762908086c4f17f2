"""A stack of plies formed on several ranks: the same part as on one.

The [0/90, ±45] stack on the paper's hemisphere (``meshes/hemisphere/stack_0_45.toml``, the
whole blank) at Δ = 30 mm in 8 s, formed on ``COMM_WORLD`` and, as the reference, on
``COMM_SELF`` in the same test. The inter-ply pairs cross the partition and follow the plies
(fe/plies.py), so only round-off may differ, within what Newton leaves (a residual 1e-9 of the
first): measured up to 8e-6 mm on the nodes and 2e-8 MPa on 2 ranks, and the same iterations;
the tolerance, 1e-4 (a tenth of a micrometre), is far below anything a part shows.
"""

import json
from pathlib import Path

import pytest

pytest.importorskip("dolfinx")
from mpi4py import MPI

import numpy as np

from fenicsx_drape.cli import main
from fenicsx_drape.fe.plies import PlyContact, ply_of, stack_plies, stack_sheet
from fenicsx_drape.fe.solver import TrussProblem
from fenicsx_drape.forming.case.format import load_case
from fenicsx_drape.forming.running.outputs import case_summary, interply_maps
from fenicsx_drape.forming.running.run import run_case
from fenicsx_drape.materials.interply import InterplyLaw
from fenicsx_drape.model import default_model

# Whole stacks formed on one rank and on N: minutes of CPU, so `make bench-parallel` (2 and 3
# ranks); the pairs' pattern growing on one rank only, the cause of a hang, is in make test
# (tests/test_plies_parallel.py).
pytestmark = pytest.mark.bench

CASE = Path(__file__).resolve().parents[1] / "meshes" / "hemisphere" / "stack_0_45.toml"
COARSE = {"cell_mm": 30.0, "duration_s": 8.0}
TOL = 1e-4  # mm, degrees, MPa


@pytest.fixture(scope="module")
def reference():
    """The stack formed on one process (every rank forms it)."""
    return run_case(load_case(CASE, **COARSE), comm=MPI.COMM_SELF)


def _numbers(faces):
    return [{k: v for k, v in face.items() if k not in ("xy", "sliding_mm", "pressure_MPa")}
            for face in faces]


@pytest.mark.parallel
@pytest.mark.compares_ranks
def test_a_stack_forms_alike_on_any_number_of_ranks(reference):
    run = run_case(load_case(CASE, **COARSE), comm=MPI.COMM_WORLD)
    assert run.stopped is None and reference.stopped is None
    assert [s.iterations for s in run.problem.steps] == [
        s.iterations for s in reference.problem.steps]
    assert len(run.plies) == len(reference.plies) == 2
    for ply, ref in zip(run.plies, reference.plies):
        np.testing.assert_allclose(ply.x, ref.x, rtol=0, atol=TOL)  # every node (mm)
        assert np.nanmax(np.abs(ply.shear_deg())) == pytest.approx(
            np.nanmax(np.abs(ref.shear_deg())), abs=TOL)
    faces, ref_faces = interply_maps(run), interply_maps(reference)
    assert ref_faces[0]["max_sliding_mm"] > 1.0  # the plies slid: the pairs mattered
    assert ref_faces[0]["max_pressure_MPa"] > 0.0
    for face, ref in zip(faces, ref_faces):
        for key in ("xy", "sliding_mm", "pressure_MPa"):  # every pair, in the same order
            np.testing.assert_allclose(face[key], ref[key], rtol=0, atol=TOL)
        for key, value in _numbers([ref])[0].items():
            assert face[key] == pytest.approx(value, abs=TOL), key


@pytest.mark.parallel
@pytest.mark.slow  # 12 s on 3 ranks (two cores): make test runs it on 2 ranks only
def test_drape_form_writes_the_summary_of_one_rank(reference, tmp_path):
    """``drape form`` of the stack under mpirun: the summary.json of a run on one process, and
    the inter-ply pressure and sliding of its XDMF fields at every pair's node."""
    h5py = pytest.importorskip("h5py")
    comm = MPI.COMM_WORLD
    out = Path(comm.bcast(str(tmp_path / "out"), root=0))
    assert main(["form", str(CASE), "--out", str(out), "--cell-mm", "30", "--duration-s", "8",
                 "--quiet"]) == 0
    if comm.rank != 0:
        return
    c = reference.interply
    with h5py.File(out / "fields.h5") as fields:
        X = fields["Mesh/mesh/geometry"][:]
        node = {tuple(np.round(x, 6)): i for i, x in enumerate(X)}
        at = [node[tuple(np.round(x, 6))] for x in c.X[c.a]]  # each pair's node a
        for name, expected in (("interply_pressure_MPa", c.pressure_MPa),
                               ("interply_sliding_mm", np.linalg.norm(c.sliding_mm, axis=1))):
            steps = fields[f"Function/{name}"]
            last = max(steps, key=lambda t: float(t.replace("_", ".")))
            np.testing.assert_allclose(steps[last][:, 0][at], expected, rtol=0, atol=TOL)
    summary = json.loads((out / "summary.json").read_text())
    expected = case_summary(reference)
    assert summary["ranks"] == comm.size
    for key in ("nodes", "steps", "snes_iterations", "cutbacks"):
        assert summary[key] == expected[key], key
    for key in ("max_shear_deg", "total_wrinkling_strain", "travel_mm"):
        assert summary[key] == pytest.approx(expected[key], abs=TOL), key
    for ply, ref in zip(summary["plies"], expected["plies"], strict=True):
        for key in ("max_shear_deg", "total_wrinkling_strain", "min_wrinkling_strain"):
            assert ply[key] == pytest.approx(ref[key], abs=TOL), key
    for face, ref in zip(summary["interply"], expected["interply"], strict=True):
        assert face == pytest.approx(ref, abs=TOL)


@pytest.mark.parallel
def test_a_stack_is_split_by_columns():
    """Each rank holds a column of the stack (every ply), so few inter-ply blocks of the
    Jacobian join nodes of two ranks (a graph partitioner gave a ply to a rank: every pair
    then joined two ranks). Every rank holds every pair (the pairs follow the plies)."""
    comm = MPI.COMM_WORLD
    case = load_case(CASE)
    plies = stack_plies([b.grid() for b in case.ply_blanks()],
                        [p.thickness_mm for p in case.plies])
    contact = PlyContact(plies, InterplyLaw(), 2000.0)
    problem = TrussProblem(stack_sheet(plies, comm), default_model(), [contact])
    assert contact.pairs_global == len(contact.a) == 541
    owned = np.bincount(ply_of(plies, problem.X[: problem.num_owned]), minlength=2)
    every = np.array(comm.allgather(owned))  # (ranks, plies)
    assert (every.sum(axis=0) == [625, 541]).all()
    assert (every >= 0.8 * every.sum(axis=0) / comm.size).all()  # each rank its share of each
