"""The square-box tool surface for Gmsh (``build(gmsh, **parameters)``, case.toml).

A square punch with rounded vertical edges (corner radius r_c) and a rounded bottom edge
(fillet r_b), standing on a flat base plane that covers the whole blank, with a foot radius
r_f where wall and base meet: the shape of the deep-drawn square box (docs/cases.md, "The square
box"; dimensions chosen there). OpenCASCADE builds it as a solid (a plate and the box fused,
then filleted); the surface kept is the box's top, walls and fillets and the plate's top.

``offset_mm`` gives the surface offset by that distance towards the sheet (the die: the punch
lifted by clearance + ply): every convex radius grows by it, the concave foot radius shrinks.
"""


def _edges(gmsh, volume):
    """The curves of a volume, each with its bounding box (x0, y0, z0, x1, y1, z1)."""
    faces = gmsh.model.getBoundary([(3, volume)], combined=False)
    curves = {t for _, t in gmsh.model.getBoundary(faces, combined=False, oriented=False)}
    return [(t, gmsh.model.getBoundingBox(1, t)) for t in sorted(curves)]


def _level_edges(gmsh, volume, z, half_side):
    """The horizontal curves at height z within |x|, |y| ≤ half_side (the box's rim)."""
    return [t for t, (x0, y0, z0, x1, y1, z1) in _edges(gmsh, volume)
            if max(abs(x0), abs(x1), abs(y0), abs(y1)) < half_side + 1e-3
            and abs(z0 - z) < 1e-3 and abs(z1 - z) < 1e-3]


def build(gmsh, half_side_mm=50.0, corner_radius_mm=20.0, fillet_radius_mm=15.0,
          foot_radius_mm=5.0, depth_mm=30.0, half_extent_mm=135.0, z_base_mm=0.0,
          offset_mm=0.0):
    """Add the box of half side a and height ``depth_mm`` on the plane z = z_base (+ offset).

    Args:
        gmsh: The Gmsh module (initialised, a model current).
        half_side_mm: Half the punch's side a (the box is 2a x 2a).
        corner_radius_mm: Radius r_c of the four vertical edges.
        fillet_radius_mm: Radius r_b of the edge between the box's bottom and its walls.
        foot_radius_mm: Radius r_f of the concave edge between the walls and the base plane.
        depth_mm: Height of the box above the base plane (the drawing depth).
        half_extent_mm: Half side of the base plane (beyond the blank).
        z_base_mm: Height of the base plane.
        offset_mm: Offset of the whole surface towards the sheet (≥ 0, < r_f).
    """
    occ = gmsh.model.occ
    o = float(offset_mm)
    a, rc, rb, rf = (half_side_mm + o, corner_radius_mm + o, fillet_radius_mm + o,
                     foot_radius_mm - o)
    z0, z1 = z_base_mm + o, z_base_mm + o + depth_mm
    plate_mm = 5.0  # thickness of the base plate: only its top face is kept
    plate = occ.addBox(-half_extent_mm, -half_extent_mm, z0 - plate_mm, 2 * half_extent_mm,
                       2 * half_extent_mm, plate_mm)
    box = occ.addBox(-a, -a, z0 - plate_mm, 2 * a, 2 * a, depth_mm + plate_mm)
    occ.synchronize()
    vertical = [t for t, (x0, y0, _, x1, y1, _) in _edges(gmsh, box)
                if abs(x1 - x0) < 1e-6 and abs(y1 - y0) < 1e-6]
    box = occ.fillet([box], vertical, [rc])[0][1]
    (solid, *_), _ = occ.fuse([(3, plate)], [(3, box)])
    occ.synchronize()
    vol = occ.fillet([solid[1]], _level_edges(gmsh, solid[1], z1, a), [rb])[0][1]
    if rf > 0:
        occ.synchronize()
        vol = occ.fillet([vol], _level_edges(gmsh, vol, z0, a), [rf])[0][1]
    occ.synchronize()
    # Keep the faces the sheet can touch: all but the plate's bottom and its four sides.
    drop = []
    for _, t in gmsh.model.getBoundary([(3, vol)], combined=False, oriented=False):
        x0, y0, zz0, x1, y1, zz1 = gmsh.model.getBoundingBox(2, t)
        side = max(abs(x0), abs(x1), abs(y0), abs(y1)) > half_extent_mm - 1e-3 \
            and zz1 - zz0 > 1e-3
        if zz1 < z0 - 1e-3 or side:
            drop.append(t)
    occ.remove([(3, vol)])
    occ.remove([(2, t) for t in drop], recursive=True)
    occ.synchronize()
