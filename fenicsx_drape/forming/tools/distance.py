"""A smooth signed distance to a triangle surface: exact samples on a grid, cubic B-spline.

Penalty contact (:mod:`~fenicsx_drape.forming.terms.contact`) needs the signed gap φ of a node to
the tool, its gradient n = ∇φ (the force direction) and its Hessian ∇∇φ (the consistent
Jacobian). On a flat-faceted surface the exact distance has a normal that jumps across
every triangle edge and a Hessian that is zero on the faces and infinite at the edges: a node
sliding over an edge sees its force turn abruptly, Newton's quadratic convergence is lost
and the Jacobian is not that of the residual. Interpolated vertex normals would be smooth
but are not the gradient of any gap, so the penalty Jacobian would be neither consistent nor
symmetric (the hemisphere factors it with a symmetric LDLᵀ, so it has to be both).

Here φ is one C² function: the exact signed distance is sampled on a regular grid of spacing
``h`` and evaluated as a uniform tensor-product cubic B-spline whose coefficients are the
samples (the *approximating* spline, no interpolation solve):

    φ(x) = Σ_ijk c_ijk B((x − x_i)/h) B((y − y_j)/h) B((z − z_k)/h),   c_ijk = d(x_ijk),

with B the cubic B-spline. Force f = p(φ) ∇φ is then the gradient of the potential P(φ), and
K = p' ∇φ⊗∇φ + p ∇∇φ is exactly its (symmetric) derivative. Why this spline: it is C²
(continuous Hessian, so Newton's model of the force is continuous too), local (64
coefficients per point: cheap, vectorised over the nodes), reproduces linear functions
exactly (a plane is exact, whatever h), and is variation-diminishing (no overshoot near the
clamped band edge or the kinks of the distance). The price is a smoothing bias: for a smooth
φ, Σ c B = φ + (h²/6) ∇²φ + O(h⁴), and ∇²φ = κ₁ + κ₂ (the curvatures of the level surface):
a sphere of radius R is offset by h²/(3R) outwards (0.006 mm for the 60 mm cap at h = 1 mm),
and edges or corners sharper than about 2h are rounded (the punch's 1 mm edge round). An
interpolating spline (a prefilter solve) would remove the h² bias on smooth parts but ring
at the band's clamp and at kinks; the bias is below the tool mesh's own chordal error when h
is the mesh size, so the approximating spline is kept.

**Spacing.** The default h is the tool mesh size: the side of the equilateral triangle of the
area-weighted median flat triangle (for a second-order Gmsh mesh, split in four, half of
Gmsh's size), raised if the grid would exceed ``max_points`` points. Accuracy against the
closed-form hemisphere tools (``benchmarks/bench_contact.py --accuracy``, points −0.3 … 3 mm
from the cap and fillet, where the sheet lies):

    tool mesh (Gmsh size, order)   4 mm, 1   4 mm, 2 / 2 mm, 1   2 mm, 2 / 1 mm, 1   1 mm, 2
    h (mm)                          3.9       2.0                  1.0                 0.5
    facets: max |φ − φ_exact| (mm)  0.15      0.035                0.009               0.002
    field: max |φ − φ_exact| (mm)   0.21      0.059                0.015               0.004
    field: normal, max angle        12°       2.3°                 1.2°                0.6°

(the punch's 1 mm edge round is resolved only at h = 0.5 mm: 0.21 mm and 20° at h = 1 mm).

**Band.** Exact point-triangle distances are computed only for grid points within
``band_mm`` (+ 1.5 h) of the surface: a Euclidean distance transform of the grid points next
to samples of the triangles selects them. Beyond the band the samples are clamped to
±``band_mm``, with the sign of the nearest band sample (a flood fill by proximity). The field
is exact (up to the spline's bias) where |φ| < band − 2h. The default band is 3 mm + 2h: the
contact needs |φ| up to a step's penetration; the out-of-plane stabilisation
(:func:`~fenicsx_drape.forming.running.run.sheet_normal`) reads the tool normal up to 3 mm.
Points outside the grid's box are farther than the band: φ = +band, ∇φ = 0 (they are skipped
at once, as are points whose 64 coefficients are all clamped alike).

**Closest triangles** of the band samples: a closest-point transform on the grid. Samples
within 1.5 h of the surface get theirs by the exact search of
:meth:`~fenicsx_drape.forming.tools.surfaces.TriangleSurface.nearest` (k-d trees of centroids);
farther ones take the best of their six grid neighbours' closest triangles, front by front
outwards (as in Mauch's and Bridson's distance-field constructions), then descend on the
mesh until no triangle across an edge or around a corner of theirs is closer. Every sample
is an exact point-triangle distance; the triangle is the closest one except, rarely, beyond
1.5 h where two parts of the surface are about equally far (on the hemisphere's punch, 7 in
20 000 band samples, by at most 0.003 mm, and one by 0.025 mm on the medial axis inside the
edge round). This is 5-10 times faster than the exact search for every sample.

**Sign.** The sign of a sample is that of (x − q)·N with q its closest surface point and N the
angle-weighted pseudo-normal of the feature q lies on (Bærentzen & Aanæs 2005: correct for
any closed, consistently oriented triangle mesh); beyond the boundary of an open surface
(closest feature on a boundary edge, farther than 2.5 h) samples count as outside, so a
holder's opening is "outside" and a punch's open rim adds no spurious inside region near the
sheet (:mod:`~fenicsx_drape.forming.tools.surfaces`).

**Open edges.** Within 2.5 h beyond the boundary of an open surface the samples are the
signed distance to the plane of the closest triangle (the surface continued straight across
its edge), farther out the distance to the edge counted outside. The spline of a point on the
surface within 2h of its edge reads samples beyond it: with the distance to the edge (which is
positive above and below the surface) a plane's gap became a false round there, φ > 0 and a
tilted normal and ~1/h curvature on the plane itself. On the hemisphere's meshed holder this
held the nodes just outside its 170 mm opening on that round and the quarter stalled at
64 mm of travel (DIVERGED_MAX_IT from 38 mm on); with the plane continued, the holder's gap is
exactly z up to its edge (a spline reproduces linear functions) and the run matches the
closed form (docs/forming.md).

**Cache.** The hemisphere's punch at h = 1 mm (2 mm second-order mesh) has a 185 × 185 × 107
grid with 0.6 M band samples, built in about 10 s (19 MB; peak memory of the build 270 MB).
The coefficients (float32: a spline of float32 coefficients is as smooth as any other, and
their rounding of 1e-7 relative is far below the tolerances; evaluation is in float64) are
stored once per surface, h and band in ``$XDG_CACHE_HOME/fenicsx-drape/distance/`` (default
``~/.cache``), named by a hash of the surface's points and triangles, h, band and the format
version, written atomically. Under MPI rank 0 builds or reads and broadcasts the grid.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import math
import os
from pathlib import Path

import numpy as np

from fenicsx_drape.errors import ParameterError

#: Bump when the construction changes: cached grids of older versions are not read.
FORMAT_VERSION = 2

#: How far (in grid spacings) beyond an open edge the surface's plane continues: the spline's
#: support (2h) and a margin.
EDGE_EXTENSION = 2.5


def cache_folder() -> Path:
    """Where built distance fields are kept: ``$XDG_CACHE_HOME/fenicsx-drape/distance``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "fenicsx-drape" / "distance"


