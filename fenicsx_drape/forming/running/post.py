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

A ply at an angle θ (:func:`~fenicsx_drape.fe.grid.sheet_grid` ``ply_angle_deg``) is a grid
turned by θ and clipped to the square sheet: absent nodes are NaN, and cells and bars with an
absent node are NaN too and left out of every maximum, minimum and sum. Its paths, the drawn
grid and :meth:`FormedGrid.sample` are in the *tow frame*: along the warp and weft from the
apex, turned by θ from the sheet's edges (the frame is read from the grid itself).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fenicsx_drape.errors import DrapeInputError


@dataclasses.dataclass(frozen=True)
class FormedGrid:
    """A formed sheet on its structured grid (mm).

    ``quarter`` grids cover x, y ≥ 0 with the apex at [0, 0]; full grids are centred on the
    apex at [n_i // 2, n_j // 2]. A half model (``symmetry = ("x",)`` or ``("y",)``) covers
    x ≥ 0 (or y ≥ 0) with its symmetry plane on the edge i = 0 (or j = 0). Absent nodes (a
    clipped net) are NaN in ``X`` and ``x``.
    """

    X: np.ndarray  # (n_i, n_j, 3) nodes on the flat sheet
    x: np.ndarray  # (n_i, n_j, 3) formed nodes
    quarter: bool
    # Symmetry planes on the edges i = 0 ("x") and j = 0 ("y"); None: both if quarter.
    symmetry: tuple[str, ...] | None = None
    # A stack: every ply's sheet, ply 1 (the punch side) first; this one is the last.
    plies: tuple[FormedGrid, ...] = dataclasses.field(default=(), repr=False, compare=False)

    def ply(self, k: int | None) -> FormedGrid:
        """The sheet of ply ``k`` (1 = the punch side) of a stack; None: this one (the last).

        Raises:
            DrapeInputError: a ply the formed sheet does not have.
        """
        if k is None:
            return self
        n = len(self.plies) or 1
        if not 1 <= k <= n:
            raise DrapeInputError(f"ply {k}: the formed sheet has {n} pl{'y' if n == 1 else 'ies'}")
        return self.plies[k - 1] if self.plies else self

    @property
    def planes(self) -> tuple[str, ...]:
        """The symmetry planes the grid is a part of the whole sheet by (``"x"``, ``"y"``)."""
        if self.symmetry is not None:
            return tuple(self.symmetry)
        return ("x", "y") if self.quarter else ()

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
    def present(self) -> np.ndarray:
        """Mask (n_i, n_j) of the nodes of the sheet (all unless the net is clipped)."""
        return np.isfinite(self.X[..., 0])

    def tow_frame(self) -> tuple[np.ndarray, float, np.ndarray]:
        """The lattice: position (mm) of node [0, 0] on the flat sheet, Δ (mm), rotation.

        Node [i, j] is at ``origin + R (i, j) Δ``; R turns the sheet's axes onto the tows.
        """
        X = self.X[..., :2]
        pairs = np.argwhere(np.isfinite(X[:-1, :, 0]) & np.isfinite(X[1:, :, 0]))
        if not len(pairs):
            raise DrapeInputError("FormedGrid: no warp bar on the grid")
        i, j = pairs[0]
        d = X[i + 1, j] - X[i, j]
        Δ = float(np.hypot(d[0], d[1]))
        c, s = d / Δ
        R = np.array([[c, -s], [s, c]])
        return X[i, j] - R @ (np.array([i, j]) * Δ), Δ, R

    @property
    def cell_mm(self) -> float:
        """The grid spacing Δ (mm)."""
        return self.tow_frame()[1]

    @property
    def quadrant(self) -> FormedGrid:
        """The quadrant x, y ≥ 0 with the apex at [0, 0] (itself for a quarter grid).

        For a ply at an angle, the quadrant of the tow frame.
        """
        if self.planes == ("x", "y"):
            return self
        g = self.full()
        r = np.linalg.norm(g.X[..., :2], axis=-1)
        c = np.unravel_index(np.nanargmin(r), r.shape)
        return FormedGrid(g.X[c[0]:, c[1]:], g.x[c[0]:, c[1]:], True)

    def full(self) -> FormedGrid:
        """The full sheet: a quarter (or half) grid mirrored in its symmetry planes."""
        planes = self.planes
        if not planes:
            return self
        n_i, n_j = self.X.shape[:2]
        k_i = np.arange(1 - n_i, n_i) if "x" in planes else np.arange(n_i)
        k_j = np.arange(1 - n_j, n_j) if "y" in planes else np.arange(n_j)
        i, j = np.abs(k_i), np.abs(k_j)
        si = np.where(k_i < 0, -1.0, 1.0)
        sj = np.where(k_j < 0, -1.0, 1.0)
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

    def tow_stretches(self) -> tuple[np.ndarray, np.ndarray]:
        """Engineering strains l/L − 1 of the warp bars (n_i − 1, n_j) and weft bars."""
        out = []
        for axis in (0, 1):
            r, L = np.diff(self.x, axis=axis), np.diff(self.X, axis=axis)
            out.append(np.linalg.norm(r, axis=-1) / np.linalg.norm(L, axis=-1) - 1.0)
        return out[0], out[1]

    def total_wrinkling_strain(self, measure: str = "green_lagrange",
                               weights: str = "strip") -> float:
        """The paper's total wrinkling strain (≤ 0): wrinkling deformation over tow length.

        Section 4.2 and Fig. 12 define it as "the sum of wrinkling deformation [over the
        elements with negative strain] divided by the total length of tow elements". Every
        tow bar has length Δ on the flat sheet, so it is Σ w ε⁻ / Σ w with ε⁻ = min(ε, 0):

        - ``measure="green_lagrange"`` (default): ε the Green-Lagrange strain of the bar, the
          model's strain measure (eq. 13), its deformation taken as ε L;
          ``"engineering"``: ε = l/L − 1, so ε L = l − L is the bar's change of length, the
          literal "wrinkling deformation". For compression |ε_GL| = |e| (1 − |e|/2) < |e|.
        - ``weights="strip"`` (default): w = ½ for the bars on the grid's edges, which stand
          for half a strip of tows (as
          :attr:`fenicsx_drape.fe.output.Results.total_wrinkling_strain`; a bar's w is half the
          number of cells beside it, so the ragged edge of a clipped net has w = ½ too);
          ``"bars"``: every tow bar of the model counts once, the literal "total tow length of
          the model".

        The paper quotes magnitudes (0.55 %); here the value is negative.
        """
        if measure not in ("green_lagrange", "engineering"):
            raise DrapeInputError(f"total_wrinkling_strain: measure {measure!r} is not "
                                  "'green_lagrange' or 'engineering'")
        if weights not in ("strip", "bars"):
            raise DrapeInputError(f"total_wrinkling_strain: weights {weights!r} is not "
                                  "'strip' or 'bars'")
        strains = self.tow_strains() if measure == "green_lagrange" else self.tow_stretches()
        cells = np.isfinite(self.shear_deg()).astype(float)
        total, weight = 0.0, 0.0
        for axis, ε in enumerate(strains):
            pad = [(0, 0), (0, 0)]
            pad[1 - axis] = (1, 1)
            c = np.pad(cells, pad)
            w = 0.5 * (c[:, :-1] + c[:, 1:] if axis == 0 else c[:-1] + c[1:])
            if weights == "bars":
                w = (w > 0).astype(float)
            total += np.sum(np.where(w > 0, w * np.minimum(ε, 0), 0.0))
            weight += w.sum()
        return float(total / weight)

    def wrinkle_strain_nodes(self) -> np.ndarray:
        """Per node, the smallest wrinkling strain (≤ 0) of the tows meeting there."""
        warp, weft = self.tow_strains()
        w = np.zeros(self.X.shape[:2])
        warp, weft = np.minimum(warp, 0.0), np.minimum(weft, 0.0)
        # fmin: an absent bar (NaN) does not count
        w[:-1, :] = np.fmin(w[:-1, :], warp)
        w[1:, :] = np.fmin(w[1:, :], warp)
        w[:, :-1] = np.fmin(w[:, :-1], weft)
        w[:, 1:] = np.fmin(w[:, 1:], weft)
        return np.where(self.present, w, np.nan)

    def shear_nodes(self) -> np.ndarray:
        """Per node, the mean shear angle (deg) of the cells around it.

        The cells of the whole part: on a symmetry plane of a quarter or half model the
        mirrored cells count too (their signed shear is the opposite, so the field is 0 on
        the plane, as the whole part's is), not only the one cell beside the plane.
        """
        if self.planes:
            n_i, n_j = self.X.shape[:2]
            return self.full().shear_nodes()[-n_i:, -n_j:]  # the part: the last rows, columns
        γ = self.shear_deg()
        ok = np.isfinite(γ)
        γ = np.where(ok, γ, 0.0)
        s, c = np.zeros(self.X.shape[:2]), np.zeros(self.X.shape[:2])
        for di in (0, 1):
            for dj in (0, 1):
                sl = (slice(di, di + γ.shape[0]), slice(dj, dj + γ.shape[1]))
                s[sl] += γ
                c[sl] += ok
        return np.divide(s, c, out=np.full_like(s, np.nan), where=c > 0)

    def mirror_asymmetry_deg(self) -> float:
        """Largest change of the shear magnitude (deg) under the mirror x → −x of the sheet.

        The magnitude at every node (:meth:`shear_nodes`) against its value at the node's
        mirror image, bilinear in the cells of the tow frame (images are nodes when the tows
        lie along the edges; images outside the net are left out). 0 for a sheet symmetric in
        the plane x = 0; a ply at an angle θ is not.
        """
        g = self.full()
        γ = np.abs(g.shear_nodes())
        field = FormedGrid(g.X, np.stack([γ] * 3, axis=-1), False)
        mirrored = field.sample(g.X[g.present][:, :2] * [-1.0, 1.0], outside="nan")[:, 0]
        return float(np.nanmax(np.abs(mirrored - γ[g.present])))

    def diagonal_path(self) -> tuple[np.ndarray, np.ndarray]:
        """Shear along the diagonal path (Fig. 11a).

        Returns the distance (mm) of the cell centres on the bias line from the apex on the
        flat sheet, and their shear angle (deg), from the apex to the corner (the cells of
        the sheet only; the bias line of the tow frame for a ply at an angle).
        """
        q = self.quadrant
        γ = np.diagonal(q.shear_deg())
        Xc = 0.5 * (np.diagonal(q.X[:-1, :-1], axis1=0, axis2=1)
                    + np.diagonal(q.X[1:, 1:], axis1=0, axis2=1))
        ok = np.isfinite(γ)
        return np.linalg.norm(Xc[:2].T, axis=1)[ok], γ[ok]

    def normal_path(self) -> tuple[np.ndarray, np.ndarray]:
        """Wrinkling strain along the normal path (Fig. 11b).

        Returns the distance (mm) from the apex on the flat sheet of the nodes on the warp
        axis, from the apex to the middle of a side, and their wrinkling strain
        (:meth:`wrinkle_strain_nodes`). In a quarter grid the weft bars of the symmetry edge
        y = 0 stand for both sides. For a ply at an angle: the warp axis of the tow frame,
        distances along it.
        """
        q = self.quadrant
        ok = q.present[:, 0]
        warp = q.tow_frame()[2][:, 0]  # the warp direction on the flat sheet
        return (q.X[:, 0, :2] @ warp)[ok], q.wrinkle_strain_nodes()[ok, 0]

    def sample(self, points_mm: np.ndarray, outside: str = "raise") -> np.ndarray:
        """Formed positions (m, 3) of flat-sheet points (m, 2), bilinear in each cell.

        NaN for points outside the cells of a clipped net. A point outside the grid's
        lattice raises, or with ``outside="nan"`` is NaN too (the mirror image of a point of
        a turned net may lie beyond the lattice).
        """
        p = np.asarray(points_mm, float)
        origin, Δ, R = self.tow_frame()
        s = ((p - origin) @ R) / Δ
        n = np.array(self.X.shape[:2]) - 1
        beyond = np.any((s < -1e-9) | (s > n + 1e-9), axis=1)
        if beyond.any() and outside != "nan":
            raise DrapeInputError("FormedGrid.sample: a point lies outside the sheet")
        x = self.x
        out = np.full((len(p), 3), np.nan)
        # A point on a side or corner of a cell of the sheet (to rounding) may have an absent
        # cell on the other side: try the cells around it.
        around = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]
        for shift in ((0, 0), *around):
            k = np.clip(np.floor(s).astype(int) + shift, 0, n - 1)
            a, b = (s - k)[:, :1], (s - k)[:, 1:]
            v = ((1 - a) * (1 - b) * x[k[:, 0], k[:, 1]] + a * (1 - b) * x[k[:, 0] + 1, k[:, 1]]
                 + (1 - a) * b * x[k[:, 0], k[:, 1] + 1] + a * b * x[k[:, 0] + 1, k[:, 1] + 1])
            inside = np.all((s - k > -1e-9) & (s - k < 1 + 1e-9), axis=1)
            out = np.where(np.isnan(out) & inside[:, None], v, out)
        out[beyond] = np.nan
        return out

    def drawn_grid(self, grid_mm: float = 10.0) -> dict[str, np.ndarray]:
        """The nodes of a drawn grid of spacing ``grid_mm`` as a forming-bundle table.

        Columns ``i, j, x0_mm, y0_mm, x_mm, y_mm, z_mm`` (``i, j`` = position / grid, zero on
        the punch axis), plus ``shear_deg`` and ``wrinkle_strain`` where the grid points are
        nodes of this grid (otherwise omitted). For a ply at an angle the drawn grid follows
        the tows (``i, j`` in the tow frame; ``x0_mm, y0_mm`` on the flat sheet), points in
        absent cells of the clipped net left out.
        """
        origin, Δ, R = self.tow_frame()
        T = self.X[..., :2] @ R  # node positions in the tow frame
        lo, hi = np.nanmin(T, axis=(0, 1)), np.nanmax(T, axis=(0, 1))
        i = np.arange(np.ceil(lo[0] / grid_mm - 1e-9), np.floor(hi[0] / grid_mm + 1e-9) + 1)
        j = np.arange(np.ceil(lo[1] / grid_mm - 1e-9), np.floor(hi[1] / grid_mm + 1e-9) + 1)
        ii, jj = (a.ravel() for a in np.meshgrid(i, j, indexing="ij"))
        ii, jj = ii + 0.0, jj + 0.0  # no negative zeros in the table
        P = (np.column_stack([ii, jj]) * grid_mm) @ R.T
        x = self.sample(P)
        ok = np.isfinite(x[:, 0])
        P, x, ii, jj = P[ok], x[ok], ii[ok], jj[ok]
        table = {"i": ii, "j": jj, "x0_mm": P[:, 0], "y0_mm": P[:, 1],
                 "x_mm": x[:, 0], "y_mm": x[:, 1], "z_mm": x[:, 2]}
        ratio = grid_mm / Δ
        if abs(ratio - round(ratio)) < 1e-9:
            k = np.rint(((P - origin) @ R) / Δ).astype(int)
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
