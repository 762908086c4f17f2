"""What makes a forming run: its case's content, the model, the solver options.

:func:`key_of` is a run's identity in memory and, hashed with the code's digest
(:func:`~fenicsx_drape.runs.store.run_key`), its name on disk: the case by content (its tables
and the bytes of its geometry files, not the path it was read from), the model's effects,
parameters and plugin files, and the user's PETSc options.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from fenicsx_drape.provenance import file_digest

if TYPE_CHECKING:
    from fenicsx_drape.model import Model

# The PETSc options a user gives every solve (fe.newton.SOLVER_PREFIXES and log_*): those a
# run depends on, unlike the ones each problem keeps under its own prefix while it lives.
USER_OPTIONS = ("snes_", "ksp_", "pc_", "mat_", "npc_", "sub_", "log_")


def key_of(case, model: Model) -> tuple:
    """The identity of the run of ``(case, model)``: equal keys, the same run."""
    from fenicsx_drape.forming.case.format import case_key  # DOLFINx: only once a run is asked
    from fenicsx_drape.forming.case.spec import MODEL_INTERPLY

    if "interply_friction" in model.effects and not case.stack:  # it acts on stacks only
        model = model.without_effects("interply_friction")
    # The inter-ply law's μ, η_f and τ₀ act only with the effect and where [interply] leaves
    # them to the model (FormingCase.interply_law).
    unused = {name for name in MODEL_INTERPLY
              if "interply_friction" not in model.effects or case.interply_given(name)}
    params = tuple(sorted((k, float(v)) for k, v in model.parameters.items() if k not in unused))
    plugins = tuple(file_digest(p) if Path(p).is_file() else f"missing {p}"
                    for p in model.plugins)
    return (case_key(case), tuple(sorted(model.effects)), params, plugins, solver_options())


def solver_options() -> tuple[tuple[str, str], ...]:
    """The user's PETSc options (``--petsc-option``, ``PETSC_OPTIONS``): a run depends on them.

    Read from PETSc's database, without the options each problem keeps under its own prefix
    while it lives (``drape_truss_N_``), and given to each worker with its job.
    """
    if "petsc4py.PETSc" not in sys.modules:  # nothing was set: no need to load PETSc
        return tuple(sorted(_options_from_env().items()))
    from petsc4py import PETSc

    return tuple(sorted((k, "" if v is None else str(v))  # None: a flag without a value
                        for k, v in PETSc.Options().getAll().items()
                        if k.startswith(USER_OPTIONS)))


def _options_from_env() -> dict[str, str]:
    import shlex

    given: dict[str, str] = {}
    name = None
    for token in shlex.split(os.environ.get("PETSC_OPTIONS", "")):
        if token.startswith("-") and not token.lstrip("-")[:1].isdigit():
            name = token.lstrip("-")
            given[name] = ""
        elif name is not None:
            given[name] = token
    return {k: v for k, v in given.items() if k.startswith(USER_OPTIONS)}


def apply_solver_options(options: tuple[tuple[str, str], ...]) -> None:
    """Make ``options`` this process's user PETSc options (a worker, given its job's).

    The user options set before and not in ``options`` are dropped: a worker outlives a
    command, and each job brings the options of the command that asked for it.
    """
    from petsc4py import PETSc

    wanted = dict(options)
    if dict(solver_options()) == wanted:
        return
    db = PETSc.Options()
    for name in set(dict(solver_options())) - set(wanted):
        db.delValue(name)
    for name, value in wanted.items():
        db[name] = value


def describe(case, model: Model) -> str:
    """A run as a person names it: the case and the model's effects and parameters."""
    effects = ", ".join(model.effects) or "no effects"
    params = ", ".join(f"{k} = {float(v):.6g}" for k, v in sorted(model.parameters.items()))
    return (f"the forming run of case {case.name!r}"
            + (f" ({case.path})" if getattr(case, "path", None) else "")
            + f" with the model [{effects}]" + (f" ({params})" if params else ""))
