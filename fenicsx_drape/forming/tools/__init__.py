"""Tool geometry and motion: what the sheet is formed on.

- :mod:`~fenicsx_drape.forming.tools.shapes`: the paper's closed-form hemisphere tools,
  tools of revolution, and a meshed tool (a surface moved by a motion);
- :mod:`~fenicsx_drape.forming.tools.surfaces`: triangle surfaces from Gmsh, CAD and STL;
- :mod:`~fenicsx_drape.forming.tools.distance`: the smooth signed distance to a surface;
- :mod:`~fenicsx_drape.forming.tools.motion`: a tool's prescribed rigid motion;
- :mod:`~fenicsx_drape.forming.tools.drawing`: the builtin tools drawn as meshes (pictures);
- :mod:`~fenicsx_drape.forming.tools.build`: a case's tools built from its tables.
"""

from fenicsx_drape._lazy import lazy_exports

# The public names, from the package, each imported on first use.
_PUBLIC = {
    "Arc": "shapes",
    "DistanceField": "distance",
    "HemisphereTools": "shapes",
    "MeshedTool": "shapes",
    "RevolvedTool": "shapes",
    "RigidMotion": "motion",
    "Segment": "shapes",
    "TriangleSurface": "surfaces",
    "build_tools": "build",
    "distance_field": "distance",
    "load_surface": "surfaces",
    "write_tool_meshes": "drawing",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _PUBLIC)
