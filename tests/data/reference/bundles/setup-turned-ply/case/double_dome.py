"""The double-dome tool surface for Gmsh (``build(gmsh, **parameters)``, case.toml).

Two domes on a flat base, joined by a saddle: the shape of the international woven-composite
forming benchmark's double dome (Khan, Boisse et al. 2010; Boisse et al. 2011). Its published
drawings are not open; the numbers here are chosen (docs/cases.md, "The double dome"). The surface
is a height field above the base plane,

    F(x, y) = (p(r₁)⁴ + p(r₂)⁴)^¼,  p(r) = H (1 + cos(π r / R_b)) / 2 for r < R_b, else 0,

r₁, r₂ the distances to the domes' centres (±c, 0): each dome a smooth bump of height H and
foot radius R_b, the two joined by a smooth maximum (a saddle of height ≈ 0.3 H at x = 0).
Gmsh holds it as a bicubic B-spline surface on a grid of control points (OpenCASCADE) and
meshes it; the surface covers the whole blank so its edge is never near the sheet.
"""

import math


def height_mm(x, y, dome_height_mm, dome_radius_mm, dome_centre_mm):
    """F(x, y): the height of the double dome above its base (mm)."""
    def bump(r):
        return 0.5 * dome_height_mm * (1.0 + math.cos(math.pi * r / dome_radius_mm)) \
            if r < dome_radius_mm else 0.0

    p1 = bump(math.hypot(x - dome_centre_mm, y))
    p2 = bump(math.hypot(x + dome_centre_mm, y))
    return (p1**4 + p2**4) ** 0.25


def build(gmsh, dome_height_mm=40.0, dome_radius_mm=60.0, dome_centre_mm=40.0,
          half_length_mm=165.0, half_width_mm=115.0, z_base_mm=0.0, offset_mm=0.0,
          control_mm=4.0):
    """Add the surface z = z_base + F(x, y) + offset over |x| ≤ half_length, |y| ≤ half_width.

    ``offset_mm`` shifts it up (the die: the punch surface lifted by the ply thickness).
    """
    nu = 2 * math.ceil(half_length_mm / control_mm) + 1
    nv = 2 * math.ceil(half_width_mm / control_mm) + 1
    tags = []
    for j in range(nv):
        y = -half_width_mm + 2.0 * half_width_mm * j / (nv - 1)
        for i in range(nu):
            x = -half_length_mm + 2.0 * half_length_mm * i / (nu - 1)
            z = z_base_mm + offset_mm + height_mm(x, y, dome_height_mm, dome_radius_mm,
                                                   dome_centre_mm)
            tags.append(gmsh.model.occ.addPoint(x, y, z))
    gmsh.model.occ.addBSplineSurface(tags, nu, degreeU=3, degreeV=3)
    gmsh.model.occ.synchronize()
