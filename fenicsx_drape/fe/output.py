"""Results of a truss solve: shear per unit cell, wrinkling per tow, totals, files.

Definitions (section 4 of the paper):

- *shear angle* of a unit cell: 90° minus the angle between its current warp and weft
  directions, each the mean of the cell's two tow sides (positive when the angle closes);
- *wrinkling strain* of a tow bar: its Green-Lagrange strain where negative (a buckled tow,
  eq. 4), zero otherwise;
- *total wrinkling strain*: "the sum of wrinkling deformation over all elements with negative
  strains divided by the total length of tow elements" (section 4.2, Fig. 12). The wrinkling
  deformation of a bar is taken as its wrinkling strain times its reference length, so the
  total is the length-weighted mean wrinkling strain of all tows, ``Σ w L ε⁻ / Σ w L``, with
  ``w`` the share of a strip of tows a bar stands for (½ on the sheet and symmetry edges).
  The paper quotes magnitudes (0.55 %, minimum 0.21); here wrinkling strains are negative.

Node positions are gathered from all ranks into the structured grid of the sheet, so every
rank holds the same :class:`Results` and the numbers do not depend on the partition.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from mpi4py import MPI

import dolfinx
import numpy as np

from fenicsx_drape.fe.grid import DIAGONAL_MINUS, DIAGONAL_PLUS, WARP, WEFT, TrussGrid
from fenicsx_drape.fe.plies import ply_of, sheet_grids
from fenicsx_drape.provenance import atomic_write_text


def gather_nodes(problem) -> tuple[np.ndarray, np.ndarray]:
    """Reference and current positions of all nodes, shaped (nx + 1, ny + 1, 3), on all ranks.

    A sheet without one structured grid (a stack of plies) gives them shaped (n, 3).
    """
    grid: TrussGrid = problem.sheet.grid
    n = problem.num_owned
    X = problem.X[:n]
    x = problem.positions()[:n]
    if grid is None:  # no single grid (a stack of plies): all nodes, (n, 3), rank by rank
        parts = problem.comm.allgather((X, x))
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    ij = np.rint(grid.grid_coordinates(X)).astype(int)
    parts = problem.comm.allgather((ij, X, x))
    Xg = np.full((grid.nx + 1, grid.ny + 1, 3), np.nan)
    xg = np.full_like(Xg, np.nan)
    for ij_r, X_r, x_r in parts:
        Xg[ij_r[:, 0], ij_r[:, 1]] = X_r
        xg[ij_r[:, 0], ij_r[:, 1]] = x_r
    return Xg, xg


def _strain(a: np.ndarray, b: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Green-Lagrange strain of bars from A-B (reference) to a-b (current)."""
    return 0.5 * (np.sum((b - a) ** 2, axis=-1) / np.sum((B - A) ** 2, axis=-1) - 1.0)


@dataclasses.dataclass
class Results:
    """The state of the sheet at one time, the same on every rank."""

    time_s: float
    grid: TrussGrid
    X: np.ndarray  # reference node positions (nx + 1, ny + 1, 3), mm
    x: np.ndarray  # current node positions (nx + 1, ny + 1, 3), mm
    shear_deg: np.ndarray  # shear angle per unit cell (nx, ny), degrees
    warp_strain: np.ndarray  # Green-Lagrange strain of warp bars (nx, ny + 1)
    weft_strain: np.ndarray  # Green-Lagrange strain of weft bars (nx + 1, ny)
    edge_tow_factor: float  # share of a strip of tows an edge bar stands for

    @property
    def displacement(self) -> np.ndarray:
        """Node displacements (nx + 1, ny + 1, 3), mm."""
        return self.x - self.X

    @property
    def warp_wrinkling(self) -> np.ndarray:
        """Wrinkling strain of warp bars (≤ 0)."""
        return np.minimum(self.warp_strain, 0.0)

    @property
    def weft_wrinkling(self) -> np.ndarray:
        """Wrinkling strain of weft bars (≤ 0)."""
        return np.minimum(self.weft_strain, 0.0)

    @property
    def max_shear_deg(self) -> float:
        """Largest shear angle magnitude over the unit cells (degrees)."""
        return float(np.abs(self.shear_deg).max())

    @property
    def min_wrinkling_strain(self) -> float:
        """Most negative wrinkling strain of any tow (0 when no tow is compressed)."""
        return float(min(self.warp_wrinkling.min(), self.weft_wrinkling.min()))

    @property
    def total_wrinkling_strain(self) -> float:
        """Σ w L ε⁻ / Σ w L over all tow bars (the paper's total wrinkling strain, ≤ 0)."""
        w_warp = np.ones_like(self.warp_strain)
        w_weft = np.ones_like(self.weft_strain)
        w_warp[:, [0, -1]] = self.edge_tow_factor
        w_weft[[0, -1], :] = self.edge_tow_factor
        # All tow bars have the reference length Δ, so it cancels.
        total = np.sum(w_warp * self.warp_wrinkling) + np.sum(w_weft * self.weft_wrinkling)
        return float(total / (w_warp.sum() + w_weft.sum()))

    def summary(self) -> dict[str, float]:
        """The global numbers of the paper's Figs. 9 and 12."""
        return {"time_s": self.time_s, "max_shear_deg": self.max_shear_deg,
                "total_wrinkling_strain": self.total_wrinkling_strain,
                "min_wrinkling_strain": self.min_wrinkling_strain,
                "nodes": int(self.X[..., 0].size), "cell_mm": self.grid.cell_mm}