def _weights(t: np.ndarray) -> np.ndarray:
    """Cubic B-spline weights and their first and second derivatives at fractions t (n,).

    Returns an array (n, 4, 3): weight of the 4 coefficients i−1 … i+2 (axis 1) for the value,
    first and second derivative with respect to t (axis 2).
    """
    s = 1.0 - t
    t2 = t * t
    w = np.empty((len(t), 4, 3))
    w[:, 0, 0] = s * s * s / 6.0
    w[:, 1, 0] = (3.0 * t2 * t - 6.0 * t2 + 4.0) / 6.0
    w[:, 2, 0] = (-3.0 * t2 * t + 3.0 * t2 + 3.0 * t + 1.0) / 6.0
    w[:, 3, 0] = t2 * t / 6.0
    w[:, 0, 1] = -0.5 * s * s
    w[:, 1, 1] = 1.5 * t2 - 2.0 * t
    w[:, 2, 1] = -1.5 * t2 + t + 0.5
    w[:, 3, 1] = 0.5 * t2
    w[:, 0, 2] = s
    w[:, 1, 2] = 3.0 * t - 2.0
    w[:, 2, 2] = 1.0 - 3.0 * t
    w[:, 3, 2] = t
    return w


@dataclasses.dataclass
class DistanceField:
    """A signed distance sampled on a regular grid, evaluated as a cubic B-spline.

    ``coefficients[i, j, k]`` is the sample at ``origin + h (i, j, k)``; φ = +band outside
    the box. Build one with :func:`distance_field`.
    """

    origin: np.ndarray  # (3,) mm, the grid point (0, 0, 0)
    h: float  # grid spacing (mm)
    band_mm: float  # exact within the band, clamped to ±band beyond
    coefficients: np.ndarray  # (nx, ny, nz) float32, C order
    key: str = ""  # the cache key (hash of surface, h, band, version)

    def __post_init__(self) -> None:
        c = np.ascontiguousarray(self.coefficients, dtype=np.float32)
        self.coefficients = c
        self.origin = np.asarray(self.origin, dtype=float)
        self.shape = np.array(c.shape)
        self._flat = c.ravel()
        self._strides = np.array([c.shape[1] * c.shape[2], c.shape[2], 1], dtype=np.int64)
        a, b, d = np.meshgrid(np.arange(4), np.arange(4), np.arange(4), indexing="ij")
        self._offsets = (a * self._strides[0] + b * self._strides[1] + d).ravel()
        self._constant = _constant_cells(c).ravel()

    @property
    def nbytes(self) -> int:
        """Memory of the grid (coefficients and the mask of constant cells), bytes."""
        return self.coefficients.nbytes + self._constant.nbytes

    def evaluate(self, X: np.ndarray, order: int = 2):
        """φ, ∇φ and ∇∇φ of the spline at the points ``X`` (n, 3) of the grid's frame.

        Args:
            X: Points (n, 3) in mm.
            order: 0 for φ only, 1 with the gradient, 2 with the Hessian too.

        Returns:
            ``(phi (n,), grad (n, 3), hess (n, 3, 3))`` (grad/hess None below their order).
        """
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        n = len(X)
        phi = np.full(n, self.band_mm)
        grad = np.zeros((n, 3)) if order >= 1 else None
        hess = np.zeros((n, 3, 3)) if order >= 2 else None
        u = (X - self.origin) / self.h
        i = np.floor(u)
        inside = np.all((i >= 1) & (i <= self.shape - 3), axis=1)
        idx = np.flatnonzero(inside)
        if not len(idx):
            return phi, grad, hess
        ii = i[idx].astype(np.int64)
        base = (ii - 1) @ self._strides
        cell = ii @ self._strides
        const = self._constant[cell]
        if const.any():
            phi[idx[const]] = self._flat[base[const] + self._offsets[21]]
        live = ~const
        idx, base, frac = idx[live], base[live], (u[idx] - i[idx])[live]
        if not len(idx):
            return phi, grad, hess
        n_live = len(idx)
        C = np.take(self._flat, base[:, None] + self._offsets).astype(float)
        # One call for the three axes: at the sheet's few hundred nodes per call the cost is
        # NumPy's per-call overhead, not arithmetic.
        w = _weights(frac.ravel()).reshape(n_live, 3, 4, 3)
        wx, wy, wz = w[:, 0], w[:, 1], w[:, 2]
        K = order + 1  # derivative orders 0 … order along each axis
        # Contract z, then y, then x with small batched products (einsum is slower here).
        Cz = np.matmul(C.reshape(n_live, 16, 4), wz[:, :, :K])  # [n, (x, y), dz]
        Cyz = np.matmul(Cz.reshape(n_live, 4, 4, K).transpose(0, 1, 3, 2),
                        wy[:, None, :, :K])  # [n, x, dz, dy]
        V = np.matmul(Cyz.reshape(n_live, 4, K * K).transpose(0, 2, 1),
                      wx[:, :, :K])  # [n, (dz, dy), dx]
        h = self.h
        phi[idx] = V[:, 0, 0]
        if order >= 1:
            grad[idx] = np.column_stack([V[:, 0, 1], V[:, 1, 0], V[:, K, 0]]) / h
        if order >= 2:
            H = np.empty((n_live, 3, 3))
            H[:, 0, 0], H[:, 1, 1], H[:, 2, 2] = V[:, 0, 2], V[:, 2, 0], V[:, 2 * K, 0]
            H[:, 0, 1] = H[:, 1, 0] = V[:, 1, 1]
            H[:, 0, 2] = H[:, 2, 0] = V[:, K, 1]
            H[:, 1, 2] = H[:, 2, 1] = V[:, K + 1, 0]
            hess[idx] = H / (h * h)
        return phi, grad, hess

    def samples(self, X: np.ndarray) -> np.ndarray:
        """The grid samples (not the spline) at the grid points nearest to ``X``, mm."""
        k = np.rint((np.asarray(X, float).reshape(-1, 3) - self.origin) / self.h)
        k = np.clip(k.astype(np.int64), 0, self.shape - 1)
        return self._flat[k @ self._strides].astype(float)

    # -- storage ------------------------------------------------------------------------

    def to_bytes(self) -> bytes:
        """The field as ``.npz`` bytes (compressed)."""
        buf = io.BytesIO()
        np.savez_compressed(buf, origin=self.origin, h=self.h, band_mm=self.band_mm,
                            coefficients=self.coefficients, version=FORMAT_VERSION)
        return buf.getvalue()

    @classmethod
    def from_file(cls, path: str | os.PathLike, key: str = "") -> DistanceField:
        """Read a field written by :meth:`to_bytes`."""
        with np.load(path) as f:
            if int(f["version"]) != FORMAT_VERSION:
                raise ValueError(f"{path}: distance field of another format version")
            return cls(f["origin"], float(f["h"]), float(f["band_mm"]), f["coefficients"], key)


