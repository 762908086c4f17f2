"""Resolution before physics: the model's own discretisation error on each measurement.

A model on a coarse net differs from the same model on a fine one, and a lab's measurement is
not made on the model's net (spec version 4, "resolution before physics"). Before an effect
is named, :func:`check_resolution` forms the fitted model again on a net of half the cell
and estimates, per forming measurement, the discretisation error of the net it ran on:

    e_Δ ≈ 2 · RMS(v_Δ − v_Δ/2)

(Richardson's estimate for a first-order scheme: the shear of the truss is one angle per
cell, its positions bilinear in the cells, so the error falls at least as Δ).

**One rule for what the net can tell** (:func:`within_net`): a residual R (noise σ) is
within the net's own error when, that error weighed as noise, the measurement is at the
noise floor: R ≤ ``adequate`` · √(σ² + e_Δ²) — the net's error comparable to the residual or
larger. Its ``explains`` is then true and no physics is concluded from that measurement,
for or against: no effect is named on it, and no missing physics is declared from it. The
same rule judges what a candidate leaves (``resolution_after``). Whether the residual *is*
the net's error is a further question, which only the finer net answers: it is so when that
net comes nearer the data and leaves no more than its own remaining error, e_Δ/2
(:func:`shown`); a residual the finer net does not shrink (data made on this very net, or a
lab's own method at the net's scale) is one the net cannot judge, not the net's error. The
net that would decide is the cell ``Δ / 2^k`` at which the error, falling as Δ, drops below
the noise (``suggested_cell_mm``): ``drape diagnose --confirm-cell-mm`` takes it.

Only measurements the model misses (normalised error above ``adequate``) are checked: the
others have nothing to explain.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds import is_formed, kind_of
from fenicsx_drape.diagnosis.kinds.forming import forming_case_of
from fenicsx_drape.errors import DrapeInputError, SolverError
from fenicsx_drape.runs import cell_override, resolution

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds import Comparison
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model

ORDER = 1  # the net's order of convergence assumed by the Richardson estimate
REFINE = 2  # the check's net: the cell divided by this
# Cells the suggestion goes down to at most (a net of 2^4 times fewer mm per cell).
MAX_HALVINGS = 4


def cell_of(test: Test) -> float:
    """The unit cell (mm) the test's runs are formed on."""
    return float(cell_override() or forming_case_of(test).blank.cell_mm)


def check_resolution(tests: Sequence[Test], model: Model, comparisons: Sequence[Comparison],
                     adequate: float, progress: Callable[[str], None] | None = None
                     ) -> list[dict[str, Any]]:
    """The spec's ``resolution`` entries of every forming measurement the baseline misses.

    Args:
        tests: The compared tests (forming measurements are checked, coupons are not).
        model: The fitted baseline.
        comparisons: The baseline's comparisons with ``tests`` (same order).
        adequate: A measurement within this many times its noise is not checked.
        progress: Called with a line of text per net.

    Returns:
        One entry per checked measurement: ``measurement, cell_mm, discretisation_error,
        residual, fine_cell_mm, fine_residual, noise, unit, explains, suggested_cell_mm``
        (and ``reason`` when the finer net could not be formed).
    """
    say = progress or (lambda line: None)
    checked = [(t, c) for t, c in zip(tests, comparisons)
               if is_formed(t) and c.normalised > adequate]
    by_cell: dict[float, list] = {}
    for t, c in checked:
        by_cell.setdefault(cell_of(t), []).append((t, c))
    out = []
    for cell, pairs in sorted(by_cell.items()):
        fine = cell / REFINE
        say(f"resolution: the baseline again on {fine:g} mm cells (it ran on {cell:g} mm) "
            f"for {len(pairs)} measurement(s)")
        for t, c in pairs:
            entry = {"measurement": t.id, "cell_mm": cell, "residual": c.rmse,
                     "noise": c.noise, "unit": c.unit}
            try:
                with resolution(fine):
                    values = np.asarray(kind_of(t).simulate(t, model), float)
            except (SolverError, DrapeInputError) as err:
                out.append({**entry, "discretisation_error": None, "explains": False,
                            "suggested_cell_mm": None,
                            "reason": f"the {fine:g} mm net could not be formed: {err}"})
                continue
            coarse, measured = np.asarray(c.simulated, float), np.asarray(c.measured, float)
            left = float(np.sqrt(np.nanmean((values - coarse) ** 2)))  # e_Δ/2
            error = REFINE**ORDER / (REFINE**ORDER - 1) * left  # e_Δ
            fine_residual = float(np.sqrt(np.nanmean((values - measured) ** 2)))
            out.append({**entry, "discretisation_error": error, "fine_cell_mm": fine,
                        "fine_residual": fine_residual,
                        "explains": within_net(c.rmse, c.noise, error, adequate),
                        "suggested_cell_mm": suggested_cell(cell, error, c.noise)})
    return out


