"""The hostile-input battery: broken and hostile inputs against the commands, each classed.

    ./drape exec python3 benchmarks/hostile_battery.py                  # every row that runs today
    ./drape exec python3 benchmarks/hostile_battery.py --class refused  # one class
    ./drape exec python3 benchmarks/hostile_battery.py --row stack-1000mm-ply --keep /tmp/b

Every input is written by the script into a temporary folder (``--keep DIR`` keeps them). Each
row runs one command (``python3 -m fenicsx_drape ...``) in a child process with a time limit
and classes what it did:

- ``refused``: exit status 2, one message naming the file (and line or key) that contains the
  row's fragment, no traceback, nothing written to ``--out``;
- ``warned``: exit status 0 and the row's warning or note on the console;
- ``accepted``: exit status 0, and the row's check of the result holds (the same numbers as
  the clean input's, a file written, no marker of code that must not run);
- ``interrupted``: Ctrl-C (SIGINT to the command's process group, as a terminal sends it)
  ends the command with exit status 130 and one "interrupted" line, no traceback;
- anything else is a failure: a traceback, another exit status, a time limit reached (a
  hang), a wrong class, or a marker file that code left when it should not have run.

A row may be marked ``pending`` (what the commands lack for it to pass): such rows run only
with ``--with-pending`` and do not fail the battery. The summary counts each class and exits
1 when a row fails.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HEMISPHERE = ROOT / "meshes" / "hemisphere" / "case.toml"
MARKER = "code_ran"


@dataclasses.dataclass
class Row:
    """One hostile input: how to write it, the command, the class it must end in."""

    name: str
    area: str  # "case" | "bundle" | "table" | "geometry" | "runs"
    expect: str  # "refused" | "warned" | "accepted"
    build: Callable[[Path], list[str]]  # writes the input into a folder; the command's args
    fragment: str = ""  # in the message (refused, warned)
    check: Callable[[Path, str], str | None] | None = None  # accepted: None when right
    env: dict[str, str] = dataclasses.field(default_factory=dict)
    timeout_s: float = 180.0
    pending: str = ""  # what the commands lack for it to pass
    interrupt_after_s: float | None = None  # Ctrl-C (SIGINT to the group) after this


# --------------------------------------------------------------------------------------------
# Inputs

PLUGIN = f"from pathlib import Path\nPath(__file__).with_name({MARKER!r}).write_text('ran')\n"
PUNCH_PY = (f"from pathlib import Path\nPath(__file__).with_name({MARKER!r}).write_text('ran')\n"
            "def build(gmsh, radius_mm):\n    gmsh.model.occ.addSphere(0.0, 0.0, -radius_mm, "
            "radius_mm)\n    gmsh.model.occ.synchronize()\n")
HOLDER_GEO = ('SetFactory("OpenCASCADE");\nDefineConstant[ side_mm = 120.0 ];\n'
              "Rectangle(1) = {-side_mm / 2, -side_mm / 2, 0, side_mm, side_mm};\n")
CASE = """\
[case]
name = "hostile"
duration_s = 10.0
{model}
[blank]
outline = {outline}
cell_mm = {cell_mm}

[holder]
tool = "holder"
holder_force_N = 10.0

[[tool]]
name = "punch"
role = "punch"
geometry = "{punch}"
{punch_parameters}mesh_mm = {mesh_mm}
[tool.motion]
time_s = [0.0, 10.0]
z_mm = [{punch_z0}, {punch_z1}]

[[tool]]
name = "die"
role = "die"
geometry = "plate.stl"
[tool.motion]
time_s = [0.0]
z_mm = [{die_z}]

