"""Forming measurements as labs take them (spec version 3): reading and checking a bundle.

Shear points, a scan (STL through meshio, or a CSV point cloud), an outline and a force curve
of one forming test on the double dome's case; the measuring frame; and every kind of bad
input refused with the file and line (exit status 2) before anything is computed.
"""

import math
from pathlib import Path

import meshio
import numpy as np
import pytest

import fenicsx_drape.forming  # noqa: F401  (registers the case reader)
from fenicsx_drape.cli import main
from fenicsx_drape.forming.case.format import case_for_test
from fenicsx_drape.measurements.bundle import BundleError, load_bundle
from fenicsx_drape.measurements.lab import Frame, rotation
from fenicsx_drape.trust import trusting

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "meshes" / "double_dome" / "case.toml"
SHEAR = "# read with a protractor\nx_mm,y_mm,z_mm,shear_deg,line,s_mm\n" + "".join(
    f"{10.0 * k},0.0,{20.0 + k},{2.0 * k},A,{10.0 * k}\n" for k in range(6))
FLAT_SHEAR = "x0_mm,y0_mm,shear_deg,shear_sd_deg\n0,0,0,1\n10,10,5,1\n20,20,9,1.5\n"
EDGE = "x_mm,y_mm,label,draw_in_mm\n140,0,mid,9.5\n0,95,side,4.0\n130,90,corner,12.0\n"
FORCE = "travel_mm,force_N,time_s\n0,0,0\n10,5,10\n20,12,20\n30,25,30\n40,43,40\n"


@pytest.fixture(autouse=True, scope="module")
def _trust_our_own_case():
    """The bundles here name the repository's double dome, whose tools are Python geometry."""
    with trusting():
        yield


def write(folder: Path, keys: str, files: dict[str, str] | None = None, frame: str = "") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in (files or {}).items():
        (folder / name).write_text(text)
    (folder / "bundle.toml").write_text(
        f'[bundle]\nname = "lab"\n\n[[test]]\nid = "dd"\nkind = "forming"\ncase = "{CASE}"\n'
        f"{keys}{frame}")
    return folder


def stl(path: Path, points: np.ndarray) -> None:
    """A scan as an STL surface: the points in a strip of triangles."""
    tri = np.array([[k, k + 1, k + 2] for k in range(len(points) - 2)])
    meshio.write(path, meshio.Mesh(points, [("triangle", tri)]), binary=True)


def test_every_measurement_of_one_test_is_read_and_split_by_measurement(tmp_path):
    P = np.array([[0.0, 0.0, 40.0], [10.0, 0.0, 39.0], [0.0, 10.0, 39.5], [10.0, 10.0, 38.0]])
    folder = write(tmp_path / "b", 'shear_points = "shear.csv"\nsurface = "scan.stl"\n'
                   'outline = "edge.csv"\npunch_force = "force.csv"\nshear_sd_deg = 1.5\n'
                   'position_sd_mm = 0.2\nforce_sd_N = 0.8\nholder_force_N = 250.0\n',
                   {"shear.csv": SHEAR, "edge.csv": EDGE, "force.csv": FORCE})
    stl(folder / "scan.stl", P)
    bundle = load_bundle(folder, read_case=case_for_test)
    ids = [t.id for t in bundle.tests]
    assert ids == ["dd/shear_points", "dd/surface", "dd/outline", "dd/punch_force"]
    shear, scan, edge, force = bundle.tests
    assert shear.lab.line_names == ("A",) * 6 and shear.lab.sd == 1.5
    assert list(shear.lab.lines) == [3, 4, 5, 6, 7, 8]  # file lines, after comment and header
    assert np.allclose(shear.columns["s_mm"], 10.0 * np.arange(6))
    assert np.allclose(np.column_stack([scan.columns[c] for c in ("x_mm", "y_mm", "z_mm")]), P)
    assert edge.lab.labels == ("mid", "side", "corner")
    assert force.lab.force_tool == "punch" and force.lab.sd == 0.8
    # The test's process keys still reach its case, for every measurement.
    assert all(t.forming_case.holder.force_N == 250.0 for t in bundle.tests)


def test_a_csv_point_cloud_and_flat_shear_points(tmp_path):
    cloud = "x_mm,y_mm,z_mm\n" + "".join(f"{k},{-k},{0.5 * k}\n" for k in range(10))
    folder = write(tmp_path / "b", 'surface = "scan.csv"\nshear_points = "flat.csv"\n'
                   "shear_magnitude = true\n", {"scan.csv": cloud, "flat.csv": FLAT_SHEAR})
    shear, scan = load_bundle(folder, read_case=case_for_test).tests
    assert shear.lab.flat and shear.lab.shear_magnitude and scan.n_rows == 10


