"""The public API: each package's names (its ``__all__``), and the demos and docs use them.

:data:`PUBLIC` is the API as it is meant to be: a package that gains or loses a public name
fails here until it is listed (and said in CHANGELOG.md). Every listed name resolves, no
public name is hidden by a module of the same name (``from fenicsx_drape.diagnosis import
compare`` is the function whatever was imported before), and the demos and the code in the
README and the docs import only listed names, from the package that lists them.
"""

from __future__ import annotations

import ast
import importlib
import pkgutil
import re
import types
from pathlib import Path

import pytest

import fenicsx_drape

ROOT = Path(__file__).resolve().parents[1]

PUBLIC = {
    "fenicsx_drape": [
        "Model", "__version__", "default_model", "history", "load_bundle", "load_model",
        "synthetic_bundle"],
    "fenicsx_drape.calibration": [
        "FitResult", "InterplyFit", "bias_test", "consistency", "fit", "fit_interply",
        "format_table", "lab_of", "picture_frame_test", "plot_fit", "shear_curve",
        "simulate_interply", "size_of", "standard_tests", "synthetic_bundle", "table2",
        "tensile_test", "write_fit"],
    "fenicsx_drape.curves": [
        "BIAS", "TENSILE", "effective_rate", "fig2b_history", "paper_tests", "write_curves"],
    "fenicsx_drape.diagnosis": [
        "CompareResult", "Report", "compare", "confirm", "diagnose", "evaluate",
        "fit_setup", "history", "history_table", "lab_tables", "setup_rules", "summary",
        "synthetic_case_test", "synthetic_forming_test", "write_case_bundle",
        "write_compare", "write_diagnosis", "write_lab_bundle"],
    "fenicsx_drape.diagnosis.kinds": [
        "BIAS_EXTENSION", "Comparison", "FitHook", "FormedKind", "GRID", "INTERPLY_FRICTION",
        "KINDS", "Kind",
        "OUTLINE", "PICTURE_FRAME", "PUNCH_FORCE", "Region", "SHEAR_POINTS", "SURFACE",
        "TENSILE", "TEST_KINDS", "comparable", "find_kind", "is_formed", "kind_of", "row_sd"],
    "fenicsx_drape.errors": [
        "DrapeInputError", "InputFileError", "ParameterError", "SolverError",
        "did_you_mean", "likely_typo", "old_name"],
    "fenicsx_drape.fe": [
        "FieldWriter", "Results", "RunReport", "Sheet", "SolverOptions", "StepReport",
        "TrussGrid", "TrussProblem", "grid_points", "load_sheet", "read_grid", "run",
        "set_petsc_options", "sheet_grid", "truss_mesh", "truss_sheet", "write_grid",
        "write_grid_csv"],
    "fenicsx_drape.forming": [
        "BlankHolder", "ExtrapolationSpring", "FlatHolder", "FormedGrid", "FormingCase",
        "FormingRun", "HemisphereTools", "MeshedTool", "PenaltyContact", "RevolvedTool",
        "RigidMotion", "TriangleSurface", "case_file", "case_for_test", "form_case",
        "kinematic_drape", "load_case", "load_surface", "mean_distance", "run_case",
        "with_overrides", "write_case"],
    "fenicsx_drape.forming.case": [
        "BlankSpec", "CaseError", "FormingCase", "HolderSpec", "OVERRIDES", "PlySpec",
        "SETUP_OVERRIDES", "ToolSpec", "broken_planes", "case_dict", "case_file",
        "case_for_test", "case_key", "case_toml", "check_run_size", "load_case", "run_size",
        "with_overrides", "write_case"],
    "fenicsx_drape.forming.paper": [
        "DURATIONS_S", "DURATION_RANGE_S", "DURATION_SHEAR_SPAN_DEG", "DURATION_WRINKLING",
        "FORCES_N", "FORCE_RANGE_N", "FORCE_SHEAR_PEAK_N", "FORCE_WRINKLING",
        "MAX_SHEAR_EXPERIMENT_DEG", "MAX_SHEAR_KINEMATIC_DEG", "MAX_SHEAR_MODEL_DEG",
        "MEAN_DISTANCE_10MM_MM", "MESH_CELLS_MM", "METRICS", "MIN_WRINKLING_EXPERIMENT",
        "MIN_WRINKLING_MODEL", "MU_LITERATURE", "PAPER_CONDITIONS", "READINGS",
        "SHEAR_PLATEAU_FROM_NODES", "STATS", "SUMMARY", "TARGETS", "TOTAL_WRINKLING_MODEL",
        "TOW_STRAIN_800N", "Variant", "WRINKLING_PLACE", "WRINKLING_STABLE_FROM_NODES",
        "default_options", "mesh_distances", "metrics", "misfit", "paper_case",
        "paper_comparison", "paper_differences", "paper_numbers", "plot_trend", "run_key",
        "run_variants", "source_tag", "sweep", "write_rows"],
    "fenicsx_drape.forming.running": [
        "FormedGrid", "FormingRun", "KinematicNet", "SheetMesh", "case_bundle",
        "closest_on_edge", "closest_points", "coverage", "drape_case", "form_case",
        "interply_maps", "kinematic_drape", "mean_distance", "plot_interply", "plot_paths",
        "plot_shear", "plot_tool_forces", "plot_wrinkling", "probe", "read_formed",
        "run_case", "shear_at_flat", "shear_at_formed", "write_drape", "write_run_bundle",
        "write_values"],
    "fenicsx_drape.forming.tools": [
        "Arc", "DistanceField", "HemisphereTools", "MeshedTool", "RevolvedTool",
        "RigidMotion", "Segment", "TriangleSurface", "build_tools", "distance_field",
        "load_surface", "write_tool_meshes"],
    "fenicsx_drape.materials": [
        "BUILT_IN_LAWS", "FrictionLaw", "InterplyLaw", "MaterialLaw", "ROLES", "ShearLaw",
        "TowLaw", "build_law", "condition", "effect", "fields_of", "get_law", "parameter",
        "register_law", "registered_laws"],
    "fenicsx_drape.measurements": [
        "Bundle", "BundleError", "Test", "load_bundle", "write_bundle"],
    "fenicsx_drape.model": [
        "Model", "PAPER_EFFECTS", "default_model", "default_parameters", "known_parameters",
        "load_model", "load_plugin", "parameter_info"],
    "fenicsx_drape.provenance": [
        "atomic_write_bytes", "atomic_write_text", "file_digest", "json_text", "run_record",
        "save_figure", "toml_text", "write_json", "write_provenance"],
    "fenicsx_drape.runs": [
        "CACHE_ENV", "Deferred", "FULL_CELL_MM", "MEMORY_SIZE", "Memo", "RunStore", "Runs",
        "SCREEN_CELL_MM", "USER_OPTIONS", "WORKERS_ENV", "cached", "capped",
        "cell_override", "cores", "current", "default_folder", "default_workers",
        "describe", "execution", "execution_record", "executor", "form_many", "key_of",
        "memo", "resolution", "runs_at_once", "runs_of", "solver_options", "spare", "stopped_at",
        "together", "tool_forces"],
    "fenicsx_drape.trust": [
        "GEO_DENIED", "GEO_READABLE", "TRUST_ENV", "UntrustedCodeError", "add_trust_option",
        "apply_trust_option", "check_geo", "geo_defines", "geo_problems", "require_trust",
        "set_trusted", "trusted", "trusting"],
    "fenicsx_drape.unitcell": [
        "EFFECTIVE_RATE_FACTOR", "UnitCellCurve", "bias_diagonal_strain", "bias_extension",
        "bias_extension_shear_force", "curves", "diagonal_response",
        "effective_strain_rate", "picture_frame", "picture_frame_displacement",
        "picture_frame_lock_mm", "picture_frame_shear_angle", "picture_frame_shear_force",
        "tensile"],
}