[[tool]]
name = "holder"
role = "holder"
geometry = "holder.geo"
mesh_mm = 40.0
"""


def dome_stl(path: Path, radius_mm: float = 60.0, rings: int = 12, segments: int = 48,
             nan: bool = False, sliver: bool = False) -> Path:
    """A faceted dome (ASCII STL); ``nan``: one vertex not a number; ``sliver``: a triangle of
    no area on an inner edge."""
    def point(a, b):
        return (radius_mm * math.sin(a) * math.cos(b), radius_mm * math.sin(a) * math.sin(b),
                radius_mm * math.cos(a))

    φ = [math.pi / 2 * k / rings for k in range(rings + 1)]
    λ = [2 * math.pi * m / segments for m in range(segments + 1)]
    facets = []
    for k in range(rings):
        for m in range(segments):
            a, b, c, d = (point(φ[k], λ[m]), point(φ[k + 1], λ[m]), point(φ[k + 1], λ[m + 1]),
                          point(φ[k], λ[m + 1]))
            facets += [(a, b, c)] + ([(a, c, d)] if k else [])
    if nan:
        facets[5] = (facets[5][0], (math.nan, math.nan, math.nan), facets[5][2])
    if sliver:  # on the edge a-c of the second band's first quad: no area
        a, c = facets[segments][0], facets[segments][2]
        mid = tuple((u + v) / 2 for u, v in zip(a, c))
        facets.append((a, mid, c))
    path.write_text("solid dome\n" + "".join(
        "facet normal 0 0 0\n outer loop\n" + "".join(f"  vertex {x} {y} {z}\n"
                                                     for x, y, z in f) + " endloop\nendfacet\n"
        for f in facets) + "endsolid dome\n")
    return path


def plate_stl(path: Path, half_mm: float = 100.0) -> Path:
    c = [(-half_mm, -half_mm), (half_mm, -half_mm), (half_mm, half_mm), (-half_mm, half_mm)]
    path.write_text("solid plate\n" + "".join(
        "facet normal 0 0 1\n outer loop\n" + "".join(f"  vertex {x} {y} 0\n" for x, y in f)
        + " endloop\nendfacet\n" for f in ((c[0], c[1], c[2]), (c[0], c[2], c[3])))
        + "endsolid plate\n")
    return path


def case(folder: Path, *, model="", outline='"rectangle"\nsize_mm = [100.0, 100.0]',
         cell_mm=20.0, punch="dome.stl", mesh_mm=10.0, punch_parameters="", punch_z0=-61.0,
         punch_z1=-41.0, die_z=19.5, holder=HOLDER_GEO, extra="", stl=None) -> Path:
    """A small case: an STL dome punch rising under a 100 mm blank, plate die, .geo holder."""
    folder.mkdir(parents=True, exist_ok=True)
    (stl or dome_stl)(folder / "dome.stl")
    plate_stl(folder / "plate.stl")
    (folder / "holder.geo").write_text(holder)
    (folder / "punch.py").write_text(PUNCH_PY)
    path = folder / "case.toml"
    path.write_text(CASE.format(model=model, outline=outline, cell_mm=cell_mm, punch=punch,
                                mesh_mm=mesh_mm, punch_parameters=punch_parameters,
                                punch_z0=punch_z0, punch_z1=punch_z1, die_z=die_z) + extra)
    return path


def model_with_plugin(folder: Path, name: str = "MODEL.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "plugin.py").write_text(PLUGIN)
    (folder / name).write_text('plugins = ["plugin.py"]\n')
    return folder / name


def hemisphere_stack(folder: Path, thickness: list[float], model: str = "") -> Path:
    """The shipped hemisphere (builtin tools, die gap 0.3 mm) as a stack, whole blank."""
    folder.mkdir(parents=True, exist_ok=True)
    text = HEMISPHERE.read_text().replace('symmetry = ["x", "y"]', "symmetry = []")
    text += "".join(f"\n[[ply]]\nangle_deg = 0.0\nthickness_mm = {t}\n"
                    + (model if k == len(thickness) - 1 else "")
                    for k, t in enumerate(thickness))
    path = folder / "stack.toml"
    path.write_text(text)
    return path


def form(path: Path | str, *more: str) -> list[str]:
    return ["form", str(path), "--quiet", "--no-fields", *more]


def coupon_bundle(folder: Path, tensile: str | None = None, extra_key: str = "") -> Path:
    """A tensile and a bias-extension test (coupons: compare runs in seconds)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "bundle.toml").write_text(
        '[bundle]\nname = "coupons"\ntows_per_mm = 0.71\n\n[[test]]\nid = "tensile"\n'
        'kind = "tensile"\nfile = "tensile.csv"\ngauge_length_mm = 100.0\nwidth_mm = 25.0\n'
        f"speed_mm_per_min = 2.0\nforce_sd_N = 5.0\n{extra_key}\n[[test]]\nid = \"bias\"\n"
        'kind = "bias_extension"\nfile = "bias.csv"\nlength_mm = 210.0\nwidth_mm = 70.0\n'
        "speed_mm_per_min = 10.0\nforce_sd_N = 0.05\n")
    (folder / "tensile.csv").write_text(tensile if tensile is not None else TENSILE)
    (folder / "bias.csv").write_text(BIAS)
    return folder