def results(problem) -> Results:
    """The :class:`Results` of a problem at its current state (collective)."""
    X, x = gather_nodes(problem)
    warp = _strain(x[:-1, :], x[1:, :], X[:-1, :], X[1:, :])
    weft = _strain(x[:, :-1], x[:, 1:], X[:, :-1], X[:, 1:])
    e_warp = (x[1:, :-1] - x[:-1, :-1]) + (x[1:, 1:] - x[:-1, 1:])
    e_weft = (x[:-1, 1:] - x[:-1, :-1]) + (x[1:, 1:] - x[1:, :-1])
    cos = np.sum(e_warp * e_weft, axis=-1) / (
        np.linalg.norm(e_warp, axis=-1) * np.linalg.norm(e_weft, axis=-1))
    shear = 90.0 - np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return Results(problem.t, problem.sheet.grid, X, x, shear, warp, weft,
                   problem.options.edge_tow_factor)


class _PlyView:
    """One ply of a stacked problem, seen as a problem of its own by the output functions."""

    def __init__(self, problem, k: int) -> None:
        plies = problem.sheet.plies
        n = problem.num_owned
        on = ply_of(plies, problem.X[:n]) == k
        self.sheet = dataclasses.replace(problem.sheet, grid=plies[k].grid, plies=None)
        self.X = problem.X[:n][on]
        self._x = problem.positions()[:n][on]
        self.num_owned = len(self.X)
        self.comm, self.t, self.options = problem.comm, problem.t, problem.options

    def positions(self) -> np.ndarray:
        return self._x


def ply_results(problem, k: int):
    """The :class:`~fenicsx_drape.fe.output.Results` of ply ``k`` (0: ply 1) of a stack."""
    return results(_PlyView(problem, k))


def grid_points(res: Results, grid_mm: float = 10.0) -> dict[str, np.ndarray]:
    """Positions of the points of a drawn grid of spacing ``grid_mm`` on the sheet.

    Drawn-grid points are at multiples of ``grid_mm`` from the punch axis along the tows;
    their current positions are interpolated bilinearly in the deformed unit cell that holds
    them (exact at the nodes when Δ divides ``grid_mm``, and for any affine deformation).
    Returns the columns of the spec's forming grid: ``i, j, x0_mm, y0_mm, x_mm, y_mm, z_mm``.
    """
    g = res.grid
    lo = np.asarray(g.origin_mm)
    hi = lo + g.cell_mm * np.array([g.nx, g.ny])
    eps = 1e-9 * g.cell_mm
    ranges = [np.arange(np.ceil((lo[k] - eps) / grid_mm), np.floor((hi[k] + eps) / grid_mm) + 1)
              for k in range(2)]
    i, j = (a.ravel().astype(int) for a in np.meshgrid(*ranges, indexing="ij"))
    x0, y0 = i * grid_mm, j * grid_mm
    s = (x0 - lo[0]) / g.cell_mm
    t = (y0 - lo[1]) / g.cell_mm
    ci = np.clip(np.floor(s + 1e-9).astype(int), 0, g.nx - 1)
    cj = np.clip(np.floor(t + 1e-9).astype(int), 0, g.ny - 1)
    ξ, η = (s - ci)[:, None], (t - cj)[:, None]

    def interpolate(x):
        return ((1 - ξ) * (1 - η) * x[ci, cj] + ξ * (1 - η) * x[ci + 1, cj]
                + (1 - ξ) * η * x[ci, cj + 1] + ξ * η * x[ci + 1, cj + 1])

    ref, pos = interpolate(res.X), interpolate(res.x)  # ref: x0, y0 of a turned sheet too
    return {"i": i, "j": j, "x0_mm": ref[:, 0], "y0_mm": ref[:, 1],
            "x_mm": pos[:, 0], "y_mm": pos[:, 1], "z_mm": pos[:, 2]}


def write_grid_csv(res: Results, path: str | os.PathLike, grid_mm: float = 10.0,
                   comm: MPI.Comm = MPI.COMM_WORLD) -> Path:
    """Write the drawn-grid positions (:func:`grid_points`) as CSV; rank 0 writes."""
    cols = grid_points(res, grid_mm)
    path = Path(path)
    if comm.rank == 0:
        lines = [",".join(cols)]
        for row in zip(*cols.values()):
            lines.append(f"{row[0]},{row[1]}," + ",".join(f"{v:.6f}" for v in row[2:]))
        atomic_write_text(path, "\n".join(lines) + "\n")
    return path


