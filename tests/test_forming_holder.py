"""Blank holder: eq. 1 friction bars, n_s with symmetry weights, clamping, consistency."""

import numpy as np
import pytest

from fenicsx_drape.forming.holder import BlankHolder
from fenicsx_drape.materials import FrictionLaw


def sheet(cell=10.0, half=120.0, quarter=True):
    c = np.arange(0.0 if quarter else -half, half + cell / 2, cell)
    X, Y = np.meshgrid(c, c, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])


def holder(force, axes, slip=0.05, friction=True):
    law = FrictionLaw(mu=0.3, holder_slip_mm=slip, holder_friction=friction)
    return BlankHolder(law, opening_radius_mm=85.0, force_N=force,
                       clamp_stiffness_N_per_mm=2.4e3, symmetry_axes=axes)


def test_quarter_and_full_share_the_force_alike():
    """A quarter with F/4 gives every node the full sheet's yield force F μ / n_s."""
    Xq, Xf = sheet(), sheet(quarter=False)
    hq, hf = holder(133.0 / 4, (0, 1)), holder(133.0, ())
    hq.bind(Xq, np.ones(len(Xq), bool), None)
    hf.bind(Xf, np.ones(len(Xf), bool), None)
    n_full = np.count_nonzero(np.hypot(Xf[:, 0], Xf[:, 1]) > 85.0)
    assert hf.n_s == n_full
    assert hq.n_s == pytest.approx(n_full / 4)
    interior = (Xq[:, 0] > 0) & (Xq[:, 1] > 0) & hq.under
    np.testing.assert_allclose(hq.yield_force_N[interior], 133.0 * 0.3 / n_full)
    edge = (Xq[:, 1] == 0) & hq.under
    np.testing.assert_allclose(hq.yield_force_N[edge], 0.5 * 133.0 * 0.3 / n_full)


def test_sliding_sheet_carries_the_holding_force_times_mu():
    """Every node under the holder drawn in by more than the stick slip: the friction forces
    sum (in magnitude) to F μ, each along the node's total displacement."""
    X = sheet(quarter=False)
    h = holder(133.0, ())
    h.bind(X, np.ones(len(X), bool), None)
    x = X * 0.99  # radial draw-in of 1 % (≥ 0.85 mm under the holder)
    f, _ = h.forces(x, 1.0, 1.0)
    under = h.under
    assert np.abs(f[~under]).max() == 0.0
    mag = np.linalg.norm(f[under, :2], axis=1)
    assert mag.sum() == pytest.approx(133.0 * 0.3)
    u = (x - X)[under, :2]
    cos = np.einsum("ij,ij->i", f[under, :2], u) / (mag * np.linalg.norm(u, axis=1))
    np.testing.assert_allclose(cos, -1.0)  # opposes the total displacement


def test_elastic_stick_then_perfectly_plastic_sliding():
    X = sheet(quarter=False)
    h = holder(133.0, (), slip=0.05)
    h.bind(X, np.ones(len(X), bool), None)
    node = np.argmax(np.hypot(X[:, 0], X[:, 1]))  # a corner
    f_y = h.yield_force_N[node]
    forces = []
    for u in (0.01, 0.02, 0.04, 0.1, 0.3):  # monotonic draw-in along the diagonal
        x = X.copy()
        x[node, :2] -= u / np.sqrt(2)
        f, _ = h.forces(x, 1.0, 1.0)
        h.commit()
        forces.append(np.linalg.norm(f[node, :2]))
    np.testing.assert_allclose(forces, [0.2 * f_y, 0.4 * f_y, 0.8 * f_y, f_y, f_y])
    # Unloading by 0.02 mm from 0.3 mm: elastic, the bar's force drops by k_f · 0.02.
    x = X.copy()
    x[node, :2] -= 0.28 / np.sqrt(2)
    f, _ = h.forces(x, 1.0, 1.0)
    assert np.linalg.norm(f[node, :2]) == pytest.approx(f_y * (1 - 0.02 / 0.05))


def test_clamping_and_jacobian_are_consistent():
    rng = np.random.default_rng(3)
    X = sheet()
    h = holder(33.25, (0, 1))
    h.bind(X, np.ones(len(X), bool), None)
    x = X + rng.uniform(-0.3, 0.3, X.shape) * [1, 1, 0.05]
    f, K = h.forces(x, 1.0, 1.0)
    np.testing.assert_allclose(f[h.under, 2], -2.4e3 * x[h.under, 2])
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-7
        dfk = -(h.forces(x + e, 1.0, 1.0)[0] - h.forces(x - e, 1.0, 1.0)[0]) / 2e-7
        np.testing.assert_allclose(K[:, :, k], dfk, atol=1e-6 * np.abs(K).max())


def test_n_s_follows_the_draw_in_and_revert_forgets():
    X = sheet(quarter=False)
    h = holder(133.0, ())
    h.bind(X, np.ones(len(X), bool), None)
    n0 = h.n_s
    x = X * 0.9  # a strong draw-in: nodes leave the holder
    h.forces(x, 1.0, 1.0)
    h.revert()
    h.commit()
    assert h.n_s == n0  # a reverted step changes nothing
    h.forces(x, 1.0, 1.0)
    h.commit()
    assert h.n_s == np.count_nonzero(np.hypot(x[:, 0], x[:, 1]) > 85.0) < n0
    assert h.yield_force_N[h.under].sum() == pytest.approx(133.0 * 0.3)


def test_without_holder_friction_the_plates_only_clamp():
    X = sheet(quarter=False)
    h = holder(133.0, (), friction=False)
    h.bind(X, np.ones(len(X), bool), None)
    f, _ = h.forces(X * 0.98, 1.0, 1.0)
    assert np.abs(f).max() == 0.0