def test_a_given_frame_moves_the_measured_positions_into_the_case_frame(tmp_path):
    frame = ('[test.frame]\ntranslation_mm = [5.0, -3.0, 2.0]\n'
             'rotation_deg = [0.0, 0.0, 90.0]\n')
    folder = write(tmp_path / "b", 'shear_points = "shear.csv"\n', {"shear.csv": SHEAR}, frame)
    (shear,) = load_bundle(folder, read_case=case_for_test).tests
    # (10 k, 0, 20 + k) turned 90° about z is (0, 10 k, 20 + k); then shifted.
    k = np.arange(6)
    assert np.allclose(shear.columns["x_mm"], 5.0)
    assert np.allclose(shear.columns["y_mm"], 10.0 * k - 3.0)
    assert np.allclose(shear.columns["z_mm"], 22.0 + k)
    R = rotation([10.0, 20.0, 30.0])  # about x, then y, then z
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    assert np.allclose(R @ np.array([0.0, 0.0, 0.0]), 0.0)
    assert np.allclose(rotation([0.0, 0.0, 30.0]), [[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert np.allclose(R.T @ R, np.eye(3))
    assert np.allclose(Frame((1.0, 2.0, 3.0)).apply(np.zeros((1, 3))), [[1.0, 2.0, 3.0]])


def test_a_grid_with_lab_measurements_is_its_own_test_and_v2_bundles_are_unchanged(tmp_path):
    grid = "i,j,x0_mm,y0_mm,x_mm,y_mm,z_mm\n0,0,0,0,0,0,40\n1,0,10,0,10,0,39\n"
    folder = write(tmp_path / "b", 'file = "grid.csv"\npunch_force = "force.csv"\n',
                   {"grid.csv": grid, "force.csv": FORCE})
    ids = [t.id for t in load_bundle(folder, read_case=case_for_test).tests]
    assert ids == ["dd/file", "dd/punch_force"]
    folder = write(tmp_path / "c", 'file = "grid.csv"\n', {"grid.csv": grid})
    (test,) = load_bundle(folder, read_case=case_for_test).tests
    assert test.id == "dd" and test.lab is None


BAD = [
    # (keys, files, line, fragments)
    ("", {}, 4, ["needs file", "shear_points, surface, outline, punch_force"]),
    ('shear_points = "force.csv"\n', {"force.csv": FORCE}, 1,
     ["force.csv:1:", "needs the columns x_mm, y_mm, z_mm, shear_deg", "missing x0_mm",
      "its columns are those of a punch_force table"]),
    ('surface = "scan.vtk"\n', {"scan.vtk": "x"}, 8, ["bundle.toml:8:", "surface = 'scan.vtk'",
                                                   "must be a .csv, .stl"]),
    ('shear_points = "shear.csv"\n', {"shear.csv": SHEAR.replace("4.0,A", "nan,A")}, 5,
     ["shear.csv:5:", "shear_deg", "not a finite number"]),
    ('shear_points = "shear.csv"\n', {"shear.csv": SHEAR.replace("6.0,A", "95.0,A")}, 6,
     ["shear.csv:6:", "beyond ±90°"]),
    ('outline = "edge.csv"\n', {"edge.csv": EDGE.replace("0,95,", "0,1e300,")}, 3,
     ["edge.csv:3:", "from where the tools reach", "farther than the blank's size"]),
    ('punch_force = "force.csv"\n', {"force.csv": FORCE.replace("20,12,", "20,inf,")}, 4,
     ["force.csv:4:", "force_N", "not a finite number"]),
    ('shear_points = "shear.csv"\n', {"shear.csv": SHEAR.replace(",A,0.0", ",A,0.0,7")}, 3,
     ["shear.csv:3:", "7 cells, but the header has 6 columns"]),
    ('outline = "missing.csv"\n', {}, 8, ["bundle.toml:8:", "outline = 'missing.csv'",
                                          "no such file", "relative to the bundle folder"]),
    ('punch_force = "force.csv"\nforce_tool = "ram"\n', {"force.csv": FORCE}, 9,
     ["force_tool = 'ram' is not a tool of the case"]),
]


@pytest.mark.parametrize(("keys", "files", "line", "fragments"), BAD)
def test_bad_lab_input_is_refused_with_file_and_line(tmp_path, capsys, keys, files, line,
                                                      fragments):
    folder = write(tmp_path / "b", keys, files)
    with pytest.raises(BundleError) as info:
        load_bundle(folder, read_case=case_for_test)
    message = str(info.value)
    assert all(f in message for f in fragments), message
    assert f":{line}:" in message
    # drape compare reports it as bad input (exit status 2), before anything runs.
    assert main(["compare", str(folder), "--out", str(tmp_path / "out")]) == 2
    assert fragments[-1] in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_grid_alone_takes_the_position_noise_key_and_the_frame(tmp_path):
    grid = "i,j,x0_mm,y0_mm,x_mm,y_mm,z_mm\n0,0,0,0,0,0,40\n1,0,10,0,10,0,39\n"
    folder = write(tmp_path / "b", 'file = "grid.csv"\nposition_sd_mm = 0.4\n',
                   {"grid.csv": grid}, "[test.frame]\ntranslation_mm = [0.0, 0.0, -1.0]\n")
    (test,) = load_bundle(folder, read_case=case_for_test).tests
    assert test.id == "dd" and list(test.columns["position_sd_mm"]) == [0.4, 0.4]
    assert list(test.columns["z_mm"]) == [39.0, 38.0]
