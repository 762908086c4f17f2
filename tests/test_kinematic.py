"""The kinematic pin-jointed-net drape (Fig. 11's PjN model)."""

import numpy as np
import pytest

from fenicsx_drape.forming.kinematic import kinematic_drape
from fenicsx_drape.forming.tools import HemisphereTools

TOOLS = HemisphereTools()


@pytest.fixture(scope="module")
def net():
    return kinematic_drape(TOOLS, 10.0)


def test_tows_are_inextensible_and_on_the_part(net):
    for axis in (0, 1):
        length = np.linalg.norm(np.diff(net.x, axis=axis), axis=-1)
        np.testing.assert_allclose(length, 10.0, atol=1e-8)
    φ = TOOLS.formed_part().gap(net.x.reshape(-1, 3), 0.0).phi
    assert np.abs(φ).max() < 1e-8
    warp, weft = net.tow_strains()
    assert min(warp.min(), weft.min()) > -1e-9  # a pin-jointed net never wrinkles


def test_symmetry_and_zero_shear_at_the_apex(net):
    γ = net.shear_deg()
    np.testing.assert_allclose(γ, -γ[::-1, :], atol=1e-9)  # mirror x -> -x flips the shear
    np.testing.assert_allclose(γ, γ.T, atol=1e-9)  # mirror x <-> y keeps it
    c = γ.shape[0] // 2
    assert np.abs(γ[c - 1:c + 1, c - 1:c + 1]).max() < 1.0  # the four apex cells
    n = net.x.shape[0] // 2
    np.testing.assert_allclose(net.x[n, n], [0, 0, TOOLS.travel_mm], atol=1e-12)


def test_maximum_shear_is_near_the_papers_kinematic_61_degrees(net):
    """The paper's PjN reaches 61° (Fig. 11a); ours 62.5° on the same 10 mm net. The
    paper's exact net (start, chord or geodesic spacing) is not given: 3° tolerance."""
    _, γ = net.diagonal_path()
    assert abs(γ).max() == pytest.approx(61.0, abs=3.0)
    k = np.argmax(np.abs(γ))
    assert 0 < k < len(γ) - 1  # low at the corner and the apex, maximum in between
    assert abs(γ[0]) < 1.0 and abs(γ[-1]) < 10.0


def test_refinement_converges():
    m = [np.abs(kinematic_drape(TOOLS, d).shear_deg()).max() for d in (10.0, 5.0, 2.5)]
    assert abs(m[2] - m[1]) < abs(m[1] - m[0]) + 0.5
    assert abs(m[2] - m[1]) < 1.0
