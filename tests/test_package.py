"""The package, its metadata, its command line and the ./drape launcher."""

import importlib
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import fenicsx_drape
from fenicsx_drape.cli import COMMANDS, main

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_version_is_the_declared_one():
    assert re.fullmatch(r"\d+\.\d+\.\d+", fenicsx_drape.__version__)
    assert PYPROJECT["project"]["dynamic"] == ["version"]
    attr = PYPROJECT["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "fenicsx_drape.__version__"


def test_pyproject_declares_package_script_and_tools():
    project = PYPROJECT["project"]
    assert project["name"] == "fenicsx-drape"
    assert project["scripts"] == {"drape": "fenicsx_drape.cli:main"}
    assert any(dep.startswith("fenics-dolfinx>=0.10") for dep in project["dependencies"])
    ruff = PYPROJECT["tool"]["ruff"]
    assert ruff["line-length"] == 100
    assert ruff["lint"]["pydocstyle"]["convention"] == "google"
    assert {"skip_in_parallel", "parallel", "slow"} <= {
        marker.split(":")[0] for marker in PYPROJECT["tool"]["pytest"]["ini_options"]["markers"]
    }


def test_cli_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"fenicsx_drape {fenicsx_drape.__version__}"


def test_cli_unknown_command_is_bad_input(capsys):
    assert main(["no-such-command"]) == 2
    err = capsys.readouterr().err
    assert "usage: drape" in err and "unknown command 'no-such-command'" in err


def test_cli_help_lists_every_command(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in COMMANDS)
    assert main([]) == 2  # no command: help, and the status of bad input


COMMAND_MODULES = sorted(p.stem for p in (ROOT / "fenicsx_drape" / "commands").glob("[!_]*.py"))
FE_STACK = {"dolfinx", "basix", "ufl", "ffcx", "mpi4py", "petsc4py", "gmsh"}


@pytest.mark.parametrize("name", COMMAND_MODULES)
def test_command_modules_follow_the_dispatcher_contract(name):
    assert name in COMMANDS, f"commands/{name}.py is not listed in cli.COMMANDS"
    try:
        module = importlib.import_module(f"fenicsx_drape.commands.{name}")
    except ModuleNotFoundError as err:
        if err.name not in FE_STACK:
            raise
        pytest.skip(f"{name} needs {err.name}")
    assert callable(module.configure) and callable(module.run)


@pytest.mark.skip_in_parallel
def test_python_m_entry_point():
    run = subprocess.run([sys.executable, "-m", "fenicsx_drape", "--version"],
                         capture_output=True, text=True, cwd=ROOT, check=False)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == f"fenicsx_drape {fenicsx_drape.__version__}"


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("args", [[], ["no-such-command"], ["--np", "0", "fit"], ["exec"]])
def test_launcher_rejects_bad_input(args):
    """./drape checks its own arguments before it starts anything."""
    run = subprocess.run([ROOT / "drape", *args], capture_output=True, text=True, check=False)
    assert run.returncode == 2
    assert "usage: ./drape" in run.stderr


@pytest.mark.skip_in_parallel
def test_launcher_runs_the_cli():
    pytest.importorskip("dolfinx")  # natively only: elsewhere ./drape would start the image
    run = subprocess.run([ROOT / "drape", "--version"], capture_output=True, text=True,
                         check=False)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == f"fenicsx_drape {fenicsx_drape.__version__}"
