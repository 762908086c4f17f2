# # The lab bundle: what a forming lab brings after a trial
#
# Writes `demos/bundles/octagon-lab/`: the small octagonal part of `meshes/octagon` as a lab
# would measure it, with the lab's own copy of the tools as STL files. Made independently of
# the runs a diagnosis makes:
#
# - the "truth" is the paper's model (Table 2) formed on the closed-form tools, on 10 mm cells
#   with 1 mm steps;
# - the bundle's case is the lab's copy: punch, die and holder as binary STL (the tools'
#   profiles tessellated in 2 mm chords and 5° turns), and the case's own 20 mm cells;
# - the measurements: shear angles along two measuring lines (1° sd), a scan of the formed ply
#   with a hole (0.15 mm), the blank's edge after forming (0.3 mm) and the punch's force
#   against its travel (2 % of its peak), seed 2026.
#
# `demos/models/without_tow_buckling.toml` is the paper's model less `tow_buckling`: the
# README's lab command names that effect from this bundle. Run from the repository root:
# `python3 demos/make_lab_bundle.py [FOLDER]`.

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "meshes" / "octagon" / "case.toml"
TRUTH = {"cell_mm": 10.0, "step_mm": 1.0}
SEED = 2026
CHORD_MM = 2.0  # the copy's profile: points this far apart along the tools' meridians
SEGMENTS = 72  # and turned about the axis in 5° steps (the sphere within 0.04 mm)


def meridian(profile, r_max: float, h_min: float) -> np.ndarray:
    """Points (r, h) along a tool's profile, about CHORD_MM apart (endless lines clipped)."""
    from fenicsx_drape.forming.tools import Arc

    out = []
    for piece in profile:
        if isinstance(piece, Arc):
            n = max(2, int(np.ceil(abs(piece.end - piece.start) * piece.radius / CHORD_MM)) + 1)
            out += [piece.point(a) for a in np.linspace(piece.start, piece.end, n)]
        else:
            a, b = (np.array([min(r, r_max), max(h, h_min)]) for r, h in (piece.a, piece.b))
            n = max(2, int(np.ceil(np.linalg.norm(b - a) / CHORD_MM)) + 1)
            out += list(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a))
    rh = np.array(out)
    keep = np.r_[True, np.linalg.norm(np.diff(rh, axis=0), axis=1) > 1e-9]
    return rh[keep]


def revolved(rh: np.ndarray, z0: float = 0.0) -> np.ndarray:
    """Triangles (m, 3, 3) of a meridian (r, h) turned about the z axis (a point on it: a fan)."""
    φ = np.linspace(0.0, 2.0 * np.pi, SEGMENTS + 1)
    ring = np.stack([rh[:, :1] * np.cos(φ), rh[:, :1] * np.sin(φ),
                     np.repeat(rh[:, 1:] + z0, SEGMENTS + 1, axis=1)], axis=-1)  # (n, k, 3)
    triangles = []
    for i in range(len(rh) - 1):
        a, b, c, d = ring[i, :-1], ring[i, 1:], ring[i + 1, :-1], ring[i + 1, 1:]
        if rh[i, 0] > 1e-9:
            triangles.append(np.stack([a, c, b], axis=1))
        if rh[i + 1, 0] > 1e-9:
            triangles.append(np.stack([b, c, d], axis=1))
    return np.concatenate(triangles)


