"""Pictures of a formed sheet, as the paper's Figs. 10-11 (Matplotlib, written atomically).

Any blank: a symmetric model is mirrored to the whole part (:meth:`FormedGrid.full`), and the
absent nodes of a clipped net (NaN) are left out with the cells and bars they belong to.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from fenicsx_drape.forming.running.post import FormedGrid
from fenicsx_drape.provenance import save_figure


def _cells(x: np.ndarray) -> np.ndarray:
    """The corners of every cell of a grid (n_i, n_j, 3) as polygons (n_cells, 4, 3).

    Cells with an absent (NaN) corner, outside a clipped net, are NaN.
    """
    return np.stack([x[:-1, :-1], x[1:, :-1], x[1:, 1:], x[:-1, 1:]], axis=2).reshape(-1, 4, 3)


def _present(polygons: np.ndarray) -> np.ndarray:
    """Mask of the polygons (or bars) without an absent corner."""
    return np.isfinite(polygons).all(axis=(1, 2))


def _limits(x: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """The ranges of x and y (mm) of the present nodes, widened to a square about their centre."""
    lo, hi = np.nanmin(x[..., :2], axis=(0, 1)), np.nanmax(x[..., :2], axis=(0, 1))
    c, half = 0.5 * (lo + hi), 0.5 * max(float(np.max(hi - lo)), 1.0) * 1.02
    return (c[0] - half, c[0] + half), (c[1] - half, c[1] + half)


def _axis_labels(grid: FormedGrid) -> tuple[str, str]:
    """Labels of the x and y axes: the tows lie along them unless the ply is turned."""
    R = grid.tow_frame()[2]
    if np.allclose(R, np.eye(2), atol=1e-12):
        return "x (warp), mm", "y (weft), mm"
    return f"x, mm (warp at {np.degrees(np.arctan2(R[1, 0], R[0, 0])):.3g}°)", "y, mm"


def plot_shear(grid: FormedGrid, path: str | os.PathLike, title: str = "") -> Path:
    """The formed sheet coloured by the cells' shear angle: a 3D view and a top view."""
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    full = grid.full()
    cells = _cells(full.x)
    γ = np.abs(full.shear_deg()).ravel()[_present(cells)]
    cells = cells[_present(cells)]
    norm = plt.Normalize(0.0, max(γ.max(), 1.0))
    cmap = plt.get_cmap("viridis")
    fig = plt.figure(figsize=(11, 4.8))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ax.add_collection3d(Poly3DCollection(cells, facecolors=cmap(norm(γ)), edgecolors="k",
                                         linewidths=0.15))
    xlim, ylim = _limits(full.x)
    bottom = min(np.nanmin(full.x[..., 2]), 0.0)
    top = max(np.nanmax(full.x[..., 2]), bottom + 1.0)
    ax.set(xlim=xlim, ylim=ylim, zlim=(bottom, top),
           zticks=np.linspace(bottom, top, 3).round())
    xlabel, ylabel = _axis_labels(full)
    ax.set_xlabel(xlabel, labelpad=8)
    ax.set_ylabel(ylabel, labelpad=8)
    ax.set_box_aspect((1, 1, max((top - bottom) / (xlim[1] - xlim[0]), 0.15)))
    ax.view_init(elev=28, azim=-60)
    ax2 = fig.add_subplot(1, 2, 2)
    ax2.add_collection(PolyCollection(cells[:, :, :2], facecolors=cmap(norm(γ)),
                                      edgecolors="k", linewidths=0.15))
    ax2.set(xlim=xlim, ylim=ylim, aspect="equal", xlabel=xlabel, ylabel=ylabel,
            title="top view")
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax2,
                 label="shear angle (deg)")
    fig.suptitle(title or f"shear angle, max {γ.max():.1f}°")
    fig.subplots_adjust(wspace=0.3)  # the top view's y label clear of the 3D view's z ticks
    return save_figure(fig, path)


