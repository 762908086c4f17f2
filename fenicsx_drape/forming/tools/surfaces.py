"""Tool surfaces as triangle meshes: read from Gmsh scripts, CAD files, STL or Gmsh meshes.

A rigid tool that is not a closed-form surface (:mod:`~fenicsx_drape.forming.tools.shapes`) is a
:class:`TriangleSurface`: points (mm) and flat triangles. :func:`load_surface` makes one from

- a Gmsh script ``.geo``: numbers of ``parameters`` are handed to Gmsh's parser before the
  script runs, so ``DefineConstant[punch_radius_mm = 60];`` takes the value given (a name
  with a slash, ``"Parameters/R"``, is set as the ONELAB parameter of that name instead);
- a Python file using the Gmsh API that defines ``build(gmsh, **parameters)``: it is called
  with Gmsh initialised and an empty current model, adds the geometry (and may mesh it);
- STEP (``.step``/``.stp``), IGES (``.iges``/``.igs``) and BREP files, read by Gmsh's
  OpenCASCADE kernel in millimetres (``Geometry.OCCTargetUnit = "MM"``);
- an STL file or a Gmsh ``.msh`` mesh: their triangles are taken as they are.

Sources without a mesh are meshed into triangles with ``mesh_size_mm`` as the largest size
(``Mesh.MeshSizeMax``; the script's own sizes otherwise). With ``order=2`` the triangles get
mid-side nodes on the CAD geometry (``setOrder(2)``); every six-node triangle is then split
into four flat triangles through its mid-side nodes, so the flat surface's chordal error falls
from h²/(8ρ) to about h²/(32ρ) at the same number of Gmsh elements (ρ the radius of
curvature). Quadrangles are split into two triangles (nine-node ones into eight).

**Orientation.** Coincident points are merged (tolerance 1e-7 of the bounding box's
diagonal), triangles that lose a corner dropped. The triangles of every connected piece are
oriented consistently (a non-orientable or non-manifold piece is an error), then flipped so
that their normals point out of the tool material: outwards for a closed piece (positive
enclosed volume), towards ``sheet_side`` for an open one (the side of the surface the sheet
is on: ``"+z"``, ``"-x"``, ... or a vector; the piece's area-weighted mean normal decides).

**Closest points** (:meth:`TriangleSurface.closest`): exact point-triangle projection
(Ericson's Voronoi-region test) over candidate triangles from a k-d tree of triangle
centroids: with d the distance to the nearest candidate found and ρ_max the largest distance
from a centroid to its corners, every triangle whose centroid is within d + ρ_max of the point
is a candidate, which makes the search exact. The point's closest *feature* (a face, an edge,
a corner) gives the sign of the distance through the angle-weighted pseudo-normals of
Bærentzen & Aanæs (IEEE TVCG 11, 2005): face normal, sum of the two face normals at an edge,
angle-weighted sum at a corner. Points whose closest feature lies on the boundary of an open
surface (an edge with one triangle) are counted outside: the distance is positive beyond
the edge of a holder's plate or a punch's rim, whatever the side. ``on_boundary`` tells
them, which is how a clamping surface knows the nodes it *covers*.

**Gmsh in-process, MPI.** Gmsh runs on rank 0 only; the surface is broadcast to every rank.
Gmsh is initialised if nobody did, and finalised again afterwards; in a session the caller
started, every model added (ours, and any a ``build()`` adds) is removed and the mesh options
touched are put back, also after an error. The parser's variables and the ONELAB parameters
are cleared before a script runs so that no value leaks from one file to the next (in a
caller's session too).

**Read once per process.** A surface read is kept (the :data:`_READ_CACHE` latest) under its
file's bytes, the other files of its folder (size and time: a script's ``Include``) and the
reading's arguments: a diagnosis forms the same tools dozens of times, and Gmsh meshing them
took a third of each run.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.tools.checks import WELD_TOLERANCE as _WELD_TOLERANCE
from fenicsx_drape.provenance import file_digest

#: Geometry sources by suffix.
CAD_SUFFIXES = (".step", ".stp", ".iges", ".igs", ".brep")
MESH_SUFFIXES = (".stl", ".msh")
SUFFIXES = (".geo", ".py", *CAD_SUFFIXES, *MESH_SUFFIXES)

_AXES = {"x": 0, "y": 1, "z": 2}
_READ_CACHE = 16
_read_cache: dict[tuple, TriangleSurface] = {}

# Regions of the closest point on a triangle (a, b, c): the face, the corners, the edges.
FACE, CORNER_A, CORNER_B, CORNER_C, EDGE_AB, EDGE_BC, EDGE_CA = range(7)
_ALL_PAIRS = 16384  # nearest(): up to this many point-triangle pairs, all are measured


def sheet_side_vector(side: str | Sequence[float] | None) -> np.ndarray:
    """The unit vector of a ``sheet_side`` (``"+z"``, ``"-x"``, ... or a vector)."""
    if side is None:
        side = "+z"
    if isinstance(side, str):
        s = side.strip().lower()
        if len(s) == 2 and s[0] in "+-" and s[1] in _AXES:
            v = np.zeros(3)
            v[_AXES[s[1]]] = 1.0 if s[0] == "+" else -1.0
            return v
        raise DrapeInputError(f"sheet_side {side!r}: expected '+x', '-x', '+y', '-y', '+z', "
                              "'-z' or a vector")
    v = np.asarray(side, dtype=float).ravel()
    if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
        raise DrapeInputError(f"sheet_side {side!r}: expected a non-zero vector of 3 numbers")
    return v / np.linalg.norm(v)


# --------------------------------------------------------------------------------------------
# Point-triangle geometry


def _barycentric(d1, d2, aa, ac_ab, cc):
    """Ericson's region test from the scalars of a point p and a triangle (a, b, c).

    With ab = b − a, ac = c − a, ap = p − a: ``d1 = ab·ap``, ``d2 = ac·ap``, ``aa = ab·ab``,
    ``ac_ab = ab·ac``, ``cc = ac·ac``. Returns the coordinates (v, w) of the closest point
    q = a + v ab + w ac and its region (Ericson, *Real-Time Collision Detection*, 2005,
    section 5.1.5; vectorised: his tests in his order, the first that holds wins).
    """
    d3, d4 = d1 - aa, d2 - ac_ab  # ab·bp, ac·bp
    d5, d6 = d1 - ac_ab, d2 - cc  # ab·cp, ac·cp
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    e4, e5 = d4 - d3, d5 - d6
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        ok = denom != 0.0
        v = np.where(ok, vb / np.where(ok, denom, 1.0), 0.0)
        w = np.where(ok, vc / np.where(ok, denom, 1.0), 0.0)
        t_ab = np.clip(np.nan_to_num(d1 / (d1 - d3)), 0.0, 1.0)
        t_ca = np.clip(np.nan_to_num(d2 / (d2 - d6)), 0.0, 1.0)
        t_bc = np.clip(np.nan_to_num(e4 / (e4 + e5)), 0.0, 1.0)
    region = np.full(np.shape(d1), FACE, dtype=np.int8)
    cases = (  # (test, region, v, w), applied last to first so that the first one wins
        ((va <= 0.0) & (e4 >= 0.0) & (e5 >= 0.0), EDGE_BC, 1.0 - t_bc, t_bc),
        ((vb <= 0.0) & (d2 >= 0.0) & (d6 <= 0.0), EDGE_CA, 0.0, t_ca),
        ((d6 >= 0.0) & (d5 <= d6), CORNER_C, 0.0, 1.0),
        ((vc <= 0.0) & (d1 >= 0.0) & (d3 <= 0.0), EDGE_AB, t_ab, 0.0),
        ((d3 >= 0.0) & (d4 <= d3), CORNER_B, 1.0, 0.0),
        ((d1 <= 0.0) & (d2 <= 0.0), CORNER_A, 0.0, 0.0),
    )
    for test, code, vv, ww in cases:
        region[test] = code
        v = np.where(test, vv, v)
        w = np.where(test, ww, w)
    return v, w, region


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                         c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The closest points of triangles (a, b, c) to points p (all (n, 3)), and their regions.

    The region (``FACE``, ``CORNER_*``, ``EDGE_*``) is that of the closest point (Ericson's
    Voronoi-region test). Degenerate triangles give one of their corners or edges.
    """
    ab, ac, ap = b - a, c - a, p - a

    def dot(u, v):
        return np.einsum("ij,ij->i", u, v)

    v, w, region = _barycentric(dot(ab, ap), dot(ac, ap), dot(ab, ab), dot(ab, ac), dot(ac, ac))
    return a + v[:, None] * ab + w[:, None] * ac, region


