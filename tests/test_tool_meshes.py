"""Tool meshes checked as meshes: damaged tools are refused or warned with where.

Every mesh is built here: a faceted dome (ASCII STL) with one vertex made ``nan``, one corner
moved onto a far vertex (a spike, as a mesher's weld leaves it), a hole cut in its top;
small raw meshes for duplicates, degenerate, mis-wound and folded triangles.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from test_untrusted_input import dome_stl

from fenicsx_drape.cli import main
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.forming.case.format import CaseError, build_tools, load_case
from fenicsx_drape.forming.tools.checks import holes, mesh_defects, pieces
from fenicsx_drape.forming.tools.surfaces import TriangleSurface, load_surface

CASE = """\
[case]
name = "stl_punch"
duration_s = 10.0

[blank]
outline = "rectangle"
size_mm = [160.0, 160.0]
cell_mm = 20.0

[holder]
tool = "holder"
holder_force_N = 10.0

[[tool]]
name = "punch"
role = "{role}"
geometry = "{stl}"
[tool.motion]
time_s = [0.0, 10.0]
z_mm = [0.0, 10.0]

[[tool]]
name = "holder"
role = "holder"
geometry = "{holder}"
"""


def facets(path: Path) -> list[list[str]]:
    """The facets of an ASCII STL as lists of its lines (7 each)."""
    lines = path.read_text().splitlines()
    return [lines[k:k + 7] for k in range(1, len(lines) - 1, 7)]


def write_facets(path: Path, items: list[list[str]]) -> Path:
    path.write_text("\n".join(["solid s", *[line for f in items for line in f],
                               "endsolid s"]) + "\n")
    return path


def vertices(facet: list[str]) -> np.ndarray:
    return np.array([[float(v) for v in line.split()[1:]] for line in facet[2:5]])


def dome(folder: Path) -> Path:
    """A dome of R = 60 mm, z = 0 ... 60, in 18 bands of 5° and 48 segments (5-8 mm edges)."""
    return dome_stl(folder / "dome.stl", 60.0, 18, 48)


def test_a_vertex_that_is_not_a_number_is_refused_with_file_and_line(tmp_path, capsys):
    path = dome(tmp_path)
    lines = path.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if i > 300 and line.strip().startswith("vertex"))
    lines[k] = "  vertex nan nan nan"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DrapeInputError, match=rf"dome\.stl:{k + 1}: vertex nan nan nan is "
                                              r"not three finite numbers"):
        load_surface(path, comm=None)
    # Through a case and the command line: exit 2, before any solve.
    plate = write_facets(tmp_path / "plate.stl", [[
        "facet normal 0 0 1", " outer loop", *[f"  vertex {x} {y} 0" for x, y in tri],
        " endloop", "endfacet"] for tri in (((-90, -90), (90, -90), (90, 90)),
                                            ((-90, -90), (90, 90), (-90, 90)))])
    case = tmp_path / "case.toml"
    case.write_text(CASE.format(role="punch", stl=path.name, holder=plate.name))
    assert main(["form", str(case), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert f"dome.stl:{k + 1}: vertex nan nan nan" in capsys.readouterr().err


def test_a_binary_stl_with_a_vertex_that_is_not_a_number_is_refused(tmp_path):
    facets = np.zeros(3, dtype=[("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    facets["v"] = [[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 0], [0, 1, 0]],
                   [[1, 0, 0], [2, 0, 0], [np.nan, 1, 0]]]
    path = tmp_path / "binary.stl"
    path.write_bytes(b"solid header of a binary file".ljust(80) + np.uint32(3).tobytes()
                     + facets.tobytes())
    with pytest.raises(DrapeInputError, match=r"binary\.stl: facet 3 \(of 3\) has a vertex "
                                              r"that is not finite"):
        load_surface(path, comm=None)


def test_a_corner_welded_onto_a_far_vertex_is_a_spike(tmp_path):
    path = dome(tmp_path)
    items = facets(path)
    # One facet near the top gets a corner of a facet at the foot on the other side: the
    # triangle the weld left (Gmsh merged the nan vertex onto an unrelated one).
    top = next(k for k, f in enumerate(items) if vertices(f)[:, 2].min() > 55.0)
    far = next(f for f in items if vertices(f)[:, 0].min() < -59.0)
    corner = far[2].split()[1:]
    items[top] = [*items[top][:4], "  vertex " + " ".join(corner), *items[top][5:]]
    write_facets(path, items)
    jump = np.linalg.norm(vertices(items[top])[2] - vertices(items[top])[1])
    with pytest.raises(DrapeInputError, match=r"dome\.stl: the tool mesh is damaged: .*spike "
                                              r"edge\(s\): an edge of (\d+\.?\d*) mm") as err:
        load_surface(path, comm=None)
    length = float(str(err.value).split("an edge of ")[1].split(" mm")[0])
    assert abs(length - jump) < 0.01 * jump and jump > 60.0


def cut_hole(path: Path, radius_mm: float) -> Path:
    """The dome without the facets within ``radius_mm`` of its axis at the top."""
    items = [f for f in facets(path)
             if np.hypot(*vertices(f)[:, :2].mean(axis=0)) > radius_mm]
    return write_facets(path, items)


def test_a_punch_with_a_hole_is_refused_and_a_holders_opening_is_not(tmp_path):
    assert holes(load_surface(dome(tmp_path), comm=None)) == []
    path = cut_hole(dome(tmp_path), 10.0)  # the top two bands: a hole 2·60·sin 10° ≈ 21 mm
    (centre, size), = holes(load_surface(path, comm=None))
    assert size == pytest.approx(2 * 60 * np.sin(np.radians(10.0)), rel=1e-6)
    assert np.allclose(centre[:2], 0.0, atol=1e-6) and centre[2] > 55.0
    # In a case: a punch (or die) with a hole is refused, a holder with one is not.
    case = tmp_path / "case.toml"
    case.write_text(CASE.format(role="punch", stl="dome.stl", holder="dome.stl"))
    with pytest.raises(CaseError, match=r"\[\[tool\]\] 1 \('punch'\): dome\.stl: the punch's "
                                        r"surface has 1 hole\(s\): one of 20\.8 mm across at "
                                        r"\(0, 0, 59\.1\) mm"):
        build_tools(load_case(case))
    case.write_text(CASE.format(role="punch", stl="dome.stl", holder="dome.stl").replace(
        'name = "punch"\nrole = "punch"', 'name = "punch"\nrole = "surface"'))
    with pytest.raises(CaseError, match=r"the surface's surface has 1 hole"):
        build_tools(load_case(case))


def test_duplicate_degenerate_miswound_and_folded_triangles():
    square = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]], dtype=float)
    two = np.array([[0, 1, 2], [0, 2, 3]])
    assert mesh_defects(square, two) == ([], [])
    errors, _ = mesh_defects(square, np.array([[0, 1, 2], [0, 2, 3], [2, 1, 0]]))
    assert errors == ["1 triangle(s) given twice, e.g. at (6.667, 3.333, 0) mm (the surface "
                      "is in the file twice?)"]
    # A triangle with three points on a line, and one with a repeated corner: warned, kept out.
    line = np.vstack([square, [[5, 0, 0]]])
    errors, warns = mesh_defects(line, np.array([[0, 1, 2], [0, 2, 3], [0, 4, 1], [1, 1, 2]]))
    assert errors == [] and warns[0].startswith("2 degenerate triangle(s)")
    # The second triangle wound against the first: warned (the surface turns it).
    errors, warns = mesh_defects(square, np.array([[0, 1, 2], [0, 3, 2]]))
    assert errors == [] and warns == ["1 shared edge(s) between triangles wound against each "
                                      "other, e.g. at (3.333, 6.667, 0) mm: turned to match "
                                      "their neighbours"]
    surface = TriangleSurface(square, np.array([[0, 1, 2], [0, 3, 2]]))
    assert np.allclose(surface.face_normals, [0, 0, 1])
    # A triangle folded back onto its neighbour (its corner pushed through the shared edge).
    folded = square.copy()
    folded[3] = [12, -2, 0.01]
    errors, _ = mesh_defects(folded, two)
    assert len(errors) == 1 and errors[0].startswith("1 fold(s): neighbouring triangles "
                                                     "turned back")
    # Non-finite points that a triangle uses.
    bad = square.copy()
    bad[2] = np.nan
    assert mesh_defects(bad, two)[0] == ["1 point(s) of the mesh are not finite (point 2: "
                                         "[nan, nan, nan])"]


def test_a_clean_mesh_from_gmsh_passes(tmp_path):
    geo = tmp_path / "plate.geo"
    geo.write_text('SetFactory("OpenCASCADE");\nRectangle(1) = {-50, -50, 0, 100, 100};\n'
                   'Disk(2) = {0, 0, 0, 20};\nBooleanDifference{ Surface{1}; Delete; }'
                   '{ Surface{2}; Delete; }\n')
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        surface = load_surface(geo, mesh_size_mm=5.0, comm=None)
    # A plate with a round opening: two boundary loops; the opening is a hole (40 mm).
    found = sorted(holes(surface), key=lambda h: h[1])
    assert found[0][1] == pytest.approx(40.0, rel=0.02)


def test_a_punch_of_two_separate_shells_is_refused_and_a_holder_of_two_blocks_is_not(
        tmp_path, capsys):
    # The dome and a copy of it 200 mm away in one file: two pieces where one is expected.
    items = facets(dome(tmp_path))
    moved = [[*f[:2], *[f"  vertex {x + 200.0} {y} {z}" for x, y, z in vertices(f)], *f[5:]]
             for f in items]
    write_facets(tmp_path / "two.stl", items + moved)
    assert len(pieces(load_surface(tmp_path / "two.stl", comm=None))) == 2
    assert [m for m, _ in pieces(load_surface(dome(tmp_path), comm=None))] == [len(items)]
    case = tmp_path / "case.toml"
    case.write_text(CASE.format(role="punch", stl="two.stl", holder="two.stl"))
    assert main(["form", str(case), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert re.search(rf"\[\[tool\]\] 1 \('punch'\): two\.stl: the punch's surface is 2 "
                     rf"separate pieces \({len(items)} triangles around \(0, 0, \S+\) mm, "
                     rf"{len(items)} triangles around \(200, 0, \S+\) mm\): a punch must be "
                     r"one closed surface or one surface", err), err
    # The same file as the holder only (two clamping blocks): accepted.
    case.write_text(CASE.format(role="punch", stl="dome.stl", holder="two.stl"))
    assert set(build_tools(load_case(case))) == {"punch", "holder"}