def declared() -> list[str]:
    """The packages (and top-level modules) of the tree that declare ``__all__``."""
    out = ["fenicsx_drape"]
    for info in pkgutil.walk_packages(fenicsx_drape.__path__, "fenicsx_drape."):
        if info.ispkg or info.name.count(".") == 1:
            if "__all__" in vars(importlib.import_module(info.name)):
                out.append(info.name)
    return out


def test_every_package_that_declares_its_names_is_listed():
    pytest.importorskip("dolfinx")  # the forming package imports it
    assert sorted(declared()) == sorted(PUBLIC)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # the moved modules' old paths
@pytest.mark.parametrize("package", sorted(PUBLIC))
def test_a_package_exports_what_it_says_and_nothing_hides_it(package):
    if package.startswith(("fenicsx_drape.fe", "fenicsx_drape.forming")):
        pytest.importorskip("dolfinx")
    module = importlib.import_module(package)
    assert sorted(module.__all__) == sorted(PUBLIC[package]), "the public names changed"
    # Every submodule imported (as any program may have): a public name is still itself,
    # never a module of the same name.
    if hasattr(module, "__path__"):
        modules = {m.name for m in pkgutil.iter_modules(module.__path__)}
        assert not modules & set(module.__all__), "a module hides a public name"
        for info in pkgutil.iter_modules(module.__path__, f"{package}."):
            importlib.import_module(info.name)
    for name in module.__all__:
        value = getattr(module, name)
        assert not isinstance(value, types.ModuleType), name


def _imports(tree: ast.AST) -> list[tuple[str, str, int]]:
    """``(module, name, line)`` of each ``from fenicsx_drape... import name`` (a whole module
    import as ``(module, "", line)``)."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("fenicsx_drape"):
            out += [(node.module, alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.Import):
            out += [(alias.name, "", node.lineno) for alias in node.names
                    if alias.name.startswith("fenicsx_drape")]
    return out


def _sources():
    """The demos, and the Python code blocks of the README and the docs."""
    for path in sorted((ROOT / "demos").glob("*.py")):
        yield path, path.read_text()
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        if path.name == "changelog.md":
            continue
        for block in re.findall(r"```python\n(.*?)```", path.read_text(), re.S):
            yield path, block


def private_imports() -> list[str]:
    """Imports of the demos and docs that are not public names (``file:line: what``)."""
    found = []
    for path, text in _sources():
        try:
            tree = ast.parse(text)
        except SyntaxError:
            continue
        for module, name, line in _imports(tree):
            where = f"{path.relative_to(ROOT)}:{line}"
            if name and f"{module}.{name}" in PUBLIC:
                continue  # a package (or module) that declares its names, imported whole
            if module not in PUBLIC or (name and name not in PUBLIC[module]):
                found.append(f"{where}: {module}{'.' + name if name else ''}")
    return found


def test_demos_and_docs_use_public_names_only():
    found = private_imports()
    assert not found, "\n".join(found)