def _constant_cells(c: np.ndarray) -> np.ndarray:
    """Cells whose 4×4×4 coefficients (i−1 … i+2 on each axis) are all equal (clamped)."""
    from scipy.ndimage import maximum_filter, minimum_filter

    # size 4 with origin −1: the window i−1 … i+2.
    hi = maximum_filter(c, size=4, origin=-1, mode="nearest")
    lo = minimum_filter(c, size=4, origin=-1, mode="nearest")
    return hi == lo


# The coarsest default grid: a few large flat triangles (an STL plate) must not give a grid
# as coarse as they are, whose band would miss a sheet a few mm away.
MAX_DEFAULT_SPACING_MM = 5.0


def default_spacing(surface) -> float:
    """The default grid spacing h (mm): the tool mesh size, at most 5 mm."""
    return min(surface.mesh_size_mm, MAX_DEFAULT_SPACING_MM)


def field_key(surface, h: float, band_mm: float) -> str:
    """The cache key of a surface's field: a hash of its geometry, h, band and version."""
    text = f"{surface.content_hash}|{h!r}|{band_mm!r}|{FORMAT_VERSION}"
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def distance_field(surface, spacing_mm: float | None = None, band_mm: float | None = None, *,
                   max_points: float = 6e7, cache: bool = True, comm=None) -> DistanceField:
    """The smooth signed distance field of a surface, from the cache or built.

    Args:
        surface: A :class:`~fenicsx_drape.forming.tools.surfaces.TriangleSurface`.
        spacing_mm: Grid spacing h (default :func:`default_spacing`, raised if the grid
            would have more than ``max_points`` points).
        band_mm: Half-width of the band of exact distances (default 3 mm + 2h).
        max_points: Largest grid allowed for a default spacing.
        cache: Read and write the on-disk cache (:func:`cache_folder`).
        comm: MPI communicator: rank 0 builds or reads, all ranks get the grid.

    Returns:
        The field.
    """
    lo, hi = surface.bounds
    if spacing_mm is None:
        h = default_spacing(surface)
        size = hi - lo + 2 * (3.0 + 5.0 * h)
        h = max(h, float(np.prod(size) / max_points) ** (1.0 / 3.0))
    else:
        h = float(spacing_mm)
        if not (math.isfinite(h) and h > 0.0):
            raise ParameterError(f"distance field of {surface.source}: spacing_mm = "
                                 f"{spacing_mm} must be positive")
    band = 3.0 + 2.0 * h if band_mm is None else float(band_mm)
    if not (math.isfinite(band) and band >= h):
        raise ParameterError(f"distance field of {surface.source}: band_mm = {band_mm} must "
                             f"be at least the spacing ({h} mm)")
    key = field_key(surface, h, band)
    field = None
    if comm is None or comm.rank == 0:
        path = cache_folder() / f"{key}.npz"
        if cache and path.is_file():
            try:
                field = DistanceField.from_file(path, key)
            except (OSError, ValueError, KeyError):
                field = None  # unreadable or stale: build again
        if field is None:
            field = build_field(surface, h, band)
            field.key = key
            if cache:
                from fenicsx_drape.provenance import atomic_write_bytes

                try:
                    atomic_write_bytes(path, field.to_bytes())
                except OSError:
                    pass  # a read-only cache costs time, not results
    if comm is not None and comm.size > 1:
        meta = comm.bcast(None if field is None else
                          (field.origin, field.h, field.band_mm, field.coefficients.shape),
                          root=0)
        c = field.coefficients if comm.rank == 0 else np.empty(meta[3], dtype=np.float32)
        comm.Bcast(c, root=0)
        if comm.rank != 0:
            field = DistanceField(meta[0], meta[1], meta[2], c, key)
    return field