TENSILE = "time_s,displacement_mm,force_N\n" + "".join(
    f"{t:g},{t * 2.0 / 60.0:.6g},{100.0 * t * 2.0 / 60.0 / 100.0 * 17.75 * 3410:.6g}\n"
    for t in range(0, 30, 3))
BIAS = "time_s,displacement_mm,force_N\n" + "".join(
    f"{t:g},{t * 10.0 / 60.0:.6g},{0.5 * t * 10.0 / 60.0:.6g}\n" for t in range(0, 600, 60))


def grid_bundle(folder: Path, keys: str, rows: list[str] | None = None) -> Path:
    """A forming grid test (the flat grid) with the given keys."""
    folder.mkdir(parents=True, exist_ok=True)
    if rows is None:
        rows = [f"{i},{j},{10 * i},{10 * j},{10 * i},{10 * j},0" for i in range(4)
                for j in range(4)]
    (folder / "grid.csv").write_text("i,j,x0_mm,y0_mm,x_mm,y_mm,z_mm\n" + "\n".join(rows) + "\n")
    (folder / "bundle.toml").write_text(f'[bundle]\nname = "grid"\n\n[[test]]\nid = "t"\n'
                                        f'kind = "forming"\nfile = "grid.csv"\n{keys}\n')
    return folder


HEMISPHERE_KEYS = ('geometry = "hemisphere"\npunch_radius_mm = 60.0\nfillet_radius_mm = 20.0\n'
                   "holder_opening_mm = 170.0\nsheet_mm = 240.0\ntravel_mm = 80.0\n"
                   "duration_s = 40.0\nholder_force_N = 133.0\ngrid_mm = 10.0")
RUN_KEYS = HEMISPHERE_KEYS + "\nposition_sd_mm = 0.5"  # a grid whose runs are formed


def compare(folder: Path, *more: str) -> list[str]:
    return ["compare", str(folder), *more]


# --------------------------------------------------------------------------------------------
# Checks of accepted results


def same_compare_as_clean(clean: Callable[[Path], Path]):
    """The compare.json of the row's input equals that of the clean input (every number)."""
    def check(folder: Path, _: str) -> str | None:
        reference = folder.parent / (folder.name + "-clean")
        bundle = clean(reference)
        out = reference / "out"
        done = subprocess.run([sys.executable, "-m", "fenicsx_drape", "compare", str(bundle),
                               "--out", str(out)], capture_output=True, text=True)
        if done.returncode != 0:
            return f"the clean input failed: {done.stderr[-300:]}"
        a = json.loads((folder / "out" / "compare.json").read_text())
        b = json.loads((out / "compare.json").read_text())
        return None if _numbers(a) == _numbers(b) else "results differ from the clean input's"
    return check


def _numbers(report) -> list:
    """The numbers of a report in order (paths and times left out)."""
    out = []
    if isinstance(report, dict):
        for k, v in sorted(report.items()):
            if k not in ("path", "folder", "wall_time_s", "provenance", "files"):
                out += _numbers(v)
    elif isinstance(report, list):
        for v in report:
            out += _numbers(v)
    elif isinstance(report, (int, float)) and not isinstance(report, bool):
        out.append(report)
    return out


def wrote(name: str):
    def check(folder: Path, _: str) -> str | None:
        return None if (folder / "out" / name).is_file() else f"no {name} written"
    return check


# --------------------------------------------------------------------------------------------
# Rows


