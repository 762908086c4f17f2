"""Untrusted input: data runs no code, sizes before memory, plausible numbers,
nothing silently dropped, the launcher mounts what a case names.

Every input here is written for the test: a small case with a Python punch, a Gmsh holder, a
bundle that names the case, hostile scripts that would leave a marker file if they ran.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

import fenicsx_drape.forming  # noqa: F401  (registers the bundle's case reader)
from fenicsx_drape.cli import load_bundle_reported, main
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case.format import (
    CaseError,
    build_tools,
    case_for_test,
    check_tool_sizes,
    coarse_mesh_problem,
    load_case,
)
from fenicsx_drape.forming.running.run import case_model
from fenicsx_drape.forming.tools.surfaces import load_surface
from fenicsx_drape.measurements.bundle import BundleError, load_bundle
from fenicsx_drape.measurements.plausible import (
    Reach,
    far_problems,
    finite_problems,
    grid_problems,
)
from fenicsx_drape.model import load_model
from fenicsx_drape.provenance import json_text, write_json
from fenicsx_drape.trust import UntrustedCodeError, geo_problems, trusting

ROOT = Path(__file__).resolve().parents[1]

PUNCH_PY = """\
from pathlib import Path
Path(__file__).with_name("punch_ran").write_text("the punch's code ran")

def build(gmsh, radius_mm):
    gmsh.model.occ.addSphere(0.0, 0.0, -radius_mm, radius_mm)
    gmsh.model.occ.synchronize()
"""

HOLDER_GEO = """\
// a flat plate under the blank's rim; "SystemCall" in a comment is harmless
DefineConstant[ side_mm = 120.0 ];
SetFactory("OpenCASCADE");
Rectangle(1) = {-side_mm / 2, -side_mm / 2, 0, side_mm, side_mm};
Printf("a message, not a file");
"""

CASE = """\
[case]
name = "untrusted"
duration_s = 10.0
{model}
[blank]
outline = "rectangle"
size_mm = [100.0, 100.0]
cell_mm = {cell_mm}

[holder]
tool = "holder"
holder_force_N = 10.0

[[tool]]
name = "punch"
role = "punch"
geometry = "{punch}"
parameters = {{ radius_mm = 20.0 }}
mesh_mm = {mesh_mm}
[tool.motion]
time_s = [0.0, 10.0]
z_mm = [0.0, 20.0]

[[tool]]
name = "holder"
role = "holder"
geometry = "../geom/holder.geo"
parameters = {{ {holder_key} = 120.0 }}
mesh_mm = 40.0
"""


def write_case(folder: Path, *, cell_mm=10.0, mesh_mm=10.0, model="", punch="punch.py",
               holder_key="side_mm", holder=HOLDER_GEO, name="case.toml") -> Path:
    """A case in ``folder/case`` whose holder is in the sibling folder ``folder/geom``."""
    (folder / "case").mkdir(parents=True, exist_ok=True)
    (folder / "geom").mkdir(exist_ok=True)
    (folder / "case" / "punch.py").write_text(PUNCH_PY)
    (folder / "geom" / "holder.geo").write_text(holder)
    path = folder / "case" / name
    path.write_text(CASE.format(cell_mm=cell_mm, mesh_mm=mesh_mm, model=model, punch=punch,
                                holder_key=holder_key))
    return path


def flat_grid(n=4, grid_mm=10.0, angle_deg=0.0, z=None):
    """Rows of a drawn grid on the flat blank, turned by ``angle_deg``."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    rows = []
    for i in range(n):
        for j in range(n):
            x0, y0 = grid_mm * (c * i - s * j), grid_mm * (s * i + c * j)
            rows.append([i, j, x0, y0, x0, y0, 0.0 if z is None else z(i, j)])
    return rows


def write_bundle(folder: Path, rows, *, test_keys: str, csv_name="grid.csv") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    lines = ["i,j,x0_mm,y0_mm,x_mm,y_mm,z_mm"] + [",".join(f"{v:g}" for v in r) for r in rows]
    (folder / csv_name).write_text("\n".join(lines) + "\n")
    (folder / "bundle.toml").write_text(
        f'[bundle]\nname = "colleague"\n\n[[test]]\nid = "t"\nkind = "forming"\n'
        f'file = "{csv_name}"\n{test_keys}\n')
    return folder


HEMISPHERE_KEYS = """geometry = "hemisphere"
punch_radius_mm = 60.0
fillet_radius_mm = 20.0
holder_opening_mm = 170.0
sheet_mm = 240.0
travel_mm = 80.0
duration_s = 40.0
holder_force_N = 133.0
grid_mm = 10.0"""


