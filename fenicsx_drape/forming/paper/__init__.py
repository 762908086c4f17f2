"""The paper's hemisphere: its numbers and its studies (Figs. 9-12), run by ``demos/study_*``.

- :mod:`~fenicsx_drape.forming.paper.numbers`: every number the paper states, and the
  comparison ``drape form hemisphere`` prints;
- :mod:`~fenicsx_drape.forming.paper.studies`: sweeps of the hemisphere (duration, force,
  mesh), cached, tabulated and plotted.
"""
