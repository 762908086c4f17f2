"""The punch's first point of contact sticks: a sheet not held by symmetry stays well-posed.

Without the stick, a half octagon (free in y) formed at 300 N on a lab's STL copy of the
tools (within 0.04 mm of the closed form) slid 9.5 mm over the punch and its nodes ended up to
11 mm from the closed-form run's; the stick brings them within the copy's own difference.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from fenicsx_drape.forming.terms.stick import ApexStick
from fenicsx_drape.forming.tools.shapes import Gap

ROOT = Path(__file__).resolve().parents[1]


class Plate:
    """A punch with a flat top at z = h(t) = t mm, moving up (normal +z)."""

    name = "punch"

    def gap(self, x, t):
        x = np.asarray(x, float).reshape(-1, 3)
        normal = np.tile([0.0, 0.0, 1.0], (len(x), 1))  # the sheet lies above it
        return Gap(x[:, 2] - t, normal, np.zeros((len(x), 3, 3)))

    def displacement(self, x, t0, t1):
        return np.tile([0.0, 0.0, t1 - t0], (len(np.atleast_2d(x)), 1))


def test_the_node_at_the_first_contact_sticks_in_the_tangent_plane():
    X = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.5], [0.0, 10.0, 0.2]])
    stick = ApexStick(Plate(), 100.0)
    stick.bind(X, np.ones(3, bool), None)
    f, K = stick.forces(X, -1.0, 1.0)  # the punch below the sheet: no contact
    stick.commit()
    assert stick.node is None and not f.any() and not K.any()
    x1 = X.copy()
    stick.forces(x1, 0.1, 1.0)  # node 0 is 0.1 mm into the punch, the only one
    stick.commit()
    assert stick.node == 0
    x2 = x1 + np.array([[0.3, -0.2, 0.7], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
    f, K = stick.forces(x2, 0.5, 1.0)  # the punch rose 0.4 mm: only the in-plane part acts
    np.testing.assert_allclose(f[0], [-30.0, 20.0, 0.0])
    assert not f[1:].any()
    for j in range(3):  # K = −∂f/∂x, by central differences
        e = np.zeros((3, 3))
        e[0, j] = 1e-6
        df = (stick.forces(x2 + e, 0.5, 1.0)[0] - stick.forces(x2 - e, 0.5, 1.0)[0]) / 2e-6
        np.testing.assert_allclose(-df[0], K[0][:, j], atol=1e-6)


def test_a_stl_copy_of_the_tools_forms_as_the_closed_form_on_a_half_model(tmp_path):
    """At 300 N the holder's bars yield: without the stick the sheet slid 9.5 mm."""
    sys.path.insert(0, str(ROOT / "demos"))
    import make_lab_bundle

    from fenicsx_drape import runs
    from fenicsx_drape.forming.case.format import load_case, with_overrides
    from fenicsx_drape.model import default_model

    closed = with_overrides(load_case(make_lab_bundle.CASE), holder_force_N=300.0)
    copy = with_overrides(load_case(make_lab_bundle.stl_case(tmp_path)), holder_force_N=300.0)
    assert closed.planes == copy.planes == ("x",)
    a, b = runs.form_many([(closed, default_model()), (copy, default_model())])
    xa, xb = (np.asarray(g.x).reshape(-1, 3) for g in (a, b))
    d = np.linalg.norm(xa - xb, axis=1)
    d = d[np.isfinite(d)]
    assert d.max() < 0.5 and np.sqrt(np.mean(d**2)) < 0.3  # 0.24 and 0.17 mm measured
    X = np.asarray(a.X).reshape(-1, 3)
    centre = np.nanargmin(np.linalg.norm(np.nan_to_num(X, nan=1e9), axis=1))
    assert abs(xb[centre, 1]) == pytest.approx(0.0, abs=0.05)