# --------------------------------------------------------------------------------------------
# The surface


class TriangleSurface:
    """A rigid tool surface: flat triangles, consistently oriented, normals out of the tool.

    Args:
        points: Node positions (n, 3) in mm.
        triangles: Node indices (m, 3).
        sheet_side: The side the sheet is on, for open pieces (see the module docstring).
        source: Where the surface came from (named in messages).
        prepared: The arrays are already merged and oriented (skip that work: broadcasts,
            cache).
    """

    def __init__(self, points: np.ndarray, triangles: np.ndarray, *,
                 sheet_side: str | Sequence[float] | None = "+z", source: str = "surface",
                 prepared: bool = False) -> None:
        self.source = str(source)
        self.sheet_side = sheet_side if isinstance(sheet_side, str) or sheet_side is None \
            else tuple(float(v) for v in sheet_side)
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        if len(triangles) == 0:
            raise DrapeInputError(f"{self.source}: no triangles (no surface in it)")
        if not np.all(np.isfinite(points)):
            raise DrapeInputError(f"{self.source}: a point is not finite")
        if triangles.min() < 0 or triangles.max() >= len(points):
            raise DrapeInputError(f"{self.source}: a triangle refers to a missing point")
        if not prepared:
            points, triangles = _weld(points, triangles)
            if len(triangles) == 0:
                raise DrapeInputError(f"{self.source}: every triangle is degenerate")
            triangles = self._orient(points, triangles, sheet_side_vector(sheet_side))
        self.points = np.ascontiguousarray(points)
        self.triangles = np.ascontiguousarray(triangles)
        self.points.flags.writeable = False
        self.triangles.flags.writeable = False

    def __repr__(self) -> str:
        return (f"TriangleSurface({self.source!r}, {len(self.points)} points, "
                f"{len(self.triangles)} triangles)")

    def __getstate__(self):
        return {"points": self.points, "triangles": self.triangles, "source": self.source,
                "sheet_side": self.sheet_side}

    def __setstate__(self, state) -> None:
        self.__init__(state["points"], state["triangles"], sheet_side=state["sheet_side"],
                      source=state["source"], prepared=True)

    # -- topology -----------------------------------------------------------------------

    @staticmethod
    def _edges(triangles: np.ndarray):
        """Unique undirected edges, the edge of every triangle side, faces per edge."""
        m = len(triangles)
        directed = triangles[:, [0, 1, 1, 2, 2, 0]].reshape(m, 3, 2)
        key = np.sort(directed, axis=2).reshape(-1, 2)
        edges, inverse, counts = np.unique(key, axis=0, return_inverse=True,
                                           return_counts=True)
        return edges, inverse.reshape(m, 3), counts

    def _orient(self, points: np.ndarray, triangles: np.ndarray,
                side: np.ndarray) -> np.ndarray:
        """Consistent orientation per connected piece, normals out of the tool material."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        m = len(triangles)
        edges, tri_edge, counts = self._edges(triangles)
        if counts.max() > 2:
            e = edges[np.argmax(counts)]
            raise DrapeInputError(
                f"{self.source}: non-manifold surface: {counts.max()} triangles share the "
                f"edge between points {points[e[0]].round(6).tolist()} and "
                f"{points[e[1]].round(6).tolist()} (select one surface, e.g. a physical group)")
        # Pairs of triangles that share an edge, and whether they traverse it the same way.
        flat = tri_edge.ravel()
        order = np.argsort(flat, kind="stable")
        shared = counts[flat[order]] == 2
        first, second = order[shared][0::2], order[shared][1::2]
        f1, f2 = first // 3, second // 3
        start = triangles.ravel()
        same = start[first] == start[second]  # same start point: same direction of traversal
        # A doubled graph: node f (as is) and f + m (flipped); an edge links the orientations
        # that agree. A piece whose two copies meet is not orientable.
        rows = np.concatenate([f1, f1 + m])
        cols = np.concatenate([np.where(same, f2 + m, f2), np.where(same, f2, f2 + m)])
        g = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(2 * m, 2 * m))
        _, label = connected_components(g, directed=False)
        if np.any(label[:m] == label[m:]):
            raise DrapeInputError(f"{self.source}: the surface is not orientable")
        # In each piece, keep the copies in the piece's first triangle's class.
        _, piece = connected_components(coo_matrix((np.ones(len(f1)), (f1, f2)),
                                                   shape=(m, m)), directed=False)
        ref = np.full(piece.max() + 1, -1)
        ref[piece[::-1]] = label[:m][::-1]  # the label of the first triangle of each piece
        flip = label[:m] != ref[piece]
        tri = np.where(flip[:, None], triangles[:, [0, 2, 1]], triangles)
        # Which way round: out of the material.
        a, b, c = points[tri[:, 0]], points[tri[:, 1]], points[tri[:, 2]]
        cross = np.cross(b - a, c - a)  # twice the area times the normal
        volume = np.einsum("ij,ij->i", a, cross)  # six times the signed volume (closed)
        open_edge = counts[tri_edge] == 1
        pieces = piece.max() + 1
        is_open = np.bincount(piece, open_edge.any(axis=1), minlength=pieces) > 0
        vol = np.bincount(piece, volume, minlength=pieces)
        towards = np.bincount(piece, cross @ side, minlength=pieces)
        area = np.bincount(piece, np.linalg.norm(cross, axis=1), minlength=pieces)
        ambiguous = is_open & (np.abs(towards) < 1e-6 * area)
        if ambiguous.any():
            raise DrapeInputError(
                f"{self.source}: cannot tell which side of an open surface the sheet is on "
                f"(its mean normal is perpendicular to sheet_side {self.sheet_side!r}); give "
                "another sheet_side")
        reverse = np.where(is_open, towards < 0.0, vol < 0.0)
        return np.where(reverse[piece][:, None], tri[:, [0, 2, 1]], tri)

    @functools.cached_property
    def _topology(self):
        edges, tri_edge, counts = self._edges(self.triangles)
        boundary_edge = counts == 1
        boundary_point = np.zeros(len(self.points), dtype=bool)
        boundary_point[edges[boundary_edge].ravel()] = True
        return edges, tri_edge, boundary_edge, boundary_point

    @functools.cached_property
    def neighbours(self) -> np.ndarray:
        """The triangle across each side (m, 3) of every triangle, −1 on the boundary."""
        _, tri_edge, _, _ = self._topology
        flat = tri_edge.ravel()
        order = np.argsort(flat, kind="stable")
        pair = flat[order][1:] == flat[order][:-1]
        first, second = order[:-1][pair], order[1:][pair]
        out = np.full(flat.shape, -1, dtype=np.int64)
        out[first], out[second] = second // 3, first // 3
        return out.reshape(-1, 3)

    @functools.cached_property
    def stars(self) -> tuple[np.ndarray, np.ndarray]:
        """The triangles at every point, CSR: ``tris[ptr[i]:ptr[i + 1]]`` touch point i."""
        flat = self.triangles.ravel()
        order = np.argsort(flat, kind="stable")
        ptr = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=len(self.points)))])
        return ptr, order // 3

    def local_candidates(self, tri: np.ndarray, region: np.ndarray):
        """Triangles that may be closer than ``tri`` to a point whose closest point is ``region``.

        Across the edge, around the corner, or across the face's edges (concave regions).
        Returns ``(which, candidate)``: index into ``tri`` and a triangle, pair by pair.
        """
        which, cand = [], []
        nbr = self.neighbours
        # In a concave region the prisms over neighbouring faces overlap: a point whose
        # closest point is inside a face can still be closer to the face next door.
        i = np.flatnonzero(region == FACE)
        c = nbr[tri[i]]
        ok = c >= 0
        which.append(np.repeat(i, 3).reshape(-1, 3)[ok])
        cand.append(c[ok])
        for code, k in ((EDGE_AB, 0), (EDGE_BC, 1), (EDGE_CA, 2)):
            i = np.flatnonzero(region == code)
            c = nbr[tri[i], k]
            ok = c >= 0
            which.append(i[ok])
            cand.append(c[ok])
        ptr, star = self.stars
        for code, k in ((CORNER_A, 0), (CORNER_B, 1), (CORNER_C, 2)):
            i = np.flatnonzero(region == code)
            v = self.triangles[tri[i], k]
            count = ptr[v + 1] - ptr[v]
            which.append(np.repeat(i, count))
            start = np.repeat(ptr[v] - np.cumsum(count) + count, count)
            cand.append(star[start + np.arange(count.sum())])
        return np.concatenate(which), np.concatenate(cand)

    @property
    def edges(self) -> np.ndarray:
        """Unique edges (k, 2) as point indices."""
        return self._topology[0]

    @property
    def boundary_edges(self) -> np.ndarray:
        """Edges (k, 2) with one triangle: the boundary of an open surface."""
        return self.edges[self._topology[2]]

    @property
    def closed(self) -> bool:
        """Whether the surface has no boundary."""
        return not self._topology[2].any()

    @functools.cached_property
    def face_normals(self) -> np.ndarray:
        """Unit normals (m, 3) of the triangles, out of the tool (zero for degenerate ones)."""
        p, t = self.points, self.triangles
        n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
        length = np.linalg.norm(n, axis=1)
        return n / np.where(length > 0.0, length, 1.0)[:, None]

    @functools.cached_property
    def areas(self) -> np.ndarray:
        """Triangle areas (m,) in mm²."""
        p, t = self.points, self.triangles
        n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
        return 0.5 * np.linalg.norm(n, axis=1)

    @functools.cached_property
    def _pseudo_normals(self) -> tuple[np.ndarray, np.ndarray]:
        """Angle-weighted point pseudo-normals and edge pseudo-normals (Bærentzen & Aanæs)."""
        p, t, nf = self.points, self.triangles, self.face_normals
        point_n = np.zeros_like(p)
        for k in range(3):
            u = p[t[:, (k + 1) % 3]] - p[t[:, k]]
            v = p[t[:, (k + 2) % 3]] - p[t[:, k]]
            cos = np.einsum("ij,ij->i", u, v) / np.maximum(
                np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1), 1e-300)
            angle = np.arccos(np.clip(cos, -1.0, 1.0))
            np.add.at(point_n, t[:, k], angle[:, None] * nf)
        edges, tri_edge = self._topology[:2]
        edge_n = np.zeros((len(edges), 3))
        for k in range(3):
            np.add.at(edge_n, tri_edge[:, k], nf)
        return point_n, edge_n

    @functools.cached_property
    def content_hash(self) -> str:
        """A hash of the points and triangles (cache key of derived data)."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.points, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(self.triangles, dtype="<i8").tobytes())
        return h.hexdigest()

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounding box (lower, upper corner) in mm."""
        return self.points.min(axis=0), self.points.max(axis=0)

    @functools.cached_property
    def mesh_size_mm(self) -> float:
        """The tool mesh's size (mm): the side of an equilateral triangle of the median area.

        The median is taken over the surface's area: half of it lies on smaller triangles.
        """
        a = np.sort(self.areas)
        k = np.searchsorted(np.cumsum(a), 0.5 * a.sum())
        return float(np.sqrt(4.0 / np.sqrt(3.0) * a[min(k, len(a) - 1)]))

    # -- closest points -----------------------------------------------------------------

    def nearest(self, x: np.ndarray, chunk: int = 20000):
        """Closest points and the features they lie on, exactly.

        Args:
            x: Points (n, 3) in mm.
            chunk: Points handled at a time (memory).

        Returns:
            ``(q, d, tri, region)``: the closest points (n, 3), distances (n,), the
            triangle (n,) and the region of it (n,) the closest point lies in.
        """
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        n = len(x)
        q, d = np.empty((n, 3)), np.empty(n)
        tri, region = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int8)
        for s in range(0, n, chunk):
            sl = slice(s, min(s + chunk, n))
            q[sl], d[sl], tri[sl], region[sl] = self._nearest(x[sl])
        return q, d, tri, region

    @functools.cached_property
    def _frames(self):
        """Per triangle: a, ab, ac and the dot products ab·ab, ab·ac, ac·ac."""
        p, t = self.points, self.triangles
        a = p[t[:, 0]]
        ab, ac = p[t[:, 1]] - a, p[t[:, 2]] - a
        dots = np.column_stack([np.einsum("ij,ij->i", ab, ab), np.einsum("ij,ij->i", ab, ac),
                                np.einsum("ij,ij->i", ac, ac)])
        return a, ab, ac, dots

    def _pairs(self, x: np.ndarray, tri: np.ndarray):
        """Squared distances, (v, w) and regions of points x (n, 3) to triangles tri (n,)."""
        a, ab, ac, dots = self._frames
        ap = x - a[tri]
        AB, AC = ab[tri], ac[tri]
        d1 = np.einsum("ij,ij->i", AB, ap)
        d2 = np.einsum("ij,ij->i", AC, ap)
        D = dots[tri]
        v, w, region = _barycentric(d1, d2, D[:, 0], D[:, 1], D[:, 2])
        # |ap − v ab − w ac|² from the scalars (no 3-vectors per candidate).
        dist2 = (np.einsum("ij,ij->i", ap, ap) - 2.0 * (v * d1 + w * d2)
                 + v * v * D[:, 0] + 2.0 * v * w * D[:, 1] + w * w * D[:, 2])
        return np.maximum(dist2, 0.0), v, w, region

    @functools.cached_property
    def _tree(self):
        """k-d trees of triangle centroids: one of all, and one per size class.

        A triangle is no closer than its centroid's distance minus its *reach* (largest
        centroid-corner distance); bounding by the largest reach of all would make a point
        near many small triangles look at hundreds of them, so triangles are grouped by
        reach (factors of two) and each group is searched with its own bound.
        """
        from scipy.spatial import cKDTree

        p, t = self.points, self.triangles
        centroid = p[t].mean(axis=1)
        reach = np.linalg.norm(p[t] - centroid[:, None, :], axis=2).max(axis=1)
        level = np.floor(np.log2(np.maximum(reach, 1e-300) / max(reach.max(), 1e-300)))
        level = np.maximum(level, -6)  # at most 7 groups
        groups = []
        for lv in np.unique(level):
            ids = np.flatnonzero(level == lv)
            groups.append((cKDTree(centroid[ids]), float(reach[ids].max()), ids))
        return cKDTree(centroid), float(reach.max()), groups

    _k_start = 8  # candidates per point in the first round of a group's search

    def _nearest(self, x: np.ndarray):
        n, m = len(x), len(self.triangles)
        if n * m <= _ALL_PAIRS:  # few pairs (a holder ring per step): measure them all
            d2, _, _, region = self._pairs(np.repeat(x, m, axis=0), np.tile(np.arange(m), n))
            d2, region = d2.reshape(n, m), region.reshape(n, m)
            # Triangles equally close to rounding (a point on an edge or corner they share):
            # one whose face holds the point wins over an edge or a corner.
            tie = d2 <= d2.min(axis=1, keepdims=True) + 1e-12
            best_t = np.argmax(np.where(tie, 1 + (region == FACE), 0), axis=1)
        else:
            tree, _, groups = self._tree
            # A first bound: the triangles of the 4 nearest centroids.
            k = min(4, m)
            _, cand = tree.query(x, k=k)
            cand = cand.reshape(n, -1)
            d2 = self._pairs(np.repeat(x, cand.shape[1], axis=0), cand.ravel())[0]
            d2 = d2.reshape(n, -1)
            j = np.argmin(d2, axis=1)
            best, best_t = d2[np.arange(n), j], cand[np.arange(n), j]
            for gtree, reach, ids in groups:
                self._search(x, gtree, reach, ids, best, best_t)
        # The winners again, with their closest points and regions.
        _, v, w, region = self._pairs(x, best_t)
        a, ab, ac, _ = self._frames
        q = a[best_t] + v[:, None] * ab[best_t] + w[:, None] * ac[best_t]
        return q, np.linalg.norm(x - q, axis=1), best_t, region

    def _search(self, x, tree, reach, ids, best, best_t) -> None:
        """Improve ``best`` (squared distances) and ``best_t`` over one group of triangles.

        Candidates come in order of centroid distance, k at a time (k doubling); a triangle
        whose centroid is farther than the best distance plus ``reach`` cannot be closer.
        """
        m = len(ids)
        todo = np.arange(len(x))
        k0, k = 0, min(self._k_start, m)
        while len(todo):
            # The k-d tree takes one upper bound per query: points in groups of similar bound.
            todo = todo[np.argsort(best[todo])]
            bound = np.sqrt(best[todo])
            dist_c = np.empty((len(todo), k))
            cand = np.empty((len(todo), k), dtype=np.int64)
            for part in np.array_split(np.arange(len(todo)), min(8, len(todo))):
                dc, cc = tree.query(x[todo[part]], k=k,
                                    distance_upper_bound=bound[part[-1]] + reach)
                dist_c[part], cand[part] = dc.reshape(len(part), -1), cc.reshape(len(part), -1)
            dist_c, cand = dist_c[:, k0:], cand[:, k0:]
            row, col = np.nonzero(dist_c - reach < bound[:, None])  # inf (none) drops out
            pts, tri = todo[row], ids[cand[row, col]]
            for s in range(0, len(pts), 65536):  # chunks that stay in cache
                ps, ts = pts[s:s + 65536], tri[s:s + 65536]
                d2 = self._pairs(x[ps], ts)[0]
                # The best pair per point: sort by (point, distance), take each one's first.
                order = np.lexsort((d2, ps))
                first = order[np.r_[True, ps[order][1:] != ps[order][:-1]]]
                better = d2[first] < best[ps[first]]
                win = ps[first][better]
                best[win], best_t[win] = d2[first][better], ts[first][better]
            # Done once the farthest centroid looked at is beyond the bound (or missing).
            done = (dist_c[:, -1] - reach >= np.sqrt(best[todo])) | (k >= m)
            todo = todo[~done]
            k0, k = k, min(2 * k, m)

    def _feature_normals(self, tri: np.ndarray, region: np.ndarray):
        """Pseudo-normal and boundary flag of the closest features ``(tri, region)``."""
        point_n, edge_n = self._pseudo_normals
        _, tri_edge, boundary_edge, boundary_point = self._topology
        t = self.triangles
        N = self.face_normals[tri].copy()
        on_boundary = np.zeros(len(tri), dtype=bool)
        for code, k in ((CORNER_A, 0), (CORNER_B, 1), (CORNER_C, 2)):
            m = region == code
            v = t[tri[m], k]
            N[m], on_boundary[m] = point_n[v], boundary_point[v]
        for code, k in ((EDGE_AB, 0), (EDGE_BC, 1), (EDGE_CA, 2)):
            m = region == code
            e = tri_edge[tri[m], k]
            N[m], on_boundary[m] = edge_n[e], boundary_edge[e]
        return N, on_boundary

    def closest(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The closest surface points, distances and whether they lie on the boundary.

        Args:
            x: Points (n, 3) in mm.

        Returns:
            ``(closest_points (n, 3), distance (n,) in mm, on_boundary (n,) bool)``:
            ``on_boundary`` is True where the closest point is on an edge of an open
            surface (the point lies beyond the surface's edge, not under it).
        """
        q, d, tri, region = self.nearest(x)
        _, on_boundary = self._feature_normals(tri, region)
        return q, d, on_boundary

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """Exact signed distance (n,) in mm: positive on the sheet's side (out of the tool).

        The sign is that of (x − q)·N with N the angle-weighted pseudo-normal of the closest
        feature; beyond the edge of an open surface the distance counts as positive.
        """
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        q, d, tri, region = self.nearest(x)
        N, on_boundary = self._feature_normals(tri, region)
        side = np.einsum("ij,ij->i", x - q, N)
        return np.where(on_boundary | (side >= 0.0), d, -d)


