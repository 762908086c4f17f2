"""The package's architecture: no import circles, and lower layers never import higher ones.

Every ``import`` of every module is read with :mod:`ast` -- at module level, inside functions
and under ``if TYPE_CHECKING:`` alike, plus ``importlib.import_module("literal")`` -- so a
circle hidden in a function-level import fails here too. An edge is the module an import
statement names (``from pkg import name`` names ``pkg.name`` when that is a module, else
``pkg``); the implicit import of parent packages is not an edge, since a package's
``__init__`` importing its own modules is how a package is built.

The layers, lowest first (docs/development.md, Layout)::

    base (errors, the package root) < provenance < materials < model (effects, model,
    unitcell, nodal) < fe | measurements < forming < runs | calibration < diagnosis
    < command line

``fe`` and ``measurements`` are side by side: neither imports the other; ``forming`` may
write a bundle (it imports ``measurements``). ``runs`` (how forming runs are formed and kept)
and ``calibration`` (coupon fits, which form nothing) are side by side too. Inside
``forming`` its parts are layered too (:data:`FORMING_PARTS`): tools < terms < case < running
< paper. ``materials`` imports only ``errors``, and neither DOLFINx (nor its stack) nor file
I/O; only the command line parses arguments.
"""

from __future__ import annotations

import ast
import importlib
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "fenicsx_drape"

# Layer of a module: the first prefix that matches, in this order (the package root only by
# its own name: a new top-level module must be placed here).
LAYER_OF = (
    ("fenicsx_drape.commands", "cli"),
    ("fenicsx_drape.cli", "cli"),
    ("fenicsx_drape.__main__", "cli"),
    ("fenicsx_drape.materials", "materials"),
    ("fenicsx_drape.fe", "fe"),
    ("fenicsx_drape.forming", "forming"),
    ("fenicsx_drape.measurements", "measurements"),
    ("fenicsx_drape.calibration", "calibration"),
    ("fenicsx_drape.runs", "runs"),
    ("fenicsx_drape.diagnosis", "diagnosis"),
    ("fenicsx_drape.effects", "model"),
    ("fenicsx_drape.model", "model"),
    ("fenicsx_drape.unitcell", "model"),
    ("fenicsx_drape.curves", "model"),
    ("fenicsx_drape.nodal", "model"),
    ("fenicsx_drape.provenance", "provenance"),
    ("fenicsx_drape.errors", "base"),
    ("fenicsx_drape.trust", "base"),
    ("fenicsx_drape.limits", "base"),
    ("fenicsx_drape._moved", "base"),
    ("fenicsx_drape._lazy", "base"),
    ("fenicsx_drape", "base"),
)

# The layers each layer may import (its own included).
_BELOW_FE = {"base", "provenance", "materials", "model"}
MAY_IMPORT = {
    "base": {"base"},
    "provenance": {"base", "provenance"},
    "materials": {"base", "materials"},
    "model": {"base", "provenance", "materials", "model"},
    "fe": _BELOW_FE | {"fe"},
    "measurements": _BELOW_FE | {"measurements"},
    "forming": _BELOW_FE | {"fe", "measurements", "forming"},
    "runs": _BELOW_FE | {"fe", "measurements", "forming", "runs"},
    "calibration": _BELOW_FE | {"fe", "measurements", "forming", "calibration"},
    "diagnosis": _BELOW_FE | {"fe", "measurements", "forming", "runs", "calibration",
                              "diagnosis"},
    "cli": _BELOW_FE | {"fe", "measurements", "forming", "runs", "calibration", "diagnosis",
                        "cli"},
}

# The parts of forming/, lowest first: a part imports only itself and the parts before it
# (tool geometry knows no case; the residual's terms know tools; the case format knows both;
# a run knows the case; the paper's studies run cases).
FORMING_PARTS = ("tools", "terms", "case", "running", "paper")

# Third-party and standard modules a layer must not import.
DOLFINX_STACK = {"dolfinx", "ufl", "basix", "ffcx", "petsc4py", "mpi4py", "adios2",
                 "adios4dolfinx"}
FILE_IO = {"os", "io", "pathlib", "json", "csv", "tomllib", "pickle", "shelve", "shutil",
           "tempfile", "meshio", "gmsh", "h5py", "matplotlib"}
FORBIDDEN_EXTERNAL = {
    "materials": DOLFINX_STACK | FILE_IO,
    "model": DOLFINX_STACK,
}
ARGUMENT_PARSERS = {"argparse", "optparse", "getopt"}


# --------------------------------------------------------------------------------------------
# Reading the imports