def rows() -> list[Row]:
    r: list[Row] = []

    def row(*args, **kwargs):
        r.append(Row(*args, **kwargs))

    # -- Case files ------------------------------------------------------------------------
    row("no-such-case", "case", "refused", lambda f: form(f / "none.toml"), "no such case file")
    row("not-toml", "case", "refused",
        lambda f: (f.mkdir(parents=True, exist_ok=True), (f / "c.toml").write_text("[case\n"),
                   form(f / "c.toml"))[-1], "c.toml: not valid TOML")
    row("misspelt-case-key", "case", "refused",
        lambda f: form(_edit(case(f), "duration_s = 10.0", "duraton_s = 10.0")),
        "unknown key 'duraton_s' (did you mean `duration_s`?)")
    row("negative-duration", "case", "refused",
        lambda f: form(_edit(case(f), "duration_s = 10.0", "duration_s = -1.0")),
        "[case] 'duration_s': -1.0 must be > 0")
    row("missing-geometry", "case", "refused",
        lambda f: form(_edit(case(f), 'geometry = "plate.stl"', 'geometry = "die.stp"')),
        "[[tool]] 2 'geometry': no such file 'die.stp'")
    row("holder-names-no-tool", "case", "refused",
        lambda f: form(_edit(case(f), 'tool = "holder"', 'tool = "plates"')),
        "[holder] 'tool': no tool named 'plates'")
    row("geo-systemcall", "case", "refused",
        lambda f: form(case(f, holder=HOLDER_GEO + f'SystemCall "touch {f / MARKER}";\n')),
        "the command 'SystemCall' runs a program")
    row("geo-merge-python", "case", "refused",
        lambda f: form(case(f, holder=HOLDER_GEO + 'Merge "evil.py";\n')),
        "Merge \"evil.py\": Gmsh would run it")
    row("outline-geo-save", "case", "refused",
        lambda f: (_write(f / "edge.geo", 'Point(1) = {0, 0, 0};\nSave "x.msh";\n'),
                   form(case(f, outline='"edge.geo"')))[-1],
        "the command 'Save' runs a program or writes files")
    row("case-model-plugins", "case", "refused",
        lambda f: (model_with_plugin(f), form(case(f, model='model = "MODEL.toml"')))[-1],
        "[case] 'model': MODEL.toml has plugins ['plugin.py'] (Python code)")
    row("ply-model-plugins", "case", "refused",
        lambda f: (model_with_plugin(f, "ply.toml"),
                   form(hemisphere_stack(f, [0.3, 0.3], "model = 'ply.toml'\n")))[-1],
        "[[ply]] 2 'model': ply.toml has plugins")
    row("net-1e10-nodes", "case", "refused", lambda f: form(case(f, cell_mm=1e-3)),
        "the sheet's net would have about 1e+10 nodes")
    row("tool-mesh-1e15-triangles", "case", "refused",
        lambda f: form(_edit(case(f), "mesh_mm = 40.0", "mesh_mm = 1e-6")),
        "triangles, more than the limit")
    row("40000-steps", "case", "refused", lambda f: form("double_dome", "--step-mm", "0.001"),
        "the run would take 40000 load steps")
    row("max-steps-option", "case", "refused",
        lambda f: form("hemisphere", "--cell-mm", "40", "--max-steps", "10"),
        "more than the limit of 10 steps (set by DRAPE_MAX_STEPS)")
    row("work-limit", "case", "refused", lambda f: form("hemisphere", "--cell-mm", "20"),
        "node-steps, about", env={"DRAPE_MAX_NODE_STEPS": "1000"})
    row("stack-500-plies", "case", "refused",
        lambda f: form(hemisphere_stack(f, [0.3] * 500)),
        "the stack (500 plies of 0.3 mm, 150 mm thick) cannot fit between the punch 'punch' "
        "and the die 'die'", timeout_s=120.0)
    row("stack-1000mm-ply", "case", "refused",
        lambda f: form(hemisphere_stack(f, [0.3, 1000.0])),
        "the stack (2 plies: 0.3 + 1000 mm, 1000.3 mm thick) cannot fit")
    row("stack-meshed-die", "case", "refused",
        lambda f: form(case(f, extra="\n[[ply]]\nangle_deg = 0.0\nthickness_mm = 0.3\n"
                            "\n[[ply]]\nangle_deg = 0.0\nthickness_mm = 1000.0\n")),
        "ply 2 of the stack starts inside the die 'die'")
    row("script-never-ends", "case", "refused",
        lambda f: (_write(f / "hang.py", "def build(gmsh, radius_mm):\n    while True:\n"
                          "        pass\n"),
                   form(case(f, punch="hang.py", punch_parameters="parameters = { radius_mm = "
                             "20.0 }\n")))[-1],
        "the geometry script did not finish in 5 s", env={"DRAPE_SCRIPT_TIMEOUT_S": "5"})
    row("stl-nan-vertex", "case", "refused",
        lambda f: form(case(f, stl=lambda p: dome_stl(p, nan=True))),
        "is not three finite numbers")
    row("blank-far-from-tools", "case", "refused",
        lambda f: form(_edit(case(f), "size_mm = [100.0, 100.0]",
                             "size_mm = [100.0, 100.0]\ncentre_mm = [400.0, 0.0]")),
        "the blank and the tools never meet")
    row("die-wrong-side", "case", "refused", lambda f: form(case(f, die_z=-10.0)),
        "tool 'die' (die) starts on the wrong side of the sheet")
    row("grid-mm-negative", "case", "refused",
        lambda f: form("hemisphere", "--grid-mm", "-10"), "--grid-mm: '-10' is not a positive")
    row("stack-thicker-than-gap", "case", "refused",
        lambda f: form(hemisphere_stack(f, [0.3, 0.3]), "--cell-mm", "40", "--duration-s", "8"),
        "is thicker than the gap of 0.3 mm")
    row("tool-mesh-too-fine", "case", "warned", lambda f: form(case(f, mesh_mm=0.5)),
        "times finer than the sheet's cell", timeout_s=300.0)
    row("stl-sliver", "case", "warned",
        lambda f: form(case(f, stl=lambda p: dome_stl(p, sliver=True))),
        "1 degenerate triangle(s) (no area)", timeout_s=300.0)
    row("own-python-geometry", "case", "accepted",
        lambda f: form(case(f, punch="punch.py", punch_parameters="parameters = { radius_mm = "
                            "60.0 }\n", punch_z0=-1.0, punch_z1=19.0)),
        check=lambda f, _: None if (f / MARKER).exists() else "the case's own .py did not run",
        timeout_s=300.0)
    row("hemisphere-coarse", "case", "accepted",
        lambda f: form("hemisphere", "--cell-mm", "40", "--duration-s", "8", "--out",
                       str(f / "out")), check=wrote("summary.json"))

    # -- Bundles ---------------------------------------------------------------------------
    row("no-bundle", "bundle", "refused",
        lambda f: (f.mkdir(parents=True, exist_ok=True), compare(f))[-1], "no bundle.toml here")
    row("bundle-bad-toml", "bundle", "refused",
        lambda f: compare(_edit(coupon_bundle(f) / "bundle.toml", "tows_per_mm = 0.71",
                                "tows_per_mm = = 0.71").parent), "bundle.toml:3: not valid TOML")
    row("table-missing", "bundle", "refused",
        lambda f: (coupon_bundle(f), (f / "bias.csv").unlink(), compare(f))[-1],
        "bundle.toml:17: test 'bias': file = 'bias.csv': no such file")
    row("duplicate-id", "bundle", "refused",
        lambda f: compare(_edit(coupon_bundle(f) / "bundle.toml", 'id = "bias"',
                                'id = "tensile"').parent), "is used twice")
    row("unknown-kind", "bundle", "refused",
        lambda f: compare(_edit(coupon_bundle(f) / "bundle.toml", 'kind = "bias_extension"',
                                'kind = "bias"').parent), "unknown test kind 'bias'")
    row("misspelt-bundle-key", "bundle", "warned",
        lambda f: compare(coupon_bundle(f, extra_key="force_sd_n = 5.0\n")),
        "key 'force_sd_n' kept as a test condition -- did you mean `force_sd_N`?")
    row("bundle-case-python", "bundle", "refused",
        lambda f: (case(f / "case", punch="punch.py", punch_parameters="parameters = { "
                        "radius_mm = 60.0 }\n"),
                   compare(grid_bundle(f / "b", 'case = "../case/case.toml"')))[-1],
        "'punch.py' is Python code that would run: a case a measurement bundle brings is data")
    row("bundle-case-model-plugins", "bundle", "refused",
        lambda f: (model_with_plugin(f / "case"), case(f / "case", model='model = "MODEL.toml"'),
                   compare(grid_bundle(f / "b", 'case = "../case/case.toml"')))[-1],
        "[case] 'model': MODEL.toml has plugins")
    row("bundle-case-ply-model-plugins", "bundle", "refused",
        lambda f: (model_with_plugin(f / "case", "ply.toml"),
                   hemisphere_stack(f / "case", [0.3, 0.3], "model = 'ply.toml'\n"),
                   compare(grid_bundle(f / "b", 'case = "../case/stack.toml"')))[-1],
        "[[ply]] 2 'model': ply.toml has plugins")
    row("grid-far-position", "bundle", "refused",
        lambda f: compare(grid_bundle(f, HEMISPHERE_KEYS, [
            f"{i},{j},{10 * i},{10 * j},{10 * i},{10 * j},{1e6 if (i, j) == (2, 1) else 0}"
            for i in range(4) for j in range(4)])), "farther than the blank's size")
    row("grid-mm-disagrees", "bundle", "refused",
        lambda f: compare(grid_bundle(f, HEMISPHERE_KEYS.replace("grid_mm = 10.0",
                                                                 "grid_mm = 20.0"))),
        "grid_mm = 20 disagrees with the flat positions")
    row("lab-file-missing", "bundle", "refused",
        lambda f: compare(_edit(grid_bundle(f, HEMISPHERE_KEYS) / "bundle.toml",
                                'file = "grid.csv"', 'outline = "edges.csv"').parent),
        "bundle.toml:7: test 't': outline = 'edges.csv': no such file")
    row("lab-wrong-columns", "bundle", "refused",
        lambda f: (_write(f / "edges.csv", "x_mm,y_m\n100,0\n0,90\n"),
                   compare(_edit(grid_bundle(f, HEMISPHERE_KEYS) / "bundle.toml",
                                 'file = "grid.csv"', 'outline = "edges.csv"').parent))[-1],
        "an outline table needs the columns x_mm, y_mm: missing y_mm")
    row("lab-shear-beyond-90", "bundle", "refused",
        lambda f: (_write(f / "s.csv", "x_mm,y_mm,z_mm,shear_deg\n0,0,80,0\n10,0,79,95\n"),
                   compare(_edit(grid_bundle(f, HEMISPHERE_KEYS) / "bundle.toml",
                                 'file = "grid.csv"', 'shear_points = "s.csv"').parent))[-1],
        "lies beyond ±90°")

    # -- Tables ----------------------------------------------------------------------------
    row("column-misnamed", "table", "refused",
        lambda f: compare(coupon_bundle(f, TENSILE.replace("force_N", "forceN"))),
        "missing column(s) force_N (a tensile table needs time_s, displacement_mm, force_N; "
        "its header: time_s, displacement_mm, forceN); 'forceN': did you mean `force_N`?")
    row("semicolons", "table", "refused",
        lambda f: compare(coupon_bundle(f, TENSILE.replace(",", ";"))),
        "the table's columns are separated by semicolons")
    row("decimal-commas", "table", "refused",
        lambda f: compare(coupon_bundle(f, TENSILE.replace(",", ";").replace(".", ","))),
        "numbers written with a decimal point (1.5, not 1,5)")
    row("nan-cell", "table", "refused",
        lambda f: compare(coupon_bundle(f, TENSILE.replace("\n6,", "\nnan,", 1))),
        "'nan' is not a finite number")
    row("time-backwards", "table", "refused",
        lambda f: compare(coupon_bundle(f, TENSILE.replace("\n9,", "\n1,", 1))),
        "time_s must increase row by row")
    row("force-in-kN", "table", "refused",
        lambda f: compare(coupon_bundle(f, TENSILE.replace("force_N", "force_kN"))),
        "force must be given in N")
    row("ragged-row", "table", "refused",
        lambda f: compare(coupon_bundle(f, TENSILE.replace("\n6,", "\n6;", 1))),
        "(separated by semicolons? the columns are separated by commas)")
    row("table-10-million-rows", "table", "refused",
        lambda f: (coupon_bundle(f), _ten_million_rows(f / "tensile.csv"), compare(f))[-1],
        "more than a table of 1e+06 lines can be", timeout_s=300.0)
    row("quoted-cells", "table", "accepted",
        lambda f: compare(coupon_bundle(f, _quoted(TENSILE)), "--out", str(f / "out")),
        check=same_compare_as_clean(lambda g: coupon_bundle(g)), timeout_s=300.0)

    # -- Runs: the cache, the workers, interrupts -----------------------------------------
    row("cache-swapped-entries", "runs", "accepted",
        lambda f: _swapped_cache(f), check=_same_as_first, timeout_s=600.0)
    row("workers-1000", "runs", "warned",
        lambda f: compare(grid_bundle(f, RUN_KEYS), "--workers", "1000",
                          "--forming-cell-mm", "40", "--no-fit", "--no-cache"),
        "--workers 1000 is more than the", timeout_s=300.0)
    row("drape-workers-1000", "runs", "warned",
        lambda f: compare(grid_bundle(f, RUN_KEYS), "--forming-cell-mm", "40",
                          "--no-fit", "--no-cache"), "DRAPE_WORKERS=1000 is more than the",
        env={"DRAPE_WORKERS": "1000"}, timeout_s=300.0)
    row("ctrl-c-diagnose", "runs", "interrupted",
        lambda f: ["diagnose", str(grid_bundle(f, RUN_KEYS)), "--json", str(f / "REPORT.json"),
                   "--workers", "2", "--forming-cell-mm", "40", "--no-cache"], "interrupted",
        interrupt_after_s=20.0, timeout_s=120.0)
    return r


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _edit(path: Path, old: str, new: str) -> Path:
    text = path.read_text()
    if old not in text:
        raise AssertionError(f"{path}: {old!r} not in the input")
    path.write_text(text.replace(old, new, 1))
    return path


