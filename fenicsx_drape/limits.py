"""Sizes before memory, and a time limit on geometry scripts.

A run's memory is decided by two numbers known before anything is built: the nodes of the
sheet's net (the blank's area over Δ²) and the triangles of the meshed tools (their area
over the triangle's, from ``mesh_mm``). Both are estimated from the case and refused at once,
with the estimate and the limit, when they are beyond what the machine's memory can hold:

- the memory planned for is ``DRAPE_MEMORY_GB`` (GB) when set, else half the machine's
  physical memory (the other half for the system and other runs);
- a sheet node costs :data:`BYTES_PER_NODE` and a tool triangle :data:`BYTES_PER_TRIANGLE`
  (peak resident memory of runs measured on this project's image, rounded up; see
  ``docs/untrusted-input.md``); ``DRAPE_MAX_NODES`` and ``DRAPE_MAX_TRIANGLES`` set the limits
  directly.

A run's *length* is known before it starts too: its load steps (the fastest tool's travel
over ``step_mm``), its nodes (every ply's net of a stack: nodes × plies) and a time estimate
from both (:func:`run_seconds`, measured per node and step). Past :data:`MAX_STEPS` load
steps (``DRAPE_MAX_STEPS``, or a forming command's ``--max-steps``) or :data:`MAX_NODE_STEPS`
node-steps (``DRAPE_MAX_NODE_STEPS``: nodes × plies × steps, the work) the run is refused at
once with the numbers (:func:`check_steps`).

A measured table's size is checked before it is read (:func:`check_table_size`): its bytes
(a file larger than :data:`BYTES_PER_ROW` × the line limit is refused unread) and its lines,
counted in blocks without holding the file, against :data:`MAX_TABLE_ROWS`
(``DRAPE_MAX_TABLE_ROWS``); any input file read whole (a case, a bundle, a model) against
:data:`MAX_FILE_BYTES` (:func:`check_file_size`).

Geometry scripts (``.geo``, ``.py``) run in a child process (:func:`run_script`) with a time
limit of ``DRAPE_SCRIPT_TIMEOUT_S`` seconds (default :data:`SCRIPT_TIMEOUT_S`) and an address
space of the planned memory, so that a script that never returns, or a mesh that grows
without end, ends in a clear error instead of a hung or swapped machine. The child runs in a
process group of its own, with a watchdog that ends the group and removes its temporary
folder when the command ends, however it ends (stopped by a signal, killed): nothing it
started keeps running.
"""

from __future__ import annotations

import math
import os
import pickle
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fenicsx_drape.errors import DrapeInputError

BYTES_PER_NODE = 40_000  # peak memory per sheet node of a forming run (DOLFINx, MUMPS)
BYTES_PER_TRIANGLE = 5_000  # peak memory per tool triangle (Gmsh meshing, distance field)
SCRIPT_TIMEOUT_S = 300.0  # a geometry script that runs longer is stopped
MAX_STEPS = 5000  # load steps of one forming run (the shipped cases: 25-80)
# Node-steps (nodes × plies × steps) of one forming run: the shipped cases take up to 7.5e5
# (the full hemisphere at 2.5 mm cells); 2e7 is about 1.2 h on one rank (run_seconds).
MAX_NODE_STEPS = 2e7
MAX_TABLE_ROWS = 1_000_000  # lines of one measured table (a coupon test at 100 Hz: 2.8 h)
BYTES_PER_ROW = 200  # a table's file larger than this × the row limit is refused unread
MAX_FILE_BYTES = 50e6  # a case, bundle.toml or MODEL.toml is read whole: a few kB in use
# Wall time of a load step: a floor and a cost per sheet node, from the hemisphere's runs
# (one rank, docs/solver-notes.md: 169 nodes 0.028 s a step, 625: 0.076 s, 2401: 0.32 s,
# the full 9409: 2.1 s; 16 nodes: 0.031 s), rounded up.
SECONDS_PER_STEP = 0.025
SECONDS_PER_NODE_STEP = 2.2e-4
# Triangles per mm² of surface per 1/h² (equilateral triangles of side h: area √3/4 h²).
_TRIANGLES_PER_AREA = 4.0 / math.sqrt(3.0)


def memory_bytes() -> float:
    """The memory a run may plan for (bytes): ``DRAPE_MEMORY_GB``, else half the machine's."""
    given = os.environ.get("DRAPE_MEMORY_GB")
    if given:
        try:
            value = float(given)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise DrapeInputError(f"DRAPE_MEMORY_GB = {given!r} must be a positive number (GB)")
        return value * 1e9
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = 8e9  # unknown: assume a small machine
    return 0.5 * float(total)


def _env_limit(name: str) -> float | None:
    given = os.environ.get(name)
    if not given:
        return None
    try:
        value = float(given)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise DrapeInputError(f"{name} = {given!r} must be a positive number")
    return value


