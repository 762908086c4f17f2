"""Tool meshes checked as meshes: the file as written and the triangles the mesher returned.

A damaged tool looks like a tool: Gmsh welds a ``vertex nan nan nan`` of an STL onto another
vertex (a long spike triangle), a missing patch leaves a hole the sheet sinks into. The checks
here run on the file (:func:`stl_problems`: every vertex a finite number, by line) and on the
points and triangles Gmsh returned (:func:`mesh_defects`), so that no repair hides a defect:

- *errors* (the tool is refused, exit 2): a point that is not finite; a triangle given twice;
  a *spike*, an edge more than :data:`SPIKE_FACTOR` times longer than the median edge at
  each of its ends (a corner that jumped away); a *fold*, two neighbouring triangles whose
  normals differ by more than :data:`FOLD_DEG` (one turned back onto the other);
- *warnings*, with where: degenerate triangles (a repeated corner or no area: dropped or
  ignored) and triangles wound against their neighbours (turned to match).

A *hole* (:func:`holes`) is a boundary loop with no surface inside it: along the normal of
the loop's mean plane, no line through its middle or halfway to its points crosses a triangle
within the loop's diameter.
The rim of an open surface (a dome's foot) encloses the surface; a holder's opening is a hole
by this test and allowed for holders (:mod:`~fenicsx_drape.forming.tools.build` decides by
role).

A punch or a die is one piece (:func:`pieces`: triangles joined through shared points): two
separate shells in one file (a surface given twice, shifted; a stray part) are refused, with
the size and place of each; holders may be made of separate blocks.

A tool whose flat triangles miss its curved geometry by much for the sheet's cell is warned
(:func:`coarse_mesh_problem`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

#: Points closer than this share of the bounding box's diagonal are one (merged).
WELD_TOLERANCE = 1e-7
#: An edge longer than this many times the median edge at each of its ends is a spike.
SPIKE_FACTOR = 6.0
#: Neighbouring triangles whose normals differ by more than this are folded onto each other.
FOLD_DEG = 170.0
#: A triangle whose area is below this share of its longest edge squared has no area.
FLAT_TRIANGLE = 1e-9
#: A tool mesh whose triangles miss the curved geometry by more than this share of the
#: sheet's cell changes the formed part (the sag h·θ/6 of triangles whose edge bends by θ).
COARSE_CHORD_OF_CELL = 0.1
#: Edges bending more than this are taken as the geometry's own creases, not its curvature.
CREASE_DEG = 60.0


def _at(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.4g}" for v in p) + ") mm"


def stl_problems(path: str | os.PathLike) -> list[str]:
    """Non-finite vertices of an STL file, named by line (ASCII) or facet (binary)."""
    path = Path(path)
    data = path.read_bytes()
    out = []
    n = int(np.frombuffer(data[80:84], "<u4")[0]) if len(data) >= 84 else -1
    if len(data) != 84 + 50 * n:  # not the size of a binary STL: ASCII
        for k, line in enumerate(data.decode(errors="replace").splitlines(), start=1):
            words = line.split()
            if not words or words[0].lower() != "vertex":
                continue
            try:
                xyz = [float(w) for w in words[1:4]]
            except ValueError:
                xyz = []
            if len(xyz) != 3 or not np.all(np.isfinite(xyz)):
                out.append(f"{path}:{k}: vertex {' '.join(words[1:]) or '(empty)'} is not "
                           "three finite numbers")
    else:
        facets = np.frombuffer(data[84:84 + 50 * n], dtype=np.dtype(
            [("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")]))
        bad = np.flatnonzero(~np.isfinite(facets["v"]).all(axis=(1, 2)))
        if len(bad):
            out.append(f"{path}: facet {bad[0] + 1} (of {n}) has a vertex that is not finite"
                       + (f" ({len(bad)} such facets)" if len(bad) > 1 else ""))
    if len(out) > 3:
        out = [*out[:3], f"{path}: ... {len(out) - 3} more such vertices"]
    return out


def _merged(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The triangles with coincident points merged (as the surface merges them)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    tol = WELD_TOLERANCE * max(float(np.linalg.norm(np.ptp(points, axis=0))), 1e-300)
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    if not len(pairs):
        return triangles
    n = len(points)
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(g, directed=False)
    first = np.full(label.max() + 1, -1)
    first[label[::-1]] = np.arange(n)[::-1]
    return first[label][triangles]


def mesh_defects(points: np.ndarray, triangles: np.ndarray) -> tuple[list[str], list[str]]:
    """Errors and warnings of a raw triangle mesh (module docstring), each saying where.

    Args:
        points: Points (n, 3) in mm, as the mesher returned them (not yet merged).
        triangles: Point indices (m, 3).

    Returns:
        ``(errors, warnings)``: lists of messages without the file's name.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    errors: list[str] = []
    warns: list[str] = []
    if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(points)):
        return errors, warns  # the surface says so (a triangle refers to a missing point)
    bad = ~np.isfinite(points).all(axis=1)
    used = np.zeros(len(points), dtype=bool)
    used[triangles.ravel()] = True
    if (bad & used).any():
        k = int(np.flatnonzero(bad & used)[0])
        errors.append(f"{int((bad & used).sum())} point(s) of the mesh are not finite (point "
                      f"{k}: {points[k].tolist()})")
        return errors, warns
    if not len(triangles):
        return errors, warns
    points = np.where(np.isfinite(points), points, 0.0)  # unused points do not count
    used, t = np.unique(_merged(points, triangles), return_inverse=True)
    p, t = points[used], t.reshape(-1, 3)  # n³ < 2⁶³ up to 2·10⁶ points
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    length = np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                       np.linalg.norm(a - c, axis=1)], axis=1)
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    flat = (area2 <= FLAT_TRIANGLE * length.max(axis=1) ** 2) | (
        (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 2] == t[:, 0]))
    if flat.any():
        k = int(np.flatnonzero(flat)[0])
        warns.append(f"{int(flat.sum())} degenerate triangle(s) (no area), e.g. at "
                     f"{_at(p[t[k]].mean(axis=0))}: ignored")
    t = t[~flat]
    if not len(t):
        return errors, warns
    n = len(p)
    key = np.sort(t, axis=1)
    _, first, count = np.unique((key[:, 0] * n + key[:, 1]) * n + key[:, 2],
                                return_index=True, return_counts=True)
    if (count > 1).any():
        k = int(first[np.argmax(count > 1)])
        errors.append(f"{int((count - 1).sum())} triangle(s) given twice, e.g. at "
                      f"{_at(p[t[k]].mean(axis=0))} (the surface is in the file twice?)")
        return errors, warns
    # Edges: unique, their lengths, and the longest other edge at each end.
    m = len(t)
    sides = t[:, [0, 1, 1, 2, 2, 0]].reshape(m, 3, 2)
    ordered = np.sort(sides, axis=2).reshape(-1, 2)
    codes, inverse = np.unique(ordered[:, 0] * n + ordered[:, 1], return_inverse=True)
    edges = np.column_stack([codes // n, codes % n])
    elen = np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1)
    # The median edge at every point (a spike triangle's two long edges meet at its far
    # corner: the median there is still the mesh's size).
    ends, lens = edges.ravel(), np.repeat(elen, 2)
    order = np.lexsort((lens, ends))
    ends, lens = ends[order], lens[order]
    start = np.r_[0, np.flatnonzero(np.diff(ends)) + 1]
    count = np.diff(np.r_[start, len(ends)])
    median = np.zeros(n)
    median[ends[start]] = lens[start + count // 2]
    around = np.maximum(median[edges[:, 0]], median[edges[:, 1]])
    spike = elen > SPIKE_FACTOR * np.maximum(around, 1e-300)
    if spike.any():
        k = int(np.argmax(np.where(spike, elen / np.maximum(around, 1e-300), 0.0)))
        errors.append(f"{int(spike.sum())} spike edge(s): an edge of {elen[k]:.3g} mm from "
                      f"{_at(p[edges[k, 0]])} to {_at(p[edges[k, 1]])}, where the edges at its "
                      f"ends are {around[k]:.3g} mm long (median) (a corner that jumped "
                      "away, e.g. a vertex the mesher merged)")
    # Winding against the neighbours, and folds (after winding consistently).
    tri_edge = inverse.reshape(m, 3)
    flat_e = tri_edge.ravel()
    order = np.argsort(flat_e, kind="stable")
    pair = flat_e[order][1:] == flat_e[order][:-1]
    s1, s2 = order[:-1][pair], order[1:][pair]
    f1, f2 = s1 // 3, s2 // 3
    start_pt = sides.reshape(-1, 2)[:, 0]
    against = start_pt[s1] == start_pt[s2]  # both traverse the shared edge the same way
    if against.any():
        k = int(f2[np.argmax(against)])
        warns.append(f"{int(against.sum())} shared edge(s) between triangles wound against "
                     f"each other, e.g. at {_at(p[t[k]].mean(axis=0))}: turned to match "
                     "their neighbours")
    normal = np.cross(b - a, c - a)[~flat]
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    cos = np.einsum("ij,ij->i", normal[f1], normal[f2])
    cos = np.where(against, -cos, cos)  # as if wound alike
    fold = cos < np.cos(np.radians(FOLD_DEG))
    if fold.any():
        k = int(f1[np.argmax(fold)])
        errors.append(f"{int(fold.sum())} fold(s): neighbouring triangles turned back onto "
                      f"each other (normals more than {FOLD_DEG:g}° apart), e.g. at "
                      f"{_at(p[t[k]].mean(axis=0))}")
    return errors, warns


def boundary_loops(surface) -> list[np.ndarray]:
    """The boundary of a surface as closed loops of point indices."""
    edges = surface.boundary_edges
    if not len(edges):
        return []
    nxt: dict[int, list[int]] = {}
    for a, b in edges.tolist():
        nxt.setdefault(a, []).append(b)
        nxt.setdefault(b, []).append(a)
    seen: set[int] = set()
    loops = []
    for s in nxt:
        if s in seen:
            continue
        loop, prev, v = [s], None, s
        seen.add(s)
        while True:
            cand = [w for w in nxt[v] if w != prev and (w not in seen or w == s)]
            if not cand or cand[0] == s:
                break
            prev, v = v, cand[0]
            seen.add(v)
            loop.append(v)
        loops.append(np.array(loop))
    return loops


def _hits(surface, origin: np.ndarray, direction: np.ndarray, reach: float) -> bool:
    """Whether the line origin + s·direction, |s| ≤ reach, crosses a triangle (Möller-Trumbore)."""
    p, t = surface.points, surface.triangles
    a = p[t[:, 0]]
    e1, e2 = p[t[:, 1]] - a, p[t[:, 2]] - a
    h = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(det) > 1e-12 * np.maximum(np.einsum("ij,ij->i", e1, e1), 1e-300)
    inv = 1.0 / np.where(ok, det, 1.0)
    s = origin - a
    u = np.einsum("ij,ij->i", s, h) * inv
    q = np.cross(s, e1)
    v = (q @ direction) * inv
    dist = np.einsum("ij,ij->i", e2, q) * inv
    return bool(np.any(ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (np.abs(dist) <= reach)))


def holes(surface) -> list[tuple[np.ndarray, float]]:
    """The holes of a surface: (centre in mm, diameter in mm) of each (module docstring)."""
    out = []
    for loop in boundary_loops(surface):
        x = surface.points[loop]
        centre = x.mean(axis=0)
        _, _, vt = np.linalg.svd(x - centre)
        size = float(np.linalg.norm(x - centre, axis=1).max()) * 2.0
        # Lines through the middle and halfway to 8 points of the loop: one crossing the
        # surface within the loop's diameter means the loop encloses surface (a rim).
        inner = [centre] + [0.5 * (centre + x[k]) for k in
                            np.linspace(0, len(x) - 1, 8).astype(int)]
        if not any(_hits(surface, o, vt[-1], size) for o in inner):
            out.append((centre, size))
    return out


def pieces(surface) -> list[tuple[int, np.ndarray]]:
    """The separate pieces of a surface: (triangles, centre in mm) of each, largest first."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    t, n = surface.triangles, len(surface.points)
    if not len(t):
        return []
    rows, cols = t[:, [0, 1, 2]].ravel(), t[:, [1, 2, 0]].ravel()
    _, label = connected_components(
        coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)), directed=False)
    of_triangle = label[t[:, 0]]
    out = []
    for k in np.unique(of_triangle):
        mine = t[of_triangle == k]
        out.append((len(mine), surface.points[np.unique(mine)].mean(axis=0)))
    return sorted(out, key=lambda e: -e[0])


def coarse_mesh_problem(surface, cell_mm: float) -> str | None:
    """A message when a tool's triangles miss its curved geometry by much (None if not).

    Over the edges between two triangles that bend by θ below :data:`CREASE_DEG` (curvature,
    not a crease), h·θ/6 for an edge of length h is how far the middle of a flat triangle
    sits from the sphere through its corners (radius ρ = h/θ: the sag r²/(2ρ) at the centre
    of an equilateral triangle, r = h/√3 its corners' distance); beyond
    :data:`COARSE_CHORD_OF_CELL` of the sheet's cell the formed part changes.
    """
    n = surface.face_normals
    nbr = surface.neighbours
    tri = np.repeat(np.arange(len(n)), 3)
    other = nbr.ravel()
    ok = other > tri  # each inner edge once
    tri, other = tri[ok], other[ok]
    θ = np.arccos(np.clip(np.einsum("ij,ij->i", n[tri], n[other]), -1.0, 1.0))
    p, t = surface.points, surface.triangles
    side = np.flatnonzero(ok) % 3
    a = p[t[tri, side]]
    b = p[t[tri, (side + 1) % 3]]
    h = np.linalg.norm(b - a, axis=1)
    curved = θ < np.radians(CREASE_DEG)
    if not curved.any():
        return None
    chord = h[curved] * θ[curved] / 6.0
    worst = int(np.argmax(chord))
    if chord[worst] <= COARSE_CHORD_OF_CELL * cell_mm:
        return None
    return (f"the tool mesh is coarse for its curved geometry: its flat triangles miss the "
            f"surface by up to about {chord[worst]:.3g} mm (an edge of {h[curved][worst]:.3g} "
            f"mm bending by {np.degrees(θ[curved][worst]):.3g}°), more than "
            f"{COARSE_CHORD_OF_CELL:g} of the sheet's cell {cell_mm:g} mm; give a smaller "
            "mesh_mm (or order = 2)")
