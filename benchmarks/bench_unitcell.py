"""Time the unit-cell solutions: one 300-row test, and many parameter sets in one call.

    python3 benchmarks/bench_unitcell.py

Prints CPU milliseconds per test (best of 5) for a tensile and a bias-extension test of 300
rows with Table 2, with 1 and with k parameter sets evaluated together (the fitting code's
finite-difference Jacobians), and the cost of a fit-sized batch (tensile + three bias rates)
one test at a time and with the bias tests side by side (``unitcell.curves``).
"""

import time

import numpy as np

from fenicsx_drape import unitcell
from fenicsx_drape.model import default_model

ROWS = 300


def best_ms(call, repeat=5):
    times = []
    for _ in range(repeat):
        start = time.process_time()
        call()
        times.append(time.process_time() - start)
    return 1e3 * min(times)


def main():
    model = default_model()
    u_t = np.linspace(0.0, 0.3, ROWS)
    u_b = np.linspace(0.0, 52.9, ROWS)
    print(f"unit-cell solutions, {ROWS} rows, CPU ms per test (best of 5)")
    print(f"{'parameter sets':>15} {'tensile':>9} {'bias':>9} {'bias per set':>13}")
    for k in (1, 13, 100):
        m = model if k == 1 else model.with_parameters(eta_o=np.linspace(1.0, 2.0, k),
                                                       E_o=np.linspace(3e3, 4e3, k))
        ten = best_ms(lambda m=m: unitcell.tensile(m, u_t * 30.0, u_t, gauge_length_mm=100.0))
        bias = best_ms(lambda m=m: unitcell.bias_extension(m, u_b * 1.5, u_b, length_mm=210.0,
                                                           width_mm=70.0))
        print(f"{k:>15} {ten:9.1f} {bias:9.1f} {bias / k:13.2f}")

    def batch():
        unitcell.tensile(model, u_t * 30.0, u_t, gauge_length_mm=100.0)
        for speed in (10.0, 40.0, 160.0):
            unitcell.bias_extension(model, u_b / (speed / 60.0), u_b, length_mm=210.0,
                                    width_mm=70.0)

    def side_by_side():
        unitcell.tensile(model, u_t * 30.0, u_t, gauge_length_mm=100.0)
        unitcell.curves(model, "bias_extension", [
            {"time_s": u_b / (speed / 60.0), "displacement_mm": u_b, "length_mm": 210.0,
             "width_mm": 70.0} for speed in (10.0, 40.0, 160.0)])

    print(f"tensile + three bias rates: {best_ms(batch, 3):.0f} ms one by one, "
          f"{best_ms(side_by_side, 3):.0f} ms side by side")


if __name__ == "__main__":
    main()
