"""Patches of unit cells reproduce the unit-cell solutions of the material-law issue.

Same laws (Table 2, the paper's effects), same history, same time steps: the FE patch and the
unit cell solve the same discrete problem, so they agree to the solver tolerances (the issue
asks for 2 %; we assert 1e-5).
"""

import pytest

pytest.importorskip("dolfinx")

import numpy as np

from fenicsx_drape.fe import SolverOptions, TrussProblem, truss_sheet
from fenicsx_drape.model import default_model
from fenicsx_drape.unitcell import bias_extension, tensile

L_T = 0.71  # tows per mm


@pytest.mark.parallel
def test_patch_along_the_tows_gives_the_tensile_solution():
    """4 × 4 cells pulled along the warp, free across: F / (l_t W) = f of eqs. 16-17."""
    model = default_model()
    size = 40.0
    sheet = truss_sheet(size, 10.0)
    # No residual stiffness of buckled tows: the unit cell has none (the weft buckles).
    problem = TrussProblem(sheet, model, options=SolverOptions(buckled_tow_stiffness_N=0.0))
    time = np.linspace(0.0, 60.0, 13)
    stretch_mm = 0.2 / 60.0 * time  # 0.2 mm/min on 40 mm: up to 0.5 % strain

    def left(X):
        return np.isclose(X[:, 0], -size / 2)

    def right(X):
        return np.isclose(X[:, 0], size / 2)

    problem.fix("all", (2,))
    problem.fix(left, (0,))
    problem.fix(lambda X: left(X) & np.isclose(X[:, 1], 0.0), (1,))
    problem.fix(right, (0,), lambda t: np.interp(t, time, stretch_mm))
    forces = [0.0]
    for t in time[1:]:
        assert problem.step(t).converged
        forces.append(problem.reaction_force(right)[0] / (L_T * size))
    curve = tensile(model, time, stretch_mm, gauge_length_mm=size)
    np.testing.assert_allclose(forces, curve.force_per_tow_N, rtol=1e-5,
                               atol=1e-6 * curve.force_per_tow_N.max())
    assert curve.force_per_tow_N[-1] > 10.0  # the tows are loaded well past decrimping


@pytest.mark.parallel
def test_patch_in_bias_gives_the_bias_extension_solution():
    """A 4 × 4 patch turned by 45°: x prescribed homogeneously on its border, y free.

    The homogeneous state balances every border node in y exactly when eq. 19 holds (and edge
    tows stand for half a strip), so the patch is in the unit cell's state. Each border node
    right of the minor diagonal holds a tow strip of n_t tows and the major diagonal of its
    cell: it transmits n_t (σ cos θ + τ_1) = n_t f / 2 along the load (eq. 20). There are
    2N − 1 such nodes (the two corners on the minor diagonal transmit nothing along x), so the
    patch carries (N − ½) n_t f, half a strip less than the N n_t f of a periodic net.
    """
    model = default_model()
    size, Δ = 40.0, 10.0
    sheet = truss_sheet(size, Δ, rotation_deg=45.0)
    problem = TrussProblem(sheet, model)
    D = size * np.sqrt(2.0)  # the diagonal of the patch along the load
    time = np.linspace(0.0, 60.0, 31)
    length, width = 210.0, 70.0
    crosshead = 40.0 / 60.0 * time  # 40 mm/min on the paper's 210 × 70 mm specimen
    e = crosshead / (length - width)  # stretch - 1 of the full-shear region's diagonal
    problem.fix("all", (2,))
    problem.fix("border", (0,), lambda t, X: np.interp(t, time, e) * X[:, [0]])
    problem.fix(lambda X: np.isclose(np.abs(X[:, 0]), D / 2), (1,))  # corners on the axis

    def right(X):
        return X[:, 0] > 1e-9

    forces, shear = [0.0], [0.0]
    for t in time[1:]:
        assert problem.step(t).converged
        forces.append(problem.reaction_force(right)[0] / ((size / Δ - 0.5) * L_T * Δ))
        # Here the loaded diagonal is a "diagonal minus": the tows' angle opens (shear < 0).
        shear.append(-problem.results().shear_deg.mean())
    curve = bias_extension(model, time, crosshead, length_mm=length, width_mm=width)
    np.testing.assert_allclose(forces, curve.force_per_tow_N, rtol=1e-5,
                               atol=1e-6 * curve.force_per_tow_N.max())
    np.testing.assert_allclose(shear, curve.shear_deg, atol=1e-6)
    res = problem.results()
    assert np.ptp(res.shear_deg) < 1e-6  # homogeneous
    assert curve.shear_deg[-1] > 20.0


@pytest.mark.parallel
def test_shear_tension_coupling_acts_on_the_cell_as_in_the_unit_cell():
    """The patch in bias with shear_tension_coupling follows the unit cell with it.

    The FE applies the factor staggered in time (extrapolated from the tow stresses of the
    last two steps), the unit cell implicitly: they agree within the issue's 2 % here.
    """
    model = default_model().with_effects("shear_tension_coupling").with_parameters(k_st=5.0)
    size, Δ = 40.0, 10.0
    sheet = truss_sheet(size, Δ, rotation_deg=45.0)
    problem = TrussProblem(sheet, model)
    D = size * np.sqrt(2.0)
    time = np.linspace(0.0, 40.0, 41)
    crosshead = 40.0 / 60.0 * time
    e = crosshead / 140.0
    problem.fix("all", (2,))
    problem.fix("border", (0,), lambda t, X: np.interp(t, time, e) * X[:, [0]])
    problem.fix(lambda X: np.isclose(np.abs(X[:, 0]), D / 2), (1,))
    forces = [0.0]
    for t in time[1:]:
        assert problem.step(t).converged
        forces.append(problem.reaction_force(lambda X: X[:, 0] > 1e-9)[0]
                      / ((size / Δ - 0.5) * L_T * Δ))
    coupled = bias_extension(model, time, crosshead, length_mm=210.0, width_mm=70.0)
    plain = bias_extension(default_model(), time, crosshead, length_mm=210.0, width_mm=70.0)
    np.testing.assert_allclose(forces, coupled.force_per_tow_N, rtol=0.02,
                               atol=0.02 * coupled.force_per_tow_N.max())
    # It does act: 5 % or more above the uncoupled force at the end.
    assert coupled.force_per_tow_N[-1] > 1.05 * plain.force_per_tow_N[-1]