def max_nodes() -> float:
    """The largest sheet net allowed (nodes): ``DRAPE_MAX_NODES``, else from the memory."""
    return _env_limit("DRAPE_MAX_NODES") or memory_bytes() / BYTES_PER_NODE


def max_triangles() -> float:
    """The most tool triangles allowed (all tools): ``DRAPE_MAX_TRIANGLES``, else from memory."""
    return _env_limit("DRAPE_MAX_TRIANGLES") or memory_bytes() / BYTES_PER_TRIANGLE


def _how(name: str, each: int) -> str:
    if os.environ.get(f"DRAPE_{name}"):
        return f"DRAPE_{name}"
    source = "DRAPE_MEMORY_GB" if os.environ.get("DRAPE_MEMORY_GB") else "half this machine's"
    return (f"{memory_bytes() / 1e9:.3g} GB of memory ({source}) at {each} bytes each; set "
            f"DRAPE_MEMORY_GB or DRAPE_{name} to change it")


def check_nodes(nodes: float, where: str) -> None:
    """Refuse a sheet net of ``nodes`` nodes beyond :func:`max_nodes`, before it is built."""
    limit = max_nodes()
    if not nodes <= limit:
        raise DrapeInputError(f"{where}: the sheet's net would have about {nodes:.3g} nodes, "
                              f"more than the limit of {limit:.3g} "
                              f"({_how('MAX_NODES', BYTES_PER_NODE)}); give a larger cell_mm")


def check_triangles(triangles: float, where: str) -> None:
    """Refuse tool meshes of ``triangles`` triangles beyond :func:`max_triangles`."""
    limit = max_triangles()
    if not triangles <= limit:
        raise DrapeInputError(f"{where}: the tool mesh would have about {triangles:.3g} "
                              f"triangles, more than the limit of {limit:.3g} "
                              f"({_how('MAX_TRIANGLES', BYTES_PER_TRIANGLE)}); give a larger "
                              "mesh_mm")


def max_steps() -> float:
    """The most load steps a run may plan: ``DRAPE_MAX_STEPS``, else :data:`MAX_STEPS`."""
    return _env_limit("DRAPE_MAX_STEPS") or MAX_STEPS


def run_seconds(steps: float, nodes: float) -> float:
    """About how long (s, one rank) ``steps`` load steps of a net of ``nodes`` nodes take."""
    return steps * (SECONDS_PER_STEP + SECONDS_PER_NODE_STEP * nodes)


def duration_text(seconds: float) -> str:
    """``"40 s"``, ``"12 min"``, ``"3.2 h"``, ``"4.1 days"``."""
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.2g} {unit}"
    return f"{seconds:.2g} s"


def max_node_steps() -> float:
    """The most node-steps a run may plan: ``DRAPE_MAX_NODE_STEPS``, else :data:`MAX_NODE_STEPS`."""
    return _env_limit("DRAPE_MAX_NODE_STEPS") or MAX_NODE_STEPS


def check_steps(steps: float, nodes: float, where: str, why: str = "", plies: int = 1) -> None:
    """Refuse a run beyond the limits, with the numbers.

    More than :func:`max_steps` load steps, or :func:`max_node_steps` node-steps (its nodes,
    all plies', times its steps).

    Args:
        steps: The load steps planned.
        nodes: The sheet's nodes (a stack's: every ply's).
        where: The case (file) named in the message.
        why: How the steps come about (e.g. "80 mm of travel at step_mm = 0.001").
        plies: The plies of the stack the nodes are shared by.
    """
    on = (f"{nodes:g} nodes ({plies} plies of {nodes / plies:.0f})" if plies > 1
          else f"{nodes:g} nodes")
    about = duration_text(run_seconds(steps, nodes))
    limit = max_steps()
    if not steps <= limit:
        how = "set by DRAPE_MAX_STEPS" if os.environ.get("DRAPE_MAX_STEPS") else "the default"
        raise DrapeInputError(
            f"{where}: the run would take {steps:g} load steps{' (' + why + ')' if why else ''}"
            f" on {on}, about {about}: more than the limit of {limit:g} steps ({how}); give a "
            "larger step_mm, or raise the limit with --max-steps N (or DRAPE_MAX_STEPS=N)")
    work = steps * nodes
    limit = max_node_steps()
    if not work <= limit:
        how = ("set by DRAPE_MAX_NODE_STEPS" if os.environ.get("DRAPE_MAX_NODE_STEPS")
               else "the default")
        raise DrapeInputError(
            f"{where}: the run would take {steps:g} load steps on {on}, {work:.3g} node-steps, "
            f"about {about}: more than the limit of {limit:.3g} node-steps ({how}); give a "
            f"larger cell_mm or step_mm{', fewer plies' if plies > 1 else ''}, or raise the "
            "limit with DRAPE_MAX_NODE_STEPS=N")