def plot_wrinkling(grid: FormedGrid, path: str | os.PathLike, title: str = "") -> Path:
    """Top view of the formed tows, the buckled ones coloured by their wrinkling strain."""
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PolyCollection

    full = grid.full()
    warp, weft = full.tow_strains()
    x = full.x
    bars = np.concatenate([np.stack([x[:-1, :, :2], x[1:, :, :2]], axis=2).reshape(-1, 2, 2),
                           np.stack([x[:, :-1, :2], x[:, 1:, :2]], axis=2).reshape(-1, 2, 2)])
    ε = np.minimum(np.concatenate([warp.ravel(), weft.ravel()]), 0.0)
    bars, ε = bars[_present(bars)], ε[_present(bars)]
    cells = _cells(x)[:, :, :2]
    low = min(ε.min(), -1e-4)
    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    ax.add_collection(PolyCollection(cells[_present(cells)], facecolors="0.95",
                                     edgecolors="none"))
    ax.add_collection(LineCollection(bars[ε >= 0], colors="0.7", linewidths=0.4))
    lines = LineCollection(bars[ε < 0], array=ε[ε < 0], cmap="inferno",
                           norm=plt.Normalize(low, 0.0), linewidths=1.6)
    ax.add_collection(lines)
    xlim, ylim = _limits(x)
    xlabel, ylabel = _axis_labels(full)
    ax.set(xlim=xlim, ylim=ylim, aspect="equal", xlabel=xlabel, ylabel=ylabel)
    fig.colorbar(lines, ax=ax, label="Green-Lagrange wrinkling strain")
    ax.set_title(title or f"wrinkled tows (min {ε.min():.3f}, total "
                          f"{100 * grid.total_wrinkling_strain():.2f} %)")
    return save_figure(fig, path)


def plot_paths(grids: Mapping[str, FormedGrid], path: str | os.PathLike,
               title: str = "") -> Path:
    """Shear along the diagonal path and wrinkling along the normal path (Fig. 11).

    ``title`` says which run it is (the paper's conditions only when the run had them).
    """
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    for label, grid in grids.items():
        s, γ = grid.diagonal_path()
        a.plot(s, np.abs(γ), "o-", ms=3, label=label)
        s, w = grid.normal_path()
        b.plot(s, w, "o-", ms=3, label=label)
    a.set(xlabel="distance from the apex on the flat sheet, diagonal path (mm)",
          ylabel="shear angle (deg)", title="(a) shear, corner to apex")
    b.set(xlabel="distance from the apex on the flat sheet, normal path (mm)",
          ylabel="Green-Lagrange wrinkling strain", title="(b) wrinkling, mid-side to apex")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend()
    if title:
        fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def plot_tool_forces(curves: Mapping[str, np.ndarray], path: str | os.PathLike,
                     title: str = "", measured: Mapping[str, np.ndarray] | None = None,
                     marked: Mapping[str, np.ndarray] | None = None) -> Path:
    """Each tool's force along its motion against the travel (N; the press's force curve).

    Args:
        curves: ``travel_mm`` and one array per tool (the run's ``tool_forces``).
        path: The PNG to write.
        title: The picture's title.
        measured: A measured curve beside them: ``travel_mm``, ``force_N`` and ``label``.
        marked: Steps (indices) of a tool whose force stands out of its neighbours', circled.
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    travel = np.asarray(curves["travel_mm"])
    marked = marked or {}
    for name, values in curves.items():
        if name not in ("time_s", "travel_mm"):
            ax.plot(travel, values, "-", label=f"model: {name}")
            if name in marked:
                i = np.asarray(marked[name])
                ax.plot(travel[i], np.asarray(values)[i], "o", mfc="none", mec="red", ms=8,
                        label=f"{name}: step out of its neighbours")
    if measured is not None:
        ax.plot(measured["travel_mm"], measured["force_N"], ".", ms=3, color="0.3",
                label=str(measured.get("label", "measured")))
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.set_xlabel("travel (mm)")
    ax.set_ylabel("force along the tool's motion (N)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def plot_interply(interfaces: list[dict], path: str | os.PathLike, title: str = "") -> Path:
    """Top views of each interface of a stack: where the plies slid, and the pressure.

    ``interfaces`` holds, per interface, ``name`` and, at its pairs (the modelled part),
    ``xy`` (n, 2) formed positions (mm), ``sliding_mm`` and ``pressure_MPa``.
    """
    import matplotlib.pyplot as plt

    n = len(interfaces)
    fig, axes = plt.subplots(2, n, figsize=(4.6 * n, 8.4), squeeze=False)
    for k, face in enumerate(interfaces):
        for row, (key, label, cmap) in enumerate((("sliding_mm", "sliding slip, mm", "magma"),
                                                  ("pressure_MPa", "pressure, MPa", "viridis"))):
            ax = axes[row, k]
            v = np.asarray(face[key])
            dots = ax.scatter(face["xy"][:, 0], face["xy"][:, 1], c=v, s=14, cmap=cmap,
                              vmin=0.0, vmax=max(float(v.max(initial=0.0)), 1e-9))
            ax.set(aspect="equal", xlabel="x, mm", ylabel="y, mm",
                   title=f"{face['name']}: {label} (max {v.max(initial=0.0):.3g})")
            fig.colorbar(dots, ax=ax, shrink=0.8)
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)