def _weld(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge coincident points, drop degenerate triangles and unused points.

    A triangle is degenerate when it lost a corner in the merge or has no area (its corners
    on a line: :data:`~fenicsx_drape.forming.tools.checks.FLAT_TRIANGLE`), as the mesh check
    says (:func:`~fenicsx_drape.forming.tools.checks.mesh_defects`: "ignored"): it covers
    nothing, and left in it would make an edge look shared by three triangles.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from fenicsx_drape.forming.tools.checks import FLAT_TRIANGLE

    lo, hi = points.min(axis=0), points.max(axis=0)
    tol = _WELD_TOLERANCE * max(float(np.linalg.norm(hi - lo)), 1e-300)
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    if len(pairs):
        n = len(points)
        g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        _, label = connected_components(g, directed=False)
        first = np.full(label.max() + 1, -1)
        first[label[::-1]] = np.arange(n)[::-1]
        triangles = first[label][triangles]
    keep = ((triangles[:, 0] != triangles[:, 1]) & (triangles[:, 1] != triangles[:, 2])
            & (triangles[:, 2] != triangles[:, 0]))
    a, b, c = (points[triangles[:, k]] for k in range(3))
    longest = np.max([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                      np.linalg.norm(a - c, axis=1)], axis=0)
    keep &= np.linalg.norm(np.cross(b - a, c - a), axis=1) > FLAT_TRIANGLE * longest**2
    triangles = triangles[keep]
    used, inverse = np.unique(triangles, return_inverse=True)
    return points[used], inverse.reshape(-1, 3)


# --------------------------------------------------------------------------------------------
# Reading with Gmsh

# Element types of Gmsh split into flat triangles (local node indices of each triangle).
_SPLITS = {
    2: np.array([[0, 1, 2]]),  # 3-node triangle
    9: np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]]),  # 6-node: through mid-sides
    3: np.array([[0, 1, 2], [0, 2, 3]]),  # 4-node quadrangle
    10: np.array([[0, 4, 8], [0, 8, 7], [4, 1, 5], [4, 5, 8],  # 9-node quadrangle
                  [8, 5, 2], [8, 2, 6], [7, 8, 6], [7, 6, 3]]),
}