# --------------------------------------------------------------------------------------------
# 1. Code runs only when the user says so


@pytest.fixture
def surfaces_only(monkeypatch):
    """Tools as their bare surfaces (no distance field: seconds saved, nothing else tested)."""
    monkeypatch.setattr("fenicsx_drape.forming.tools.shapes.MeshedTool",
                        lambda name, surface, motion: surface)


def test_a_bundles_python_geometry_runs_only_with_trust(tmp_path, surfaces_only):
    write_case(tmp_path)
    write_bundle(tmp_path, flat_grid(), test_keys='case = "case/case.toml"\ngrid_mm = 10.0')
    with pytest.raises(BundleError, match=r"bundle\.toml:8: test 't': case 'case/case.toml': "
                                          r".*case\.toml: \[\[tool\]\] 1 'geometry': 'punch\.py' "
                                          r"is Python code .* --trust"):
        load_bundle(tmp_path, read_case=case_for_test)
    with trusting():
        case = load_bundle(tmp_path, read_case=case_for_test).tests[0].forming_case
    with pytest.raises(UntrustedCodeError, match=r"punch\.py: the Python geometry of tool "
                                                 r"'punch' .* --trust"):
        build_tools(case)
    assert not (tmp_path / "case" / "punch_ran").exists()
    with trusting():
        tools = build_tools(case)
    assert (tmp_path / "case" / "punch_ran").exists()
    assert set(tools) == {"punch", "holder"}
    # Nothing written into the input folders (no __pycache__, no Gmsh side files).
    assert sorted(p.name for p in (tmp_path / "case").iterdir()) == [
        "case.toml", "punch.py", "punch_ran"]
    assert sorted(p.name for p in (tmp_path / "geom").iterdir()) == ["holder.geo"]


def test_a_case_the_user_names_runs_its_own_python_geometry(tmp_path, surfaces_only):
    tools = build_tools(load_case(write_case(tmp_path)))
    assert len(tools["punch"].triangles) > 0
    assert (tmp_path / "case" / "punch_ran").exists()


def test_the_plugins_of_a_bundles_model_run_only_with_trust(tmp_path):
    (tmp_path / "case").mkdir()
    (tmp_path / "case" / "plugin.py").write_text(
        "from pathlib import Path\nPath(__file__).with_name('plugin_ran').write_text('ran')\n")
    (tmp_path / "case" / "MODEL.toml").write_text('plugins = ["plugin.py"]\n')
    write_case(tmp_path, model='model = "MODEL.toml"')
    write_bundle(tmp_path, flat_grid(), test_keys='case = "case/case.toml"')
    with pytest.raises(BundleError, match=r"\[case\] 'model': MODEL\.toml has plugins "
                                          r"\['plugin\.py'\] \(Python code\)"):
        load_bundle(tmp_path, read_case=case_for_test)
    with trusting():
        case = load_bundle(tmp_path, read_case=case_for_test).tests[0].forming_case
    with pytest.raises(UntrustedCodeError, match=r"plugin\.py: a plugin of the model .*"
                                                 r"MODEL\.toml that comes with the case"):
        case_model(case)
    assert not (tmp_path / "case" / "plugin_ran").exists()
    load_model(tmp_path / "case" / "MODEL.toml")  # the user names it: it runs
    assert (tmp_path / "case" / "plugin_ran").exists()
    assert not (tmp_path / "case" / "__pycache__").exists()


@pytest.mark.parametrize("line, command", [
    ('SystemCall "touch {marker}";', "SystemCall"),
    ('NonBlockingSystemCall Sprintf("touch %s", "{marker}");', "NonBlockingSystemCall"),
    ('OnelabRun("x", "touch {marker}");', "OnelabRun"),
    ('Save "{marker}";', "Save"),
    ('Printf("x") > "{marker}";', "Printf"),
    ('Merge "evil.py";', "Merge"),
])
def test_a_geo_that_reaches_the_shell_or_writes_files_is_refused_in_every_case(
        tmp_path, line, command):
    marker = tmp_path / "marker"
    hostile = HOLDER_GEO + line.format(marker=marker) + "\n"
    path = write_case(tmp_path, holder=hostile)
    with pytest.raises(CaseError, match=rf"\[\[tool\]\] 2 'geometry': .*holder\.geo:6: .*"
                                        rf"{command}.*--trust"):
        load_case(path)
    with pytest.raises(UntrustedCodeError, match=r"holder\.geo:6"):
        load_surface(tmp_path / "geom" / "holder.geo", comm=None)
    assert not marker.exists()