class FieldWriter:
    """XDMF time series for ParaView: displacement and per-bar fields.

    Fields: ``displacement_mm`` (nodes); per bar ``strain`` (Green-Lagrange),
    ``stress_per_tow_N``, ``wrinkling_strain`` (tows, ≤ 0), ``shear_deg`` (the shear angle of
    the unit cell, on its two diagonals) and ``kind`` (1 warp, 2 weft, 3/4 diagonals). A
    stack of plies adds ``ply`` (per bar, 1 on the punch side) and, at the nodes of each
    upper ply of a pair, ``interply_pressure_MPa`` and ``interply_sliding_mm`` (the sliding
    slip's length).
    """

    def __init__(self, problem, path: str | os.PathLike):
        self.problem = problem
        mesh = problem.sheet.mesh
        path = Path(path)
        if mesh.comm.rank == 0:
            path.parent.mkdir(parents=True, exist_ok=True)
        mesh.comm.Barrier()
        self.file = dolfinx.io.XDMFFile(mesh.comm, str(path), "w")
        self.file.write_mesh(mesh)
        W = dolfinx.fem.functionspace(mesh, ("DG", 0))
        self.fields = {name: dolfinx.fem.Function(W, name=name) for name in
                       ("strain", "stress_per_tow_N", "wrinkling_strain", "shear_deg", "kind")}
        n = mesh.topology.index_map(1).size_local
        self._dofs = W.dofmap.list[:n, 0]
        self._kinds = np.zeros(n, dtype=np.int32)
        tags = problem.sheet.bar_tags
        owned = tags.indices < n
        self._kinds[tags.indices[owned]] = tags.values[owned]
        self.fields["kind"].x.array[self._dofs] = self._kinds
        mid = mesh.geometry.x[mesh.geometry.dofmaps[0][:n]].mean(axis=1)
        self._cells = []  # each ply's grid (one for a single ply): its bars' unit cells
        for grid, on in sheet_grids(problem.sheet, mid):
            cell = np.floor(grid.grid_coordinates(mid)).astype(int)
            self._cells.append((on, np.clip(cell[:, 0], 0, grid.nx - 1),
                                np.clip(cell[:, 1], 0, grid.ny - 1)))
        # A stack: each bar's ply, and the inter-ply pressure and sliding at the nodes.
        self._contact = next((t for t in problem.nodal_terms if hasattr(t, "pattern")), None)
        if problem.sheet.plies:
            self.fields["ply"] = dolfinx.fem.Function(W, name="ply")
            self.fields["ply"].x.array[self._dofs] = 1 + ply_of(problem.sheet.plies, mid)
        if self._contact is not None:
            S = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
            self._nodal = {name: dolfinx.fem.Function(S, name=name)
                           for name in ("interply_pressure_MPa", "interply_sliding_mm")}

    def write(self, res: Results | None = None) -> None:
        """Append the fields at the problem's current time (collective)."""
        p = self.problem
        if p.sheet.plies:
            shear_of = [ply_results(p, k).shear_deg for k in range(len(p.sheet.plies))]
        else:
            shear_of = [(res if res is not None else p.results()).shear_deg]
        q = p.state.dofs
        ε = p.state.strain.x.array[q]
        tow = (self._kinds == WARP) | (self._kinds == WEFT)
        diag = (self._kinds == DIAGONAL_PLUS) | (self._kinds == DIAGONAL_MINUS)
        shear = np.zeros(len(ε))
        for (on, i, j), cells in zip(self._cells, shear_of):
            shear[on] = cells[i[on], j[on]]
        values = {
            "strain": ε,
            "stress_per_tow_N": p.state.stress.x.array[q],
            "wrinkling_strain": np.where(tow, np.minimum(ε, 0.0), 0.0),
            "shear_deg": np.where(diag, shear, 0.0),
        }
        for name, v in values.items():
            self.fields[name].x.array[self._dofs] = v
        for f in self.fields.values():
            f.x.scatter_forward()
        self.file.write_function(p.u, p.t)
        for f in self.fields.values():
            self.file.write_function(f, p.t)
        if self._contact is not None:  # the values of a pair at its node on the upper ply
            c = self._contact
            pressure, sliding = self._nodal.values()
            pressure.x.array[:] = 0.0
            sliding.x.array[:] = 0.0
            nodes, mine = c.owned_pairs()
            pressure.x.array[nodes] = c.pressure_MPa[mine]
            sliding.x.array[nodes] = np.linalg.norm(c.sliding_mm[mine], axis=1)
            for f in self._nodal.values():
                f.x.scatter_forward()
                self.file.write_function(f, p.t)

    def close(self) -> None:
        """Close the file."""
        self.file.close()

    def __enter__(self) -> FieldWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
