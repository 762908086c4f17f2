"""The forming case and its file format (``case.toml``, ``docs/case-format.md``).

- :mod:`~fenicsx_drape.forming.case.spec`: the case as frozen dataclasses
  (:class:`FormingCase`, its tools, blank, plies and holder);
- :mod:`~fenicsx_drape.forming.case.reading`: reading and checking a file, every problem with
  its file and key (:func:`load_case`, :func:`case_file`, :func:`case_for_test`);
- :mod:`~fenicsx_drape.forming.case.overrides`: a case with some values changed (a command
  line's options, a measured test's keys, a set-up: :func:`with_overrides`);
- :mod:`~fenicsx_drape.forming.case.size`: a run's size and a stack's fit before it runs;
- :mod:`~fenicsx_drape.forming.case.writing`: the case written back (:func:`write_case`).

The tools a case names are built by :func:`fenicsx_drape.forming.tools.build.build_tools`.
A file that cannot be used raises :class:`~fenicsx_drape.errors.InputFileError` (``CaseError``
is its earlier name).
"""

from fenicsx_drape.errors import InputFileError
from fenicsx_drape.forming.case.overrides import (
    OVERRIDES,
    SETUP_OVERRIDES,
    broken_planes,
    with_overrides,
)
from fenicsx_drape.forming.case.reading import case_file, case_for_test, load_case
from fenicsx_drape.forming.case.size import check_run_size, run_size
from fenicsx_drape.forming.case.spec import (
    BlankSpec,
    FormingCase,
    HolderSpec,
    PlySpec,
    ToolSpec,
)
from fenicsx_drape.forming.case.writing import case_dict, case_key, case_toml, write_case

CaseError = InputFileError  # the earlier name, kept for one release

__all__ = [
    "OVERRIDES",
    "SETUP_OVERRIDES",
    "BlankSpec",
    "CaseError",
    "FormingCase",
    "HolderSpec",
    "PlySpec",
    "ToolSpec",
    "broken_planes",
    "case_dict",
    "case_file",
    "case_for_test",
    "case_key",
    "case_toml",
    "check_run_size",
    "load_case",
    "run_size",
    "with_overrides",
    "write_case",
]
