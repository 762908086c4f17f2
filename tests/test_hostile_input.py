"""Hostile and broken input refused at the reader, before anything runs or fills memory.

Every input is written here: models with a plugin that leaves a marker when it runs, named
from each place a case or a bundle can name one; stacks that cannot fit their tools' gap;
runs whose work is beyond the limit; tables too large to read, quoted or separated by
semicolons; misspelt keys; a geometry script that never ends, its command killed; a tool
mesh with a triangle of no area on an inner edge.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from test_bundle import TOML, bias_csv, grid_csv, tensile_csv
from test_case_geometry import problems
from test_case_geometry import write_case as write_placed_case
from test_lab_bundle import FORCE
from test_lab_bundle import write as write_lab_bundle
from test_untrusted_input import flat_grid, write_bundle, write_case

import fenicsx_drape.forming  # noqa: F401  (registers the bundle's case reader)
from fenicsx_drape.cli import main
from fenicsx_drape.errors import InputFileError, likely_typo
from fenicsx_drape.forming.case import PlySpec, case_for_test, load_case, run_size
from fenicsx_drape.forming.running.run import case_model, run_case
from fenicsx_drape.forming.tools.checks import mesh_defects
from fenicsx_drape.forming.tools.surfaces import TriangleSurface
from fenicsx_drape.measurements.bundle import BundleError, load_bundle
from fenicsx_drape.trust import UntrustedCodeError, trusting

ROOT = Path(__file__).resolve().parents[1]
PLUGIN = "from pathlib import Path\nPath(__file__).with_name('plugin_ran').write_text('ran')\n"


def model_with_plugin(folder: Path, name: str = "MODEL.toml") -> Path:
    """A MODEL.toml whose plugin writes ``plugin_ran`` beside itself when it runs."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "plugin.py").write_text(PLUGIN)
    (folder / name).write_text('plugins = ["plugin.py"]\n')
    return folder / name


def hemisphere_stack(folder: Path, plies: str, name: str = "stack.toml") -> Path:
    """The shipped hemisphere case (builtin tools, die gap 0.3 mm) with ``[[ply]]`` tables."""
    text = load_case("hemisphere").path.read_text().replace('symmetry = ["x", "y"]',
                                                            "symmetry = []")
    path = folder / name
    path.write_text(text + plies)
    return path


PLY = "\n[[ply]]\nangle_deg = {angle}\nthickness_mm = {thickness}\n{model}"


def plies(*thickness: float, model: str = "") -> str:
    return "".join(PLY.format(angle=0.0, thickness=t, model=model if k == 1 else "")
                   for k, t in enumerate(thickness))


# --------------------------------------------------------------------------------------------
# 1. No code from data without --trust, wherever a model is named


def test_a_model_a_case_names_runs_its_plugins_only_with_trust(tmp_path):
    model_with_plugin(tmp_path / "case")
    path = write_case(tmp_path, model='model = "MODEL.toml"')
    with pytest.raises(InputFileError, match=r"case\.toml: \[case\] 'model': MODEL\.toml has "
                                             r"plugins \['plugin\.py'\] \(Python code\) that "
                                             r"would run: .* --trust"):
        load_case(path)
    assert not (tmp_path / "case" / "plugin_ran").exists()
    with trusting():
        case = load_case(path)
        case_model(case)
    assert (tmp_path / "case" / "plugin_ran").exists()