def load_surface(path: str | os.PathLike, parameters: Mapping[str, float] | None = None,
                 mesh_size_mm: float | None = None, order: int = 1, *,
                 sheet_side: str | Sequence[float] | None = "+z",
                 physical: str | None = None, comm=None) -> TriangleSurface:
    """Read a tool surface from a Gmsh script, a Python/Gmsh file, CAD, STL or ``.msh``.

    Args:
        path: The geometry file (suffix: ``.geo``, ``.py``, ``.step``/``.stp``,
            ``.iges``/``.igs``, ``.brep``, ``.stl``, ``.msh``).
        parameters: Numbers for the source: Gmsh parser variables (``DefineConstant``) of a
            ``.geo`` (names with a ``/`` are ONELAB parameters), keyword arguments of a
            ``.py`` file's ``build(gmsh, **parameters)``; not allowed for other files.
        mesh_size_mm: Largest triangle size when Gmsh meshes the geometry
            (``Mesh.MeshSizeMax``); default: the source's own sizes.
        order: 1, or 2 for curved six-node triangles (split into four flat ones) where the
            source has a geometry (not STL/``.msh``, whose elements are taken as they are).
        sheet_side: The side of an open surface the sheet is on (see the module docstring).
        physical: Take only the surfaces of this physical group (by name).
        comm: MPI communicator: rank 0 reads, every rank gets the surface (default: the
            world when mpi4py is there).

    Returns:
        The surface, oriented.

    Raises:
        DrapeInputError: naming the file (missing, unknown kind, Gmsh's error text, no
            surface in it, bad parameters).
    """
    path = Path(path)
    if comm is None:
        try:
            from mpi4py import MPI

            comm = MPI.COMM_WORLD
        except ImportError:
            comm = None
    result: object = None
    if comm is None or comm.rank == 0:
        try:
            result = _read_once(path, parameters, mesh_size_mm, order, sheet_side, physical)
        except DrapeInputError as error:
            result = error
    if comm is not None and comm.size > 1:
        result = comm.bcast(result, root=0)
    if isinstance(result, DrapeInputError):
        raise result
    return result