def build_field(surface, h: float, band_mm: float) -> DistanceField:
    """Sample the signed distance of ``surface`` on a grid (see the module docstring)."""
    from scipy.ndimage import distance_transform_edt

    lo, hi = surface.bounds
    pad = band_mm + 3.0 * h  # the band and the spline's support inside the box
    origin = lo - pad
    shape = np.ceil((hi - lo + 2 * pad) / h).astype(np.int64) + 1
    # Grid points near the surface: those nearest to points sampled on the triangles at h/2.
    near = np.zeros(shape, dtype=bool)
    for pts in _surface_samples(surface, 0.5 * h):
        k = np.clip(np.rint((pts - origin) / h).astype(np.int64), 0, shape - 1)
        near[k[:, 0], k[:, 1], k[:, 2]] = True
    # Distance (mm) to the nearest marked point: it exceeds the true distance by at most
    # 1.4 h (a marked point is within 0.87 h of a sample, a sample within 0.5 h of any
    # surface point) and falls short of it by at most 0.87 h.
    approx = distance_transform_edt(~near, sampling=h)
    del near
    band = approx <= band_mm + 1.5 * h
    idx = np.flatnonzero(band)
    shell = approx.ravel()[idx] <= 1.5 * h
    del approx
    X = origin + h * np.column_stack(np.unravel_index(idx, tuple(shape)))
    best_t, best = _closest_triangles(surface, X, idx, shell, shape)
    # The sign of every band sample from its closest feature.
    _, v, w, region = surface._pairs(X, best_t)
    a, ab, ac, _ = surface._frames
    q = a[best_t] + v[:, None] * ab[best_t] + w[:, None] * ac[best_t]
    N, on_boundary = surface._feature_normals(best_t, region)
    side = np.einsum("ij,ij->i", X - q, N)
    d = np.sqrt(best)
    phi = np.where(on_boundary | (side >= 0.0), d, -d)
    # Just beyond an open edge the surface continues along its last triangle: the spline of a
    # node on the surface near its edge reads samples up to 2h beyond it, and the Euclidean
    # distance to the edge there (positive on both sides) bends the holder's plane at its
    # opening into a false round (the meshed hemisphere's stall: docstring, "Open edges").
    along = np.einsum("ij,ij->i", X - q, surface.face_normals[best_t])
    across = np.sqrt(np.maximum(best - along * along, 0.0))
    extend = on_boundary & (across <= EDGE_EXTENSION * h)
    phi[extend] = along[extend]
    values = np.empty(tuple(shape), dtype=np.float32)
    values.flat[idx] = np.clip(phi, -band_mm, band_mm)
    del X, q, N
    # Beyond the band: ±band with the sign of the nearest band point.
    nearest = distance_transform_edt(~band, return_distances=False, return_indices=True)
    sign = np.sign(values[tuple(nearest)])
    del nearest
    sign[sign == 0] = 1.0
    out = ~band
    values[out] = band_mm * sign[out]
    return DistanceField(origin, h, band_mm, values)