def _quoted(table: str) -> str:
    return "\n".join(",".join(f'"{c}"' for c in line.split(","))
                     for line in table.splitlines()) + "\n"


def _ten_million_rows(path: Path) -> Path:
    """A tensile table of 10 million rows (about 150 MB), written in blocks."""
    with path.open("w") as out:
        out.write("time_s,displacement_mm,force_N\n")
        for start in range(0, 10_000_000, 100_000):
            out.write("".join(f"{k},{k * 1e-3:g},{k * 1e-2:g}\n"
                              for k in range(start, start + 100_000)))
    return path


def _swapped_cache(folder: Path) -> list[str]:
    """Two models compared on one grid (two runs cached), their cache entries' values swapped;
    the command is the first compare again."""
    bundle = grid_bundle(folder / "b", RUN_KEYS)
    cache = folder / "cache"
    (folder / "m").mkdir(parents=True, exist_ok=True)
    (folder / "m" / "no_buckling.toml").write_text(
        'effects = ["rate_dependence", "strain_dependent_viscosity", "decrimping", '
        '"holder_friction"]\n')
    for name, extra in (("first", []), ("second", ["--model", str(folder / "m" /
                                                                    "no_buckling.toml")])):
        subprocess.run([sys.executable, "-m", "fenicsx_drape", "compare", str(bundle), "--out",
                        str(folder / name), "--no-fit", "--forming-cell-mm", "40", "--cache",
                        str(cache), *extra], check=True, capture_output=True)
    db = cache / "cache.db"
    with sqlite3.connect(db) as con:
        rows_ = con.execute("SELECT rowid, value, filename FROM Cache").fetchall()
        if len(rows_) >= 2:
            (a, va, fa), (b, vb, fb) = rows_[:2]
            con.execute("UPDATE Cache SET value = ?, filename = ? WHERE rowid = ?", (vb, fb, a))
            con.execute("UPDATE Cache SET value = ?, filename = ? WHERE rowid = ?", (va, fa, b))
    return ["compare", str(bundle), "--out", str(folder / "out"), "--no-fit",
            "--forming-cell-mm", "40", "--cache", str(cache)]


