"""The kinematic drape: a pin-jointed net of inextensible tows mapped onto any surface.

This is the classic "fishnet" algorithm (Van Der Ween, the paper's ref. 1), the geometric
model the paper compares with in Fig. 11 (its maximum shear: 61°), in the form of KinDrape
(Krogh et al., Struct. Multidisc. Optim. 64, 2021): a start point, an initial tow direction
and a ply angle on any mould surface. It has no mechanics:

1. The *surface* is anything with ``gap(x, t) -> Gap`` whose zero level set is the mould: a
   closed-form tool (:meth:`HemisphereTools.formed_part`), a meshed tool, a height field
   z = F(x, y) (:class:`HeightField`), a plane (:class:`Plane`) or several tools at their
   final positions united (:func:`formed_surface`, :class:`UnionSurface`: φ = min φ_k).
2. The *flat net*: node (i, j) lies at ``S + Δ (i u + j v)`` on the flat sheet, S the start
   point, u and v the warp and weft at the ply angle θ to x and y. Nodes outside the blank
   outline are absent (NaN).
3. The *start* node is the surface point above S (the highest one, or the given 3D point).
   The warp leaves it along the tangent whose projection on the xy-plane is at the
   direction α to x (default α = θ), the weft along the tangent 90° further (seen from +z).
4. Four *generator* tows, warp and weft both ways from the start, nodes a chord Δ apart.
   By default each is a discrete geodesic: node k + 1 lies in the plane through node k
   spanned by the incoming chord and the surface normal at node k (no turn within the
   tangent plane: zero geodesic curvature). It is intrinsic (independent of the frame):
   exactly the meridians of a surface of revolution through its pole and the great circles
   of a sphere, a geodesic to O(Δ²) on any surface (Clairaut's relation on a cone). This is
   the classic fishnet choice: a tow laid without in-plane bending follows a geodesic.
   ``generator="normal_section"`` instead keeps each generator in the one plane through the
   start spanned by its initial direction and the start's normal (the surface's normal
   section; the same as the geodesic on a sphere and through the pole of a surface of
   revolution). KinDrape itself places its generator strips by minimising their cells'
   shear, and measures its direction from y; here α is measured from x (the warp).
5. Every other node closes a cell: it is the point of the surface at chord distance Δ from
   its two known neighbours A = P(i ∓ 1, j), B = P(i, j ∓ 1), on the side away from the
   cell's third node C, found by Newton from the parallelogram guess A + B − C. The four
   quadrants are built together (no symmetry assumed), wave front by wave front
   |i| + |j| = s, the generator nodes of the front with them: every node of a front is an
   independent 3 × 3 Newton solve, vectorised.

A node that cannot be placed (Newton fails: the surface ends or the two chord spheres miss
it; the cell locks: |A − B| ≥ 2Δ, or its shear passes ``locking_angle_deg`` if given; the
solution folds back onto C) is left absent with every node that depends on it, counted in
:attr:`KinematicNet.unplaced` and warned about.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from fenicsx_drape.errors import DrapeInputError, ParameterError
from fenicsx_drape.forming.running.post import FormedGrid
from fenicsx_drape.forming.tools.shapes import Gap, HemisphereTools

GENERATORS = ("geodesic", "normal_section")
ON_SURFACE_MM = 0.01  # a 3D start point further than this from the surface is an error
SEARCH_MM = 2000.0  # the start's vertical search spans |z| <= this
_TOL = 1e-10  # Newton: residual (mm) of every equation, relative to max(1, Δ)
_ITERATIONS = 40


class Surface(Protocol):
    """A rigid surface: the zero level set of a signed distance (a tool of ``tools.shapes``)."""

    def gap(self, x: np.ndarray, t: float) -> Gap:
        """Signed distance φ (n,), its gradient (n, 3) and Hessian (n, 3, 3) at ``x`` (n, 3)."""


# --- surfaces ------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Plane:
    """The plane through ``point_mm`` with unit normal ``normal`` (φ > 0 on its side)."""

    point_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    name: str = "plane"

    def gap(self, x: np.ndarray, t: float = 0.0) -> Gap:
        """Exact signed distance, normal and (zero) curvature."""
        x = np.asarray(x, float).reshape(-1, 3)
        n = np.asarray(self.normal, float)
        n = n / np.linalg.norm(n)
        return Gap((x - np.asarray(self.point_mm, float)) @ n, np.broadcast_to(n, x.shape),
                   np.zeros((len(x), 3, 3)))


@dataclasses.dataclass(frozen=True)
class HeightField:
    """The surface z = F(x, y) of a mould (KinDrape's analytic moulds), φ > 0 above it.

    φ = (z − F) / g with g = √(1 + |∇F|²): its zero set is the surface exactly and |∇φ| = 1
    on it (a signed distance to first order). ``gradient`` returns (F_x, F_y) and
    ``hessian`` (F_xx, F_xy, F_yy); central differences of ``height`` (``gradient``) replace
    them when not given. The Hessian of φ is exact on the surface. Where F is NaN (outside
    its domain) the surface ends.
    """

    height: Callable[[np.ndarray, np.ndarray], np.ndarray]
    gradient: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None
    hessian: Callable[[np.ndarray, np.ndarray], tuple] | None = None
    name: str = "height field"
    step_mm: float = 1e-4  # central-difference step

    def _gradient(self, x, y):
        if self.gradient is not None:
            return self.gradient(x, y)
        h = self.step_mm
        F = self.height
        return (F(x + h, y) - F(x - h, y)) / (2 * h), (F(x, y + h) - F(x, y - h)) / (2 * h)

    def _hessian(self, x, y):
        if self.hessian is not None:
            return self.hessian(x, y)
        h = self.step_mm if self.gradient is not None else 1e-3
        xp, yp = self._gradient(x + h, y)
        xm, ym = self._gradient(x - h, y)
        xq, yq = self._gradient(x, y + h)
        xr, yr = self._gradient(x, y - h)
        return (xp - xm) / (2 * h), 0.25 * (yp - ym + xq - xr) / h, (yq - yr) / (2 * h)

    def gap(self, x: np.ndarray, t: float = 0.0) -> Gap:
        """φ, ∇φ (exact) and ∇∇φ (exact on the surface) at ``x`` (n, 3)."""
        x = np.asarray(x, float).reshape(-1, 3)
        X, Y = x[:, 0], x[:, 1]
        w = x[:, 2] - self.height(X, Y)
        Fx, Fy = self._gradient(X, Y)
        Fxx, Fxy, Fyy = self._hessian(X, Y)
        g = np.sqrt(1.0 + Fx**2 + Fy**2)
        dw = np.column_stack([-Fx, -Fy, np.ones_like(w)])
        dinv = -np.column_stack([Fx * Fxx + Fy * Fxy, Fx * Fxy + Fy * Fyy,
                                 np.zeros_like(w)]) / g[:, None] ** 3  # ∇(1/g)
        H = np.zeros((len(x), 3, 3))
        H[:, 0, 0], H[:, 0, 1], H[:, 1, 1] = -Fxx, -Fxy, -Fyy
        H[:, 1, 0] = -Fxy
        H = H / g[:, None, None] + np.einsum("ni,nj->nij", dw, dinv)
        H += np.einsum("ni,nj->nij", dinv, dw)
        return Gap(w / g, dw / g[:, None] + w[:, None] * dinv, H)


@dataclasses.dataclass(frozen=True)
class AtTime:
    """A moving tool frozen at ``time_s``: ``gap(x, t)`` ignores ``t``."""

    tool: Surface
    time_s: float

    @property
    def name(self) -> str:
        """The tool's name and the time."""
        return f"{getattr(self.tool, 'name', 'surface')} at {self.time_s:g} s"

    def gap(self, x: np.ndarray, t: float = 0.0) -> Gap:
        """The tool's gap at ``time_s``."""
        return self.tool.gap(x, self.time_s)


@dataclasses.dataclass(frozen=True)
class UnionSurface:
    """Several rigid surfaces whose materials are united: φ = min_k φ_k.

    Outside the material the minimum is the exact distance to the union, so the zero set is
    exactly the outer surface (e.g. the punch at its final position and the holder plane).
    The normal is the active surface's, blended over ``blend_mm`` where another surface is
    as near (at a crease where two meet: the mean of their normals, turning smoothly to
    either within ``blend_mm``), so Newton's Jacobian does not jump at the crease. The
    Hessian is the active surface's.

    ``bridge_mm`` > 0 replaces the minimum by a smooth one of that width k (the quadratic
    smooth minimum, min − k s²/4 with s = max(k − |φ_a − φ_b|, 0)/k, folded over the parts;
    C¹, its gradient and Hessian exact): it fills concave creases with a round of about k and
    bridges gaps narrower than about k, such as the slot between a punch and a holder's
    opening that the nodes of a net would fall into. It lifts the surface by k/4 where two
    parts coincide (a punch's shoulder on the holder plane), so it is off by default.
    """

    parts: tuple
    name: str = "formed surface"
    blend_mm: float = 0.5
    bridge_mm: float = 0.0

    def __post_init__(self) -> None:
        if not self.parts:
            raise ParameterError("UnionSurface: no surface to unite")
        for key in ("blend_mm", "bridge_mm"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0.0):
                raise ParameterError(f"UnionSurface: {key} = {value} must be >= 0")

    def gap(self, x: np.ndarray, t: float = 0.0) -> Gap:
        """φ = min φ_k, the blended normal and the active surface's Hessian.

        With ``bridge_mm``: the smooth minimum, its gradient and Hessian.
        """
        x = np.asarray(x, float).reshape(-1, 3)
        gaps = [p.gap(x, t) for p in self.parts]
        if self.bridge_mm > 0.0:
            out = gaps[0]
            for g in gaps[1:]:
                out = _smooth_min(out, g, self.bridge_mm, len(x))
            return out
        Φ = np.stack([g.phi for g in gaps])
        k = np.argmin(np.where(np.isnan(Φ), np.inf, Φ), axis=0)
        i = np.arange(len(x))
        phi = Φ[k, i]
        N = np.stack([np.broadcast_to(g.normal, x.shape) for g in gaps])
        normal = N[k, i]
        if len(gaps) > 1 and self.blend_mm > 0.0:
            s = np.clip(1.0 - (Φ - phi) / self.blend_mm, 0.0, 1.0)
            w = np.nan_to_num(s * s * (3.0 - 2.0 * s))
            blend = np.einsum("kn,kni->ni", w, np.nan_to_num(N))
            size = np.linalg.norm(blend, axis=1)
            ok = size > 1e-6 * np.linalg.norm(normal, axis=1)
            scale = np.linalg.norm(normal, axis=1)  # keep |∇φ| of the active surface
            normal = np.where(ok[:, None], blend * (scale / np.where(ok, size, 1.0))[:, None],
                              normal)
        hessian = np.stack([np.broadcast_to(g.hessian, (len(x), 3, 3)) for g in gaps])[k, i]
        return Gap(phi, normal, hessian)


def _smooth_min(a: Gap, b: Gap, k: float, n: int) -> Gap:
    """The quadratic smooth minimum of two gaps (see :class:`UnionSurface`)."""
    na, nb = np.broadcast_to(a.normal, (n, 3)), np.broadcast_to(b.normal, (n, 3))
    Ha, Hb = np.broadcast_to(a.hessian, (n, 3, 3)), np.broadcast_to(b.hessian, (n, 3, 3))
    s = np.maximum(k - np.abs(a.phi - b.phi), 0.0) / k
    lower = a.phi <= b.phi
    wa = np.where(lower, 1.0 - 0.5 * s, 0.5 * s)  # ∂/∂φ_a; 1 − wa for φ_b
    d = na - nb
    hessian = (wa[:, None, None] * Ha + (1.0 - wa)[:, None, None] * Hb
               - np.where(s > 0.0, 0.5 / k, 0.0)[:, None, None] * np.einsum("ni,nj->nij", d, d))
    return Gap(np.minimum(a.phi, b.phi) - 0.25 * k * s * s,
               wa[:, None] * na + (1.0 - wa)[:, None] * nb, hessian)


def formed_surface(tools: Sequence[Surface], time_s: float, *, blend_mm: float = 0.5,
                   bridge_mm: float = 0.0, name: str = "formed surface") -> UnionSurface:
    """The surface the sheet lies on at ``time_s``: the tools there, their materials united.

    Give the tools on the sheet's one side (e.g. the punch and the holder plane, not the die
    above the sheet): their union's outer surface is the formed part. ``blend_mm`` and
    ``bridge_mm``: see :class:`UnionSurface`.
    """
    return UnionSurface(tuple(AtTime(tool, time_s) for tool in tools), name=name,
                        blend_mm=blend_mm, bridge_mm=bridge_mm)


# --- blank outline ---------------------------------------------------------------------------


def rectangle(size_mm: Sequence[float], centre_mm: Sequence[float] = (0.0, 0.0)) -> np.ndarray:
    """The outline (4, 2) of a rectangular blank, sides along x and y."""
    a, b = 0.5 * float(size_mm[0]), 0.5 * float(size_mm[1])
    if not (a > 0 and b > 0):
        raise ParameterError(f"rectangle: size_mm = {tuple(size_mm)} must be positive")
    c = np.asarray(centre_mm, float)
    return c + np.array([[-a, -b], [a, -b], [a, b], [-a, b]])


def inside_outline(points: np.ndarray, outline: np.ndarray, tol_mm: float = 1e-9) -> np.ndarray:
    """Mask of the points (n, 2) inside the polygon ``outline`` (m, 2) or on its edges."""
    p = np.asarray(points, float).reshape(-1, 2)
    a = np.asarray(outline, float)
    b = np.roll(a, -1, axis=0)
    inside = np.zeros(len(p), bool)
    near = np.zeros(len(p), bool)
    for (ax, ay), (bx, by) in zip(a, b):
        # crossing number along +x, and the distance to the edge for points on it
        straddle = (ay > p[:, 1]) != (by > p[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = ax + (p[:, 1] - ay) * (bx - ax) / (by - ay)
        inside ^= straddle & (p[:, 0] < xc)
        e = np.array([bx - ax, by - ay])
        s = np.clip(((p - [ax, ay]) @ e) / max(e @ e, 1e-300), 0.0, 1.0)
        near |= np.linalg.norm(p - [ax, ay] - s[:, None] * e, axis=1) <= tol_mm
    return inside | near


def _outline(outline) -> np.ndarray:
    a = np.asarray(outline, float)
    if a.ndim != 2 or a.shape[1] != 2 or len(a) < 3 or not np.isfinite(a).all():
        raise ParameterError("kinematic drape: outline must be a polygon of at least 3 finite "
                             f"(x, y) points in mm, got shape {a.shape}")
    b = np.roll(a, -1, axis=0)
    if abs(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])) < 1e-12:
        raise ParameterError("kinematic drape: the outline encloses no area")
    return a


# --- the net -------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class KinematicNet(FormedGrid):
    """A draped pin-jointed net: a :class:`FormedGrid` (absent nodes NaN) and how it was built.

    ``start_index`` is the grid index of the start node; ``unplaced`` (n_i, n_j) marks the
    nodes of the blank that could not be placed (absent, with NaN in ``X`` and ``x``).
    """

    start_mm: np.ndarray = None  # (3,) the start node on the surface
    start_index: tuple[int, int] = (0, 0)
    unplaced: np.ndarray = None  # (n_i, n_j) bool
    direction_deg: float = 0.0
    ply_angle_deg: float = 0.0
    generator: str = "geodesic"
    locking_angle_deg: float | None = None
    surface: str = ""

    @property
    def unplaced_count(self) -> int:
        """Number of nodes of the blank that could not be placed."""
        return int(self.unplaced.sum())

    def summary(self) -> dict:
        """The net's numbers (for ``summary.json``)."""
        γ = np.abs(self.shear_deg())
        return {"max_shear_deg": float(np.nanmax(γ)) if np.isfinite(γ).any() else None,
                "cell_mm": self.cell_mm, "nodes": int(self.present.sum()),
                "unplaced_nodes": self.unplaced_count, "start_mm": self.start_mm.tolist(),
                "direction_deg": self.direction_deg, "ply_angle_deg": self.ply_angle_deg,
                "generator": self.generator, "locking_angle_deg": self.locking_angle_deg,
                "surface": self.surface}


def _solve(surface, t, Δ, A, second, cell, Q):
    """Place nodes by Newton on their three equations, vectorised over nodes.

    Cells (``cell`` True): |Q − A| = Δ, |Q − B| = Δ with B = ``second``; generators:
    |Q − A| = Δ, (Q − A)·b = 0 with b = ``second`` (the plane's normal); both: φ(Q) = 0.

    Returns the nodes (m, 3), the surface normals there (m, 3) and the converged mask.
    """
    tol = _TOL * max(1.0, Δ)
    Q = Q.copy()
    N = np.full_like(Q, np.nan)
    done = np.zeros(len(Q), bool)
    act = np.flatnonzero(np.isfinite(Q).all(axis=1))
    for _ in range(_ITERATIONS):
        if not len(act):
            break
        q, a, s, c = Q[act], A[act], second[act], cell[act]
        g = surface.gap(q, t)
        n = np.broadcast_to(g.normal, q.shape)
        da, db = q - a, q - s
        r = np.column_stack([(da * da).sum(1) - Δ**2,
                             np.where(c, (db * db).sum(1) - Δ**2, (da * s).sum(1)), g.phi])
        size = np.maximum(np.linalg.norm(n, axis=1), 1e-300)
        err = np.abs(r) / np.column_stack([np.full(len(q), 2 * Δ), np.where(c, 2 * Δ, 1.0),
                                           size])
        conv = np.all(err < tol, axis=1)  # NaN (the surface ends) never converges
        N[act[conv]] = n[conv]
        done[act[conv]] = True
        J = np.stack([2 * da, np.where(c[:, None], 2 * db, s), n], axis=1)
        # One more step for the converged nodes too: it costs no evaluation of the surface.
        ok = np.isfinite(r).all(1) & np.isfinite(J).all((1, 2))
        det = np.linalg.det(np.where(ok[:, None, None], J, np.eye(3)))
        scale = np.prod(np.linalg.norm(J, axis=2), axis=1)
        ok &= np.abs(det) > 1e-10 * np.where(ok, scale, 1.0)
        Jok = np.where(ok[:, None, None], J, np.eye(3))
        dQ = np.linalg.solve(Jok, -np.where(ok[:, None], r, 0.0)[..., None])[..., 0]
        step = np.linalg.norm(dQ, axis=1)
        Q[act] = q + dQ * np.minimum(1.0, 0.5 * Δ / np.maximum(step, 1e-300))[:, None]
        act = act[ok & ~conv]
    return Q, N, done


def _start(surface, t: float, start_mm, Δ: float) -> tuple[np.ndarray, np.ndarray]:
    """The start node on the surface and the unit normal there (oriented with n_z ≥ 0)."""
    s = np.asarray(start_mm, float).ravel()
    if s.shape not in ((2,), (3,)) or not np.isfinite(s).all():
        raise ParameterError(f"kinematic drape: start_mm = {start_mm!r} must be (x, y) or "
                             "(x, y, z) in mm")
    name = getattr(surface, "name", "surface")
    where = "(" + ", ".join(f"{v:g}" for v in s) + ")"
    if len(s) == 3:
        φ = float(surface.gap(s[None], t).phi[0])
        if not abs(φ) <= ON_SURFACE_MM:
            raise DrapeInputError(f"kinematic drape: start point {where} mm is off the "
                                  f"surface '{name}' (signed distance {φ:.4g} mm, more than "
                                  f"{ON_SURFACE_MM} mm)")
        p = s.copy()
        for _ in range(20):  # onto the surface along its normal
            g = surface.gap(p[None], t)
            n = g.normal[0]
            p = p - g.phi[0] * n / (n @ n)
    else:
        def phi(z):
            x = np.column_stack([np.full_like(z, s[0]), np.full_like(z, s[1]), z])
            return surface.gap(x, t).phi

        def roots(z, φ):  # brackets of the sign changes, from the top down
            k = np.flatnonzero(np.isfinite(φ[:-1]) & np.isfinite(φ[1:])
                               & (np.sign(φ[:-1]) != np.sign(φ[1:])))
            return [(z[i], z[i + 1]) for i in k]

        z = np.arange(SEARCH_MM, -SEARCH_MM - 0.5, -1.0)
        p = None
        for hi, lo in roots(z, phi(z)):  # the highest root that is a real zero of φ
            for _ in range(2):  # narrow the bracket 1000-fold, twice
                zz = np.linspace(hi, lo, 1001)
                brackets = roots(zz, phi(zz))
                if not brackets:
                    break
                hi, lo = brackets[0]
            q = np.array([s[0], s[1], 0.5 * (hi + lo)])
            if abs(surface.gap(q[None], t).phi[0]) < 1e-5:
                p = q
                break
        if p is None:
            raise DrapeInputError(f"kinematic drape: start point (x, y) = {where} mm is off "
                                  f"the surface '{name}': no surface point above or below it "
                                  f"within |z| <= {SEARCH_MM:g} mm")
        for _ in range(20):  # polish along z
            g = surface.gap(p[None], t)
            if abs(g.normal[0, 2]) < 1e-9:
                break
            p[2] -= g.phi[0] / g.normal[0, 2]
    g = surface.gap(p[None], t)
    n = g.normal[0]
    if not (abs(g.phi[0]) < _TOL * max(1.0, Δ) * 10 and np.isfinite(n).all()
            and np.linalg.norm(n) > 1e-6):
        raise DrapeInputError(f"kinematic drape: the start point {where} mm could not be "
                              f"put on the surface '{name}' (φ = {g.phi[0]:.3g} mm)")
    n = n / np.linalg.norm(n)
    return p, (n if n[2] >= 0 else -n)


def _needed(inside: np.ndarray, c: tuple[int, int]) -> np.ndarray:
    """Nodes to place: those of the blank and the ones they hang on (towards the start).

    A node (i, j) hangs on every node between it and the start: |i'| ≤ |i|, |j'| ≤ |j| in
    its quadrant.
    """
    need = np.zeros_like(inside)
    ci, cj = c
    for si in (slice(ci, None), slice(ci, None, -1) if ci else slice(0, 1)):
        for sj in (slice(cj, None), slice(cj, None, -1) if cj else slice(0, 1)):
            q = inside[si, sj]
            q = np.logical_or.accumulate(q[::-1], axis=0)[::-1]
            q = np.logical_or.accumulate(q[:, ::-1], axis=1)[:, ::-1]
            need[si, sj] |= q
    need[ci, cj] = True
    return need


def drape(surface: Surface, cell_mm: float, *, outline, start_mm=(0.0, 0.0),
          direction_deg: float | None = None, ply_angle_deg: float = 0.0,
          generator: str = "geodesic", locking_angle_deg: float | None = None,
          time_s: float = 0.0, warn: bool = True) -> KinematicNet:
    """Drape a pin-jointed net of cell ``cell_mm`` on ``surface`` (see the module's notes).

    Args:
        surface: Anything with ``gap(x, t) -> Gap``; its zero level set is the mould.
        cell_mm: The cell size Δ (mm): every bar of the net is a chord of this length.
        outline: The blank on the flat sheet: a polygon (m, 2) in mm (:func:`rectangle`).
        start_mm: The start node: (x, y) on the flat sheet, placed on the highest surface
            point above it; or (x, y, z) on the surface (within 0.01 mm).
        direction_deg: The warp's initial direction on the surface: its tangent's projection
            on the xy-plane at this angle to x (default: the ply angle).
        ply_angle_deg: The warp at this angle to x on the flat sheet (the net turned about
            the start node inside the outline).
        generator: ``"geodesic"`` (default) or ``"normal_section"``.
        locking_angle_deg: A cell sheared beyond this angle locks: its last node is left
            absent (default: no limit; the net folds up to 90°).
        time_s: The time at which the surface is evaluated.
        warn: Warn when nodes of the blank could not be placed.

    Returns:
        The net: flat (``X``) and draped (``x``) nodes, absent ones NaN.

    Raises:
        ParameterError: A bad option. DrapeInputError: the start point is off the surface.
    """
    Δ = float(cell_mm)
    if not (math.isfinite(Δ) and Δ > 0.0):
        raise ParameterError(f"kinematic drape: cell_mm = {cell_mm} must be positive")
    if generator not in GENERATORS:
        raise ParameterError(f"kinematic drape: generator = {generator!r} is not one of "
                             f"{', '.join(GENERATORS)}")
    if locking_angle_deg is not None and not 0.0 < locking_angle_deg <= 90.0:
        raise ParameterError(f"kinematic drape: locking_angle_deg = {locking_angle_deg} must "
                             "lie in (0, 90]")
    θ = float(ply_angle_deg)
    α = θ if direction_deg is None else float(direction_deg)
    if not (math.isfinite(θ) and math.isfinite(α)):
        raise ParameterError("kinematic drape: ply_angle_deg and direction_deg must be finite")
    poly = _outline(outline)
    S, n0 = _start(surface, time_s, start_mm, Δ)
    where = "(" + ", ".join(f"{v:.6g}" for v in S) + ")"

    # The flat net: node (i, j) at S + Δ (i u + j v), over the outline's extent.
    u = np.array([math.cos(math.radians(θ)), math.sin(math.radians(θ))])
    v = np.array([-u[1], u[0]])
    T = (poly - S[:2]) @ np.column_stack([u, v]) / Δ
    lo = np.minimum(np.ceil(T.min(axis=0) - 1e-9), 0).astype(int)
    hi = np.maximum(np.floor(T.max(axis=0) + 1e-9), 0).astype(int)
    ti, tj = np.meshgrid(  # tow indices of the nodes, 0 at the start
        np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    X = np.zeros((*ti.shape, 3))
    X[..., :2] = S[:2] + Δ * (ti[..., None] * u + tj[..., None] * v)
    inside = inside_outline(X[..., :2].reshape(-1, 2), poly, 1e-9 * Δ).reshape(ti.shape)
    c = (int(-lo[0]), int(-lo[1]))
    need = _needed(inside, c)

    # The initial directions on the surface: warp t0 (projection at α to x), weft n0 × t0.
    d = np.array([math.cos(math.radians(α)), math.sin(math.radians(α)), 0.0])
    if abs(n0[2]) < 1e-6:
        raise DrapeInputError(f"kinematic drape: the surface is vertical at the start point "
                              f"{where} mm: no tangent has a direction in the xy-plane")
    t0 = d - (d @ n0) / n0[2] * np.array([0.0, 0.0, 1.0])
    t0 /= np.linalg.norm(t0)
    w0 = np.cross(n0, t0)

    P = np.full((*ti.shape, 3), np.nan)
    N = np.full((*ti.shape, 3), np.nan)
    P[c], N[c] = S, n0
    si, sj = np.sign(ti), np.sign(tj)
    arm = np.zeros((*ti.shape, 3))  # a generator's initial direction (zero off the generators)
    arm[(tj == 0) & (ti != 0)] = si[(tj == 0) & (ti != 0), None] * t0
    arm[(ti == 0) & (tj != 0)] = sj[(ti == 0) & (tj != 0), None] * w0
    level = np.abs(ti) + np.abs(tj)
    for s in range(1, int(level[need].max(initial=0)) + 1):
        ii, jj = np.nonzero(need & (level == s))
        gi, gj = ii - c[0], jj - c[1]  # net indices
        gen = (gi == 0) | (gj == 0)
        di, dj = np.sign(gi), np.sign(gj)
        A = np.where(gen[:, None], P[ii - di, jj - dj], P[ii - di, jj])
        B = P[ii, jj - dj]
        C = P[ii - di, jj - dj]
        # Generators: the incoming chord (the initial direction at the start's neighbours)
        # and the plane through A holding it and the normal.
        e = arm[ii, jj]
        behind = P[np.clip(ii - 2 * di, 0, ti.shape[0] - 1),
                   np.clip(jj - 2 * dj, 0, ti.shape[1] - 1)]
        chord = np.where((gen & (s >= 2))[:, None], A - behind, e)
        if generator == "geodesic":
            b = np.cross(N[ii - di, jj - dj], chord)
        else:
            b = np.cross(n0, e)
        b /= np.maximum(np.linalg.norm(b, axis=1), 1e-300)[:, None]
        second = np.where(gen[:, None], b, B)
        guess = np.where(gen[:, None],
                         A + Δ * chord / np.maximum(np.linalg.norm(chord, axis=1),
                                                    1e-300)[:, None],
                         A + B - C)
        # Locked cells (the chord spheres about A and B do not meet) are not tried.
        locked = ~gen & ~(np.linalg.norm(A - B, axis=1) < 2 * Δ * (1 - 1e-9))
        guess[locked] = np.nan
        Q, nQ, ok = _solve(surface, time_s, Δ, A, second, ~gen, guess)
        # The right root: ahead on a generator, across AB from C in a cell.
        M = 0.5 * (A + B)
        ok &= np.where(gen, np.einsum("ni,ni->n", Q - A, chord) > 0,
                       np.einsum("ni,ni->n", Q - M, C - M) < 0)
        if locking_angle_deg is not None:  # the cell's shear (FormedGrid.shear_deg)
            a, b = (B - C) + (Q - A), (A - C) + (Q - B)
            with np.errstate(divide="ignore", invalid="ignore"):
                cos = np.einsum("ni,ni->n", a, b) / (np.linalg.norm(a, axis=1)
                                                     * np.linalg.norm(b, axis=1))
            γ = np.degrees(np.arcsin(np.clip(np.abs(cos), 0.0, 1.0)))
            ok &= gen | (γ <= locking_angle_deg)
        P[ii[ok], jj[ok]], N[ii[ok], jj[ok]] = Q[ok], nQ[ok]

    placed = np.isfinite(P[..., 0])
    unplaced = inside & ~placed
    keep = inside & placed
    X[~keep], P[~keep] = np.nan, np.nan
    if warn and unplaced.any():
        warnings.warn(f"kinematic drape on '{getattr(surface, 'name', 'surface')}': "
                      f"{int(unplaced.sum())} of {int(inside.sum())} nodes of the blank could "
                      "not be placed (the surface ends or the net locks); they are absent",
                      stacklevel=2)
    return KinematicNet(X=X, x=P, quarter=False, start_mm=S, start_index=c,
                        unplaced=unplaced, direction_deg=α, ply_angle_deg=θ,
                        generator=generator, locking_angle_deg=locking_angle_deg,
                        surface=str(getattr(surface, "name", "")))


def kinematic_drape(surface, cell_mm: float = 10.0, **options) -> KinematicNet:
    """Drape a pin-jointed net on a surface: :func:`drape`, with the hemisphere as a default.

    Given a :class:`HemisphereTools`, the surface is its formed part
    (:meth:`HemisphereTools.formed_part`), the blank the ``sheet_mm`` square centred on the
    axis and the start the apex, unless given in ``options``: today's
    ``kinematic_drape(tools, cell_mm)``.

    Args:
        surface: A surface (``gap(x, t)``) or a :class:`HemisphereTools`.
        cell_mm: The cell size Δ (mm).
        **options: Keyword options of :func:`drape` (``outline`` needed for a surface).
    """
    if isinstance(surface, HemisphereTools):
        options.setdefault("outline", rectangle((surface.sheet_mm, surface.sheet_mm)))
        surface = surface.formed_part()
    elif "outline" not in options:
        raise ParameterError("kinematic drape: give the blank's outline (outline=...)")
    return drape(surface, cell_mm, **options)


def case_surface(case, tools: dict | None = None, *, time_s: float | None = None,
                 blend_mm: float = 0.5) -> UnionSurface:
    """The formed surface of a forming case: the tools the sheet lies on, at the end, united.

    The tools whose sheet side is +z (by default punches, holders and plain surfaces: the
    sheet lies on them), or, when there are none, those whose sheet side is −z; dies on the
    other side are left out. For the hemisphere: the punch at full travel and the holder
    plane, i.e. :meth:`HemisphereTools.formed_part`.

    Args:
        case: The forming case (:func:`~fenicsx_drape.forming.case.reading.load_case`).
        tools: Built tools by name (default :func:`~fenicsx_drape.forming.tools.build.build_tools`).
        time_s: When (default: the end of the motion, ``case.duration_s``).
        blend_mm: See :class:`UnionSurface`.
    """
    from fenicsx_drape.forming.tools.build import build_tools

    for side in ("+z", "-z"):
        names = [t.name for t in case.tools if t.side == side]
        if names:
            break
    else:
        raise ParameterError(f"{case.path or case.name}: kinematic drape: no tool with its sheet "
                             "side +z or -z to drape on")
    if tools is None:
        tools = build_tools(case, skip=tuple(t.name for t in case.tools if t.name not in names))
    t = case.duration_s if time_s is None else float(time_s)
    return formed_surface([tools[n] for n in names], t, blend_mm=blend_mm,
                          name=f"{case.name} formed surface ({', '.join(names)})")


def drape_case(case, *, tools: dict | None = None, cell_mm: float | None = None,
               start_mm=None, direction_deg: float | None = None,
               ply_angle_deg: float | None = None, **options) -> KinematicNet:
    """The kinematic drape of a forming case's blank on its formed surface.

    The case gives the defaults: the whole blank's outline (symmetry planes are not used:
    the four quadrants are built), its Δ, its ply angle, and its net's origin
    (``origin_mm``) as the start; the surface is :func:`case_surface`.

    Args:
        case: The forming case.
        tools: Built tools by name (default: the case's).
        cell_mm: Δ (mm), default the case's.
        start_mm: The start (default: the blank's ``origin_mm``).
        direction_deg: The warp's initial direction (default: the ply angle).
        ply_angle_deg: Default the case's.
        **options: Other options of :func:`drape` (``generator``, ``locking_angle_deg``).
    """
    blank = case.blank
    return drape(case_surface(case, tools), blank.cell_mm if cell_mm is None else cell_mm,
                 outline=blank.polygon(),
                 start_mm=blank.origin_mm if start_mm is None else start_mm,
                 direction_deg=direction_deg,
                 ply_angle_deg=blank.ply_angle_deg if ply_angle_deg is None else ply_angle_deg,
                 **options)


def write_drape(out_dir: str | os.PathLike, net: KinematicNet, *, grid_mm: float = 10.0,
                setup: dict | None = None, pictures: bool = True,
                case: dict | None = None, forming_case=None) -> dict:
    """Write a draped net: ``summary.json``, ``shear.png``, ``bundle/``, ``provenance.json``.

    Args:
        out_dir: The output folder (created).
        net: The net (:class:`~fenicsx_drape.forming.running.kinematic.KinematicNet`).
        grid_mm: Spacing of the bundle's drawn grid (mm).
        setup: The forming test's keys of the bundle (geometry, sheet_mm, ...); no bundle
            when None (nor ``forming_case``).
        pictures: Write ``shear.png``.
        case: What was draped, for ``summary.json`` and ``provenance.json``.
        forming_case: A forming case (:class:`~fenicsx_drape.forming.case.spec.FormingCase`):
            the bundle's test names a copy of it (``case = "case/case.toml"``), as
            :func:`~fenicsx_drape.forming.running.outputs.form_case` writes it.

    Returns:
        The summary.
    """
    from pathlib import Path

    from fenicsx_drape.forming.running.plots import plot_shear
    from fenicsx_drape.measurements.bundle import Bundle, Test, write_bundle
    from fenicsx_drape.provenance import write_json, write_provenance

    out = Path(out_dir)
    summary = {**net.summary(), "case": case or {}}
    write_json(out / "summary.json", summary)
    notes = {"simulation": "kinematic drape (pin-jointed net)", "generator": net.generator}
    if forming_case is not None:
        from fenicsx_drape.forming.case import write_case

        write_case(forming_case, out / "bundle" / "case")
        notes["case"] = "case/case.toml"
        setup = {"travel_mm": forming_case.total_travel_mm,
                 "duration_s": forming_case.duration_s, **(setup or {})}
        if forming_case.holder is not None:
            setup.setdefault("holder_force_N", forming_case.holder.force_N)
    if setup is not None:
        table = net.drawn_grid(grid_mm)
        columns = {k: np.asarray(v, dtype=float) for k, v in table.items()}
        setup = {**setup, "grid_mm": grid_mm}
        geometry = setup.pop("geometry", None)
        test = Test(id=f"kinematic-{summary['cell_mm']:g}mm", kind="forming",
                    file="kinematic_grid.csv", columns=columns, geometry=geometry,
                    forming=setup, notes=notes)
        label = geometry or (forming_case.name if forming_case is not None else "case")
        write_bundle(Bundle(name=f"kinematic-drape-{label}", tests=(test,)),
                     out / "bundle", comment=f"kinematic drape by fenicsx_drape: cell "
                     f"{summary['cell_mm']:g} mm, {net.generator} generators, direction "
                     f"{net.direction_deg:g}°, ply angle {net.ply_angle_deg:g}°")
    if pictures:
        plot_shear(net, out / "shear.png", f"kinematic drape on {net.surface}, shear angle "
                   f"(max {summary['max_shear_deg']:.1f}°)")
    write_provenance(out, case=case or {}, kinematic={
        k: summary[k] for k in ("cell_mm", "start_mm", "direction_deg", "ply_angle_deg",
                                "generator", "locking_angle_deg", "surface")})
    return summary