def write_stl(triangles: np.ndarray, path: Path) -> Path:
    """A binary STL of triangles (m, 3, 3)."""
    t = np.asarray(triangles, np.float32)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    rows = np.zeros(len(t), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rows["n"], rows["v"] = n, t
    header = f"{path.stem}: a lab's copy of the tool (demos/make_lab_bundle.py)".encode()
    path.write_bytes(header.ljust(80, b" ")[:80] + np.uint32(len(t)).tobytes() + rows.tobytes())
    return path


def stl_case(folder: Path) -> Path:
    """The octagon's case with its tools as STL files: the closed-form tools tessellated."""
    from fenicsx_drape.forming import load_case
    from fenicsx_drape.forming.tools import HemisphereTools

    folder.mkdir(parents=True, exist_ok=True)
    text = CASE.read_text()
    params = dict(load_case(CASE).tool("punch").params)
    tools = HemisphereTools(**params)
    punch = tools.punch(duration_s=1.0)
    holder = np.array([[tools.opening_radius_mm, 0.0], [0.75 * 190.0, 0.0]])
    die = tools.die()
    # As the tools' pictures clip them (forming.tools.drawing): the punch's side wall 20 mm
    # below its profile's origin, the die's flat face at the holder opening.
    for name, triangles in (
            ("punch", revolved(meridian(punch.profile, tools.shoulder_radius_mm, -20.0),
                               punch.z_offset(0.0))),
            ("die", revolved(meridian(die.profile, tools.opening_radius_mm, -np.inf),
                             die.z_offset(0.0))),
            ("holder", revolved(holder))):
        write_stl(triangles, folder / f"{name}.stl")
        start = text.index(f'name = "{name}"')
        end = text.index("}", start) + 1  # the tool's parameters table
        text = text[:start] + f'name = "{name}"\nrole = "{name}"\ngeometry = "{name}.stl"' \
            + text[end:]
    # The builtin punch travels travel_mm in the forming time; the STL punch by its motion.
    text = text.replace('geometry = "punch.stl"', 'geometry = "punch.stl"\n[tool.motion]\n'
                        f'time_s = [0.0, 20.0]\nz_mm = [0.0, {tools.travel_mm}]')
    (folder / "case.toml").write_text(text)
    return folder / "case.toml"


DOUBLE_DOME = ROOT / "meshes" / "double_dome"


def stack_stl_case(folder: Path, angles=(0.0, 45.0), cell_mm: float = 20.0,
                   interply: str = "mu_ply = 0.2") -> Path:
    """A lab's stack case: the double dome's whole blank as a stack, its punch and die as STL.

    The punch and die are the shipped double dome's surfaces (Gmsh, 3 mm), the die at the
    stack's gap, written as binary STL; the holder stays the plate of ``holder.geo``. One
    ``[[ply]]`` of 0.3 mm per angle, ``interply`` the ``[interply]`` table's text.
    """
    from fenicsx_drape.forming.case import load_case
    from fenicsx_drape.forming.tools import build_tools

    folder.mkdir(parents=True, exist_ok=True)
    source = DOUBLE_DOME / "case.toml"
    built = build_tools(load_case(source, offset_mm=0.3 * len(angles)))
    text = source.read_text()
    for name in ("punch", "die"):
        surface = built[name].surface
        write_stl(surface.points[surface.triangles], folder / f"{name}.stl")
        start = text.index(f'name = "{name}"')
        end = text.index("mesh_mm = 3.0", start) + len("mesh_mm = 3.0")
        text = (text[:start] + f'name = "{name}"\nrole = "{name}"\ngeometry = "{name}.stl"'
                + text[end:])
    (folder / "holder.geo").write_text((DOUBLE_DOME / "holder.geo").read_text())
    text = text.replace('symmetry = ["x", "y"]', "symmetry = []").replace(
        "cell_mm = 10.0", f"cell_mm = {cell_mm:g}")
    text += "".join(f"\n[[ply]]\nangle_deg = {a:g}\nthickness_mm = 0.3\n" for a in angles)
    (folder / "case.toml").write_text(text + f"\n[interply]\n{interply}\n")
    return folder / "case.toml"


def make(out: Path, seed: int = SEED, measurements=None, truth_model=None, stl: bool = True,
         **overrides) -> Path:
    """Form the truth and write the lab bundle at ``out`` (the module doc).

    ``stl=False``: the bundle's case is the octagon's own (closed-form tools), not the lab's
    STL copy; ``overrides`` change the truth's case (its net, step, set-up).
    """
    from fenicsx_drape import runs
    from fenicsx_drape.diagnosis import lab_tables, write_lab_bundle
    from fenicsx_drape.forming import load_case, with_overrides
    from fenicsx_drape.model import default_model

    model = truth_model or default_model()
    truth = with_overrides(load_case(CASE), **{**TRUTH, **overrides})
    (grid,) = runs.form_many([(truth, model)])
    tables = lab_tables(grid, runs.tool_forces(truth, model), seed=seed, points_per_line=20,
                        scan_points=600, holes=[(20.0, 20.0, 10.0)], edge_points=40)
    lab_case = load_case(stl_case(out / "stl") if stl else CASE)
    write_lab_bundle(out, lab_case, tables, name="octagon-lab", measurements=measurements,
                     comment="A lab's forming trial of meshes/octagon (demos/make_lab_bundle.py)")
    if stl:
        for path in (out / "stl").iterdir():  # the case's copy holds its tools
            path.unlink()
        (out / "stl").rmdir()
    return out


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "demos" / "bundles" / \
        "octagon-lab"
    print(f"wrote {make(folder)}")