def max_steps_argument(parser) -> None:
    """``--max-steps N`` of the forming commands: the run-length limit (``DRAPE_MAX_STEPS``)."""
    parser.add_argument("--max-steps", type=float, default=None, metavar="N",
                        help=f"refuse a forming run of more than N load steps (default "
                        f"{MAX_STEPS}, or DRAPE_MAX_STEPS; docs/untrusted-input.md)")


def apply_max_steps(args) -> None:
    """Set ``DRAPE_MAX_STEPS`` from ``--max-steps`` (worker processes inherit it)."""
    value = getattr(args, "max_steps", None)
    if value is not None:
        if not (math.isfinite(value) and value > 0):
            raise DrapeInputError(f"--max-steps {value:g}: must be a positive number")
        os.environ["DRAPE_MAX_STEPS"] = repr(float(value))


def max_table_rows() -> float:
    """The most rows of a measured table: ``DRAPE_MAX_TABLE_ROWS``, else :data:`MAX_TABLE_ROWS`."""
    return _env_limit("DRAPE_MAX_TABLE_ROWS") or MAX_TABLE_ROWS


def check_file_size(path: str | os.PathLike, what: str, limit: float = MAX_FILE_BYTES) -> None:
    """Refuse an input file read whole (a case, a bundle, a model) larger than ``limit`` bytes.

    Raises:
        DrapeInputError: naming the file, its size and the limit.
    """
    size = Path(path).stat().st_size
    if size > limit:
        raise DrapeInputError(f"{path}: the {what} is {size / 1e6:.3g} MB, more than the "
                              f"{limit / 1e6:.3g} MB such a file can be (the wrong file?)")


def check_table_size(path: str | os.PathLike, what: str = "table") -> int:
    """Refuse a table beyond :func:`max_table_rows` lines before it is read; its lines.

    The file's size first (beyond :data:`BYTES_PER_ROW` × the limit it is not opened), then
    its lines counted in blocks of 1 MB (no more memory than a block).

    Raises:
        DrapeInputError: naming the file, its lines (or size) and the limit.
    """
    limit = max_table_rows()
    how = ("DRAPE_MAX_TABLE_ROWS" if os.environ.get("DRAPE_MAX_TABLE_ROWS") else
           "the default; DRAPE_MAX_TABLE_ROWS=N raises it")
    size = Path(path).stat().st_size
    if size > BYTES_PER_ROW * limit:
        raise DrapeInputError(f"{path}: the {what} is {size / 1e6:.3g} MB, more than a table of "
                              f"{limit:.3g} lines can be ({BYTES_PER_ROW} bytes a line; the "
                              f"limit is {how}): not read")
    lines = 0
    with open(path, "rb") as f:
        while block := f.read(1 << 20):
            lines += block.count(b"\n")
            if lines > limit:
                raise DrapeInputError(f"{path}: the {what} has more than {limit:.3g} lines "
                                      f"(the limit is {how}): not read")
    return lines


def triangles_for(area_mm2: float, mesh_mm: float, order: int = 1) -> float:
    """Triangles of a surface of ``area_mm2`` meshed with size ``mesh_mm`` (×4 for order 2)."""
    return _TRIANGLES_PER_AREA * area_mm2 / mesh_mm**2 * (4 if order == 2 else 1)


# --------------------------------------------------------------------------------------------
# Geometry scripts in a child process


def script_timeout_s() -> float:
    """The time limit of a geometry script (s): ``DRAPE_SCRIPT_TIMEOUT_S``, else the default."""
    return _env_limit("DRAPE_SCRIPT_TIMEOUT_S") or SCRIPT_TIMEOUT_S