def _same_as_first(folder: Path, _: str) -> str | None:
    a = json.loads((folder / "first" / "compare.json").read_text())
    b = json.loads((folder / "out" / "compare.json").read_text())
    return None if _numbers(a) == _numbers(b) else \
        "the swapped cache changed the result (another run's returned)"


# --------------------------------------------------------------------------------------------
# Running and classing


def run_row(row: Row, folder: Path) -> tuple[str, str, float]:
    """The class the row ended in, the message's first line (or why it failed), the time."""
    folder.mkdir(parents=True, exist_ok=True)
    try:
        args = row.build(folder)
    except Exception as err:  # the input could not be made: the row fails, the battery goes on
        return "input not made", f"{type(err).__name__}: {str(err)[-200:]}", 0.0
    if "--out" not in args and args[0] in ("form", "compare", "diagnose", "fit"):
        args = [*args, "--out", str(folder / "out")]
    env = {**os.environ, "PYTHONPATH": str(ROOT), **row.env}
    start = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-m", "fenicsx_drape", *args], env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             cwd=folder, start_new_session=True)
    try:
        if row.interrupt_after_s is not None:
            try:
                out, err = child.communicate(timeout=row.interrupt_after_s)
            except subprocess.TimeoutExpired:
                os.killpg(child.pid, signal.SIGINT)  # Ctrl-C: the terminal signals the group
                out, err = child.communicate(timeout=row.timeout_s)
        else:
            out, err = child.communicate(timeout=row.timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)
        child.communicate()
        return "hang", f"no end in {row.timeout_s:g} s", time.perf_counter() - start
    seconds = time.perf_counter() - start
    text = err + out
    first = next((line for line in err.splitlines() if row.fragment and row.fragment in line),
                 (err.strip().splitlines() or out.strip().splitlines() or [""])[-1])
    if "Traceback" in err:
        return "traceback", err.strip().splitlines()[-1], seconds
    if (folder / MARKER).exists() or any(p.name == MARKER for p in folder.rglob(MARKER)):
        if row.expect != "accepted":
            return "code ran", f"{MARKER} written: code ran that must not", seconds
    if row.expect == "interrupted":
        ok = child.returncode == 130 and row.fragment in err
        return ("interrupted" if ok else f"exit {child.returncode}"), first, seconds
    if child.returncode == 2:
        if row.fragment not in err:
            return "refused (other message)", first, seconds
        if row.expect == "refused" and (folder / "out").exists():
            return "refused (wrote --out)", first, seconds
        return "refused", first, seconds
    if child.returncode == 0:
        if row.expect == "warned":
            return ("warned" if row.fragment in text else "accepted (no warning)"), first, \
                seconds
        if row.expect == "accepted" and row.check is not None:
            problem = row.check(folder, text)
            if problem:
                return "wrong result", problem, seconds
        return "accepted", first, seconds
    return f"exit {child.returncode}", first, seconds


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--class", dest="only",
                        choices=("refused", "warned", "accepted", "interrupted"),
                        help="run the rows of one class")
    parser.add_argument("--row", nargs="+", help="run these rows (by name)")
    parser.add_argument("--with-pending", action="store_true",
                        help="run the rows marked pending too")
    parser.add_argument("--keep", type=Path, help="write the inputs here and keep them")
    parser.add_argument("--list", action="store_true", help="list the rows and stop")
    args = parser.parse_args()
    chosen = [r for r in rows() if (args.only is None or r.expect == args.only)
              and (args.row is None or r.name in args.row)
              and (args.with_pending or not r.pending or args.row)]
    if args.list:
        for r in rows():
            pending = f"pending: {r.pending}" if r.pending else ""
            print(f"{r.name:32s} {r.area:8s} {r.expect:10s} {pending}")
        return 0
    base = args.keep or Path(tempfile.mkdtemp(prefix="drape_battery_"))
    print(f"load average {os.getloadavg()[0]:.2f}; {len(chosen)} rows; inputs in {base}",
          flush=True)
    counts: dict[str, list[int]] = {}
    failed = []
    for r in chosen:
        got, line, seconds = run_row(r, base / r.name)
        ok = got == r.expect
        tally = counts.setdefault(r.expect + (" (pending)" if r.pending else ""), [0, 0])
        tally[0] += ok
        tally[1] += 1
        if not ok and not r.pending:
            failed.append(r.name)
        mark = "ok  " if ok else ("PEND" if r.pending else "FAIL")
        print(f"{mark} {r.name:30s} {r.area:7s} {r.expect:9s} -> {got:22s} {seconds:6.1f} s  "
              f"{line[:150]}", flush=True)
    print()
    for name, (ok, n) in counts.items():
        print(f"{name}: {ok} of {n} as intended")
    if not args.keep:
        shutil.rmtree(base, ignore_errors=True)
    if failed:
        print(f"failed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
