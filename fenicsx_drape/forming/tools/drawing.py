"""The tools as Gmsh geometry, for pictures and ParaView (the contact uses the exact surfaces).

Each profile of :mod:`fenicsx_drape.forming.tools.shapes` is drawn in the x-z plane with OpenCASCADE
arcs and lines and revolved about the z axis; the blank holder is two square plates with the
circular opening. The surfaces are meshed with triangles and written as legacy VTK files that
ParaView opens next to the sheet's XDMF fields.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from fenicsx_drape.forming.tools.shapes import Arc, HemisphereTools, RevolvedTool

PLATE_MM = 6.0  # thickness of the drawn holder plates (mm), for the picture only


def _profile_curves(occ, tool: RevolvedTool, t: float, r_max: float, h_min: float) -> list[int]:
    """Curves of a tool's profile at time ``t`` in the x-z plane, long pieces clipped."""
    z0 = tool.z_offset(t)
    curves = []
    for piece in tool.profile:
        if isinstance(piece, Arc):
            a, b = piece.point(piece.start), piece.point(piece.end)
            pa = occ.addPoint(a[0], 0.0, z0 + a[1])
            pc = occ.addPoint(piece.centre[0], 0.0, z0 + piece.centre[1])
            pb = occ.addPoint(b[0], 0.0, z0 + b[1])
            curves.append(occ.addCircleArc(pa, pc, pb))
        else:
            ends = []
            for r, h in (piece.a, piece.b):
                ends.append((min(r, r_max), max(h, h_min)))
            pa = occ.addPoint(ends[0][0], 0.0, z0 + ends[0][1])
            pb = occ.addPoint(ends[1][0], 0.0, z0 + ends[1][1])
            curves.append(occ.addLine(pa, pb))
    return curves


def write_tool_meshes(tools: HemisphereTools, folder: str | os.PathLike, *,
                      travel_mm: float | None = None, size_mm: float = 3.0) -> list[Path]:
    """Write ``punch.vtk``, ``die.vtk`` and ``holder.vtk`` into ``folder``.

    Args:
        tools: The tool set.
        folder: Output folder.
        travel_mm: Punch travel to draw it at (default: the full travel).
        size_mm: Target triangle size.

    Returns:
        The written files.
    """
    import gmsh

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    travel = tools.travel_mm if travel_mm is None else travel_mm
    duration = 1.0  # the punch is drawn at time t = travel / speed with speed = travel_mm
    punch = tools.punch(duration)
    half = 0.5 * tools.sheet_mm + 20.0
    initialised = gmsh.isInitialized()
    if not initialised:
        gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    written = []
    try:
        for name, tool, t, r_max, h_min in (
                ("punch", punch, travel / tools.travel_mm, tools.shoulder_radius_mm, -20.0),
                ("die", tools.die(), 0.0, tools.opening_radius_mm, -math.inf)):
            gmsh.model.add(name)
            occ = gmsh.model.occ
            curves = _profile_curves(occ, tool, t, r_max, h_min)
            occ.revolve([(1, c) for c in curves], 0, 0, 0, 0, 0, 1, 2 * math.pi)
            occ.synchronize()
            written.append(_mesh_and_write(gmsh, folder / f"{name}.vtk", size_mm))
        gmsh.model.add("holder")
        occ = gmsh.model.occ
        R = tools.opening_radius_mm
        for z in (0.0, -PLATE_MM):
            box = occ.addBox(-half, -half, z, 2 * half, 2 * half, PLATE_MM)
            hole = occ.addCylinder(0, 0, z - 1.0, 0, 0, PLATE_MM + 2.0, R)
            occ.cut([(3, box)], [(3, hole)])
        occ.synchronize()
        written.append(_mesh_and_write(gmsh, folder / "holder.vtk", 2 * size_mm))
    finally:
        if not initialised:
            gmsh.finalize()
    return written


def _mesh_and_write(gmsh, path: Path, size_mm: float) -> Path:
    gmsh.option.setNumber("Mesh.MeshSizeMax", size_mm)
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.2 * size_mm)
    gmsh.model.mesh.generate(2)
    tmp = path.with_name(f".{path.name}.tmp.vtk")
    gmsh.write(str(tmp))
    os.replace(tmp, path)
    gmsh.model.remove()
    return path
