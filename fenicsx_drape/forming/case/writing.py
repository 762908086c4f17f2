"""Writing a case back: its tables, a case file, a self-contained case folder, its run key.

:func:`case_dict` gives a :class:`~fenicsx_drape.forming.case.spec.FormingCase` as the plain
tables of its file, :func:`case_toml` as the file's text (written by the project's one TOML
writer, :func:`fenicsx_drape.provenance.toml_text`), :func:`write_case` as a folder with
copies of its geometry (or the meshes a run made of it), and :func:`case_key` as what a run
of it depends on (the run cache's key).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fenicsx_drape.forming.case.spec import FormingCase, ToolSpec
from fenicsx_drape.provenance import file_digest, toml_text


def case_key(case) -> str:
    """What a forming run of ``case`` depends on, as text.

    A :class:`FormingCase` by content: its tables (paths relative to its folder, the model file
    left out: the run's model is given) and the digests of the geometry files it reads, so
    that the same case read from two copies (a bundle's and the mesh folder's) shares its
    runs (the run cache) and its geometry check.
    """
    tables = case_dict(case, case.folder)
    tables["case"].pop("model", None)
    files = [t.path for t in case.tools if t.path is not None]
    if case.blank.path is not None:
        files.append(case.blank.path)
    files += [p.model for p in case.plies if p.model is not None]  # a ply's own model
    digests = [file_digest(Path(p)) if Path(p).is_file() else f"missing {p}" for p in files]
    return json.dumps([tables, digests], sort_keys=True, default=str)


def case_dict(case: FormingCase, relative_to: str | os.PathLike | None = None) -> dict:
    """The case as the plain tables of its file (paths relative to ``relative_to``)."""
    base = Path(relative_to).resolve() if relative_to is not None else None

    def rel(p: Path | None, written: str) -> str:
        if p is None or base is None:
            return written
        return os.path.relpath(p, base)

    c: dict[str, Any] = {"name": case.name}
    if case.description:
        c["description"] = case.description
    c["duration_s"] = case.duration_s
    if case.model is not None:
        c["model"] = rel(case.model, str(case.model))
    c.update(step_mm=case.step_mm, penalty_factor=case.penalty_factor,
             stabilisation_N_per_mm=case.stabilisation_N_per_mm)
    b = case.blank
    blank: dict[str, Any] = {"outline": rel(b.path, b.outline) if b.path else b.outline}
    if b.outline == "rectangle":
        blank.update(size_mm=list(b.size_mm), centre_mm=list(b.centre_mm))
    elif b.outline == "polygon":
        blank["points_mm"] = [list(p) for p in b.points_mm]
    blank.update(cell_mm=b.cell_mm, ply_angle_deg=b.ply_angle_deg, origin_mm=list(b.origin_mm),
                 symmetry=list(b.symmetry))
    if b.hold_origin:
        blank["hold_origin"] = True
    out: dict[str, Any] = {"case": c, "blank": blank}
    if case.holder is not None:
        h = case.holder
        out["holder"] = {"tool": h.tool, "holder_force_N": h.force_N,
                         "holder_force_share": h.force_share}
        if h.mu is not None:
            out["holder"]["mu"] = h.mu
    tools = []
    for t in case.tools:
        d: dict[str, Any] = {"name": t.name, "role": t.role,
                             "geometry": rel(t.path, t.geometry) if t.path else t.geometry}
        if t.parameters:
            d["parameters"] = dict(t.parameters)
        for key in ("mesh_mm", "order", "sheet_side"):
            if getattr(t, key) is not None:
                d[key] = getattr(t, key)
        if t.motion is not None:
            m = t.motion
            d["motion"] = {"time_s": list(m.time_s), "x_mm": list(m.x_mm),
                           "y_mm": list(m.y_mm), "z_mm": list(m.z_mm)}
            if m.rotation_deg is not None:
                d["motion"].update(rotation_deg=list(m.rotation_deg), axis=list(m.axis),
                                   centre_mm=list(m.centre_mm))
        tools.append(d)
    out["tool"] = tools
    if case.plies:
        out["ply"] = [{"angle_deg": p.angle_deg, "thickness_mm": p.thickness_mm,
                       **({"model": rel(p.model, str(p.model))} if p.model else {})}
                      for p in case.plies]
    if case.interply:
        out["interply"] = dict(case.interply)
    return out


def case_toml(case: FormingCase, relative_to: str | os.PathLike | None = None,
              comment: str = "") -> str:
    """The text of a case file for ``case`` (the format that ``load_case`` reads)."""
    return toml_text(case_dict(case, relative_to), comment=comment)


def write_case(case: FormingCase, folder: str | os.PathLike, *, name: str = "case.toml",
               comment: str = "", surfaces: Mapping[str, Any] | None = None) -> Path:
    """Write the case into ``folder`` with copies of its geometry files: a self-contained case.

    Tool geometry and the outline curve are copied next to the case file (renamed on a
    clash) and named relative to it; the model file is not copied (a bundle names no model).
    A tool named in ``surfaces`` (its
    :class:`~fenicsx_drape.forming.tools.surfaces.TriangleSurface`, as a run meshed it) is
    written as that mesh instead, ``<name>.msh``:
    data that any reader takes without ``--trust``, at the resolution the run used.
    Returns the written case file.
    """
    from fenicsx_drape.forming.tools.surfaces import write_msh
    from fenicsx_drape.provenance import atomic_write_bytes, atomic_write_text

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    used: set[str] = {name}
    copies: dict[Path, Path] = {}

    def copy(p: Path) -> Path:
        if p in copies:
            return copies[p]
        target = p.name
        k = 1
        while target in used:
            target = f"{p.stem}_{k}{p.suffix}"
            k += 1
        used.add(target)
        atomic_write_bytes(folder / target, p.read_bytes())
        copies[p] = folder / target
        return copies[p]

    def meshed(t: ToolSpec) -> ToolSpec:
        target = f"{t.name}.msh" if f"{t.name}.msh" not in used else f"{t.name}_tool.msh"
        used.add(target)
        write_msh(surfaces[t.name], folder / target)
        return dataclasses.replace(t, geometry=target, path=folder / target, parameters=(),
                                   mesh_mm=None, order=None)

    surfaces = surfaces or {}
    tools = tuple(meshed(t) if t.name in surfaces and t.path else
                  dataclasses.replace(t, path=copy(t.path)) if t.path else t
                  for t in case.tools)
    blank = case.blank
    if blank.path is not None:
        blank = dataclasses.replace(blank, path=copy(blank.path))
    plies = tuple(dataclasses.replace(p, model=None) for p in case.plies)
    local = dataclasses.replace(case, tools=tools, blank=blank, model=None, path=None,
                                plies=plies)
    text = case_toml(local, relative_to=folder, comment=comment)
    return atomic_write_text(folder / name, text)
