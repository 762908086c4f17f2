"""Post-processing of a formed sheet on its structured grid: shear, wrinkling, paths, bundle.

A formed sheet is a :class:`FormedGrid`: the nodes of the truss on the flat sheet (``X``) and
formed (``x``), both shaped (n_i, n_j, 3) with index [i, j] along warp (x) and weft (y). The
same functions serve the FE result, the kinematic net and a measured grid, so the three are
compared on equal terms (the paper's Figs. 10-11):

- **shear angle** of a unit cell: 90° minus the angle between its mean warp and weft tow
  vectors, ``a = ½(P₁₀ − P₀₀ + P₁₁ − P₀₁)`` and ``b = ½(P₀₁ − P₀₀ + P₁₁ − P₁₀)``;
- **Green-Lagrange strain** of a tow bar, ε = (|r|² − L²) / (2 L²) (eq. 13); a tow is
  wrinkled (buckled, eq. 4) when ε < 0 and ε is then its *wrinkling strain*;
- **total wrinkling strain** (section 4.2, Fig. 9): the wrinkling deformation (wrinkling
  strain × length) summed over the compressed tows, divided by the total tow length; it is
  negative, and reported as such (the paper quotes its magnitude, about 0.55 %);
- the **diagonal path** (Fig. 11a): the cells on the bias line from a sheet corner to the
  apex; the **normal path** (Fig. 11b): the nodes on the warp axis from the middle of a side
  to the apex, each with the smallest wrinkling strain of the tows meeting there.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fenicsx_drape.errors import DrapeInputError


@dataclasses.dataclass(frozen=True)
class FormedGrid:
    """A formed sheet on its structured grid (mm).

    ``quarter`` grids cover x, y ≥ 0 with the apex at [0, 0]; full grids are centred on the
    apex at [n_i // 2, n_j // 2].
    """

    X: np.ndarray  # (n_i, n_j, 3) nodes on the flat sheet
    x: np.ndarray  # (n_i, n_j, 3) formed nodes
    quarter: bool

    @classmethod
    def from_nodes(cls, X: np.ndarray, x: np.ndarray, cell_mm: float,
                   quarter: bool) -> FormedGrid:
        """Arrange scattered nodes of a structured sheet (any order) on their grid."""
        X, x = np.asarray(X, float), np.asarray(x, float)
        ij = np.rint(X[:, :2] / cell_mm).astype(int)
        ij -= ij.min(axis=0)
        shape = tuple(ij.max(axis=0) + 1)
        if shape[0] * shape[1] != len(X) or len(np.unique(ij, axis=0)) != len(X):
            raise DrapeInputError(f"FormedGrid: {len(X)} nodes are not a structured "
                                  f"{shape[0]}×{shape[1]} grid of {cell_mm} mm cells")
        G, g = np.empty((*shape, 3)), np.empty((*shape, 3))
        G[ij[:, 0], ij[:, 1]] = X
        g[ij[:, 0], ij[:, 1]] = x
        return cls(G, g, quarter)

    @property
    def cell_mm(self) -> float:
        """The grid spacing Δ (mm)."""
        return float(self.X[1, 0, 0] - self.X[0, 0, 0])

    @property
    def quadrant(self) -> FormedGrid:
        """The quadrant x, y ≥ 0 with the apex at [0, 0] (itself for a quarter grid)."""
        if self.quarter:
            return self
        c = np.argmin(np.abs(self.X[:, 0, 0])), np.argmin(np.abs(self.X[0, :, 1]))
        return FormedGrid(self.X[c[0]:, c[1]:], self.x[c[0]:, c[1]:], True)

    def full(self) -> FormedGrid:
        """The full sheet: a quarter grid mirrored in the planes x = 0 and y = 0."""
        if not self.quarter:
            return self
        n_i, n_j = self.X.shape[:2]
        i = np.abs(np.arange(1 - n_i, n_i))
        j = np.abs(np.arange(1 - n_j, n_j))
        si = np.where(np.arange(1 - n_i, n_i) < 0, -1.0, 1.0)
        sj = np.where(np.arange(1 - n_j, n_j) < 0, -1.0, 1.0)
        out = []
        for A in (self.X, self.x):
            B = A[i[:, None], j[None, :]].copy()
            B[..., 0] *= si[:, None]
            B[..., 1] *= sj[None, :]
            out.append(B)
        return FormedGrid(out[0], out[1], False)

    def shear_deg(self) -> np.ndarray:
        """Shear angle (deg) of every cell, shaped (n_i − 1, n_j − 1)."""
        x = self.x
        a = 0.5 * (x[1:, :-1] - x[:-1, :-1] + x[1:, 1:] - x[:-1, 1:])
        b = 0.5 * (x[:-1, 1:] - x[:-1, :-1] + x[1:, 1:] - x[1:, :-1])
        cos = np.sum(a * b, -1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
        return 90.0 - np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))

    def tow_strains(self) -> tuple[np.ndarray, np.ndarray]:
        """Green-Lagrange strains of the warp bars (n_i − 1, n_j) and weft bars (n_i, n_j − 1)."""
        out = []
        for axis in (0, 1):
            r = np.diff(self.x, axis=axis)
            L = np.diff(self.X, axis=axis)
            out.append(0.5 * (np.sum(r * r, -1) / np.sum(L * L, -1) - 1.0))
        return out[0], out[1]

    def total_wrinkling_strain(self) -> float:
        """The paper's total wrinkling strain (≤ 0), as the FE results define it.

        Σ w ε⁻ / Σ w over the tow bars (all of length Δ), ε⁻ = min(ε, 0), with w = ½ for the
        bars on the grid's edges (they stand for half a strip of tows):
        :attr:`fenicsx_drape.fe.output.Results.total_wrinkling_strain`.
        """
        warp, weft = self.tow_strains()
        w_warp, w_weft = np.ones_like(warp), np.ones_like(weft)
        w_warp[:, [0, -1]] = 0.5
        w_weft[[0, -1], :] = 0.5
        total = np.sum(w_warp * np.minimum(warp, 0)) + np.sum(w_weft * np.minimum(weft, 0))
        return float(total / (w_warp.sum() + w_weft.sum()))

    def wrinkle_strain_nodes(self) -> np.ndarray:
        """Per node, the smallest wrinkling strain (≤ 0) of the tows meeting there."""
        warp, weft = self.tow_strains()
        w = np.zeros(self.X.shape[:2])
        warp, weft = np.minimum(warp, 0.0), np.minimum(weft, 0.0)
        w[:-1, :] = np.minimum(w[:-1, :], warp)
        w[1:, :] = np.minimum(w[1:, :], warp)
        w[:, :-1] = np.minimum(w[:, :-1], weft)
        w[:, 1:] = np.minimum(w[:, 1:], weft)
        return w

    def shear_nodes(self) -> np.ndarray:
        """Per node, the mean shear angle (deg) of the cells around it."""
        γ = self.shear_deg()
        s, c = np.zeros(self.X.shape[:2]), np.zeros(self.X.shape[:2])
        for di in (0, 1):
            for dj in (0, 1):
                sl = (slice(di, di + γ.shape[0]), slice(dj, dj + γ.shape[1]))
                s[sl] += γ
                c[sl] += 1.0
        return s / c

    def diagonal_path(self) -> tuple[np.ndarray, np.ndarray]:
        """Shear along the diagonal path (Fig. 11a).

        Returns the distance (mm) of the cell centres on the bias line from the apex on the
        flat sheet, and their shear angle (deg), from the apex to the corner.
        """
        q = self.quadrant
        γ = np.diagonal(q.shear_deg())
        Xc = 0.5 * (np.diagonal(q.X[:-1, :-1], axis1=0, axis2=1)
                    + np.diagonal(q.X[1:, 1:], axis1=0, axis2=1))
        return np.linalg.norm(Xc[:2].T, axis=1), γ

    def normal_path(self) -> tuple[np.ndarray, np.ndarray]:
        """Wrinkling strain along the normal path (Fig. 11b).

        Returns the distance (mm) from the apex on the flat sheet of the nodes on the warp
        axis, from the apex to the middle of a side, and their wrinkling strain
        (:meth:`wrinkle_strain_nodes`). In a quarter grid the weft bars of the symmetry edge
        y = 0 stand for both sides.
        """
        q = self.quadrant
        return q.X[:, 0, 0], q.wrinkle_strain_nodes()[:, 0]

    def sample(self, points_mm: np.ndarray) -> np.ndarray:
        """Formed positions (m, 3) of flat-sheet points (m, 2), bilinear in each cell."""
        p = np.asarray(points_mm, float)
        Δ = self.cell_mm
        s = (p - self.X[0, 0, :2]) / Δ
        n = np.array(self.X.shape[:2]) - 1
        if (s < -1e-9).any() or (s > n + 1e-9).any():
            raise DrapeInputError("FormedGrid.sample: a point lies outside the sheet")
        k = np.clip(np.floor(s).astype(int), 0, n - 1)
        a, b = (s - k)[:, :1], (s - k)[:, 1:]
        x = self.x
        return ((1 - a) * (1 - b) * x[k[:, 0], k[:, 1]] + a * (1 - b) * x[k[:, 0] + 1, k[:, 1]]
                + (1 - a) * b * x[k[:, 0], k[:, 1] + 1] + a * b * x[k[:, 0] + 1, k[:, 1] + 1])

    def drawn_grid(self, grid_mm: float = 10.0) -> dict[str, np.ndarray]:
        """The nodes of a drawn grid of spacing ``grid_mm`` as a forming-bundle table.

        Columns ``i, j, x0_mm, y0_mm, x_mm, y_mm, z_mm`` (``i, j`` = position / grid, zero on
        the punch axis), plus ``shear_deg`` and ``wrinkle_strain`` where the grid points are
        nodes of this grid (otherwise omitted).
        """
        lo, hi = self.X[0, 0, :2], self.X[-1, -1, :2]
        i = np.arange(np.ceil(lo[0] / grid_mm - 1e-9), np.floor(hi[0] / grid_mm + 1e-9) + 1)
        j = np.arange(np.ceil(lo[1] / grid_mm - 1e-9), np.floor(hi[1] / grid_mm + 1e-9) + 1)
        ii, jj = (a.ravel() for a in np.meshgrid(i, j, indexing="ij"))
        ii, jj = ii + 0.0, jj + 0.0  # no negative zeros in the table
        P = np.column_stack([ii, jj]) * grid_mm
        x = self.sample(P)
        table = {"i": ii, "j": jj, "x0_mm": P[:, 0], "y0_mm": P[:, 1],
                 "x_mm": x[:, 0], "y_mm": x[:, 1], "z_mm": x[:, 2]}
        ratio = grid_mm / self.cell_mm
        if abs(ratio - round(ratio)) < 1e-9:
            k = np.rint((P - lo) / self.cell_mm).astype(int)
            table["shear_deg"] = self.shear_nodes()[k[:, 0], k[:, 1]]
            table["wrinkle_strain"] = self.wrinkle_strain_nodes()[k[:, 0], k[:, 1]]
        return table


def mean_distance(a: FormedGrid, b: FormedGrid, grid_mm: float = 10.0) -> float:
    """Mean distance (mm) between two formed sheets at the points of a drawn grid.

    The paper's convergence measure (Fig. 9: 169 points of a 13 × 13 grid of the quarter)
    and its forming error against a measured grid (section 4.2).
    """
    ta, tb = a.drawn_grid(grid_mm), b.drawn_grid(grid_mm)
    key = {(i, j): k for k, (i, j) in enumerate(zip(tb["i"], tb["j"]))}
    common = [(k, key[(i, j)]) for k, (i, j) in enumerate(zip(ta["i"], ta["j"])) if (i, j) in key]
    if not common:
        raise DrapeInputError("mean_distance: the two sheets share no grid point")
    ka, kb = np.array(common).T
    pa = np.column_stack([ta[c][ka] for c in ("x_mm", "y_mm", "z_mm")])
    pb = np.column_stack([tb[c][kb] for c in ("x_mm", "y_mm", "z_mm")])
    return float(np.linalg.norm(pa - pb, axis=1).mean())
