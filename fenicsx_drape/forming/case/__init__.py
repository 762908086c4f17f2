"""The forming case and its file format (``case.toml``, ``docs/case-format.md``).

:mod:`~fenicsx_drape.forming.case.format`: the case's dataclasses, reading and checking a
file (every problem with its file and key), overrides (a command line's options, a measured
test's keys, a set-up's changes), building its tools, and writing it back.
"""