def _read_once(path: Path, parameters, mesh_size_mm, order, sheet_side,
               physical) -> TriangleSurface:
    """:func:`_read`, kept per process (the module doc); surfaces are immutable."""
    if not path.is_file():
        return _read(path, parameters, mesh_size_mm, order, sheet_side, physical)
    folder = sorted((e.name, e.stat().st_size, e.stat().st_mtime_ns)
                    for e in os.scandir(path.parent) if e.is_file() and e.name != path.name)
    key = (str(path.resolve()), file_digest(path), tuple(folder),
           repr(sorted((parameters or {}).items())), mesh_size_mm, order, repr(sheet_side),
           physical)
    if key not in _read_cache:
        surface = _read(path, parameters, mesh_size_mm, order, sheet_side, physical)
        while len(_read_cache) >= _READ_CACHE:
            _read_cache.pop(next(iter(_read_cache)))
        _read_cache[key] = surface
    return _read_cache[key]


def _read(path: Path, parameters, mesh_size_mm, order, sheet_side,
          physical) -> TriangleSurface:
    """Check the source, then read it: scripts in a child process with a time limit."""
    suffix = path.suffix.lower()
    if suffix == ".geo" and path.is_file():
        from fenicsx_drape.trust import check_geo, geo_defines

        check_geo(path)
        unknown = [k for k in (parameters or {}) if not geo_defines(path, k)]
        if unknown:
            raise DrapeInputError(f"{path}: parameter(s) {', '.join(map(repr, unknown))} "
                                  "not used by the script (a misspelt name would be ignored)")
    if suffix == ".stl" and path.is_file():
        from fenicsx_drape.forming.tools.checks import stl_problems

        if problems := stl_problems(path):
            raise DrapeInputError("; ".join(problems))
    if suffix in (".geo", ".py") and path.is_file():
        from fenicsx_drape.limits import run_script

        points, triangles = run_script(_read_raw, (path, parameters, mesh_size_mm, order,
                                                   sheet_side, physical), path)
    else:
        points, triangles = _read_raw(path, parameters, mesh_size_mm, order, sheet_side,
                                      physical)
    _check_mesh(points, triangles, path)
    return TriangleSurface(points, triangles, sheet_side=sheet_side, source=str(path))


