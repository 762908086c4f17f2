"""A forming run and what it writes.

- :mod:`~fenicsx_drape.forming.running.run`: the run of any case (load steps, cut-backs,
  tool forces);
- :mod:`~fenicsx_drape.forming.running.outputs`: the outputs of ``drape form`` (summary,
  fields, bundle, pictures, provenance);
- :mod:`~fenicsx_drape.forming.running.post`: the formed sheet on its grid (shear,
  wrinkling, draw-in, the drawn grid of a bundle);
- :mod:`~fenicsx_drape.forming.running.measure`: the formed sheet measured as labs do
  (shear at points, distance to a scan, the edge);
- :mod:`~fenicsx_drape.forming.running.plots`: the pictures;
- :mod:`~fenicsx_drape.forming.running.kinematic`: the kinematic (pin-jointed net) drape.
"""

from fenicsx_drape._lazy import lazy_exports

# The public names, from the package, each imported on first use.
_PUBLIC = {
    "FormedGrid": "post",
    "FormingRun": "run",
    "KinematicNet": "kinematic",
    "SheetMesh": "measure",
    "case_bundle": "outputs",
    "closest_on_edge": "measure",
    "closest_points": "measure",
    "coverage": "measure",
    "drape_case": "kinematic",
    "form_case": "outputs",
    "interply_maps": "outputs",
    "kinematic_drape": "kinematic",
    "mean_distance": "post",
    "plot_interply": "plots",
    "plot_paths": "plots",
    "plot_shear": "plots",
    "plot_tool_forces": "plots",
    "plot_wrinkling": "plots",
    "probe": "measure",
    "read_formed": "measure",
    "run_case": "run",
    "shear_at_flat": "measure",
    "shear_at_formed": "measure",
    "write_drape": "kinematic",
    "write_run_bundle": "outputs",
    "write_values": "measure",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _PUBLIC)
