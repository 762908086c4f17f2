"""A lab's STL copies of forming tools, from their drawings: triangles computed with NumPy.

Nothing here imports ``fenicsx_drape``: the shapes are those the parts' drawings give
(``meshes/*/case.toml`` and the geometry files they name state them in words and numbers).

- :func:`height_field`: a surface z = z₀ + F(x, y) on a rectangle (the double dome's tools).
- :func:`swept_box`: a box punch or die — a rounded rectangle (half sides a, b, corner radius
  r_c) with a rounded top edge (r_b), vertical walls, a rounded foot (r_f) and a flat base —
  as rounded-rectangle rings offset inward or outward by δ (an exact rolling-ball fillet of a
  rounded box when r_c ≥ r_b): the square box's tools and the user's part.
- :func:`holder_plate`: the plane z = 0 outside a rounded-rectangle opening.
"""

from __future__ import annotations

import math

import numpy as np


def _grid_triangles(P: np.ndarray, closed: bool = False) -> np.ndarray:
    """Triangles (m, 3, 3) of a structured grid of points P (n_u, n_v, 3).

    ``closed``: the v direction wraps around (rings).
    """
    if closed:
        P = np.concatenate([P, P[:, :1]], axis=1)
    a, b = P[:-1, :-1], P[1:, :-1]
    c, d = P[:-1, 1:], P[1:, 1:]
    tri = np.concatenate([np.stack([a, b, d], axis=-2).reshape(-1, 3, 3),
                          np.stack([a, d, c], axis=-2).reshape(-1, 3, 3)])
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return tri[area > 1e-9]


def height_field(F, half_x: float, half_y: float, step_mm: float, z0: float = 0.0
                 ) -> np.ndarray:
    """Triangles of z = z0 + F(x, y) over |x| ≤ half_x, |y| ≤ half_y, ``step_mm`` apart."""
    nx = 2 * math.ceil(half_x / step_mm) + 1
    ny = 2 * math.ceil(half_y / step_mm) + 1
    x, y = np.meshgrid(np.linspace(-half_x, half_x, nx), np.linspace(-half_y, half_y, ny),
                       indexing="ij")
    return _grid_triangles(np.stack([x, y, z0 + F(x, y)], axis=-1))


def double_dome_height(H: float = 40.0, R: float = 60.0, c: float = 40.0):
    """The double dome's height above its base: (p(r₁)⁴ + p(r₂)⁴)^¼, p(r) = H(1 + cos πr/R)/2
    for r < R (domes of height H and foot radius R centred at (±c, 0))."""
    def F(x, y):
        def bump(r):
            return np.where(r < R, 0.5 * H * (1.0 + np.cos(np.pi * np.minimum(r, R) / R)), 0.0)
        return (bump(np.hypot(x - c, y)) ** 4 + bump(np.hypot(x + c, y)) ** 4) ** 0.25
    return F


def rounded_rectangle(a: float, b: float, r: float, n_side: int, n_corner: int) -> np.ndarray:
    """Points (k, 2) around a rounded rectangle of half sides a, b and corner radius r.

    The same number of points for any a, b, r (rings of one sweep join point to point); a
    side or a corner of zero length gives repeated points.
    """
    r = max(min(r, a, b), 0.0)
    pts = []
    centres = [(a - r, b - r), (-(a - r), b - r), (-(a - r), -(b - r)), (a - r, -(b - r))]
    for k, (cx, cy) in enumerate(centres):
        φ0 = k * np.pi / 2
        φ = φ0 + np.linspace(0.0, np.pi / 2, n_corner, endpoint=False)
        pts.append(np.column_stack([cx + r * np.cos(φ), cy + r * np.sin(φ)]))
        # then the straight side to the next corner
        e = np.array([np.cos(φ0 + np.pi / 2), np.sin(φ0 + np.pi / 2)]) * r + (cx, cy)
        nxt = centres[(k + 1) % 4]
        f = np.array([np.cos(φ0 + np.pi / 2), np.sin(φ0 + np.pi / 2)]) * r + nxt
        t = np.linspace(0.0, 1.0, n_side, endpoint=False)[:, None]
        pts.append(e + t * (f - e))
    return np.concatenate(pts)


def swept_box(a: float, b: float, rc: float, rb: float, rf: float, depth: float,
              z_base: float, extent: float, chord_mm: float = 2.0, offset: float = 0.0
              ) -> np.ndarray:
    """Triangles of a box punch (or its die: ``offset`` towards the sheet) on a flat base.

    The box: half sides a, b, vertical edges of radius rc, top edge rb, foot rf, ``depth``
    above the base plane z = z_base; the base plane reaches ``extent`` mm beyond the wall.
    With ``offset`` o every convex radius and the sides grow by o, the foot shrinks by o and
    the whole rises by o (the punch's surface offset towards the sheet).
    """
    o = offset
    a, b, rc, rb, rf = a + o, b + o, rc + o, rb + o, max(rf - o, 0.0)
    zb, zt = z_base + o, z_base + o + depth
    profile = []  # (δ inward, z) from the box's centre out to the base's edge
    for δ in np.linspace(min(a, b), rb, max(2, math.ceil((min(a, b) - rb) / chord_mm) + 1)):
        profile.append((δ, zt))
    n = max(3, math.ceil(rb * np.pi / 2 / chord_mm) + 1)
    for φ in np.linspace(np.pi / 2, 0.0, n)[1:]:
        profile.append((rb - rb * math.cos(φ), zt - rb + rb * math.sin(φ)))
    wall = zt - rb - (zb + rf)
    for z in np.linspace(zt - rb, zb + rf, max(2, math.ceil(wall / chord_mm) + 1))[1:]:
        profile.append((0.0, z))
    if rf > 0:
        n = max(3, math.ceil(rf * np.pi / 2 / chord_mm) + 1)
        for φ in np.linspace(0.0, np.pi / 2, n)[1:]:
            profile.append((-rf + rf * math.cos(φ), zb + rf - rf * math.sin(φ)))
    for δ in np.linspace(-rf, -extent, max(2, math.ceil((extent - rf) / (2 * chord_mm)) + 1))[1:]:
        profile.append((δ, zb))
    n_side = max(2, math.ceil(2 * max(a, b) / chord_mm))
    n_corner = max(4, math.ceil((rc + extent) * np.pi / 2 / (2 * chord_mm)))
    rings = []
    for δ, z in profile:
        xy = rounded_rectangle(a - δ, b - δ, rc - δ, n_side, n_corner)
        rings.append(np.column_stack([xy, np.full(len(xy), z)]))
    return _grid_triangles(np.array(rings), closed=True)


def holder_plate(a: float, b: float, r: float, reach: float, chord_mm: float = 4.0
                 ) -> np.ndarray:
    """Triangles of the plane z = 0 outside a rounded-rectangle opening (half sides a, b,
    corner radius r), out to ``reach`` mm beyond the opening."""
    n_side = max(2, math.ceil(2 * max(a, b) / chord_mm))
    n_corner = max(4, math.ceil((r + reach) * np.pi / 2 / chord_mm))
    rings = []
    for e in np.linspace(0.0, reach, max(2, math.ceil(reach / chord_mm) + 1)):
        xy = rounded_rectangle(a + e, b + e, r + e, n_side, n_corner)
        rings.append(np.column_stack([xy, np.zeros(len(xy))]))
    return _grid_triangles(np.array(rings), closed=True)
