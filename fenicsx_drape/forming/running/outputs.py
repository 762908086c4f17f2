"""Everything a forming run writes: summary, fields, forming bundle, tools, pictures.

:func:`form_case` is the Python twin of ``drape form CASE.toml``: it runs any case
(:func:`~fenicsx_drape.forming.running.run.run_case`) and writes into one folder

- ``summary.json``: the net's own cell (``cell_mm``; ``net``: the cell asked and the share
  of the blank its cells cover, with a ``note`` when the net was fitted to the blank, which
  ``drape form`` prints: :func:`net_fit`), max shear angle, total and minimum wrinkling
  strain, the free edge's in-plane displacement (and a rectangle's mid-side and corner
  draw-in), nodes, steps, cut-backs, Newton iterations, wall time, penetration, ranks,
  travel and the case, and the kinematic drape on the same tools:
  ``kinematic_placed_nodes`` of ``kinematic_blank_nodes`` placed (``kinematic_complete``
  false when the surface ends or the net locks before every node of the blank is placed)
  and ``kinematic_max_shear_deg``, the maximum over the placed nodes only;
- ``fields.xdmf`` (+ ``.h5``) every 5 mm of the fastest tool's travel; ``tools/*.vtk``: the
  tools at the end of their motion;
- ``formed_sheet.csv``: the formed sheet node by node (every ply of a stack), which
  ``drape probe`` reads to give the model's values at a lab's points
  (:func:`~fenicsx_drape.forming.running.measure.probe`);
- ``bundle/``: the formed part's drawn grid as a forming bundle whose test names a copy of
  the case (``case = "case/case.toml"``, with its meshed tools as ``bundle/case/<tool>.msh``
  at the resolution of the run: data, read without ``--trust``; its ``cell_mm`` the net's
  own), so that it can be compared later like a measured part. The grid's spacing
  (``grid_mm``) is 10 mm when the net's nodes lie on it, else the net's own cell
  (:func:`default_grid_mm`); with ``lab_lines`` the test also holds shear along three
  measuring lines and the blank's edge in the lab's kinds (``shear_points``, ``outline``,
  with their noise keys: :func:`lab_tables`);
- ``kinematic_shear.png``: the kinematic drape (pin-jointed net) beside the FE result; a
  partial net says how many nodes it placed in its title;
- ``shear.png``, ``wrinkling.png``: the formed sheet (mirrored to the whole part for a
  symmetric model) coloured by shear angle, and the wrinkled tows;
- ``provenance.json``: version, command, model, solver options and the case;
- ``tool_forces.csv`` and ``tool_forces.png``: the force of every tool along its motion
  against the travel, for the whole part, one point per converged step (the press's force
  curve; ``summary.json`` gives each tool's peak, ``max_tool_force_N``, and the steps whose
  force stands out of both neighbours', ``tool_force_outliers``, each with a note in
  ``tool_force_notes``; :func:`write_tool_forces`).

A stack of plies (``[[ply]]``): the numbers, pictures and bundle above are of the ply away
from the punch (the one a camera sees; ``measured_ply``); ``summary.json`` adds ``plies``
(each ply's shear, wrinkling and draw-in) and ``interply`` (each interface's pressure and
sliding), and the folder ``shear_ply<k>.png``, ``wrinkling_ply<k>.png`` and ``interply.png``
(where the plies slid, and their pressure); ``fields.xdmf`` has every ply.

The paper's hemisphere (``drape form hemisphere``, ``meshes/hemisphere/case.toml``: tools that
are all builtin) is a case like any other. ``summary.json`` says whether a run on its tools
had the paper's conditions (``paper_conditions``, and ``paper_differences``: what differs,
:func:`~fenicsx_drape.forming.running.conditions.paper_differences`); only then does its folder
hold ``paths.png`` (shear along the diagonal path and wrinkling along the normal path, the
paper's Figs. 10-11, with the kinematic drape beside the FE result) and does ``drape form
hemisphere`` print the run beside the paper's numbers
(:func:`~fenicsx_drape.forming.paper.numbers.paper_comparison`); otherwise it says that the
run is not compared, and why.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from fenicsx_drape.forming.case import FormingCase, case_dict, write_case
from fenicsx_drape.forming.running.plots import (
    plot_interply,
    plot_paths,
    plot_shear,
    plot_wrinkling,
)
from fenicsx_drape.forming.running.post import FormedGrid
from fenicsx_drape.forming.running.run import FormingRun, run_case
from fenicsx_drape.measurements.bundle import Bundle, Test, write_bundle
from fenicsx_drape.provenance import write_json, write_provenance

FRAME_MM = 5.0  # punch travel between two frames of the field output


class FormingOutputError(RuntimeError):
    """The solve finished but writing its outputs failed; what was computed is written."""


class _Partial:
    """The summary as far as it was computed (the run's statistics until then)."""

    def __init__(self, run):
        self.result = {"steps": run.steps, "cutbacks": run.cutbacks,
                       "snes_iterations": run.iterations, "wall_time_s": run.wall_time_s,
                       "travel_mm": run.travel_mm, "max_penetration_mm": run.max_penetration_mm}

    def update(self, result: dict) -> dict:
        self.result = result
        return result


class _WrittenOnFailure:
    """Context of the outputs after a solve: on a failure, write what was computed and say so.

    The fields (written during the solve) stay; ``summary.json`` gets the summary as far as it
    was computed with the error; :class:`FormingOutputError` names the folder and the files.
    """

    def __init__(self, out: Path, run, comm, what: str):
        self.out, self.comm, self.what = out, comm, what
        self.partial = _Partial(run)

    def __enter__(self) -> _Partial:
        return self.partial

    def __exit__(self, kind, err, tb) -> bool:
        if err is None or not isinstance(err, Exception):
            return False
        result = dict(self.partial.result)
        result["error"] = f"after the solve: {type(err).__name__}: {err}"
        if self.comm.rank == 0:
            write_json(self.out / "summary.json", result)
        written = sorted(p.name for p in self.out.iterdir()) if self.out.is_dir() else []
        raise FormingOutputError(
            f"{self.what}: the solve finished but its outputs failed ({err}); what was "
            f"computed is in {self.out}: {', '.join(written)}") from err


def _plain(d: dict) -> dict:
    return {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in d.items()}


# --------------------------------------------------------------------------------------------
# Any case


def is_paper_hemisphere(case: FormingCase) -> bool:
    """Whether the case is the paper's hemisphere: its tools are all the builtin ones."""
    return bool(case.tools) and all(t.builtin for t in case.tools)


def case_summary(run: FormingRun) -> dict:
    """The numbers of a run of any case (the content of its ``summary.json``)."""
    g, case = run.grid, run.case
    warp, weft = g.tow_strains()
    out = {
        "case_name": case.name,
        "max_shear_deg": float(np.nanmax(np.abs(g.shear_deg()))),
        "total_wrinkling_strain": g.total_wrinkling_strain(),
        # The paper's literal measure: length change of the compressed tows over the length
        # of all tow bars (FormedGrid.total_wrinkling_strain).
        "total_wrinkling_engineering": g.total_wrinkling_strain("engineering", "bars"),
        "min_wrinkling_strain": float(min(np.nanmin(warp), np.nanmin(weft), 0.0)),
        "max_tow_strain": float(max(np.nanmax(warp), np.nanmax(weft))),
        "edge_displacement_mm": run.edge_displacement_mm,
    }
    if run.draw_in_mm is not None:
        out["draw_in_mm"] = run.draw_in_mm
    b = case.blank
    out["ply_angle_deg"] = b.ply_angle_deg
    if b.outline == "rectangle" and b.centre_mm[0] == 0.0:
        out["mirror_asymmetry_deg"] = g.mirror_asymmetry_deg()
    out.update({
        "symmetry": list(case.planes),
        "nodes": int(g.present.sum()),
        "steps": run.steps,
        "cutbacks": run.cutbacks,
        "snes_iterations": run.iterations,
        "wall_time_s": run.wall_time_s,
        "ranks": run.problem.comm.size,
        "max_penetration_mm": run.max_penetration_mm,
        "travel_mm": run.travel_mm,
        "full_travel_mm": case.total_travel_mm,
        "stopped": run.stopped,
    })
    if case.holder is not None:
        out["holder_force_share"] = case.holder.force_share
        out["holder_nodes"] = float(run.holder.n_s)
    if run.plies:
        out["measured_ply"] = len(run.plies)  # the numbers above: the ply away from the punch
        out["plies"] = [ply_summary(run, k) for k in range(len(run.plies))]
        out["interply"] = [{k: v for k, v in face.items()
                            if k not in ("xy", "sliding_mm", "pressure_MPa")}
                           for face in interply_maps(run)]
    out["case"] = case_dict(case, case.folder)
    return out


def ply_summary(run: FormingRun, k: int) -> dict:
    """Shear, wrinkling and draw-in of ply ``k`` (0: ply 1, on the punch side) of a stack."""
    from fenicsx_drape.forming.running.run import draw_in, edge_displacement

    g, spec = run.plies[k], run.case.plies[k]
    warp, weft = g.tow_strains()
    out = {"ply": k + 1, "angle_deg": run.case.ply_blanks()[k].ply_angle_deg,
           "thickness_mm": spec.thickness_mm,
           "max_shear_deg": float(np.nanmax(np.abs(g.shear_deg()))),
           "total_wrinkling_strain": g.total_wrinkling_strain(),
           "min_wrinkling_strain": float(min(np.nanmin(warp), np.nanmin(weft), 0.0)),
           "edge_displacement_mm": edge_displacement(g)}
    if run.case.blank.outline == "rectangle":
        out["draw_in_mm"] = draw_in(g)
    return out


def interply_maps(run: FormingRun) -> list[dict]:
    """Each interface's numbers and maps (:meth:`~fenicsx_drape.fe.plies.PlyContact.summary`)."""
    if run.interply is None:
        return []
    return run.interply.summary(run.problem.positions())


def default_grid_mm(cell_mm: float) -> float:
    """The drawn grid's spacing by default: 10 mm on the net's nodes, else the net's cell.

    10 mm when a whole number of cells makes it (so the table holds nodes, with their shear
    and wrinkling), else the net's own cell: no grid finer than the net, interpolated.
    """
    ratio = 10.0 / cell_mm
    return 10.0 if abs(ratio - round(ratio)) < 1e-9 else float(cell_mm)


LAB_SHEAR_SD_DEG = 1.0  # the bundle's noise keys for its lab kinds: a lab's shear angle ...
LAB_POSITION_SD_MM = 0.3  # ... and a measured position (the spec's example)


def lab_tables(grid: FormedGrid, centre_mm=(0.0, 0.0)) -> dict[str, dict[str, Any]]:
    """The model's shear along three measuring lines and its blank's edge, as a lab's tables.

    ``shear_points`` (flat positions ``x0_mm, y0_mm``, ``shear_deg`` by the lab's definition
    (:func:`~fenicsx_drape.forming.running.measure.shear_at_flat`), ``line``, ``s_mm``): every
    half cell along the diagonal from the net's origin (``centre_mm``) towards the corner
    x, y > 0 (the paper's diagonal path), and along x and along y at half the net's half
    width from the origin (``"x"`` from (0, h_y / 2), ``"y"`` from (h_x / 2, 0), relative to
    the origin), each to the blank's edge. ``outline``: the formed blank's edge at its nodes
    (whole part, in plan, ordered by angle about the origin), with the model's
    ``draw_in_mm`` there. The values are the model's own, exact.
    """
    from fenicsx_drape.forming.running import measure

    full = grid.full()
    Δ = full.cell_mm
    c = np.asarray(centre_mm, float)[:2]
    X = full.X[full.present][:, :2] - c
    hx, hy = np.max(X, axis=0)
    lines = {"diagonal": ((0.0, 0.0), (1.0, 1.0)), "x": ((0.0, 0.5 * hy), (1.0, 0.0)),
             "y": ((0.5 * hx, 0.0), (0.0, 1.0))}
    s = np.arange(0.0, 2.0 * float(np.hypot(hx, hy)), 0.5 * Δ)
    shear: dict[str, list] = {"x0_mm": [], "y0_mm": [], "shear_deg": [], "line": [], "s_mm": []}
    for name, (start, direction) in lines.items():
        d = np.asarray(direction) / np.linalg.norm(direction)
        flat = c + np.asarray(start) + s[:, None] * d
        γ = measure.shear_at_flat(full, flat)
        ok = np.isfinite(γ)
        shear["x0_mm"] += list(flat[ok, 0])
        shear["y0_mm"] += list(flat[ok, 1])
        shear["shear_deg"] += list(γ[ok])
        shear["line"] += [name] * int(ok.sum())
        shear["s_mm"] += list(s[ok])
    mesh = measure.SheetMesh.of(full)
    edges, _ = measure.edge_segments(mesh)
    nodes = np.unique(edges)
    x = mesh.x[nodes]
    order = np.argsort(np.arctan2(x[:, 1] - c[1], x[:, 0] - c[0]), kind="stable")
    nodes, x = nodes[order], x[order]
    outline = {"x_mm": x[:, 0], "y_mm": x[:, 1],
               "draw_in_mm": measure.draw_in_at(mesh.X[nodes], x, c)}
    return {"shear_points": {k: (tuple(v) if k == "line" else np.asarray(v, float))
                             for k, v in shear.items()},
            "outline": outline}


def case_bundle(run: FormingRun, friction: float, grid_mm: float | None = None,
                case_file: str = "case/case.toml", name: str = "") -> Bundle:
    """The formed part as a one-test forming bundle whose test names its case file.

    The test's keys (``duration_s``, ``holder_force_N``, ``travel_mm``, ``grid_mm``) repeat
    the case's values; ``case_file`` is relative to the bundle folder (write the case there
    with :func:`~fenicsx_drape.forming.case.writing.write_case`). The holder's μ the part was
    formed with is the test's condition ``mu`` (a record: a condition changes nothing in the
    case the test names). ``grid_mm`` None: :func:`default_grid_mm` of the net's cell.
    """
    case = run.case
    grid_mm = grid_mm or default_grid_mm(run.grid.cell_mm)
    table = run.grid.drawn_grid(grid_mm)
    columns = {k: np.asarray(v, dtype=float) for k, v in table.items()}
    setup = {"travel_mm": case.total_travel_mm, "duration_s": case.duration_s}
    if case.holder is not None:
        setup["holder_force_N"] = case.holder.force_N
    setup["grid_mm"] = grid_mm
    force = f"-{case.holder.force_N:g}N" if case.holder is not None else ""
    test_id = f"{case.name}{force}-{case.duration_s:g}s"
    test = Test(id=test_id, kind="forming", file=f"{case.name}_grid.csv", columns=columns,
                forming=setup, conditions={"mu": friction},
                case=case_file)
    return Bundle(name=name or f"simulated-{test_id}", tests=(test,),
                  material="simulated by fenicsx_drape")


def write_run_bundle(run: FormingRun, folder: str | os.PathLike, friction: float, *,
                     grid_mm: float | None = None, lab_lines: bool = False,
                     comment: str = "") -> Path:
    """Write :func:`case_bundle` (with :func:`lab_tables` when ``lab_lines``) at ``folder``.

    The lab tables are ``<case>_shear.csv`` and ``<case>_edge.csv``, named by the test's
    ``shear_points`` and ``outline`` with the noise keys ``shear_sd_deg``
    (:data:`LAB_SHEAR_SD_DEG`) and ``position_sd_mm`` (:data:`LAB_POSITION_SD_MM`, which
    the spec applies to the grid's positions too). The case copy is written separately.
    """
    import dataclasses

    from fenicsx_drape.forming.running.measure import write_values

    bundle = case_bundle(run, friction, grid_mm)
    folder = Path(folder)
    if lab_lines:
        (test,) = bundle.tests
        tables = lab_tables(run.grid, run.case.blank.origin_mm)
        files = {"shear_points": f"{run.case.name}_shear.csv",
                 "outline": f"{run.case.name}_edge.csv"}
        for kind, file in files.items():
            write_values(tables[kind], folder / file, comment=comment)
        test = dataclasses.replace(
            test, forming={**test.forming, "shear_sd_deg": LAB_SHEAR_SD_DEG,
                           "position_sd_mm": LAB_POSITION_SD_MM},
            notes={**test.notes, **files})
        bundle = dataclasses.replace(bundle, tests=(test,))
    return write_bundle(bundle, folder, comment=comment)


def net_fit(case: FormingCase, grid: FormedGrid) -> dict[str, Any]:
    """The net's own cell and how much of the blank its cells cover, with a note when fitted.

    A rectangle with the tows along its sides gets whole cells along each half of its x
    side (:meth:`~fenicsx_drape.forming.case.spec.BlankSpec.grid`): the cell may differ
    from the one asked, and the y side keeps the whole cells that fit. Returns ``cell_mm``
    (the net's), ``net`` (``cell_asked_mm``, ``area_share``: the share of the blank's area
    the net's cells cover, and ``note`` when the cell changed or a rectangle's side was
    clipped: by how much, and which cells would keep the whole blank). The ragged edge of a
    turned ply or an outline is the net's by design and gets no note.

    Args:
        case: The case.
        grid: The formed sheet (a stack: every ply in ``grid.plies``; the figures are of the
            first ply whose tows lie along the blank's sides, else of ``grid``).
    """
    asked = float(case.blank.cell_mm)
    grids = list(grid.plies) or [grid]
    blanks = case.ply_blanks() if len(grids) > 1 else [case.blank]
    k = next((k for k, b in enumerate(blanks) if b.ply_angle_deg == 0.0), len(grids) - 1)
    full, b = grids[k].full(), blanks[k]
    Δ = full.cell_mm
    cells = int(np.isfinite(full.shear_deg()).sum())
    share = cells * Δ * Δ / b.area_mm2
    net: dict[str, Any] = {"cell_asked_mm": asked, "area_share": share}
    notes = []
    changed = abs(Δ - asked) > 1e-9 * asked
    aligned = (b.outline == "rectangle" and b.ply_angle_deg == 0.0
               and tuple(b.centre_mm) == tuple(b.origin_mm))
    if aligned:
        a_x, a_y = b.size_mm
        X = full.X[full.present][:, :2]
        span = np.max(X, axis=0) - np.min(X, axis=0)
        n_x = round(span[0] / Δ)
        if changed:
            notes.append(f"the net is fitted to the blank: cell {Δ:g} mm, not the {asked:g} mm "
                         f"asked, so that {n_x} whole cells span its {a_x:g} mm along x")
        clipped = span[1] < a_y - 1e-6 * a_y
        if clipped:
            left = 0.5 * (a_y - span[1])
            whose = "its" if notes else "the net's"
            notes.append(f"{whose} {round(span[1] / Δ)} cells "
                         f"span {span[1]:g} mm of the blank's {a_y:g} mm along y: {left:g} mm "
                         f"of the blank left out at each side (y = ±{a_y / 2:g} mm), "
                         f"{100 * share:.1f} % of its area modelled")
        if clipped:
            fits = whole_blank_cells(0.5 * a_x, 0.5 * a_y, asked)
            if fits:
                notes.append("a cell of " + " or ".join(f"{v:.4g} mm" for v in fits)
                             + " keeps the whole blank")
    elif changed:
        notes.append(f"the net's cell is {Δ:g} mm, not the {asked:g} mm asked (the plies of "
                     "a stack share the cell of the one fitted to the blank)")
    if notes:
        net["note"] = "; ".join(notes)
    return {"cell_mm": Δ, "net": net}


def whole_blank_cells(half_x: float, half_y: float, near_mm: float) -> list[float]:
    """The cells nearest ``near_mm`` (below and above) that span both half sides wholly.

    None when the half sides' ratio is not a simple fraction.
    """
    from fractions import Fraction

    ratio = Fraction(half_y / half_x).limit_denominator(1000)
    if abs(float(ratio) - half_y / half_x) > 1e-9:
        return []
    unit = half_x / ratio.denominator  # every cell half_x / (denominator k) fits both
    k = unit / near_mm
    found = sorted({unit / m for m in (math.floor(k), math.ceil(k)) if m >= 1}, reverse=True)
    return [v for v in found if abs(v - near_mm) > 1e-9 * near_mm]


def form_case(out_dir: str | os.PathLike, case: FormingCase, model=None, options=None, *,
              tools=None, grid_mm: float | None = None, lab_lines: bool = False,
              fields: bool = True, pictures: bool = True,
              progress: Callable[[str], None] | None = None,
              comm=None) -> tuple[FormingRun, dict]:
    """Run a forming case and write all its outputs into ``out_dir`` (module docstring).

    Args:
        out_dir: Output folder (created).
        case: The forming case (:func:`~fenicsx_drape.forming.case.reading.load_case`).
        model: The material model (default: the case's, else the paper's).
        options: Solver options of the truss.
        tools: Built tools by name replacing the case's (see :func:`run_case`).
        grid_mm: Spacing of the drawn grid of the bundle (None: :func:`default_grid_mm`).
        lab_lines: The bundle's test also holds shear along three measuring lines and the
            blank's edge (:func:`lab_tables`).
        fields: Write the XDMF fields and the tool meshes.
        pictures: Write the PNG pictures.
        progress: Called with a line per load step (rank 0).
        comm: MPI communicator (default ``COMM_WORLD``).

    Returns:
        The run and its summary.
    """
    from mpi4py import MPI

    from fenicsx_drape.forming.running.run import case_model

    comm = comm or MPI.COMM_WORLD
    model = model or case_model(case)
    out = Path(out_dir)
    writer = {}
    total = case.total_travel_mm

    def frame(problem) -> None:
        from fenicsx_drape.fe.output import FieldWriter

        if "file" not in writer:
            writer["file"] = FieldWriter(problem, out / "fields.xdmf")
            writer["next"] = 0.0
        travel = case.travel_mm(problem.t)
        if travel >= writer["next"] - 1e-9 or travel >= total - 1e-9:
            writer["file"].write()
            writer["next"] = (np.floor(travel / FRAME_MM + 1e-9) + 1.0) * FRAME_MM

    try:
        run = run_case(case, model, options, tools=tools, progress=progress,
                       on_step=frame if fields else None, comm=comm, failure_dir=out)
    finally:
        if "file" in writer:
            writer["file"].close()
    with _WrittenOnFailure(out, run, comm, "drape form") as partial:
        result = partial.update({**net_fit(case, run.grid), **case_summary(run)})
        paper = is_paper_hemisphere(case)
        if paper:
            from fenicsx_drape.forming.running.conditions import paper_differences

            result["paper_differences"] = paper_differences(result, model)
            result["paper_conditions"] = not result["paper_differences"]
        if comm.rank == 0:
            from fenicsx_drape.forming.running.measure import SHEET_FILE, write_sheet

            left_out: dict[str, str] = {}  # an output that cannot be made: its name, why

            def attempt(name: str, make: Callable[[], object]) -> object:
                try:
                    return make()
                except Exception as err:  # left out with a note, not the whole run
                    left_out[name] = f"{type(err).__name__}: {err}"
                    return None

            net, kinematic = _kinematic_beside(case, run, out if pictures else None)
            result.update(kinematic)
            if "kinematic_error" in kinematic:
                left_out["kinematic drape"] = kinematic["kinematic_error"]
            result.update(attempt("tool_forces.csv", lambda: write_tool_forces(
                run, out, run_title(case, result), pictures=pictures)) or {})
            Δ = result["cell_mm"]
            note = (f"simulated by fenicsx_drape (drape form): case {case.name!r}, cell "
                    f"{Δ:g} mm, symmetry {list(case.planes) or 'none'}")
            if attempt(SHEET_FILE, lambda: write_sheet(run.grid, out / SHEET_FILE,
                                                       comment=note)) is not None:
                result["sheet_file"] = SHEET_FILE
            write_json(out / "summary.json", result)
            given = case.holder.mu if case.holder is not None else None
            μ = float(np.max(given if given is not None else model.parameters.get("mu", 0.0)))
            # The tools as the run meshed them: the bundle is data (no code, no Gmsh script).
            meshes = {name: tool.surface for name, tool in run.tools.items()
                      if hasattr(getattr(tool, "surface", None), "triangles")}
            import dataclasses

            own = dataclasses.replace(case, blank=dataclasses.replace(case.blank, cell_mm=Δ))

            def bundle() -> None:
                write_case(own, out / "bundle" / "case", comment=note, surfaces=meshes)
                write_run_bundle(run, out / "bundle", μ, grid_mm=grid_mm, lab_lines=lab_lines,
                                 comment=note)

            attempt("bundle", bundle)
            if pictures:
                what = run_title(case, result)  # the run's conditions, as the run had them
                attempt("shear.png", lambda: plot_shear(
                    run.grid, out / "shear.png",
                    f"{what}: shear angle (max {result['max_shear_deg']:.1f}°)"))
                attempt("wrinkling.png", lambda: plot_wrinkling(
                    run.grid, out / "wrinkling.png", _wrinkling_title(what, result)))
                for k, (g, ply) in enumerate(zip(run.plies, result.get("plies", [])), 1):
                    attempt(f"shear_ply{k}.png", lambda g=g, k=k, ply=ply: plot_shear(
                        g, out / f"shear_ply{k}.png",
                        f"{what}: ply {k} at {ply['angle_deg']:g}°, shear angle "
                        f"(max {ply['max_shear_deg']:.1f}°)"))
                    attempt(f"wrinkling_ply{k}.png", lambda g=g, k=k, ply=ply: plot_wrinkling(
                        g, out / f"wrinkling_ply{k}.png",
                        _wrinkling_title(f"{what}: ply {k}", ply)))
                if run.plies:
                    faces = [dict(face, name=face["interface"]) for face in interply_maps(run)]
                    attempt("interply.png", lambda: plot_interply(
                        faces, out / "interply.png",
                        f"{case.name}: where the plies slid, and their pressure "
                        "(the modelled part)"))
                if paper and result["paper_conditions"] and net is not None:
                    attempt("paths.png", lambda: plot_paths(
                        {"FE truss": run.grid, "kinematic (PjN)": net}, out / "paths.png",
                        "the paper's hemisphere under its section 4 conditions "
                        "(10 mm cells, 133 N, 40 s): Figs. 10-11's paths"))
            if fields:
                files = attempt("tools", lambda: [str(p.relative_to(out)) for p in
                                                  write_case_tools(run, out / "tools")])
                if files is not None:
                    result["tool_files"] = files
            if left_out:
                result["outputs_left_out"] = left_out
            write_json(out / "summary.json", result)
            write_provenance(out, model={"effects": list(model.effects),
                                         "parameters": _plain(model.parameters)},
                             case=case_dict(case, case.folder),
                             case_file=str(case.path) if case.path else None,
                             solver=_plain(vars(run.problem.options)))
    comm.Barrier()
    return run, result


def run_title(case: FormingCase, result: dict) -> str:
    """The run as its pictures' titles name it: case, net's cell, where it stopped.

    The case's name, the net's own cell (``result["cell_mm"]``) and, for a run that stopped
    short of the full travel, where.
    """
    text = f"{case.name}, {result.get('cell_mm', case.blank.cell_mm):g} mm cells"
    if result.get("stopped"):
        text += (f", stopped at {result['travel_mm']:.3g} of {result['full_travel_mm']:.3g} mm "
                 "of travel")
    return text


def _wrinkling_title(what: str, numbers: dict) -> str:
    return (f"{what}: wrinkled tows (min {numbers['min_wrinkling_strain']:.3f}, total "
            f"{100 * numbers['total_wrinkling_strain']:.2f} %)")


def write_tool_forces(run: FormingRun, out: str | os.PathLike, part: str, *,
                      pictures: bool = True) -> dict:
    """Write the run's tool forces (``tool_forces.csv``, ``tool_forces.png``).

    One row per converged step: ``time_s``, ``travel_mm`` and each tool's force along its
    motion (N, the whole part; :func:`~fenicsx_drape.forming.running.run.record_tool_forces`).

    Args:
        run: The forming run.
        out: The output folder.
        part: The part's name, for the picture's title.
        pictures: Also draw ``tool_forces.png``.

    Returns:
        For ``summary.json``: ``max_tool_force_N`` (each tool's largest force in magnitude,
        signed, over the converged steps) and ``tool_forces_file``; where a step's force
        stands out of its neighbours' (:func:`outliers`), ``tool_force_outliers`` and
        ``tool_force_notes``, which say it and give the peak without those steps.
    """
    from fenicsx_drape.forming.running.plots import plot_tool_forces
    from fenicsx_drape.provenance import atomic_write_text

    rows = run.tool_forces
    if not rows:
        return {}
    names = list(rows[0])
    text = ",".join(names) + "\n" + "".join(
        ",".join(repr(float(r[n])) for n in names) + "\n" for r in rows)
    atomic_write_text(Path(out) / "tool_forces.csv", text)
    curves = {n: np.array([r[n] for r in rows]) for n in names}
    travel = curves["travel_mm"]
    tools = {n: v for n, v in curves.items() if n not in ("time_s", "travel_mm")}
    found = {n: outliers(travel, v) for n, v in tools.items()}
    if pictures:
        plot_tool_forces(curves, Path(out) / "tool_forces.png",
                         f"{part}: force of each tool along its motion",
                         marked={n: i for n, i in found.items() if len(i)})
    peak = {n: float(v[np.argmax(np.abs(v))]) for n, v in tools.items()}
    result = {"max_tool_force_N": peak, "tool_forces_file": "tool_forces.csv"}
    listed, notes = [], []
    for name, steps in found.items():
        v = tools[name]
        for i in steps:
            listed.append({"tool": name, "step": int(i) + 1, "travel_mm": float(travel[i]),
                           "force_N": float(v[i]),
                           "neighbours_N": [float(v[i - 1]), float(v[i + 1])]})
            notes.append(f"{name}: the force of step {i + 1} ({travel[i]:.1f} mm of travel), "
                         f"{v[i]:.3g} N, stands out of its neighbours' ({v[i - 1]:.3g} and "
                         f"{v[i + 1]:.3g} N)")
        if len(steps):
            rest = np.delete(v, steps)
            notes.append(f"{name}: peak {peak[name]:.3g} N over all converged steps, "
                         f"{rest[np.argmax(np.abs(rest))]:.3g} N without the steps that "
                         "stand out")
    if listed:
        result.update(tool_force_outliers=listed, tool_force_notes=notes)
    return result


def outliers(travel: np.ndarray, force: np.ndarray, *, factor: float = 3.0,
             share: float = 0.1) -> np.ndarray:
    """The steps whose force stands out of both neighbours' (indices into ``force``).

    A step stands out when its force departs from the line through its two neighbours (in
    travel) by more than ``factor`` times the neighbours' own difference and by more than
    ``share`` of the curve's largest magnitude: a one-step spike or dip, as a step that
    converged on a transient contact or friction state gives, and not a steep but steady
    rise (where the neighbours differ by as much) or the noise of a curve near zero. The
    first and last steps have one neighbour and are never listed.
    """
    s, f = np.asarray(travel, float), np.asarray(force, float)
    if len(f) < 3:
        return np.zeros(0, int)
    a, b, m = f[:-2], f[2:], f[1:-1]
    span = s[2:] - s[:-2]
    w = np.divide(s[1:-1] - s[:-2], span, out=np.full(len(m), 0.5), where=span > 0)
    departure = np.abs(m - (a + w * (b - a)))
    big = (departure > factor * np.abs(b - a)) & (departure > share * np.abs(f).max())
    return np.flatnonzero(big) + 1


def _kinematic_beside(case: FormingCase, run: FormingRun, pictures: Path | None
                      ) -> tuple[FormedGrid | None, dict]:
    """The kinematic drape on the formed tools: the net (None if it fails) and its numbers.

    Its picture ``kinematic_shear.png`` goes to ``pictures`` when given.

    A net that cannot be draped (a surface the generators leave, a net that places too few
    nodes to have a cell) is reported, not raised: the mechanical result it stands beside is
    kept. The net has the run's Δ and, on a stack, the measured ply's angle.
    """
    from fenicsx_drape.forming.running.kinematic import drape_case

    # The sheet the run formed: its Δ (a rectangle fits whole cells to its sides) and, on a
    # stack, the measured ply's angle.
    blank = case.ply_blanks()[-1]
    try:
        net = drape_case(case, tools=run.tools, warn=False, cell_mm=run.grid.cell_mm,
                         ply_angle_deg=blank.ply_angle_deg)  # summary and console say it
        numbers = net.summary()
    except Exception as err:  # the mechanical result is kept; the note says why
        return None, {"kinematic_error": f"{type(err).__name__}: {err}"}
    placed, unplaced = numbers["nodes"], numbers["unplaced_nodes"]
    result = {"kinematic_max_shear_deg": numbers["max_shear_deg"],
              "kinematic_placed_nodes": placed, "kinematic_blank_nodes": placed + unplaced,
              "kinematic_unplaced_nodes": unplaced, "kinematic_complete": unplaced == 0}
    if pictures is not None and numbers["max_shear_deg"] is not None:
        pictures.mkdir(parents=True, exist_ok=True)
        plot_shear(net, pictures / "kinematic_shear.png",
                   f"{case.name}: kinematic drape (pin-jointed net)\n{kinematic_text(result)}")
    return net, result


def kinematic_text(result: dict) -> str:
    """The kinematic drape's maximum shear as a phrase, saying so when the net is partial.

    Args:
        result: A ``summary.json`` with the ``kinematic_*`` keys of :func:`form_case`.
    """
    γ = result.get("kinematic_max_shear_deg")
    shear = "no cell" if γ is None else f"{γ:.1f}°"
    if result.get("kinematic_complete", True):
        return f"max shear {shear}"
    placed, total = result["kinematic_placed_nodes"], result["kinematic_blank_nodes"]
    return (f"PARTIAL: {placed} of {total} nodes of the blank placed "
            f"({100 * placed / max(total, 1):.0f} %), max shear {shear} on them only")


def write_case_tools(run: FormingRun, folder: str | os.PathLike) -> list[Path]:
    """Write the tools at the end of their motion as VTK surfaces into ``folder``.

    Builtin hemisphere tools are drawn with Gmsh
    (:func:`~fenicsx_drape.forming.tools.drawing.write_tool_meshes`); a meshed tool with a
    triangle ``surface`` and a ``motion`` is written moved to the end. Other tools (e.g. an
    analytic surface given in Python) are not drawn.
    """
    import meshio

    from fenicsx_drape.forming.case.spec import _builtin_tools
    from fenicsx_drape.provenance import atomic_write_bytes

    folder = Path(folder)
    case, t = run.case, run.problem.t
    written = []
    builtin = [s for s in case.tools if s.builtin]
    if builtin:
        from fenicsx_drape.forming.tools.drawing import write_tool_meshes

        tools = _builtin_tools(next((s for s in builtin if s.role == "punch"), builtin[0]))
        written += write_tool_meshes(tools, folder, travel_mm=case.travel_mm(t))
    for spec in case.tools:
        if spec.builtin:
            continue
        tool = run.tools.get(spec.name)
        surface, motion = getattr(tool, "surface", None), getattr(tool, "motion", None)
        if surface is None or not hasattr(surface, "triangles"):
            continue
        points = np.asarray(surface.points, dtype=float)
        if motion is not None and hasattr(motion, "at"):
            R, T = motion.at(t)
            c = np.asarray(getattr(motion, "centre_mm", (0.0, 0.0, 0.0)), dtype=float)
            points = (points - c) @ np.asarray(R).T + c + np.asarray(T)
        mesh = meshio.Mesh(points, [("triangle", np.asarray(surface.triangles))])
        with tempfile.TemporaryDirectory() as tmp:  # meshio writes files only: then atomically
            path = Path(tmp) / f"{spec.name}.vtk"
            mesh.write(path)
            written.append(atomic_write_bytes(folder / path.name, path.read_bytes()))
    return written