def test_geo_checks_read_includes_and_skip_comments_and_strings(tmp_path):
    (tmp_path / "inner.geo").write_text('Point(1) = {0, 0, 0};\nCreateDir "x";\n')
    (tmp_path / "outer.geo").write_text(
        '// SystemCall "rm -rf /" in a comment\n/* Save "x"\n */ Printf("Save SystemCall");\n'
        'Include "inner.geo";\nMerge StrCat("a", ".py");\n')
    problems = geo_problems(tmp_path / "outer.geo")
    assert len(problems) == 2
    assert "inner.geo:2: the command 'CreateDir'" in problems[0]
    assert "outer.geo:5: Merge of a computed file name" in problems[1]
    assert geo_problems(tmp_path / "inner.geo") != []
    assert geo_problems(ROOT / "meshes" / "hemisphere" / "punch.geo") == []


def test_trust_is_one_option_of_every_command(tmp_path, capsys):
    write_case(tmp_path)
    write_bundle(tmp_path, flat_grid(), test_keys='case = "case/case.toml"\ngrid_mm = 10.0')
    assert main(["compare", str(tmp_path), "--out", str(tmp_path / "out"),
                 "--forming-cell-mm", "50"]) == 2
    assert "'punch.py' is Python code that would run" in capsys.readouterr().err
    for command in ("compare", "diagnose", "fit", "form", "drape", "curves", "mesh",
                    "history"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        assert "--trust" in capsys.readouterr().out


# --------------------------------------------------------------------------------------------
# 2. Sizes before memory


def test_a_net_beyond_the_memory_is_refused_with_the_estimate_and_the_limit(tmp_path,
                                                                            monkeypatch):
    monkeypatch.setenv("DRAPE_MEMORY_GB", "8")
    with pytest.raises(CaseError, match=r"about 1e\+10 nodes, more than the limit of "
                                        r"2e\+05 \(8 GB of memory \(DRAPE_MEMORY_GB\)"):
        load_case(write_case(tmp_path, cell_mm=1e-3))
    # 100 mm at 10 mm: 11 × 11 = 121 nodes; the limit set directly.
    monkeypatch.setenv("DRAPE_MAX_NODES", "120")
    with pytest.raises(CaseError, match=r"about 121 nodes, more than the limit of 120 "
                                        r"\(DRAPE_MAX_NODES\)"):
        load_case(write_case(tmp_path))
    monkeypatch.setenv("DRAPE_MAX_NODES", "121")
    load_case(write_case(tmp_path))


def test_a_tool_mesh_beyond_the_memory_is_refused_before_gmsh_runs(tmp_path, monkeypatch):
    monkeypatch.setenv("DRAPE_MEMORY_GB", "8")
    # (100 + 2·20)² mm² over equilateral triangles of 1e-6 mm: 4/√3 · 140² / 1e-12.
    expected = 4 / math.sqrt(3) * 140.0**2 / 1e-12
    n = re.escape(f"{expected:.3g}")
    with pytest.raises(CaseError, match=rf"punch {n}.*about {n} triangles, more than the "
                                        r"limit of 1.6e\+06"):
        load_case(write_case(tmp_path, mesh_mm=1e-6))
    assert not (tmp_path / "case" / "punch_ran").exists()


def test_a_tool_mesh_far_finer_than_the_sheet_warns_with_the_numbers(tmp_path):
    case = load_case(write_case(tmp_path, mesh_mm=0.25))
    with pytest.warns(UserWarning, match=r"tool 'punch': mesh_mm = 0\.25 is 40 times finer "
                                         r"than the sheet's cell 10 mm"):
        check_tool_sizes(case)


def dome_stl(path: Path, radius_mm: float, rings: int, segments: int) -> Path:
    """A faceted hemispherical dome (ASCII STL): ``rings`` bands of latitude, ``segments``."""
    φ = np.linspace(0.0, np.pi / 2, rings + 1)
    λ = np.linspace(0.0, 2 * np.pi, segments + 1)

    def point(a, b):
        return radius_mm * np.array([np.sin(a) * np.cos(b), np.sin(a) * np.sin(b), np.cos(a)])

    facets = []
    for k in range(rings):
        for m in range(segments):
            a, b, c, d = (point(φ[k], λ[m]), point(φ[k + 1], λ[m]), point(φ[k + 1], λ[m + 1]),
                          point(φ[k], λ[m + 1]))
            facets += [(a, b, c)] + ([(a, c, d)] if k else [])
    text = ["solid dome"] + [
        "facet normal 0 0 0\n outer loop\n" + "".join(f"  vertex {x} {y} {z}\n"
                                                     for x, y, z in f) + " endloop\nendfacet"
        for f in facets] + ["endsolid dome"]
    path.write_text("\n".join(text) + "\n")
    return path


def test_a_tool_mesh_coarse_for_its_curvature_warns_with_the_numbers(tmp_path):
    # Bands of 30° on R = 60 mm: edges of 31 mm bending by about 30°, triangles whose middle
    # sits 31² / (6 · 60) ≈ 2.7 mm under the sphere; on 10 mm cells that is too coarse.
    coarse = load_surface(dome_stl(tmp_path / "coarse.stl", 60.0, 3, 12), comm=None)
    message = coarse_mesh_problem(coarse, 10.0)
    assert message is not None and "more than 0.1 of the sheet's cell 10 mm" in message
    sag = float(message.split("by up to about ")[1].split(" mm")[0])
    assert 2.0 < sag < 3.5
    # Bands of 3°: edges of 3.1 mm, sag ≈ 0.03 mm.
    fine = load_surface(dome_stl(tmp_path / "fine.stl", 60.0, 30, 120), comm=None)
    assert coarse_mesh_problem(fine, 10.0) is None


def test_a_geometry_script_that_never_returns_is_stopped(tmp_path, monkeypatch):
    monkeypatch.setenv("DRAPE_SCRIPT_TIMEOUT_S", "3")
    path = tmp_path / "forever.py"
    path.write_text("def build(gmsh):\n    while True:\n        pass\n")
    with pytest.raises(DrapeInputError, match=r"forever\.py: the geometry script did not "
                                              r"finish in 3 s"):
        load_surface(path, comm=None)


def test_a_geometry_script_beyond_the_memory_ends_in_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv("DRAPE_MEMORY_GB", "2")
    path = tmp_path / "greedy.py"
    path.write_text("def build(gmsh):\n    x = bytearray(8 * 10**9)\n")
    with pytest.raises(DrapeInputError, match=r"greedy\.py: (out of the memory limit of 2 GB|"
                                              r"the geometry script ended without)"):
        load_surface(path, comm=None)


# --------------------------------------------------------------------------------------------
# 3. Every number plausible


def test_finite_and_far_checks_name_the_first_row_and_count_the_others():
    lines = [3, 4, 5, 6]
    columns = {"x_mm": np.array([1.0, np.nan, 2.0, np.inf]), "y_mm": np.zeros(4)}
    assert finite_problems(columns, lines) == [
        (4, "column x_mm: nan is not a finite number (2 such rows)")]
    reach = Reach((-50.0, -50.0, 0.0), (50.0, 50.0, 20.0), 100.0)
    p = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 119.0], [0.0, 0.0, 121.0], [1e300, 0, 0]])
    assert reach.distance(p)[:3].tolist() == [0.0, 99.0, 101.0]
    (line, text), = far_problems(p, lines, reach)
    assert line == 5 and "101 mm from where the tools reach" in text and "(2 such rows)" in text