def module_names(root: Path, package: str) -> dict[str, Path]:
    """Every module of ``package`` under ``root``, by dotted name (``__init__`` as the package)."""
    out = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _is_package(path: Path) -> bool:
    return path.name == "__init__.py"


def imports_of(path: Path, name: str, known: dict[str, Path], package: str = PACKAGE
               ) -> list[tuple[str, int]]:
    """The modules (dotted names, lines) the file imports anywhere in its code.

    Names of ``package`` that are not modules of the tree come back as they are written,
    so that :func:`unknown_imports` can report them.
    """
    tree = ast.parse(path.read_text(), filename=str(path))
    here = name if _is_package(path) else name.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here.split(".")[: len(here.split(".")) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                out.append((sub if sub in known else source, node.lineno))
        elif (isinstance(node, ast.Call) and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
              and (getattr(node.func, "attr", None) == "import_module"
                   or getattr(node.func, "id", None) == "import_module")):
            out.append((node.args[0].value, node.lineno))
    return out


def import_graph(root: Path = ROOT, package: str = PACKAGE
                 ) -> tuple[dict[str, set[str]], dict[tuple[str, str], int],
                            dict[str, list[tuple[str, int]]]]:
    """The package's import graph.

    Returns:
        ``graph`` (module -> the package's modules it imports), ``lines`` ((module, target)
        -> line of the first such import) and ``imports`` (module -> every import, external
        ones included, with its line).
    """
    known = module_names(root, package)
    graph: dict[str, set[str]] = {name: set() for name in known}
    lines: dict[tuple[str, str], int] = {}
    everything: dict[str, list[tuple[str, int]]] = {}
    for name, path in known.items():
        everything[name] = imports_of(path, name, known, package)
        for target, line in everything[name]:
            if target in known and target != name:
                graph[name].add(target)
                lines.setdefault((name, target), line)
    return graph, lines, everything


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles: strongly connected components of more than one module (Tarjan).

    Each is returned sorted; the list is sorted too. Self-imports are ignored.
    """
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        # iterative depth-first search (the graph may be deep)
        work = [(v, iter(sorted(graph.get(v, ()))))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        while work:
            node, children = work[-1]
            for w in children:
                if w == node:
                    continue
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                    break
                if w in on_stack:
                    low[node] = min(low[node], index[w])
            else:
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.append(w)
                        if w == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def layer(module: str) -> str:
    """The layer of a module of the package (see the module docstring).

    Raises:
        ValueError: for a module no layer claims (a new top-level module must be given one
            in :data:`LAYER_OF`).
    """
    for prefix, name in LAYER_OF:
        if module == prefix or (prefix != PACKAGE and module.startswith(prefix + ".")):
            return name
    raise ValueError(f"{module}: in no layer (add it to LAYER_OF in {Path(__file__).name})")


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    """Imports of a higher layer (or sideways between fe and measurements), as sentences."""
    out = []
    for module, targets in sorted(graph.items()):
        for target in sorted(targets):
            if layer(target) not in MAY_IMPORT[layer(module)]:
                out.append(f"{module} ({layer(module)}) imports {target} ({layer(target)})")
    return out


def forming_part(module: str) -> str | None:
    """The part of forming/ a module is in (:data:`FORMING_PARTS`), None outside its parts."""
    head = "fenicsx_drape.forming."
    part = module[len(head):].split(".")[0] if module.startswith(head) else None
    return part if part in FORMING_PARTS else None


def forming_violations(graph: dict[str, set[str]]) -> list[str]:
    """Imports of a later part of forming/ by an earlier one, as sentences."""
    out = []
    for module, targets in sorted(graph.items()):
        here = forming_part(module)
        for target in sorted(targets):
            there = forming_part(target)
            if here and there and FORMING_PARTS.index(there) > FORMING_PARTS.index(here):
                out.append(f"{module} (forming/{here}) imports {target} (forming/{there})")
    return out


def external_violations(imports: dict[str, list[tuple[str, int]]]) -> list[str]:
    """Forbidden third-party or standard imports (DOLFINx or files in the physics, argparse
    outside the command line), as sentences."""
    out = []
    for module, found in sorted(imports.items()):
        forbidden = FORBIDDEN_EXTERNAL.get(layer(module), set())
        if layer(module) != "cli":
            forbidden = forbidden | ARGUMENT_PARSERS
        for target, line in found:
            top = target.split(".")[0]
            if top in forbidden:
                out.append(f"{module}:{line} ({layer(module)}) imports {target}")
    return out


def unknown_imports(imports: dict[str, list[tuple[str, int]]], known: dict[str, Path]
                    ) -> list[str]:
    """Imports of a ``fenicsx_drape`` name that is no module of this tree (e.g. an old name)."""
    return [f"{module}:{line} imports {target}" for module, found in sorted(imports.items())
            for target, line in found
            if target.split(".")[0] == PACKAGE and target not in known]


def _describe(component: list[str], graph, lines) -> str:
    members = set(component)
    edges = [f"{a} -> {b} (line {lines[a, b]})" for a in component
             for b in sorted(graph[a] & members)]
    return "circle among " + ", ".join(component) + ": " + "; ".join(edges)


# --------------------------------------------------------------------------------------------
# The package


@pytest.fixture(scope="module")
def graph():
    return import_graph()


def test_the_walk_sees_the_package(graph):
    edges, _, _ = graph
    # a module-level, a function-level and a TYPE_CHECKING import of the real package
    assert "fenicsx_drape.fe.stepping" in edges["fenicsx_drape.fe.solver"]
    assert "fenicsx_drape.calibration.fitting" in edges["fenicsx_drape.diagnosis.kinds.coupon"]
    assert "fenicsx_drape.measurements.bundle" in edges["fenicsx_drape.diagnosis.kinds"]
    assert len(edges) > 60 and sum(map(len, edges.values())) > 150
    assert all(layer(m) for m in edges)  # every module is in a layer
    with pytest.raises(ValueError, match="in no layer"):
        layer("fenicsx_drape.new_flat_module")


def test_no_import_circles(graph):
    edges, lines, _ = graph
    found = cycles(edges)
    assert not found, "\n".join(_describe(c, edges, lines) for c in found)


def test_lower_layers_never_import_higher_ones(graph):
    edges, _, _ = graph
    found = layer_violations(edges)
    assert not found, "\n".join(found)


def test_the_parts_of_forming_import_only_earlier_parts(graph):
    edges, _, known = graph
    assert {forming_part(m) for m in known} - {None} == set(FORMING_PARTS)  # the layout
    assert not [m for m in known if m.startswith("fenicsx_drape.forming.")
                and forming_part(m) is None], "a module of forming/ outside its parts"
    assert not forming_violations(edges), "\n".join(forming_violations(edges))
    injected = {k: set(v) for k, v in edges.items()}
    injected["fenicsx_drape.forming.tools.shapes"].add("fenicsx_drape.forming.case.format")
    assert forming_violations(injected) == [
        "fenicsx_drape.forming.tools.shapes (forming/tools) imports "
        "fenicsx_drape.forming.case.format (forming/case)"]


def test_physics_imports_no_dolfinx_or_files_and_only_the_cli_parses_arguments(graph):
    _, _, imports = graph
    found = external_violations(imports)
    assert not found, "\n".join(found)


def test_imports_name_modules_of_this_tree(graph):
    """The package imports only modules of its own tree."""
    _, _, imports = graph
    known = module_names(ROOT, PACKAGE)
    found = unknown_imports(imports, known)
    assert not found, "\n".join(found)


def test_tests_demos_and_benchmarks_use_the_new_names():
    known = module_names(ROOT, PACKAGE)
    found = []
    for folder in ("tests", "demos", "benchmarks"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path.resolve() == Path(__file__).resolve():
                continue  # the test of the old names below
            for target, line in imports_of(path, path.stem, known):
                if target.split(".")[0] == PACKAGE and target not in known:
                    found.append(f"{path.relative_to(ROOT)}:{line} imports {target}")
    assert not found, "\n".join(found)


# --------------------------------------------------------------------------------------------
# The checks can fail


def test_cycles_finds_injected_circles():
    toy = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"a", "e"},
           "f": {"g"}, "g": {"f"}}
    assert cycles(toy) == [["a", "b", "c"], ["f", "g"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set(), "d": {"d"}}) == []


def test_the_old_solver_stepping_circle_would_be_found(graph):
    edges, _, _ = graph
    injected = {k: set(v) for k, v in edges.items()}
    injected["fenicsx_drape.fe.stepping"].add("fenicsx_drape.fe.solver")  # before 4c390df
    assert ["fenicsx_drape.fe.solver", "fenicsx_drape.fe.stepping"] in cycles(injected)
    # and the grid kind importing compare back (compare reads the table of kinds)
    injected = {k: set(v) for k, v in edges.items()}
    injected["fenicsx_drape.diagnosis.kinds.grid"].add("fenicsx_drape.diagnosis.comparison")
    assert any({"fenicsx_drape.diagnosis.comparison", "fenicsx_drape.diagnosis.kinds.grid"}
               <= set(c) for c in cycles(injected))


def test_layer_violations_are_found(graph):
    edges, _, _ = graph
    injected = {k: set(v) for k, v in edges.items()}
    injected["fenicsx_drape.materials.tow"].add("fenicsx_drape.fe.grid")
    injected["fenicsx_drape.fe.output"].add("fenicsx_drape.measurements.bundle")
    injected["fenicsx_drape.measurements.bundle"].add("fenicsx_drape.forming.running.post")
    injected["fenicsx_drape.forming.running.outputs"].add("fenicsx_drape.calibration.fitting")
    injected["fenicsx_drape.calibration.fitting"].add("fenicsx_drape.diagnosis.comparison")
    injected["fenicsx_drape.model"].add("fenicsx_drape.commands.fit")
    injected["fenicsx_drape.runs.runner"].add("fenicsx_drape.diagnosis.comparison")
    injected["fenicsx_drape.runs.store"].add("fenicsx_drape.calibration.fit")
    injected["fenicsx_drape.forming.running.run"].add("fenicsx_drape.runs.runner")
    assert layer_violations(injected) == [
        "fenicsx_drape.calibration.fitting (calibration) imports "
        "fenicsx_drape.diagnosis.comparison (diagnosis)",
        "fenicsx_drape.fe.output (fe) imports fenicsx_drape.measurements.bundle (measurements)",
        "fenicsx_drape.forming.running.outputs (forming) imports fenicsx_drape.calibration.fitting "
        "(calibration)",
        "fenicsx_drape.forming.running.run (forming) imports fenicsx_drape.runs.runner (runs)",
        "fenicsx_drape.materials.tow (materials) imports fenicsx_drape.fe.grid (fe)",
        "fenicsx_drape.measurements.bundle (measurements) imports "
        "fenicsx_drape.forming.running.post (forming)",
        "fenicsx_drape.model (model) imports fenicsx_drape.commands.fit (cli)",
        "fenicsx_drape.runs.runner (runs) imports fenicsx_drape.diagnosis.comparison (diagnosis)",
        "fenicsx_drape.runs.store (runs) imports fenicsx_drape.calibration.fit (calibration)",
    ]


def test_the_walk_reads_every_kind_of_import(tmp_path):
    """A toy package: module-level, function-level, TYPE_CHECKING, relative, importlib."""
    pkg = tmp_path / PACKAGE
    (pkg / "materials").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "materials" / "__init__.py").write_text("from . import tow\n")
    (pkg / "materials" / "tow.py").write_text(
        "import json\nfrom typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from fenicsx_drape.fe import Thing\n"
        "def law():\n    from dolfinx import fem\n")
    (pkg / "fe.py").write_text(
        "import argparse\n"
        "def f():\n    from .materials import tow\n    import fenicsx_drape.fit\n"
        "def g():\n    import importlib\n    importlib.import_module('fenicsx_drape.materials')\n")
    known = module_names(tmp_path, PACKAGE)
    assert set(known) == {"fenicsx_drape", "fenicsx_drape.materials",
                          "fenicsx_drape.materials.tow", "fenicsx_drape.fe"}
    edges, _, imports = import_graph(tmp_path, PACKAGE)
    assert edges["fenicsx_drape.materials"] == {"fenicsx_drape.materials.tow"}
    assert edges["fenicsx_drape.materials.tow"] == {"fenicsx_drape.fe"}
    assert edges["fenicsx_drape.fe"] == {"fenicsx_drape.materials.tow", "fenicsx_drape.materials"}
    assert cycles(edges) == [["fenicsx_drape.fe", "fenicsx_drape.materials",
                              "fenicsx_drape.materials.tow"]]
    assert layer_violations(edges) == [
        "fenicsx_drape.materials.tow (materials) imports fenicsx_drape.fe (fe)"]
    assert unknown_imports(imports, known) == ["fenicsx_drape.fe:4 imports fenicsx_drape.fit"]
    assert external_violations(imports) == [
        "fenicsx_drape.fe:1 (fe) imports argparse",
        "fenicsx_drape.materials.tow:1 (materials) imports json",
        "fenicsx_drape.materials.tow:6 (materials) imports dolfinx"]


# --------------------------------------------------------------------------------------------
# The old names


def test_no_module_answers_to_a_name_no_release_had():
    """The flat names of the package before its subpackages are gone: no alias, no file."""
    known = module_names(ROOT, PACKAGE)
    import fenicsx_drape  # noqa: F401

    # no import hook of the package's own
    assert not any(type(f).__module__.startswith(PACKAGE) for f in sys.meta_path)
    for old in ("fenicsx_drape.fit", "fenicsx_drape.bundle", "fenicsx_drape.forming.run"):
        assert old not in known
        with pytest.raises(ModuleNotFoundError):
            importlib.import_module(old)