def test_a_plys_own_model_runs_its_plugins_only_with_trust(tmp_path, capsys):
    model_with_plugin(tmp_path, "ply.toml")
    path = hemisphere_stack(tmp_path, plies(0.3, 0.3, model="model = 'ply.toml'\n"))
    with pytest.raises(InputFileError, match=r"stack\.toml: \[\[ply\]\] 2 'model': ply\.toml "
                                             r"has plugins"):
        load_case(path)
    # The command stops at the reader, naming the file and the key (exit status 2).
    assert main(["form", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "[[ply]] 2 'model': ply.toml has plugins" in capsys.readouterr().err
    assert not (tmp_path / "plugin_ran").exists() and not (tmp_path / "out").exists()
    # A case built in Python that names such a model: the run refuses it (the second check).
    case = dataclasses.replace(load_case("hemisphere", cell_mm=40.0), model=tmp_path / "ply.toml")
    with pytest.raises(UntrustedCodeError, match=r"plugin\.py: a plugin of the model .*ply\.toml "
                                                 r"that comes with the case .* --trust"):
        case_model(case)
    assert not (tmp_path / "plugin_ran").exists()


def test_a_bundles_case_whose_ply_names_a_model_with_plugins_is_refused_at_the_reader(tmp_path):
    model_with_plugin(tmp_path / "case", "ply.toml")
    hemisphere_stack(tmp_path / "case", plies(0.3, 0.3, model="model = 'ply.toml'\n"),
                     "case.toml")
    write_bundle(tmp_path / "b", flat_grid(), test_keys='case = "../case/case.toml"')
    with pytest.raises(BundleError, match=r"bundle\.toml:\d+: test 't': case "
                                          r"'\.\./case/case\.toml': .*case\.toml: \[\[ply\]\] 2 "
                                          r"'model': ply\.toml has plugins"):
        load_bundle(tmp_path / "b", read_case=case_for_test)
    assert not (tmp_path / "case" / "plugin_ran").exists()


def test_a_hostile_outline_script_is_refused_at_the_reader(tmp_path):
    marker = tmp_path / "marker"
    (tmp_path / "edge.geo").write_text(f'Point(1) = {{0, 0, 0}};\nSystemCall "touch {marker}";\n')
    path = write_case(tmp_path)
    text = path.read_text().replace('outline = "rectangle"\nsize_mm = [100.0, 100.0]',
                                    'outline = "../edge.geo"')
    path.write_text(text)
    with pytest.raises(InputFileError, match=r"(?s)\[blank\] 'outline': .*edge\.geo:2: the command "
                                             r"'SystemCall'"):
        load_case(path)
    assert not marker.exists()


# --------------------------------------------------------------------------------------------
# 2. Stacks against the tools' gap, and the run's estimate over every ply


def test_a_stack_that_cannot_fit_the_builtin_dies_gap_is_refused_at_the_reader(tmp_path, capsys):
    path = hemisphere_stack(tmp_path, plies(0.3, 1000.0))
    with pytest.raises(InputFileError) as err:
        load_case(path)
    assert str(err.value) == (
        f"{path}: [[ply]]: the stack (2 plies: 0.3 + 1000 mm, 1000.3 mm thick) cannot fit "
        "between the punch 'punch' and the die 'die' (its ply_thickness_mm): the plies' "
        "mid-planes span 500.15 mm, more than the gap of 0.3 mm the tools leave at the end of "
        "the motion; make the gap the stack's thickness (1000.3 mm) or check the plies' "
        "thickness_mm")
    assert main(["form", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "cannot fit between the punch 'punch' and the die 'die'" in capsys.readouterr().err
    # The tools as the overrides leave them: without the die the stack has no gap to fit.
    assert load_case(path, die=False).stack
    # Two plies of 0.3 mm: their mid-planes 0.3 mm apart fit the 0.3 mm gap, but the die
    # would press the 0.6 mm stack into 0.3 mm: refused too, naming the plies and the gap.
    thick = hemisphere_stack(tmp_path, plies(0.3, 0.3))
    with pytest.raises(InputFileError) as err:
        load_case(thick)
    assert str(err.value) == (
        f"{thick}: [[ply]]: the stack (2 plies: 0.3 + 0.3 mm, 0.6 mm thick) is thicker than the "
        "gap of 0.3 mm between the punch 'punch' and the die 'die' (its ply_thickness_mm) at the "
        "end of the motion: the die would press the plies into each other; make the gap the "
        "stack's thickness (0.6 mm) or check the plies' thickness_mm")
    assert load_case(thick, ply_thickness_mm=0.6).stack  # the gap made the stack's: it fits


def test_a_stack_that_cannot_fit_a_meshed_die_is_refused_before_the_first_step(tmp_path):
    # The dome punch ends 0.5 mm under the plate die (die_z = 19.5).
    case = load_case(write_placed_case(tmp_path, die_z=19.5))
    stack = dataclasses.replace(case, plies=(PlySpec(0.0, 0.3), PlySpec(0.0, 1000.0)))
    from fenicsx_drape.forming.running.geometry import geometry_problems
    from fenicsx_drape.forming.tools.build import build_tools

    errors, _ = geometry_problems(stack, build_tools(stack), stack.blank.grid().nodes)
    assert any(e.startswith("ply 2 of the stack starts inside the die 'die' (ply 2, 1000 mm "
                            "thick, lies with its mid-plane 500.15 mm above ply 1's")
               for e in errors)
    assert ("the stack (2 plies: 0.3 + 1000 mm, 1000.3 mm thick) cannot fit between the punch "
            "'punch' and the die 'die': the plies' mid-planes span 500.15 mm, more than the gap "
            "of 0.5 mm") in "\n".join(errors)
    thick = dataclasses.replace(case, plies=(PlySpec(0.0, 0.3), PlySpec(0.0, 0.3)))
    errors, _ = geometry_problems(thick, build_tools(thick), thick.blank.grid().nodes)
    assert errors == [
        "the stack (2 plies: 0.3 + 0.3 mm, 0.6 mm thick) is thicker than the gap of 0.5 mm "
        "between the punch 'punch' and the die 'die' at the end of the motion: the die would "
        "press the plies into each other; make the gap the stack's thickness (0.6 mm) or check "
        "the plies' thickness_mm"]
    thin = dataclasses.replace(case, plies=(PlySpec(0.0, 0.25), PlySpec(0.0, 0.25)))
    assert geometry_problems(thin, build_tools(thin), thin.blank.grid().nodes)[0] == []
    assert problems(write_placed_case(tmp_path, die_z=19.5)) == ([], [])  # one ply: no stack


def test_a_stack_of_500_plies_is_estimated_at_once_and_refused_before_the_first_step(
        monkeypatch):
    case = load_case("hemisphere", cell_mm=40.0)  # a quarter of 4 × 4 nodes, 80 steps
    stack = dataclasses.replace(case, plies=tuple(PlySpec(0.0, 0.3) for _ in range(500)))
    size = run_size(stack)
    assert size["nodes"] == 500 * 16 and size["plies"] == 500 and size["steps"] == 80
    from fenicsx_drape.forming.running import run

    lines, printed_before_tools = [], []
    build_tools = run.build_tools
    monkeypatch.setattr(run, "build_tools", lambda *a, **k: printed_before_tools.append(
        len(lines)) or build_tools(*a, **k))
    with pytest.raises(InputFileError, match=r"the stack \(500 plies of 0\.3 mm, 150 mm thick\) "
                                             r"cannot fit"):
        run_case(stack, progress=lines.append)
    # The estimate came first, before the tools were built; no step was made.
    assert printed_before_tools == [1] and len(lines) == 1
    assert lines[0].startswith("hemisphere: about 80 load steps (80 mm at 1 mm) on 8000 nodes "
                               "(500 plies of 16), about ")


def test_a_run_beyond_the_work_limit_is_refused_with_its_plies(monkeypatch):
    monkeypatch.setenv("DRAPE_MAX_NODE_STEPS", "5e4")
    case = load_case("hemisphere", cell_mm=40.0)  # 16 nodes × 80 steps: 1280 node-steps
    stack = dataclasses.replace(case, plies=tuple(PlySpec(0.0, 0.3) for _ in range(40)))
    with pytest.raises(Exception, match=r"the run would take 80 load steps on 640 nodes \(40 "
                                        r"plies of 16\), 5\.12e\+04 node-steps, about .*: more "
                                        r"than the limit of 5e\+04 node-steps \(set by "
                                        r"DRAPE_MAX_NODE_STEPS\); give a larger cell_mm or "
                                        r"step_mm, fewer plies"):
        run_case(stack)


# --------------------------------------------------------------------------------------------
# 3. Tables: their size before they are read; quotes read, other separators refused


def test_a_table_beyond_the_row_limit_is_refused_before_it_is_read(tmp_path, monkeypatch):
    (tmp_path / "bundle.toml").write_text(TOML)
    for name, text in (("tensile.csv", tensile_csv()), ("bias_10.csv", bias_csv()),
                       ("grid.csv", grid_csv())):
        (tmp_path / name).write_text(text)
    rows = 100_000
    t = np.arange(rows, dtype=float)
    (tmp_path / "tensile.csv").write_text("time_s,displacement_mm,force_N\n" + "".join(
        f"{v:g},{v * 1e-3:g},{v * 1e-2:g}\n" for v in t))
    monkeypatch.setenv("DRAPE_MAX_TABLE_ROWS", "1000")
    with pytest.raises(BundleError):
        load_bundle(tmp_path)  # once: what it imports is not the table
    tracemalloc.start()
    with pytest.raises(BundleError, match=r"tensile\.csv: test 'tensile-warp': the table is "
                                          r"1\.9\d MB, more than a table of 1e\+03 lines can "
                                          r"be .*DRAPE_MAX_TABLE_ROWS\): not read"):
        load_bundle(tmp_path)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 4e6  # the 1.9 MB file was never held (a block of 1 MB at most)
    # Within the bytes a line may take but past the lines: counted, not read.
    monkeypatch.setenv("DRAPE_MAX_TABLE_ROWS", "20000")
    with pytest.raises(BundleError, match=r"tensile\.csv: test 'tensile-warp': the table has "
                                          r"more than 2e\+04 lines"):
        load_bundle(tmp_path)


def test_quoted_cells_are_read_and_semicolons_refused_by_name(tmp_path):
    (tmp_path / "bundle.toml").write_text(TOML)
    for name, text in (("bias_10.csv", bias_csv()), ("grid.csv", grid_csv())):
        (tmp_path / name).write_text(text)
    plain = tensile_csv()
    lines = plain.splitlines()
    quoted = [lines[0], ",".join(f'"{c}"' for c in lines[1].split(","))] + [
        ",".join(f'"{c}"' for c in line.split(",")) for line in lines[2:]]
    (tmp_path / "tensile.csv").write_text("\n".join(quoted) + "\n")
    test = load_bundle(tmp_path).test("tensile-warp")
    assert test.n_rows == 10 and test.force_N[-1] == 900.0
    (tmp_path / "tensile.csv").write_text(plain.replace(",", ";"))
    with pytest.raises(BundleError) as err:
        load_bundle(tmp_path)
    assert err.value.problems == [
        f"{tmp_path / 'tensile.csv'}:2: test 'tensile-warp': the table's columns are separated "
        "by semicolons ('time_s;displacement_mm;force_N'); a table's columns are separated by "
        "commas, numbers written with a decimal point (1.5, not 1,5)"]
    # A row of another separator under a comma header: the hint names it.
    (tmp_path / "tensile.csv").write_text(plain.replace("4,", "4;", 1))
    with pytest.raises(BundleError, match=r"2 cells, but the header has 3 columns \(separated "
                                          r"by semicolons\?"):
        load_bundle(tmp_path)


# --------------------------------------------------------------------------------------------
# 4. Messages: a misspelt key, a misnamed column, a missing file


def test_a_misspelt_key_is_named_as_a_likely_typo(tmp_path, capsys):
    assert likely_typo("shear_noise_deg", ["shear_sd_deg", "position_sd_mm"]) == "shear_sd_deg"
    assert likely_typo("temperature_C", ["shear_sd_deg", "holder_force_N"]) is None
    folder = write_lab_bundle(tmp_path / "b", 'punch_force = "force.csv"\nshear_noise_deg = 2.0\n',
                              {"force.csv": FORCE})
    with trusting():
        bundle = load_bundle(folder, read_case=case_for_test)
    # Kept as a condition, as the spec says unknown keys are, and the note names the key meant.
    assert bundle.tests[0].conditions["shear_noise_deg"] == 2.0
    assert any("key 'shear_noise_deg' kept as a test condition -- did you mean `shear_sd_deg`?"
               in note for note in bundle.unknown_keys)
    # In a case file an unknown key is an error; the likely one is named.
    path = write_case(tmp_path)
    path.write_text(path.read_text().replace("duration_s = 10.0", "duraton_s = 10.0"))
    with pytest.raises(InputFileError, match=r"\[case\]: unknown key 'duraton_s' \(did you mean "
                                             r"`duration_s`\?\)"):
        load_case(path)


def test_a_misnamed_column_names_the_missing_one(tmp_path):
    (tmp_path / "bundle.toml").write_text(TOML)
    for name, text in (("bias_10.csv", bias_csv()), ("grid.csv", grid_csv())):
        (tmp_path / name).write_text(text)
    (tmp_path / "tensile.csv").write_text(tensile_csv().replace("force_N", "forceN"))
    with pytest.raises(BundleError, match=r"missing column\(s\) force_N \(a tensile table needs "
                                          r"time_s, displacement_mm, force_N; its header: time_s,"
                                          r" displacement_mm, forceN\); 'forceN': did you mean "
                                          r"`force_N`\?"):
        load_bundle(tmp_path)
    folder = write_lab_bundle(tmp_path / "b", 'outline = "edge.csv"\n',
                              {"edge.csv": "x_mm,y_m,label\n140,0,mid\n0,95,side\n"})
    with trusting(), pytest.raises(BundleError) as err:
        load_bundle(folder, read_case=case_for_test)
    assert ("test 'dd': an outline table needs the columns x_mm, y_mm: missing y_mm (its header: "
            "x_mm, y_m, label)") in str(err.value)


# --------------------------------------------------------------------------------------------
# 5. A geometry script's process group ends with the command


def _gone(pid: int) -> bool:
    """Whether a process has ended (no such process, or a zombie nobody reaped yet)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return True
    return state in ("Z", "X")


@pytest.mark.skip_in_parallel
def test_a_script_that_never_ends_leaves_nothing_when_its_command_is_killed(tmp_path):
    marker = tmp_path / "marker"
    (tmp_path / "hang.py").write_text(
        "import os, subprocess, pathlib\n\ndef build(gmsh):\n"
        "    child = subprocess.Popen(['sleep', '300'])\n"
        f"    pathlib.Path({str(marker)!r}).write_text(\n"
        "        f\"{os.getpid()} {child.pid} {os.environ['TMPDIR']}\")\n"
        "    while True:\n        pass\n")
    env = {**os.environ, "DRAPE_SCRIPT_TIMEOUT_S": "600", "PYTHONPATH": str(ROOT)}
    command = subprocess.Popen(
        [sys.executable, "-c", "import sys; from fenicsx_drape.forming.tools.surfaces import "
         "load_surface; load_surface(sys.argv[1], comm=None)", str(tmp_path / "hang.py")],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(600):
        if marker.exists() and len(marker.read_text().split()) == 3:
            break
        time.sleep(0.1)
    script, grandchild, folder = marker.read_text().split()
    assert Path(folder).is_dir() and not _gone(int(script)) and not _gone(int(grandchild))
    command.send_signal(signal.SIGKILL)
    command.wait()
    for _ in range(100):
        if _gone(int(script)) and _gone(int(grandchild)) and not Path(folder).exists():
            break
        time.sleep(0.1)
    assert _gone(int(script)) and _gone(int(grandchild))
    assert not Path(folder).exists()


# --------------------------------------------------------------------------------------------
# 6. Degenerate triangles are ignored, as the mesh check says


def test_a_triangle_of_no_area_on_an_inner_edge_is_ignored():
    square = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0], [5, 5, 0]], dtype=float)
    # Two triangles share the diagonal 0-2; a third, of no area, lies on it (corner 4 at its
    # middle): three triangles on one edge would be a non-manifold surface.
    triangles = np.array([[0, 1, 2], [0, 2, 3], [0, 4, 2]])
    errors, warns = mesh_defects(square, triangles)
    assert errors == [] and warns[0].startswith("1 degenerate triangle(s) (no area)")
    assert warns[0].endswith(": ignored")
    surface = TriangleSurface(square, triangles)
    assert len(surface.triangles) == 2 and len(surface.points) == 4
    assert np.isclose(surface.face_normals[:, 2], 1.0).all()


# --------------------------------------------------------------------------------------------
# 7. The battery script runs and classes its rows


def test_the_battery_script_classes_its_rows(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("hostile_battery",
                                                  ROOT / "benchmarks" / "hostile_battery.py")
    battery = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = battery  # its dataclass looks its module up
    spec.loader.exec_module(battery)
    rows = {r.name: r for r in battery.rows()}
    assert len(rows) == len(battery.rows()) >= 50  # names unique
    assert {r.expect for r in rows.values()} <= {"refused", "warned", "accepted", "interrupted"}
    got, line, _ = battery.run_row(rows["misspelt-case-key"], tmp_path / "a")
    assert got == "refused" and "did you mean `duration_s`?" in line
    # A row whose message is not the one expected is not counted as refused.
    wrong = dataclasses.replace(rows["negative-duration"], fragment="something else")
    assert battery.run_row(wrong, tmp_path / "b")[0] == "refused (other message)"