def test_grid_indices_spacing_and_mirroring_are_checked():
    rows = np.array(flat_grid(n=5, grid_mm=12.0, angle_deg=30.0))
    lines = list(range(2, 2 + len(rows)))
    i, j, x0, y0 = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]
    assert grid_problems(i, j, x0, y0, lines, grid_mm=12.0) == []
    (line, text), = grid_problems(i, j, x0, y0, lines, grid_mm=10.0)
    assert line is None and "grid_mm = 10 disagrees" in text and "12 mm" in text
    wrong = i.copy()
    wrong[7] += 2  # one node's index does not match its position
    (line, text), = grid_problems(wrong, j, x0, y0, lines, grid_mm=12.0)
    assert line == lines[7] and "do not match its position" in text
    (line, text), = grid_problems(j, i, x0, y0, lines)  # i and j swapped
    assert "mirrored" in text


def test_a_position_no_measurement_gives_is_refused_with_file_and_line(tmp_path):
    rows = flat_grid(z=lambda i, j: 1e6 if (i, j) == (2, 1) else 0.0)
    write_bundle(tmp_path, rows, test_keys=HEMISPHERE_KEYS)
    with pytest.raises(BundleError, match=r"grid\.csv:11: test 't': formed position .*1e\+06"
                                          r".* farther than the blank's size 339\.4 mm"):
        load_bundle(tmp_path, read_case=case_for_test)
    assert main(["compare", str(tmp_path), "--out", str(tmp_path / "out")]) == 2


