"""The kinematic drape: a pin-jointed net of inextensible tows mapped onto the formed surface.

This is the classic "fishnet" algorithm (Van Der Ween, the paper's ref. 1), the geometric
model the paper compares with in Fig. 11 (its maximum shear: 61°). It has no mechanics:

1. the surface is the formed part (:meth:`HemisphereTools.formed_part`: the punch at its final
   position inside the holder opening, the plane z = 0 outside);
2. two *generator* tows, the warp and the weft through the apex, follow the meridians in the
   x-z and y-z planes (geodesics of a surface of revolution), with nodes a chord Δ apart;
3. every other node closes a cell: it is the point of the surface at chord distance Δ from its
   two known neighbours (P_{i-1,j} and P_{i,j-1}) on the side away from the cell's third node,
   found by Newton from the parallelogram guess P_{i-1,j} + P_{i,j-1} − P_{i-1,j-1}. The
   cells of one anti-diagonal i + j = s are independent and solved together (vectorised).

The part and the net are symmetric, so one quadrant is built and mirrored to the full sheet.
"""

from __future__ import annotations

import numpy as np

from fenicsx_drape.errors import SolverError
from fenicsx_drape.forming.post import FormedGrid
from fenicsx_drape.forming.tools import HemisphereTools, RevolvedTool


def _solve(F, P: np.ndarray, what: str) -> np.ndarray:
    """Newton on the 3 equations ``F(P) -> (residual (m, 3), jacobian (m, 3, 3))``."""
    for _ in range(50):
        r, J = F(P)
        dP = np.linalg.solve(J, -r[..., None])[..., 0]
        step = np.linalg.norm(dP, axis=1)
        P = P + dP * np.minimum(1.0, 5.0 / np.maximum(step, 1e-300))[:, None]
        if step.max(initial=0.0) < 1e-10:
            return P
    raise SolverError(f"kinematic drape: Newton did not converge for {what}")


def _on_surface(part: RevolvedTool, P: np.ndarray):
    g = part.gap(P, 0.0)
    return g.phi, g.normal


def drape_quadrant(tools: HemisphereTools, cell_mm: float, n_cells: int) -> np.ndarray:
    """Nodes (n_cells + 1, n_cells + 1, 3) of the quadrant x, y ≥ 0 draped on the part."""
    part = tools.formed_part()
    Δ = float(cell_mm)
    n = n_cells + 1
    P = np.full((n, n, 3), np.nan)
    P[0, 0] = [0.0, 0.0, tools.travel_mm]

    # Generators: meridians in the planes y = 0 (warp) and x = 0 (weft), nodes a chord Δ apart.
    for i in range(1, n):
        A = P[i - 1, 0][None]

        def meridian(Q, A=A):
            φ, nrm = _on_surface(part, Q)
            d = Q - A
            r = np.column_stack([(d * d).sum(1) - Δ**2, Q[:, 1], φ])
            J = np.stack([2 * d, np.broadcast_to([0.0, 1.0, 0.0], Q.shape), nrm], axis=1)
            return r, J

        guess = A + Δ * np.array([[1.0, 0.0, 0.0]])
        if i > 1:
            guess = 2 * A - P[i - 2, 0][None]
        P[i, 0] = _solve(meridian, guess, f"the warp generator node {i}")[0]
    P[0, 1:] = P[1:, 0][:, [1, 0, 2]]  # the weft generator is the warp's mirror in x = y

    # Fill the cells wavefront by wavefront.
    for s in range(2, 2 * n - 1):
        i = np.arange(max(1, s - n + 1), min(s, n))
        j = s - i
        keep = j >= 1
        i, j = i[keep], j[keep]
        A, B, C = P[i - 1, j], P[i, j - 1], P[i - 1, j - 1]

        def cell(Q, A=A, B=B):
            φ, nrm = _on_surface(part, Q)
            a, b = Q - A, Q - B
            r = np.column_stack([(a * a).sum(1) - Δ**2, (b * b).sum(1) - Δ**2, φ])
            return r, np.stack([2 * a, 2 * b, nrm], axis=1)

        P[i, j] = _solve(cell, A + B - C, f"the cells i + j = {s}")
    return P


def kinematic_drape(tools: HemisphereTools, cell_mm: float = 10.0) -> FormedGrid:
    """Drape the full sheet (side ``tools.sheet_mm``) with the pin-jointed net.

    Args:
        tools: the tool set (its formed part is the drape surface).
        cell_mm: the net's cell size Δ; the half-sheet must hold a whole number of cells.

    Returns:
        The full sheet's net on the flat sheet and on the part.
    """
    half = 0.5 * tools.sheet_mm
    n_cells = round(half / cell_mm)
    if abs(n_cells * cell_mm - half) > 1e-9 * half:
        raise SolverError(f"kinematic drape: the half sheet {half} mm is not a whole number "
                          f"of {cell_mm} mm cells")
    Q = drape_quadrant(tools, cell_mm, n_cells)
    # Mirror the quadrant to the four quadrants: index k = -n..n maps to |k|.
    k = np.abs(np.arange(-n_cells, n_cells + 1))
    sign = np.sign(np.arange(-n_cells, n_cells + 1))
    sign[sign == 0] = 1
    x = Q[k[:, None], k[None, :]].copy()
    x[..., 0] *= sign[:, None]
    x[..., 1] *= sign[None, :]
    c = cell_mm * np.arange(-n_cells, n_cells + 1)
    X = np.stack([*np.meshgrid(c, c, indexing="ij"), np.zeros((len(c), len(c)))], axis=-1)
    return FormedGrid(X=X, x=x, quarter=False)
