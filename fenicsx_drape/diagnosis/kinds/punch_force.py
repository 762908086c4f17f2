"""The press force against the travel (``punch_force``): a tool's force curve.

The kind :data:`PUNCH_FORCE` (a :class:`~fenicsx_drape.diagnosis.kinds.lab.LabKind`; what
every lab kind shares, the noise rule, runs and measures, is in
:mod:`~fenicsx_drape.diagnosis.kinds.lab`):

- **values**: the force (N) on the named tool (``force_tool``, default the punch);
- **simulation** (:func:`read`): the model's force on that tool along its motion
  (:func:`~fenicsx_drape.runs.tool_forces`), linear in the travel between
  the run's steps, at the measured travels (a run that stopped short holds its last force);
- **noise**: ``force_sd_N`` (column or key), else second differences along the travel
  (:func:`model_free_noise`);
- **regions**: thirds of the travel;
- **fit**: the friction coefficients (:func:`~fenicsx_drape.diagnosis.kinds.forming.
  fit_forming`, shared by every forming kind);
- **picture** (:func:`draw`): the measured and the models' force curves;
- **data check** (:func:`check`): a travel that exceeds the case's by more than
  :data:`TRAVEL_MARGIN` (and a load step), or is mostly ≤ 0 (a travel of the wrong sign: the
  lab's sign convention?), makes it suspect. It has no frame to register.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds.forming import case_of
from fenicsx_drape.diagnosis.kinds.lab import LabKind, Match, _along, add_region, matched
from fenicsx_drape.errors import DrapeInputError

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds.base import Comparison, Region
    from fenicsx_drape.forming.case import FormingCase
    from fenicsx_drape.forming.running.measure import SheetMesh
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model

#: A force curve's travel may pass the case's by this share (and a load step).
TRAVEL_MARGIN = 0.05


def measured(test: Test) -> np.ndarray:
    """The measured force (N), one per row."""
    return np.asarray(test.columns["force_N"], float)


def model_free_noise(test: Test) -> tuple[float, str]:
    """Second differences of the force along the travel."""
    c = test.columns
    return _along(c["travel_mm"], c["force_N"]), "second_differences"


def read(test: Test, grid: FormedGrid, mesh: SheetMesh,
         moved: Callable[[np.ndarray], np.ndarray], reach: float,
         model: Model | None = None) -> Match:
    """The model's force on the tool at the measured travels (from the ``model``'s run)."""
    from fenicsx_drape.runs import tool_forces

    c = test.columns
    if model is None:
        raise ValueError("a force curve is matched with the model's run")
    curves = tool_forces(case_of(test), model)
    tool = test.lab.force_tool
    if not curves:  # a run that stopped before its first step: the flat sheet, no force
        curves = {"travel_mm": np.zeros(1), tool: np.zeros(1)}
    if tool not in curves:
        known = ", ".join(k for k in curves if k not in ("time_s", "travel_mm"))
        raise DrapeInputError(f"test {test.id!r}: the model records no force of tool "
                              f"{tool!r} (its tools: {known})")
    # A run that stopped short is compared as far as it got (its last force held), as
    # the grid compares the sheet where it stopped.
    values = np.interp(c["travel_mm"], curves["travel_mm"], curves[tool])
    return Match(values, np.zeros(len(values), bool),
                 model_curve={"travel_mm": curves["travel_mm"], "force_N": curves[tool]})


def regions(test: Test) -> list[Region]:
    """The start, middle and end thirds of the travel."""
    out: list[Region] = []
    travel = test.columns["travel_mm"]
    cuts = np.linspace(travel.min(), travel.max(), 4)
    for a, b, where in zip(cuts[:-1], cuts[1:], ("start", "middle", "end")):
        add_region(out, "travel_mm", travel, (travel >= a - 1e-9) & (travel <= b + 1e-9),
                   f"{where} of the travel")
    return out


def abscissa(test: Test) -> tuple[str, np.ndarray]:
    """The travel (mm)."""
    return "travel_mm", test.columns["travel_mm"]


def draw(comparisons: Mapping[str, Comparison], test: Test) -> Any:
    """The measured force curve and each model's whole curve."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    c = test.columns
    ax.plot(c["travel_mm"], c["force_N"], ".", ms=3, color="0.3", label="measured")
    for i, (label, comparison) in enumerate(comparisons.items()):
        hit = matched(test, comparison)
        curve = hit.model_curve if hit is not None else {
            "travel_mm": c["travel_mm"], "force_N": comparison.simulated}
        ax.plot(curve["travel_mm"], curve["force_N"], "-", color=f"C{i}",
                label=f"model ({label})")
    ax.set_xlabel("travel (mm)")
    ax.set_ylabel(f"force of the {test.lab.force_tool} (N)")
    ax.legend(fontsize=7)
    return fig


def check(test: Test, case: FormingCase) -> tuple[bool, str] | None:
    """A force curve's travel against the case's: not beyond it, not of the wrong sign."""
    travel = test.columns.get("travel_mm")
    if travel is None or not len(travel):
        return None
    travel = np.asarray(travel, dtype=float)
    full = float(case.total_travel_mm)
    if np.mean(travel <= 0.0) > 0.5:
        return True, (f"the force curve's travel runs from {travel.min():.4g} to "
                      f"{travel.max():.4g} mm, mostly ≤ 0: a travel of the wrong sign (the "
                      f"case's tools travel {full:.4g} mm forward; the lab's sign convention?)")
    allowed = (1.0 + TRAVEL_MARGIN) * full + case.step_mm
    if travel.max() > allowed:
        return True, (f"the force curve's travel reaches {travel.max():.4g} mm, the case's "
                      f"tools travel {full:.4g} mm (allowed {allowed:.4g} mm): a curve of "
                      "another test, or travel in other units?")
    return None


PUNCH_FORCE = LabKind("punch_force", "N", measured, model_free_noise, read, regions, abscissa,
                      draw, check, registers=False)