def test_a_grid_mm_that_disagrees_names_the_key_in_bundle_toml(tmp_path):
    write_bundle(tmp_path, flat_grid(grid_mm=20.0), test_keys=HEMISPHERE_KEYS)
    with pytest.raises(BundleError, match=r"bundle\.toml:16: test 't': grid_mm = 10 disagrees "
                                          r"with the flat positions .* 20 mm"):
        load_bundle(tmp_path, read_case=case_for_test)


def test_a_grid_without_noise_asks_for_position_sd_instead_of_dividing_by_zero(tmp_path):
    from fenicsx_drape.diagnosis.kinds import grid

    write_bundle(tmp_path, flat_grid(n=6, z=lambda i, j: 0.5 * i * j), test_keys=HEMISPHERE_KEYS)
    (test,) = load_bundle(tmp_path, read_case=case_for_test).tests
    with pytest.raises(DrapeInputError, match=r"test 't': the grid's positions show no noise"
                                              r".*give position_sd_mm"):
        grid.noise(test)


def test_every_json_written_is_valid_json(tmp_path):
    report = {"rmse": float("nan"), "per_test": {"a": np.inf, "b": np.float64(-np.inf)},
              "values": np.array([1.0, np.nan]), "n": np.int64(3), "ok": 1.5}
    path = write_json(tmp_path / "REPORT.json", report)

    def no_constants(name):
        raise AssertionError(f"{name} is not JSON")

    back = json.loads(path.read_text(), parse_constant=no_constants)
    assert back == {"rmse": None, "per_test": {"a": None, "b": None}, "values": [1.0, None],
                    "n": 3, "ok": 1.5}
    assert json_text([math.nan], indent=None) == "[null]"


@pytest.mark.parametrize("value", ["-10", "0", "nan", "inf"])
def test_a_grid_spacing_that_is_not_positive_is_refused_up_front(tmp_path, value, capsys):
    for command in ("form", "drape"):
        with pytest.raises(SystemExit) as exit_:
            main([command, "hemisphere", "--out", str(tmp_path / "o"), "--grid-mm", value])
        assert exit_.value.code == 2
        assert f"--grid-mm: {value!r} is not a positive number" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------------------------
# 4. Nothing silently dropped


def test_a_misspelt_bundle_key_is_reported_by_the_commands(tmp_path, capsys):
    write_bundle(tmp_path, flat_grid(), test_keys=HEMISPHERE_KEYS + "\nholder_force_n = 150.0")
    bundle = load_bundle_reported(tmp_path)
    assert bundle.tests[0].conditions["holder_force_n"] == 150.0
    assert "bundle.toml:17: test 't': key 'holder_force_n' kept as a test condition" in \
        capsys.readouterr().err


def test_a_geometry_parameter_the_script_does_not_use_is_an_error(tmp_path):
    with pytest.raises(CaseError, match=r"\[\[tool\]\] 2 'parameters' 'side_m': not used by "
                                        r"holder\.geo"):
        load_case(write_case(tmp_path, holder_key="side_m"))
    with pytest.raises(DrapeInputError, match=r"holder\.geo: parameter\(s\) 'side_m' not used"):
        load_surface(tmp_path / "geom" / "holder.geo", {"side_m": 1.0}, comm=None)


# --------------------------------------------------------------------------------------------
# 5. The launcher mounts what a case or bundle names


def test_the_launcher_lists_the_files_a_bundle_its_case_and_its_model_name(tmp_path):
    (tmp_path / "case").mkdir()
    (tmp_path / "case" / "MODEL.toml").write_text('plugins = ["/abs/laws.py"]\n')
    write_case(tmp_path, model='model = "MODEL.toml"')
    (tmp_path / "geom" / "holder.geo").write_text(HOLDER_GEO + 'Include "../inc/part.geo";\n')
    write_bundle(tmp_path / "b", flat_grid(), test_keys='case = "../case/case.toml"')
    script = (ROOT / "drape").read_text()
    function = script[script.index("named_paths() {"):script.index("\n}\n", script.index(
        "named_paths() {")) + 3]
    out = subprocess.run(["bash", "-c", function + '\nnamed_paths "$@"', "drape",
                          "--out=x", str(tmp_path / "b")], capture_output=True, text=True,
                         check=True).stdout.split()
    named = {Path(p).resolve() if not p.startswith("/abs") else Path(p) for p in out}
    assert named >= {tmp_path / "b" / "grid.csv", tmp_path / "case" / "case.toml",
                     tmp_path / "case" / "punch.py", tmp_path / "geom" / "holder.geo",
                     tmp_path / "case" / "MODEL.toml", Path("/abs/laws.py"),
                     tmp_path / "inc" / "part.geo"}
    assert "TMPDIR=\"$state/tmp\"" in script  # temporary files land where the host sees them

