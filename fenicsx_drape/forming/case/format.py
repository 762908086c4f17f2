"""The earlier module of the case format, kept for one release: import from its parts.

The case format is now :mod:`fenicsx_drape.forming.case` (its ``__init__`` exports the public
names) in four modules: :mod:`~fenicsx_drape.forming.case.spec` (the dataclasses),
:mod:`~fenicsx_drape.forming.case.reading` (``load_case``, ``case_file``, ``case_for_test``),
:mod:`~fenicsx_drape.forming.case.overrides` (``with_overrides``, ``broken_planes``),
:mod:`~fenicsx_drape.forming.case.writing` (``write_case``, ``case_dict``, ``case_key``) and
:mod:`~fenicsx_drape.forming.case.size` (``run_size``, ``check_run_size``); the tools are
built by :mod:`fenicsx_drape.forming.tools.build`. ``CaseError`` is
:class:`fenicsx_drape.errors.InputFileError`. Every name this module had is here still.
"""

from fenicsx_drape.errors import InputFileError
from fenicsx_drape.forming.case.overrides import (
    HOLDER_OVERRIDES,
    OLD_OVERRIDES,
    OVERRIDES,
    SETUP_OVERRIDES,
    SPEC_FORMING_KEYS,
    _offset,
    _offset_punches,
    _setup_text,
    broken_planes,
    case_value,
    override_names,
    renamed,
    with_overrides,
)
from fenicsx_drape.forming.case.reading import (
    CASES_FOLDER,
    _check_builtin,
    _check_geo_tool,
    _read_blank,
    _read_motion,
    _read_plies,
    _read_tools,
    _Reader,
    _untrusted_code,
    case_file,
    case_for_test,
    load_case,
    sample_outline,
)
from fenicsx_drape.forming.case.size import check_run_size, run_size
from fenicsx_drape.forming.case.spec import (
    BUILTIN,
    DEFAULT_SHEET_SIDE,
    GEOMETRY_SUFFIXES,
    INTERPLY_KEYS,
    OUTLINE_SUFFIXES,
    ROLES,
    SHEET_SIDES,
    BlankSpec,
    FormingCase,
    HolderSpec,
    PlySpec,
    ToolSpec,
    _builtin_tools,
    _case_problems,
    _finite,
    builtin_tools,
)
from fenicsx_drape.forming.case.writing import case_dict, case_key, case_toml, write_case
from fenicsx_drape.forming.tools.build import (
    FINE_MESH_FACTOR,
    _meshed_tool,
    build_tools,
    check_tool_sizes,
    tool_triangles,
)
from fenicsx_drape.forming.tools.checks import (
    COARSE_CHORD_OF_CELL,
    CREASE_DEG,
    coarse_mesh_problem,
)

CaseError = InputFileError

__all__ = [
    "BUILTIN",
    "CASES_FOLDER",
    "COARSE_CHORD_OF_CELL",
    "CREASE_DEG",
    "DEFAULT_SHEET_SIDE",
    "FINE_MESH_FACTOR",
    "GEOMETRY_SUFFIXES",
    "HOLDER_OVERRIDES",
    "INTERPLY_KEYS",
    "OLD_OVERRIDES",
    "OUTLINE_SUFFIXES",
    "OVERRIDES",
    "ROLES",
    "SETUP_OVERRIDES",
    "SHEET_SIDES",
    "SPEC_FORMING_KEYS",
    "BlankSpec",
    "CaseError",
    "FormingCase",
    "HolderSpec",
    "PlySpec",
    "ToolSpec",
    "_Reader",
    "_builtin_tools",
    "_case_problems",
    "_check_builtin",
    "_check_geo_tool",
    "_finite",
    "_meshed_tool",
    "_offset",
    "_offset_punches",
    "_read_blank",
    "_read_motion",
    "_read_plies",
    "_read_tools",
    "_setup_text",
    "_untrusted_code",
    "broken_planes",
    "build_tools",
    "builtin_tools",
    "case_dict",
    "case_file",
    "case_for_test",
    "case_key",
    "case_toml",
    "case_value",
    "check_run_size",
    "check_tool_sizes",
    "coarse_mesh_problem",
    "load_case",
    "override_names",
    "renamed",
    "run_size",
    "sample_outline",
    "tool_triangles",
    "with_overrides",
    "write_case",
]
