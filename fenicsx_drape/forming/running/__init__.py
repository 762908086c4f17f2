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
