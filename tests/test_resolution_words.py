"""The resolution check's advice: which net would decide, its cost, what it would leave.

The error estimate is first order (e falls as Δ, ``diagnosis.resolution``): at 20 mm cells an
error of 1.6° against a noise of 1° is below the noise on 10 mm cells (one halving, four
times the nodes); an error of 12.1 mm against 0.3 mm would need 40× finer cells, past the
four halvings suggested at most, and 1.25 mm cells would still leave 12.1 / 16 = 0.76 mm.
"""

from fenicsx_drape.diagnosis.resolution import MAX_HALVINGS, finer_net, sentence, suggested_cell


def entry(measurement, error, noise, unit):
    return {"measurement": measurement, "cell_mm": 20.0, "residual": error, "noise": noise,
            "unit": unit, "discretisation_error": error, "explains": True,
            "suggested_cell_mm": suggested_cell(20.0, error, noise)}


def test_a_net_that_falls_below_the_noise_is_named_with_its_cost():
    shear = entry("part/shear_points", 1.6, 1.0, "deg")
    assert shear["suggested_cell_mm"] == 10.0
    assert finer_net([shear]) == ("a 10 mm net would decide (--confirm-cell-mm 10, about 4 "
                                  "times the nodes)")
    assert sentence([shear]).endswith("A 10 mm net would decide (--confirm-cell-mm 10, about "
                                      "4 times the nodes). ")


def test_a_net_past_the_finest_suggested_says_what_it_would_still_leave():
    outline = entry("part/outline", 12.1, 0.3, "mm")
    shear = entry("part/shear_points", 1.6, 1.0, "deg")
    assert outline["suggested_cell_mm"] == 20.0 / 2**MAX_HALVINGS == 1.25
    words = finer_net([outline, shear])
    assert words == ("a finer net would decide: by the net's first-order estimate, even 1.25 "
                     "mm cells (--confirm-cell-mm 1.25, about 256 times the nodes) would still "
                     "leave 0.76 mm on part/outline (noise 0.3 mm)")
    assert "would decide (" not in sentence([outline, shear])
