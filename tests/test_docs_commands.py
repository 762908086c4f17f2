"""Every command the README and the docs show is a real one.

The command lines (``./drape ...``, ``make ...``, ``python3 -m fenicsx_drape ...``) are collected
from the code blocks and the inline code of README.md and docs/*.md and checked against the
real command line: the command exists, its own parser accepts every option it uses, and every
path it names exists in the repository or is an output (under ``results/``, or given to
``--out`` / ``--json``). Synopses keep their placeholders: a word in capitals (``BUNDLE``,
``MODEL.toml``, ``DIR``), ``...`` and ``[optional]`` brackets.

That each command also *runs* is the business of the tests of that command, on small cases;
the last test checks that every command the docs show has one.
"""

import re
import shlex
from pathlib import Path

import pytest

from fenicsx_drape import cli

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PREFIXES = ("./drape ", "make ", "python3 -m fenicsx_drape ")
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]*\d*(\.[a-z]+)?$")  # BUNDLE, MODEL2.toml, DIR
PATH_SUFFIXES = {".toml", ".json", ".csv", ".py", ".msh", ".xdmf", ".geo", ".png", ".md"}
OUTPUT_OPTIONS = {"out", "json"}


def command_lines(page: Path) -> list[tuple[str, str]]:
    """The command lines of a Markdown page, each with ``page:line``."""
    found, fence, pending = [], False, None
    for number, line in enumerate(page.read_text().splitlines(), start=1):
        where = f"{page.relative_to(ROOT)}:{number}"
        if line.lstrip().startswith("```"):
            fence = not fence
            continue
        if fence:
            text = line.strip()
            if pending is not None:  # a continued line
                pending = (pending[0] + " " + text, pending[1])
            else:
                start = min((text.find(p) for p in PREFIXES if p in text), default=-1)
                if start < 0 or text[:start].strip() not in ("", "mpirun -n 2", "mpirun -n 3"):
                    continue
                pending = (text[start:], where)
            if pending[0].endswith("\\"):
                pending = (pending[0][:-1], pending[1])
                continue
            found.append((pending[0].split(" #")[0].strip(), pending[1]))
            pending = None
        else:
            for span in re.findall(r"`([^`]+)`", line):
                if span.startswith(PREFIXES):
                    found.append((span, where))
    return found


COMMANDS = [c for page in PAGES for c in command_lines(page)]


def is_placeholder(word: str) -> bool:
    return bool(PLACEHOLDER.match(word)) or word in ("...", "…")


MAKEFILE = (ROOT / "Makefile").read_text()
MAKE_TARGETS = set(re.findall(r"^([A-Za-z][\w-]*):", MAKEFILE, flags=re.MULTILINE))


def check_path(value: str, output: bool, where: str) -> None:
    """A repository path must exist, unless it is an output or a placeholder."""
    path = Path(value)
    if is_placeholder(path.name) or path.is_absolute():
        return
    if "/" not in value and path.suffix not in PATH_SUFFIXES:
        return  # a word (``hemisphere``), not a path
    if output or path.parts[0] in ("results", "out"):
        return
    assert (ROOT / path).exists(), f"{where}: {value} does not exist in the repository"


def check_cli(words: list[str], where: str) -> str | None:
    """Check ``python3 -m fenicsx_drape WORDS``; returns the command's name."""
    if not words or words[0] in ("--help", "-h", "--version") or is_placeholder(words[0]):
        return None
    name = words[0]
    assert name in cli.COMMANDS, f"{where}: no command {name!r}"
    _, parser = cli.command_parser(name)
    if "--help" in words:
        return name
    values = [w for w in words[1:] if w not in ("...", "…")]  # a placeholder is a value
    try:
        args = parser.parse_args(values)
    except SystemExit:
        pytest.fail(f"{where}: 'drape {name}' rejects {' '.join(values)!r}")
    by_dest = {a.dest: a for a in parser._actions}
    for dest, value in vars(args).items():
        for item in value if isinstance(value, list) else [value]:
            if isinstance(item, (str, Path)) and by_dest[dest].default != item:
                check_path(str(item), dest in OUTPUT_OPTIONS, where)
    return name


