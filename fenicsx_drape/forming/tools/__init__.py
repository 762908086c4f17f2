"""Tool geometry and motion: what the sheet is formed on.

- :mod:`~fenicsx_drape.forming.tools.shapes`: the paper's closed-form hemisphere tools,
  tools of revolution, and a meshed tool (a surface moved by a motion);
- :mod:`~fenicsx_drape.forming.tools.surfaces`: triangle surfaces from Gmsh, CAD and STL;
- :mod:`~fenicsx_drape.forming.tools.distance`: the smooth signed distance to a surface;
- :mod:`~fenicsx_drape.forming.tools.motion`: a tool's prescribed rigid motion;
- :mod:`~fenicsx_drape.forming.tools.drawing`: the builtin tools drawn as meshes (pictures).
"""
