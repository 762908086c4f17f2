"""Sphinx configuration of the fenicsx_drape documentation (``make docs``).

The pages are Markdown (MyST); the demos are the jupytext "light" scripts of ``demos/``
(``docs/demos`` links to them), executed by MyST-NB and rendered as pages; the API reference
is generated from the docstrings (autodoc, napoleon for Google style, autosummary).
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the working tree's package, as ./drape runs it

import fenicsx_drape  # noqa: E402

project = "fenicsx_drape"
author = "the fenicsx_drape authors"
copyright = "2026, the fenicsx_drape authors"
version = release = fenicsx_drape.__version__

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]

# Sources: Markdown pages and the demos; the rest of demos/ (studies, bundles, user laws,
# outputs) is not a page.
exclude_patterns = [
    "_build",
    "conf.py",
    "**/__pycache__",
    "demos/study_*.py",
    "demos/make_demo_bundle.py",
    "demos/make_lab_bundle.py",
    "demos/make_pull_out_bundle.py",
    "demos/user_laws",
    "demos/bundles",
    "demos/results",
]
nb_custom_formats = {".py": ["jupytext.reads", {"fmt": "py:light"}]}

# Every demo runs at each build, except those too long for it: they are shown without their
# output (the page says so) and run by their tests. The build stops on a demo's error.
nb_execution_mode = "force"
nb_execution_excludepatterns = ["demos/demo_forming_diagnosis.py", "demos/demo_diagnosis.py",
                                "demos/demo_case_diagnosis.py", "demos/demo_lab_diagnosis.py",
                                "demos/demo_laminates.py"]
nb_execution_timeout = 600
nb_execution_raise_on_error = True
nb_execution_show_tb = True
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3

# The API reference: one page per module, the members from their docstrings (Google style).
# A package's page lists its modules only (what it re-exports is documented where it lives).
templates_path = ["_templates"]
autosummary_generate = True
autodoc_member_order = "bysource"
autodoc_typehints = "description"
napoleon_google_docstring = True
napoleon_numpy_docstring = False

html_theme = "sphinx_book_theme"
html_title = "fenicsx_drape"
html_theme_options = {"show_toc_level": 2}


def escape_bars(lines):
    """Escape the ``|`` of plain-text magnitudes (``|ε|``) outside literals, in place.

    Docstrings write a magnitude as in the paper, ``|x|``, which reStructuredText reads as a
    substitution reference. Literal blocks (after ``::``) and inline literals are kept.
    """
    literal_indent = None  # the indentation of the paragraph that opened a literal block
    previous = ""
    for i, line in enumerate(lines):
        indent = len(line) - len(line.lstrip())
        if literal_indent is not None and line.strip() and indent <= literal_indent:
            literal_indent = None
        if literal_indent is None and previous.rstrip().endswith("::"):
            literal_indent = len(previous) - len(previous.lstrip())
        if line.strip():
            previous = line
        if literal_indent is not None or "|" not in line:
            continue
        parts = line.split("``")
        parts[::2] = [part.replace("|", "\\|") for part in parts[::2]]
        lines[i] = "``".join(parts)


def cli_reference():
    """A directive writing every command's ``--help``, from the real parsers (``cli.md``)."""
    from docutils import nodes
    from sphinx.util.docutils import SphinxDirective

    class CommandLine(SphinxDirective):
        def run(self):
            out = []
            for name, block in cli_blocks():
                section = nodes.section(ids=[f"drape-{name}"])
                section += nodes.title(text=f"drape {name}")
                section += block
                out.append(section)
            return out

    return CommandLine


def cli_blocks():
    """Each command's name and its ``--help`` as a plain-text literal block (not highlighted)."""
    from docutils import nodes

    from fenicsx_drape import cli

    return [(name, nodes.literal_block(text, text, language="text"))
            for name in cli.COMMANDS for text in [cli.help_text(name)]]


def public_packages() -> list[str]:
    """The packages (and top-level modules) that declare their public names (``__all__``)."""
    import importlib
    import pkgutil

    names = ["fenicsx_drape"]
    for info in pkgutil.walk_packages(fenicsx_drape.__path__, "fenicsx_drape."):
        if info.ispkg or info.name.count(".") == 1:
            module = importlib.import_module(info.name)
            if "__all__" in vars(module):
                names.append(info.name)
    return names


def api_reference():
    """A directive listing each package's public names (its ``__all__``), with their summaries.

    A heading a package, its first docstring line, then an autosummary table of its
    ``__all__``: each name links to where it is defined (the module pages below).
    """
    import importlib

    from docutils import nodes
    from docutils.statemachine import StringList
    from sphinx.util.docutils import SphinxDirective

    def target(module, name: str) -> str:
        obj = getattr(module, name)
        home = getattr(obj, "__module__", None)
        if (callable(obj) and isinstance(home, str) and home.startswith("fenicsx_drape")
                and hasattr(obj, "__qualname__")):
            return f"{home}.{obj.__qualname__}"
        return f"{module.__name__}.{name}"

    class PublicApi(SphinxDirective):
        def run(self):
            lines = []
            for package in public_packages():
                module = importlib.import_module(package)
                summary = (module.__doc__ or "").strip().splitlines()[0]
                names = [n for n in module.__all__ if not n.startswith("__")]
                code = [n for n in names if callable(getattr(module, n))]
                data = [n for n in names if n not in code]  # constants: named, not summed up
                lines += [f".. rubric:: {package}", "", summary, "", ".. autosummary::", ""]
                lines += [f"   ~{target(module, name)}" for name in code]
                lines.append("")
                if data:
                    lines += ["Constants: " + ", ".join(f"``{n}``" for n in data) + ".", ""]
            node = nodes.container()
            self.state.nested_parse(StringList(lines, "drape-api"), self.content_offset, node)
            return node.children

    return PublicApi


def skip_reexported(app, what, name, obj, skip, options):
    """Document each class and function once, in the module that defines it.

    A module that re-exports another's names (an old path kept for a release) lists them in
    its ``__all__``; documenting them there too would give one name two targets.
    """
    import inspect

    module = app.env.temp_data.get("autodoc:module")
    home = getattr(obj, "__module__", None)
    if (what == "module" and module and isinstance(home, str) and home != module
            and home.startswith("fenicsx_drape") and (inspect.isclass(obj)
                                                      or inspect.isfunction(obj))):
        return True
    return None


def setup(app):
    """Run :func:`escape_bars` on the docstrings; add ``drape-commands`` and ``drape-api``."""
    app.connect("autodoc-process-docstring",
                lambda app, what, name, obj, options, lines: escape_bars(lines), priority=900)
    app.add_directive("drape-commands", cli_reference())
    app.add_directive("drape-api", api_reference())
    app.connect("autodoc-skip-member", skip_reexported)