def check(line: str, where: str) -> str | None:
    """Check one command line; returns the drape command it runs, if any."""
    words = [w.strip("[]") for w in shlex.split(line)]
    words = [w for w in words if w]
    if words[0] == "make":
        for target in words[1:]:
            if "=" in target:  # a variable of the Makefile set on the command line
                name = target.split("=")[0]
                assert re.search(rf"^{name}\s*:?=", MAKEFILE, flags=re.MULTILINE), \
                    f"{where}: Makefile has no variable {name!r}"
                continue
            assert target in MAKE_TARGETS, f"{where}: Makefile has no target {target!r}"
        return None
    if words[0] == "python3":
        return check_cli(words[3:], where)
    rest = words[1:]
    while rest[:1] in (["--np"], ["--mount"]):
        if rest[0] == "--np":
            assert rest[1].isdigit() or is_placeholder(rest[1]), f"{where}: --np needs a number"
        else:
            assert (is_placeholder(rest[1]) or Path(rest[1]).is_absolute()
                    or (ROOT / rest[1]).is_dir()), \
                f"{where}: --mount {rest[1]}: no such folder"
        rest = rest[2:]
    if rest[:1] != ["exec"]:
        return check_cli(rest, where)
    rest = rest[1:]
    if "fenicsx_drape" in rest:  # exec python3 -m fenicsx_drape ...
        return check_cli(rest[rest.index("fenicsx_drape") + 1:], where)
    for word in rest[1:]:
        if "/" in word and not word.startswith("-"):
            check_path(word, False, where)
    return None


def test_the_pages_show_commands():
    pages = {where.split(":")[0] for _, where in COMMANDS}
    assert "README.md" in pages and len(pages) >= 5
    assert len(COMMANDS) >= 30


@pytest.mark.parametrize(("line", "where"), COMMANDS, ids=[w for _, w in COMMANDS])
def test_command_is_real(line, where):
    check(line, where)


def test_a_wrong_command_is_caught():
    with pytest.raises(AssertionError, match="no command"):
        check("./drape forge hemisphere --out out", "x")
    with pytest.raises(pytest.fail.Exception, match="rejects"):
        check("./drape form hemisphere --out out --cell-size 5", "x")
    with pytest.raises(AssertionError, match="does not exist"):
        check("./drape fit demos/bundles/no-such-bundle --out results/fit", "x")
    with pytest.raises(AssertionError, match="no target"):
        check("make everything", "x")
    with pytest.raises(AssertionError, match="no variable"):
        check("make test-parallel RANKS=3", "x")
    assert check("make test-parallel PARALLEL3=parallel", "x") is None
    assert check("./drape --np 2 exec python3 -m fenicsx_drape mesh --out DIR", "x") == "mesh"
    assert check("./drape --mount /tmp --np 2 form hemisphere --out out", "x") == "form"


def test_every_command_shown_is_run_by_a_test():
    """Each drape command the docs show is called by some test (``main(["NAME", ...])``)."""
    shown = {check(line, where) for line, where in COMMANDS} - {None}
    tests = "\n".join(p.read_text() for p in (ROOT / "tests").glob("test_*.py"))
    for name in sorted(shown):
        assert re.search(rf'main\(\[\s*"{name}"', tests), f"no test runs 'drape {name}'"


def _docs_conf():
    """``docs/conf.py`` as a module (the CLI page's blocks are made there)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_conf", ROOT / "docs" / "conf.py")
    conf = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(conf)
    return conf


def test_the_cli_page_is_each_command_s_help_as_plain_text_that_fits():
    """docs/cli.md's blocks: what ``drape CMD --help`` prints, unhighlighted, lines that fit."""
    import os
    import subprocess
    import sys

    pytest.importorskip("docutils")
    assert "{drape-commands}" in (ROOT / "docs" / "cli.md").read_text()
    blocks = dict(_docs_conf().cli_blocks())
    assert list(blocks) == list(cli.COMMANDS)
    env = {**os.environ, "COLUMNS": str(cli.HELP_COLUMNS), "PYTHONPATH": str(ROOT)}
    for name, block in blocks.items():
        assert block["language"] == "text", f"drape {name}: its help is highlighted as code"
        text = block.astext()
        printed = subprocess.run([sys.executable, "-m", "fenicsx_drape", name, "--help"],
                                 env=env, capture_output=True, text=True, check=True).stdout
        assert text == printed, f"drape {name}: the page's help is not what --help prints"
        too_long = [line for line in text.splitlines() if len(line) > cli.HELP_COLUMNS]
        assert not too_long, f"drape {name}: lines wider than the page's block: {too_long}"
        broken = re.findall(r"\S+-\n\s*\S+", text)
        assert not broken, f"drape {name}: words broken at a hyphen: {broken}"


def test_the_help_names_nothing_of_the_machine_it_was_made_on(monkeypatch):
    """The page is made on one machine and read on others: no core count in the help."""
    import os

    from fenicsx_drape.runs import workers

    texts = {name: cli.help_text(name) for name in cli.COMMANDS}
    monkeypatch.setattr(workers, "cores", lambda: 97)
    monkeypatch.setattr(os, "cpu_count", lambda: 97)
    for name in cli.COMMANDS:
        assert cli.help_text(name) == texts[name], f"drape {name}: its help names the cores"
        assert not re.search(r"\bhere \d", texts[name]), f"drape {name}: 'here N' in its help"