def _check_mesh(points: np.ndarray, triangles: np.ndarray, path: Path) -> None:
    """The mesh as the mesher returned it, checked (:mod:`.checks`): refused or warned."""
    import warnings

    from fenicsx_drape.forming.tools.checks import mesh_defects

    errors, warns = mesh_defects(points, triangles)
    if errors:
        raise DrapeInputError(f"{path}: the tool mesh is damaged: " + "; ".join(errors))
    for text in warns:
        warnings.warn(f"{path}: {text}", stacklevel=4)


def _read_raw(path: Path, parameters, mesh_size_mm, order, sheet_side,
              physical) -> tuple[np.ndarray, np.ndarray]:
    """The points and triangles of a source as Gmsh gives them (in this process)."""
    where = str(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise DrapeInputError(f"{where}: unknown kind of tool geometry (known: "
                              f"{', '.join(SUFFIXES)})")
    if not path.is_file():
        raise DrapeInputError(f"{where}: no such file")
    if order not in (1, 2):
        raise DrapeInputError(f"{where}: order = {order!r}: 1 or 2")
    if mesh_size_mm is not None and not (np.isfinite(mesh_size_mm) and mesh_size_mm > 0):
        raise DrapeInputError(f"{where}: mesh_size_mm = {mesh_size_mm!r} must be positive")
    parameters = dict(parameters or {})
    for k, v in parameters.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, np.number)) \
                or not np.isfinite(v):
            raise DrapeInputError(f"{where}: parameter {k!r} = {v!r} is not a finite number")
    if parameters and suffix not in (".geo", ".py"):
        raise DrapeInputError(f"{where}: parameters {sorted(parameters)} apply to .geo and "
                              f".py sources only")
    sheet_side_vector(sheet_side)  # checked before Gmsh runs

    import gmsh

    initialised = gmsh.isInitialized()
    if not initialised:
        gmsh.initialize(interruptible=False)
    models = set(gmsh.model.list())
    saved = _save_options(gmsh)
    model = f"fenicsx_drape_surface_{os.getpid()}_{id(path)}"
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.parser.clear()
        gmsh.onelab.clear()
        gmsh.model.add(model)
        try:
            if suffix == ".py":
                _run_build(gmsh, path, parameters)  # may add its own model and make it current
            else:
                if suffix == ".geo":
                    for k, v in parameters.items():
                        if "/" in k:
                            gmsh.onelab.setNumber(k, [float(v)])
                        else:
                            gmsh.parser.setNumber(k, [float(v)])
                if suffix in CAD_SUFFIXES:
                    gmsh.option.setString("Geometry.OCCTargetUnit", "MM")
                gmsh.merge(str(path))
            meshed = _has_triangles(gmsh)
            if not meshed:
                if not gmsh.model.getEntities(2):
                    raise DrapeInputError(f"{where}: no surface in it")
                if mesh_size_mm is not None:
                    gmsh.option.setNumber("Mesh.MeshSizeMax", float(mesh_size_mm))
                    gmsh.option.setNumber("Mesh.MeshSizeMin",
                                          min(gmsh.option.getNumber("Mesh.MeshSizeMin"),
                                              float(mesh_size_mm)))
                gmsh.model.mesh.generate(2)
            if order == 2 and suffix not in MESH_SUFFIXES and _max_order(gmsh) == 1:
                gmsh.option.setNumber("Mesh.SecondOrderLinear", 0)
                gmsh.model.mesh.setOrder(2)
            points, triangles = _triangles(gmsh, physical, where)
        except (DrapeInputError, MemoryError):
            raise
        except Exception as error:  # Gmsh reports its errors as plain exceptions
            raise DrapeInputError(f"{where}: Gmsh: {error}") from None
    finally:
        # Leave no model behind (ours and any a build() added), nor our options or parameters.
        for name in set(gmsh.model.list()) - models:
            gmsh.model.setCurrent(name)
            gmsh.model.remove()
        gmsh.parser.clear()
        gmsh.onelab.clear()
        if initialised:
            _restore_options(gmsh, saved)
        else:
            gmsh.finalize()
    return points, triangles