def run_script(function: Callable[..., Any], args: tuple, path: str | os.PathLike) -> Any:
    """``function(*args)`` in a child process, with the time and memory limits.

    ``function`` must be a module-level function of the package (the child imports its module
    alone, without the ``__init__`` of its subpackage: no DOLFINx, no MPI), its arguments
    and result picklable. A :class:`DrapeInputError` in the child is raised here with its
    message.

    Raises:
        DrapeInputError: the script's own error, or it ran past the time limit, or the child
            ended without a result (e.g. out of the memory limit).
    """
    timeout = script_timeout_s()
    package_root = str(Path(__file__).resolve().parents[1])
    # Not a rank of the caller's MPI job (as the forming workers: diagnosis.forming_runs).
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "PMI_"))}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, env.get("PYTHONPATH")) if p)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    with tempfile.TemporaryDirectory(prefix="drape_script_") as tmp:
        job, out = Path(tmp) / "job.pickle", Path(tmp) / "result.pickle"
        job.write_bytes(pickle.dumps(((function.__module__, function.__qualname__), args,
                                      memory_bytes())))
        # The script's temporary files go into this folder, removed with it, also when the
        # script is stopped; its own children are stopped with it (one process group, which
        # the child's watchdog ends if this process ends first: _watch).
        env.update(TMPDIR=tmp, TMP=tmp, TEMP=tmp)
        child = subprocess.Popen(
            [sys.executable, "-c", "import sys; from fenicsx_drape.limits import _child; "
             "_child(sys.argv[1], sys.argv[2])", str(job), str(out)],
            env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, cwd=tmp, start_new_session=True)
        try:
            _, stderr = child.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            _stop(child)
            raise DrapeInputError(
                f"{path}: the geometry script did not finish in {timeout:g} s and was stopped "
                "(DRAPE_SCRIPT_TIMEOUT_S sets the limit; its temporary files are removed)"
            ) from None
        except BaseException:  # interrupted: leave nothing running
            _stop(child)
            raise
        if not out.is_file():
            tail = stderr.decode(errors="replace").strip().splitlines()[-3:]
            raise DrapeInputError(
                f"{path}: the geometry script ended without a result (exit status "
                f"{child.returncode}; a mesh beyond the memory limit of "
                f"{memory_bytes() / 1e9:.3g} GB ends so)" + (": " + " / ".join(tail)
                                                               if tail else ""))
        status, value = pickle.loads(out.read_bytes())
    if status == "error":
        raise DrapeInputError(value)
    return value


def _stop(child: subprocess.Popen) -> None:
    """Kill a script's process group (the child and anything it started) and reap it."""
    import signal

    try:
        os.killpg(child.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    child.communicate()


# How often (s) the watchdog of a script looks whether the command still runs.
WATCH_S = 0.2


def _watch(command: int, child: int, folder: str) -> None:
    """The watchdog of a script's process group: a process of its own, forked by the child.

    It waits for the command (process ``command``) or the ``child`` (the leader of the
    script's process group) to end. The child ending first is the usual way (it ends its
    group itself, the command removes the folder); the command ending first (a signal, a
    kill) leaves the script with no one waiting for it: the watchdog then kills the script's
    group and removes its temporary ``folder``, so that nothing keeps running and nothing is
    left behind.
    """
    import select
    import shutil
    import signal

    os.setpgid(0, 0)  # out of the group it kills
    devnull = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):  # the command reads the child's stderr to its end: not held open
        os.dup2(devnull, fd)
    try:
        handle = os.pidfd_open(command)
    except (AttributeError, OSError):  # no pidfd (old kernel): the command is polled
        handle = None
    while True:
        if os.getppid() != child:  # the child ended: the command takes it from here
            os._exit(0)
        if handle is not None:
            ended = bool(select.select([handle], [], [], WATCH_S)[0])
        else:
            import time

            time.sleep(WATCH_S)
            try:
                os.kill(command, 0)
                ended = False
            except ProcessLookupError:
                ended = True
        if ended:
            try:
                os.killpg(child, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
            shutil.rmtree(folder, ignore_errors=True)
            os._exit(0)


def _child(job: str, out: str) -> None:
    """The child of :func:`run_script`: limit the address space, run, pickle the result."""
    import importlib
    import resource
    import types

    # First, before anything is imported or started: the watchdog (see _watch).
    command, me = os.getppid(), os.getpid()
    if os.fork() == 0:
        _watch(command, me, str(Path(job).parent))
    (module_name, name), args, memory = pickle.loads(Path(job).read_bytes())
    # The module alone: its subpackages as bare namespaces, their __init__ not run.
    import fenicsx_drape  # noqa: F401  (the top package is light)

    parts = module_name.split(".")
    for k in range(2, len(parts)):
        package = ".".join(parts[:k])
        if package not in sys.modules:
            bare = types.ModuleType(package)
            bare.__path__ = [os.path.join(sys.modules[".".join(parts[:k - 1])].__path__[0],
                                          parts[k - 1])]
            sys.modules[package] = bare
    function = getattr(importlib.import_module(module_name), name)
    limit = int(memory)
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    import signal

    try:
        try:
            result = ("ok", function(*args))
        except DrapeInputError as err:
            result = ("error", str(err))
        except MemoryError:
            result = ("error", f"{args[0]}: out of the memory limit of {memory / 1e9:.3g} GB "
                               "(DRAPE_MEMORY_GB)")
        Path(out).write_bytes(pickle.dumps(result))
    except BaseException:  # told on stderr, which the command shows
        import traceback

        traceback.print_exc()
    finally:  # what the script started ends with it: the whole group, this process included
        sys.stderr.flush()
        os.killpg(0, signal.SIGKILL)