def _closest_triangles(surface, X, idx, shell, shape):
    """The closest triangle (and squared distance) of every band sample.

    A closest-point transform on the grid: samples of the thin ``shell`` (within 1.5 h of
    the triangles' samples) get their closest triangle by the exact search of
    :meth:`TriangleSurface.nearest`; the farther ones take the best of the closest
    triangles of their six grid neighbours, front by front outwards (as in Mauch's and
    Bridson's distance-field constructions), then descend on the mesh until no triangle
    across an edge or around a corner of theirs is closer. Every distance is an exact
    point-triangle distance; the triangle is the closest one except, rarely, near a medial
    axis where two parts of the surface are equally far
    (``tests/test_distance.py`` compares with a brute-force search).
    """
    n = len(idx)
    best = np.full(n, np.inf)
    best_t = np.full(n, -1, dtype=np.int64)
    s = np.flatnonzero(shell)
    if len(s):
        _, d, t, _ = surface.nearest(X[s])
        best[s], best_t[s] = d * d, t
    pos = np.full(int(np.prod(shape)), -1, dtype=np.int32)
    pos[idx] = np.arange(n, dtype=np.int32)
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    offsets = np.concatenate([strides, -strides])
    front = s
    while len(front):
        nb = (idx[front][:, None] + offsets[None, :]).ravel()
        tri = np.repeat(best_t[front], len(offsets))
        p = pos[nb]
        keep = p >= 0
        p, tri = p[keep], tri[keep]
        keep = ~shell[p]
        front = _improve(surface, X, p[keep], tri[keep], best, best_t)
    # Descend on the mesh: a triangle across an edge or around the corner the closest point
    # lies on may be closer (small triangles that no grid neighbour saw), and so may the
    # faces next to it in a concave region.
    todo = np.flatnonzero(~shell)
    while len(todo):
        region = surface._pairs(X[todo], best_t[todo])[3]
        which, tri = surface.local_candidates(best_t[todo], region)
        todo = _improve(surface, X, todo[which], tri, best, best_t)
    return best_t, best