# Options this module or the project's scripts set: put back for a caller's Gmsh session.
_NUMBER_OPTIONS = ("General.Terminal", "Mesh.MeshSizeMax", "Mesh.MeshSizeMin",
                   "Mesh.MeshSizeFromCurvature", "Mesh.MeshSizeExtendFromBoundary",
                   "Mesh.ElementOrder", "Mesh.SecondOrderLinear")
_STRING_OPTIONS = ("Geometry.OCCTargetUnit",)


def _save_options(gmsh) -> dict:
    return ({k: gmsh.option.getNumber(k) for k in _NUMBER_OPTIONS},
            {k: gmsh.option.getString(k) for k in _STRING_OPTIONS})


def _restore_options(gmsh, saved) -> None:
    numbers, strings = saved
    for name, value in numbers.items():
        gmsh.option.setNumber(name, value)
    for name, value in strings.items():
        gmsh.option.setString(name, value)


def _run_build(gmsh, path: Path, parameters: dict) -> None:
    """Run ``build(gmsh, **parameters)`` of a Python geometry file."""
    import types

    name = f"_fenicsx_drape_geometry_{abs(hash(str(path.resolve())))}"
    module = types.ModuleType(name)
    module.__file__ = str(path)
    try:
        # Compiled from its text: no __pycache__ written next to the input.
        exec(compile(path.read_text(encoding="utf-8"), str(path), "exec"), module.__dict__)
    except Exception as error:
        raise DrapeInputError(f"{path}: could not run it: {type(error).__name__}: "
                              f"{error}") from None
    build = getattr(module, "build", None)
    if not callable(build):
        raise DrapeInputError(f"{path}: defines no function build(gmsh, **parameters)")
    try:
        build(gmsh, **parameters)
    except MemoryError:
        raise  # the memory limit's message (fenicsx_drape.limits)
    except TypeError as error:
        raise DrapeInputError(f"{path}: build(gmsh, **parameters) with parameters "
                              f"{sorted(parameters)}: {error}") from None
    except Exception as error:
        raise DrapeInputError(f"{path}: build() failed: {type(error).__name__}: "
                              f"{error}") from None
    if not gmsh.model.getEntities(2):  # build() did not synchronise its kernel
        with contextlib.suppress(Exception):
            gmsh.model.occ.synchronize()
        with contextlib.suppress(Exception):
            gmsh.model.geo.synchronize()


def _has_triangles(gmsh) -> bool:
    types = gmsh.model.mesh.getElementTypes(2)
    return len(types) > 0


def _max_order(gmsh) -> int:
    orders = [gmsh.model.mesh.getElementProperties(t)[2]
              for t in gmsh.model.mesh.getElementTypes(2)]
    return max(orders, default=1)


