"""A scan of the formed ply (``surface``): an STL, PLY or OBJ surface, or a CSV point cloud.

The kind :data:`SURFACE` (a :class:`~fenicsx_drape.diagnosis.kinds.lab.LabKind`; what every
lab kind shares, the noise rule, runs, registration and measures, is in
:mod:`~fenicsx_drape.diagnosis.kinds.lab`):

- **values**: the signed distance (mm, along the sheet's normal) from each scanned point to
  the formed sheet: the value of a point is the model's offset from it, measured 0
  (:func:`read`); the share of the formed sheet the scan covers is reported
  (:func:`~fenicsx_drape.forming.running.measure.coverage`);
- **noise**: ``position_sd_mm`` (column or key), else the residual of a local plane through
  each point's :data:`PLANE_NEIGHBOURS` neighbours (:func:`model_free_noise`);
- **regions**: the regions of the part at the scanned points;
- **fit**: the friction coefficients (:func:`~fenicsx_drape.diagnosis.kinds.forming.
  fit_forming`, shared by every forming kind);
- **picture** (:func:`draw`): the scan's deviation from each model's sheet, in plan;
- **data check**: its positions against the case (:func:`~fenicsx_drape.diagnosis.kinds.
  checks.check_positions`), or only its size when registered (``register = true``: a scan's
  frame is fitted to the model's sheet, :func:`~fenicsx_drape.diagnosis.kinds.lab.register`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from fenicsx_drape.diagnosis.kinds import checks
from fenicsx_drape.diagnosis.kinds.lab import (
    LabKind,
    Match,
    formed_abscissa,
    part_or_all,
    points,
)
from fenicsx_drape.errors import DrapeInputError

if TYPE_CHECKING:
    from fenicsx_drape.diagnosis.kinds.base import Comparison, Region
    from fenicsx_drape.forming.running.measure import SheetMesh
    from fenicsx_drape.forming.running.post import FormedGrid
    from fenicsx_drape.measurements.bundle import Test
    from fenicsx_drape.model import Model

PLANE_NEIGHBOURS = 12  # neighbours of a scanned point in its local plane (noise estimate)


def measured(test: Test) -> np.ndarray:
    """Zero per point: a point's value is the model's signed distance from it."""
    return np.zeros(test.n_rows)


def _local_plane_noise(P: np.ndarray) -> float:
    """σ of a point cloud from the residual of each point to its neighbours' plane."""
    from scipy.spatial import cKDTree

    k = min(PLANE_NEIGHBOURS, len(P))
    if k < 5:
        raise DrapeInputError("too few scanned points to estimate their noise (give "
                              "position_sd_mm)")
    _, idx = cKDTree(P).query(P, k=k)
    Q = P[idx]
    centred = Q - Q.mean(axis=1, keepdims=True)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))
    normal = vectors[:, :, 0]
    r = np.einsum("ni,ni->n", centred[:, 0], normal)
    # The plane through k points (the point among them) leaves it (k - 3)/k of its variance.
    return float(np.median(np.abs(r)) / 0.6745 * math.sqrt(k / (k - 3)))


def model_free_noise(test: Test) -> tuple[float, str]:
    """The residual of a local plane through each point's neighbours."""
    return _local_plane_noise(points(test)), "local_plane_fit"


def read(test: Test, grid: FormedGrid, mesh: SheetMesh,
         moved: Callable[[np.ndarray], np.ndarray], reach: float,
         model: Model | None = None) -> Match:
    """The model sheet's signed distance from each scanned point, and the scan's coverage."""
    from fenicsx_drape.forming.running import measure

    P = moved(points(test))
    near = measure.closest_points(mesh, P)
    unmatched = near.distance > reach
    values = np.where(unmatched, 0.0, -near.signed)
    coverage = measure.coverage(mesh, P[~unmatched]) if (~unmatched).any() else 0.0
    return Match(values, unmatched, coverage=coverage)


def regions(test: Test) -> list[Region]:
    """The regions of the part at the scanned points."""
    return part_or_all(test, [], lambda: SURFACE.noise(test)[0])


def draw(comparisons: Mapping[str, Comparison], test: Test) -> Any:
    """The scan's deviation from each model's sheet, in plan, one panel a model."""
    import matplotlib.pyplot as plt

    P = points(test)
    n = len(comparisons)
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n, 4.4), squeeze=False)
    top = max(float(np.abs(c.residual).max()) for c in comparisons.values()) or 1.0
    for ax, (label, c) in zip(axes[0], comparisons.items()):
        art = ax.scatter(P[:, 0], P[:, 1], c=c.residual, s=2, cmap="coolwarm", vmin=-top,
                         vmax=top)
        ax.set_aspect("equal")
        ax.set_title(f"{label}: scan − model sheet (mm)", fontsize=8)
        ax.set_xlabel("x (mm)")
        fig.colorbar(art, ax=ax, shrink=0.8)
    axes[0, 0].set_ylabel("y (mm)")
    return fig


def registration_noise(test: Test) -> float:
    """A scan is registered against its own noise."""
    return SURFACE.noise(test)[0]


SURFACE = LabKind("surface", "mm", measured, model_free_noise, read, regions, formed_abscissa,
                  draw, checks.check_registered_or_positions,
                  registration_noise=registration_noise, lists_points=True)