def _improve(surface, X, p, tri, best, best_t, chunk: int = 65536) -> np.ndarray:
    """Try triangles ``tri`` for samples ``p``; keep the closer; return the improved ones."""
    improved = []
    for s in range(0, len(p), chunk):
        ps, ts = p[s:s + chunk], tri[s:s + chunk]
        d2 = surface._pairs(X[ps], ts)[0]
        order = np.lexsort((d2, ps))
        first = order[np.r_[True, ps[order][1:] != ps[order][:-1]]]
        better = d2[first] < best[ps[first]] * (1.0 - 1e-12) - 1e-300
        win = ps[first][better]
        best[win], best_t[win] = d2[first][better], ts[first][better]
        improved.append(win)
    return np.unique(np.concatenate(improved)) if improved else np.empty(0, np.int64)


def _surface_samples(surface, spacing: float, chunk: int = 200000):
    """Points on every triangle no farther apart than ``spacing`` (batches of points)."""
    p, t = surface.points, surface.triangles
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    longest = np.max(np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                               np.linalg.norm(a - c, axis=1)]), axis=0)
    divisions = np.maximum(np.ceil(longest / spacing).astype(np.int64), 1)
    for n in np.unique(divisions):
        sel = np.flatnonzero(divisions == n)
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        u, v = i[keep] / n, j[keep] / n  # barycentric coordinates of the sample pattern
        step = max(1, chunk // len(u))
        for s in range(0, len(sel), step):
            q = sel[s:s + step]
            pts = (a[q, None, :] + u[None, :, None] * (b[q] - a[q])[:, None, :]
                   + v[None, :, None] * (c[q] - a[q])[:, None, :])
            yield pts.reshape(-1, 3)