def _triangles(gmsh, physical: str | None, where: str) -> tuple[np.ndarray, np.ndarray]:
    """All (or one physical group's) 2D elements as flat triangles, and the points."""
    if physical is None:
        entities = [tag for _, tag in gmsh.model.getEntities(2)]
    else:
        groups = {gmsh.model.getPhysicalName(d, g): g
                  for d, g in gmsh.model.getPhysicalGroups(2)}
        if physical not in groups:
            raise DrapeInputError(f"{where}: no physical surface named {physical!r} "
                                  f"(there are: {sorted(groups) or 'none'})")
        entities = list(gmsh.model.getEntitiesForPhysicalGroup(2, groups[physical]))
    tags, xyz = gmsh.model.mesh.getNodes()[:2]
    xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
    index = np.full(int(tags.max(initial=0)) + 1, -1, dtype=np.int64)
    index[np.asarray(tags, dtype=np.int64)] = np.arange(len(tags))
    tris = []
    for entity in entities:
        types, _, nodes = gmsh.model.mesh.getElements(2, entity)
        for etype, enodes in zip(types, nodes):
            if etype not in _SPLITS:
                name = gmsh.model.mesh.getElementProperties(etype)[0]
                raise DrapeInputError(f"{where}: element type {name!r} is not supported "
                                      "(triangles and quadrangles of order 1 or 2)")
            split = _SPLITS[etype]
            conn = index[np.asarray(enodes, dtype=np.int64)].reshape(-1, _nodes_of(etype))
            tris.append(conn[:, split].reshape(-1, 3))
    if not tris:
        raise DrapeInputError(f"{where}: no surface in it (no 2D elements)")
    triangles = np.concatenate(tris)
    if (triangles < 0).any():
        raise DrapeInputError(f"{where}: an element refers to a missing node")
    return xyz, triangles


def _nodes_of(etype: int) -> int:
    return {2: 3, 9: 6, 3: 4, 10: 9}[etype]


def write_msh(surface: TriangleSurface, path: str | os.PathLike) -> Path:
    """Write a surface as a Gmsh mesh (format 2.2, ASCII, every number exact), atomically.

    Read back (:func:`load_surface`) it is the same surface: the same points and triangles,
    oriented by the same rule. A forming bundle's case carries its tools so (data, not code).
    """
    from fenicsx_drape.provenance import atomic_write_text

    p, t = surface.points, surface.triangles
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$Nodes", str(len(p))]
    lines += [f"{k + 1} {x!r} {y!r} {z!r}" for k, (x, y, z) in enumerate(p.tolist())]
    lines += ["$EndNodes", "$Elements", str(len(t))]
    lines += [f"{k + 1} 2 2 0 1 {a + 1} {b + 1} {c + 1}" for k, (a, b, c) in enumerate(t.tolist())]
    lines.append("$EndElements")
    return atomic_write_text(path, "\n".join(lines) + "\n")


# --------------------------------------------------------------------------------------------
# Outline curves


def sample_curve_loop(path: Path, spacing_mm: float) -> tuple[tuple[float, float], ...]:
    """The closed curve loop of a Gmsh file as a polygon, in this process.

    See :func:`~fenicsx_drape.forming.case.reading.sample_outline` (which checks a script first and
    runs this in a child process).
    """
    import gmsh

    initialised = gmsh.isInitialized()
    if not initialised:
        gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        gmsh.model.add("outline")
        try:
            gmsh.open(str(path))
        except Exception as err:  # Gmsh raises plain Exceptions with its message
            raise DrapeInputError(f"Gmsh cannot read {path.name} ({err})") from err
        if not gmsh.model.getEntities(1):
            raise DrapeInputError(f"{path.name} holds no curve")
        if not len(gmsh.model.mesh.getElements(1)[0]):
            gmsh.option.setNumber("Mesh.MeshSizeMax", spacing_mm)
            gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)
            gmsh.model.mesh.generate(1)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        xyz = dict(zip(tags.tolist(), np.asarray(coords).reshape(-1, 3)))
        edges = []
        for etype, _, nodes in zip(*gmsh.model.mesh.getElements(1)):
            n = gmsh.model.mesh.getElementProperties(etype)[3]
            edges.append(np.asarray(nodes).reshape(-1, n)[:, :2])  # the end nodes
    finally:
        gmsh.model.remove()
        if not initialised:
            gmsh.finalize()
    edges = np.concatenate(edges) if edges else np.zeros((0, 2), int)
    edges = edges[edges[:, 0] != edges[:, 1]]
    loop = _chain(edges, path.name)
    P = np.array([xyz[k] for k in loop])
    size = max(np.ptp(P[:, :2], axis=0).max(), 1e-300)
    if np.abs(P[:, 2]).max() > 1e-6 * size:
        raise DrapeInputError(f"{path.name}: the curve loop is not in the sheet plane z = 0 "
                              f"(|z| up to {np.abs(P[:, 2]).max():g} mm)")
    return tuple((float(x), float(y)) for x, y in P[:, :2])


def _chain(edges: np.ndarray, name: str) -> list[int]:
    """The nodes of one closed loop of line segments, in order."""
    if not len(edges):
        raise DrapeInputError(f"{name}: no curve segment")
    neighbours: dict[int, list[int]] = {}
    for a, b in edges.tolist():
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    if any(len(v) != 2 for v in neighbours.values()):
        raise DrapeInputError(f"{name}: the curves are not one closed loop (a curve end meets "
                              "no other curve, or three curves meet)")
    start = edges[0, 0]
    loop, previous, node = [start], None, start
    while True:
        a, b = neighbours[node]
        nxt = b if a == previous else a
        if nxt == start:
            break
        loop.append(nxt)
        previous, node = node, nxt
    if len(loop) != len(neighbours):
        raise DrapeInputError(f"{name}: the curves form {len(neighbours) - len(loop)} more "
                              "node(s) than one loop: the outline must be one closed curve loop")
    return loop
