"""Tow deactivation in compression (eq. 4) and reactivation in tension, in the FE solve."""

import pytest

pytest.importorskip("dolfinx")

import numpy as np

from fenicsx_drape.fe import SolverOptions, TrussProblem, truss_sheet
from fenicsx_drape.fe.grid import WARP
from fenicsx_drape.model import default_model

SIZE = 40.0


def _patch(buckled_tow_stiffness_N):
    model = default_model()
    assert "tow_buckling" in model.effects
    sheet = truss_sheet(SIZE, 10.0)
    problem = TrussProblem(sheet, model,
                           options=SolverOptions(buckled_tow_stiffness_N=buckled_tow_stiffness_N))
    problem.fix("all", (2,))
    problem.fix(lambda X: np.isclose(X[:, 0], -SIZE / 2), (0,))
    problem.fix(lambda X: np.isclose(X[:, 0], -SIZE / 2) & np.isclose(X[:, 1], 0.0), (1,))
    # Squeeze along the warp by 1.2 mm over 12 s, then pull to +0.6 mm at 24 s.
    history_s, history_mm = [0.0, 12.0, 24.0], [0.0, -1.2, 0.6]
    problem.fix(lambda X: np.isclose(X[:, 0], SIZE / 2), (0,),
                lambda t: np.interp(t, history_s, history_mm))
    warp = problem.state.groups["tow"][0]
    warp = warp[np.isin(warp, np.flatnonzero(_kinds(problem) == WARP))]
    return model, problem, warp


def _kinds(problem):
    n = len(problem.state.dofs)
    kinds = np.zeros(n, dtype=np.int32)
    tags = problem.sheet.bar_tags
    owned = tags.indices < n
    kinds[tags.indices[owned]] = tags.values[owned]
    return kinds


@pytest.mark.parallel
@pytest.mark.parametrize("stiffness", [0.0, 0.04])
def test_compressed_tows_carry_nothing_then_carry_again(stiffness):
    model, problem, warp = _patch(stiffness)
    law = model.laws()["tow"]
    q = problem.state.dofs[warp]
    for t in np.arange(1.0, 24.5, 1.0):
        assert problem.step(t).converged
        ε = problem.state.strain.x.array[q]
        σ = problem.state.stress.x.array[q]
        if t <= 12.0:
            assert (ε < -1e-3).all()  # the warp is compressed ...
            # ... and carries nothing but the stated residual stiffness of a buckled tow.
            np.testing.assert_array_equal(σ, stiffness * ε)
        if t >= 22.0:
            assert (ε > 1e-3).all()  # in tension again: active with the tow law, eq. 3
            np.testing.assert_allclose(σ, law.update(ε, 1.0, np.zeros((len(ε), 0)))[0],
                                       rtol=1e-12)
            assert (σ > 1.0).all()
    res = problem.results()
    assert (res.warp_wrinkling == 0.0).all()  # no warp tow is compressed at the end
    force = problem.reaction_force(lambda X: np.isclose(X[:, 0], SIZE / 2))[0]
    assert force > 0.71 * SIZE * 1.0  # the patch carries tension along the warp again


@pytest.mark.parallel
def test_wrinkling_outputs_while_compressed():
    _, problem, _ = _patch(0.0)
    problem.run(12.0, 1.0)
    res = problem.results()
    ε_expected = 0.5 * ((SIZE - 1.2) ** 2 / SIZE**2 - 1)  # the warp follows the edges
    np.testing.assert_allclose(res.warp_strain, ε_expected, rtol=1e-9)
    assert res.min_wrinkling_strain == pytest.approx(ε_expected, rel=1e-9)
    # All warp bars compressed, weft not: Σ w L ε⁻ / Σ w L is half the warp strain.
    assert (res.weft_wrinkling == 0).all()
    assert res.total_wrinkling_strain == pytest.approx(ε_expected / 2, rel=1e-9)