def within_net(residual: float, noise: float, error: float | None, adequate: float) -> bool:
    """Whether a residual is within the net's own error (module doc): the net cannot judge it.

    ``residual <= adequate · √(noise² + error²)``: with the net's error ``error`` weighed as
    noise, the measurement is at the noise floor. False when the error is unknown.
    """
    if error is None or not math.isfinite(error):
        return False
    return bool(residual <= adequate * math.hypot(noise, error))


def shown(entry: dict[str, Any]) -> bool:
    """Whether the finer net shows the residual to be the net's own error (module doc).

    It comes nearer the data, and what it leaves beyond the noise is within the error it
    still has (e_Δ/2 of a first-order net halved).
    """
    error, fine = entry.get("discretisation_error"), entry.get("fine_residual")
    if error is None or fine is None:
        return False
    beyond = math.sqrt(max(0.0, fine**2 - entry["noise"] ** 2))
    return bool(fine < entry["residual"] and beyond <= error / REFINE**ORDER)


def suggested_cell(cell_mm: float, error: float, noise: float) -> float:
    """The cell at which a discretisation error falls below the noise.

    The cell ``Δ / 2^k`` at which ``error`` at Δ, falling as Δ^ORDER, is below the
    noise (at most :data:`MAX_HALVINGS` halvings; Δ itself when already below).
    """
    k = 0
    while error / 2 ** (ORDER * k) > noise and k < MAX_HALVINGS:
        k += 1
    return cell_mm / 2**k


def explained(entries: Sequence[dict[str, Any]]) -> set[str]:
    """The ids of the measurements whose residual the net explains."""
    return {e["measurement"] for e in entries if e["explains"]}


def sentence(entries: Sequence[dict[str, Any]]) -> str:
    """The conclusion's words on the measurements the net cannot judge ("" when none)."""
    hits = [e for e in entries if e["explains"]]
    if not hits:
        return ""
    cells = sorted({e["cell_mm"] for e in hits})
    net = " and ".join(f"{c:g}" for c in cells)
    advice = finer_net(hits)
    return (f"Resolution: the {net} mm net cannot judge {', '.join(map(judged_text, hits))}: "
            f"no physics is concluded from {'it' if len(hits) == 1 else 'them'}. "
            f"{advice[0].upper()}{advice[1:]}. ")


def judged_text(e: dict[str, Any]) -> str:
    """One measurement the net cannot judge: its residual, the net's error, the finer net."""
    u = e["unit"]
    fine = e.get("fine_residual")
    if shown(e):
        tail = (f"; the {e['fine_cell_mm']:g} mm net comes nearer, {fine:.3g} {u}: the "
                "net's own error")
    elif fine is not None and fine >= e["residual"]:
        tail = (f"; the {e['fine_cell_mm']:g} mm net is farther from the data, {fine:.3g} "
                f"{u}: not shown to be the net's error")
    else:
        tail = ""
    return (f"{e['measurement']} (residual {e['residual']:.3g} {u}, noise {e['noise']:.2g} "
            f"{u}; the net's own error there {e['discretisation_error']:.3g} {u}{tail})")


def finer_net(entries: Sequence[dict[str, Any]]) -> str:
    """Which net would decide, with its cost and how to ask for it, and what it would leave.

    The finest ``suggested_cell_mm`` of the entries and its nodes against the net they ran
    on; ``--confirm-cell-mm`` takes it. When even that cell (:data:`MAX_HALVINGS` halvings)
    leaves an estimated error above the noise, the words say so, with the measurement,
    rather than promise it decides.
    """
    cell = min(e["suggested_cell_mm"] for e in entries)
    nodes = (max(e["cell_mm"] for e in entries) / cell) ** 2
    cost = f"about {nodes:.0f} times the nodes" if nodes >= 1.5 else "the same net"
    left = [(e, e["discretisation_error"] * (cell / e["cell_mm"]) ** ORDER) for e in entries]
    left = [(e, v) for e, v in left if v > e["noise"]]
    ask = f"--confirm-cell-mm {cell:g}, {cost}"
    if not left:
        return f"a {cell:g} mm net would decide ({ask})"
    still = ", ".join(f"{v:.2g} {e['unit']} on {e['measurement']} (noise {e['noise']:.2g} "
                      f"{e['unit']})" for e, v in left)
    return (f"a finer net would decide: by the net's first-order estimate, even {cell:g} mm "
            f"cells ({ask}) would still leave {still}")
