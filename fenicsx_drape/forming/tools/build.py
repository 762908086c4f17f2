"""The tools of a forming case, built: closed-form builtin tools and meshed geometry files.

:func:`build_tools` turns a case's tool specifications (``[[tool]]`` tables, read by
:mod:`fenicsx_drape.forming.case`) into the rigid tools a run contacts: the builtin hemisphere
set (:class:`~fenicsx_drape.forming.tools.shapes.HemisphereTools`) in closed form, every other
geometry file meshed once by Gmsh (:func:`~fenicsx_drape.forming.tools.surfaces.load_surface`)
and checked as a mesh (:mod:`~fenicsx_drape.forming.tools.checks`): a punch, die or surface of
separate pieces or with a hole is refused, a mesh coarse for its curvature warned.

Before anything is meshed, :func:`check_tool_sizes` estimates every tool's triangles from the
case (:func:`tool_triangles`) and refuses meshes beyond the memory limit
(:mod:`fenicsx_drape.limits`).

This module reads a case through its attributes only (``tools``, ``blank``, ``duration_s``,
``path``, ``origin``...): tool geometry knows no case format.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from fenicsx_drape.errors import InputFileError
from fenicsx_drape.forming.tools.checks import coarse_mesh_problem

# A tool mesh finer than the sheet's cell by this factor costs memory and time for nothing.
FINE_MESH_FACTOR = 20.0


def builtin_tool_set(spec):
    """The closed-form hemisphere tool set a builtin tool's parameters give."""
    from fenicsx_drape.forming.tools.shapes import HemisphereTools

    return HemisphereTools(**spec.params)


def build_tools(case, skip: tuple[str, ...] = ()) -> dict[str, object]:
    """The rigid tools of a case by name (builtin: closed form; files: meshed surfaces).

    A builtin punch moves ``travel_mm`` in the case's ``duration_s``; the builtin die is fixed
    at the punch's final position; the builtin holder is the plane z = 0 outside the opening
    (:class:`~fenicsx_drape.forming.tools.shapes.FlatHolder`). Tools named in ``skip`` are
    left out.
    """
    from fenicsx_drape.forming.tools.shapes import FlatHolder

    check_tool_sizes(case, skip)
    out: dict[str, object] = {}
    for spec in case.tools:
        if spec.name in skip:
            continue
        if spec.builtin:
            tools = builtin_tool_set(spec)
            if spec.role == "punch":
                tool = tools.punch(case.duration_s)
            elif spec.role == "die":
                tool = tools.die()
            else:
                tool = FlatHolder(tools.opening_radius_mm, name=spec.name)
            if getattr(tool, "name", spec.name) != spec.name and spec.role != "holder":
                tool = dataclasses.replace(tool, name=spec.name)
            out[spec.name] = tool
        else:
            out[spec.name] = _meshed_tool(case, spec)
    return out


def tool_triangles(case, spec) -> float | None:
    """About how many triangles a tool's mesh will have, from the case alone (None: unknown).

    A source Gmsh meshes at ``mesh_mm`` covers about the blank's box widened by the case's
    travel on every side; an STL or ``.msh`` file about its size over 50 bytes a triangle.
    """
    if spec.builtin or spec.path is None:
        return 0.0
    from fenicsx_drape.limits import triangles_for

    if spec.path.suffix.lower() in (".stl", ".msh"):
        try:
            return spec.path.stat().st_size / 50.0
        except OSError:
            return None
    if spec.mesh_mm is None:
        return None
    w, h = np.ptp(case.blank.polygon(), axis=0)
    travel = case.total_travel_mm
    return triangles_for((w + 2 * travel) * (h + 2 * travel), spec.mesh_mm, spec.order or 1)


def check_tool_sizes(case, skip: tuple[str, ...] = (), warn: bool = True) -> None:
    """Refuse tool meshes beyond the memory limit, warn of ones much finer than the sheet.

    Raises:
        DrapeInputError: with the estimate and the limit (:mod:`fenicsx_drape.limits`).
    """
    from fenicsx_drape.limits import check_triangles

    where = str(case.path or case.name)
    total, named = 0.0, []
    for spec in case.tools:
        n = None if spec.name in skip else tool_triangles(case, spec)
        if n:
            total += n
            named.append(f"{spec.name} {n:.3g}")
        Δ = case.blank.cell_mm
        if warn and spec.mesh_mm is not None and spec.mesh_mm * FINE_MESH_FACTOR < Δ:
            warnings.warn(f"{where}: tool {spec.name!r}: mesh_mm = {spec.mesh_mm:g} is "
                          f"{Δ / spec.mesh_mm:.3g} times finer than the sheet's cell "
                          f"{Δ:g} mm (about {n or 0:.3g} triangles): time and memory for no "
                          "accuracy", stacklevel=3)
    if total:
        check_triangles(total, f"{where}: tools ({', '.join(named)})")


def _meshed_tool(case, spec):
    """A tool from a geometry file: its surface meshed once by Gmsh, moved rigidly."""
    from fenicsx_drape.forming.tools.checks import holes, pieces
    from fenicsx_drape.forming.tools.shapes import MeshedTool
    from fenicsx_drape.forming.tools.surfaces import load_surface
    from fenicsx_drape.trust import require_trust

    k = case.tools.index(spec) + 1
    where = f"{case.path or case.name}: [[tool]] {k} ({spec.name!r})"
    if spec.path.suffix.lower() == ".py":
        require_trust(spec.path, "the Python geometry of tool " + repr(spec.name), case.origin)
    surface = load_surface(spec.path, spec.params or None, spec.mesh_mm, spec.order or 1,
                           sheet_side=spec.side)
    if spec.role != "holder":  # a holder's opening is a hole by design
        parts = pieces(surface)
        if len(parts) > 1:
            each = ", ".join(f"{m} triangles around ("
                             + ", ".join(f"{v:g}" for v in np.round(c, 1) + 0.0) + ") mm"
                             for m, c in parts[:3])
            raise InputFileError([f"{where}: {spec.path.name}: the {spec.role}'s surface is "
                                  f"{len(parts)} separate pieces ({each}): a {spec.role} must "
                                  "be one closed surface or one surface (a second shell in "
                                  "the file?)"])
        found = holes(surface)
        if found:
            centre, size = found[0]
            at = ", ".join(f"{v:g}" for v in np.round(centre, 1) + 0.0)
            raise InputFileError([f"{where}: {spec.path.name}: the {spec.role}'s surface has "
                                  f"{len(found)} hole(s): one of {size:.3g} mm across at "
                                  f"({at}) mm (a {spec.role} must be closed or one surface "
                                  "without holes: the sheet would sink into it)"])
    coarse = coarse_mesh_problem(surface, case.blank.cell_mm)
    if coarse:
        warnings.warn(f"{where}: {coarse}", stacklevel=3)
    return MeshedTool(spec.name, surface, spec.motion)
