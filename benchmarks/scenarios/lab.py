"""What a lab measures on a formed ply, and how it writes it down: the scenario generator's own
code, written as another group would write it.

Nothing here imports ``fenicsx_drape``. A forming run is read from its documented output
files, as an FE result from another code would be read: ``fields.h5`` (the flat net's nodes,
its bars with their ``kind`` — 1 warp, 2 weft, 3/4 diagonals — and ``ply``, and the
displacement at each written time), ``summary.json`` (the symmetry planes the run kept) and
``tool_forces.csv`` (each tool's force against travel). From the formed net the lab measures
with NumPy:

- the whole sheet (a symmetric run mirrored through its planes), as a lattice of nodes
  ``(i, j)`` along the tows with the cells between them, the formed surface bilinear in each
  cell (the material point at flat position P lies at the bilinear map of its cell's corners);
- **grid**: the nodes of a grid drawn on the flat blank (any spacing), tracked after forming;
- **shear at cell centres**: each cell's own angle between its tows (the mean of its two warp
  sides against the mean of its two weft sides), at the cell's centre, along measuring lines;
- **shear by finite differences**: at points along measuring lines, the tows' directions by
  central differences of formed positions of material points ±h along each tow;
- **scan**: points sampled at random over the formed sheet, with noise and holes;
- **edge**: points along the blank's edge after forming, with draw-in (in-plane inward
  movement from the tool axis, flat minus formed distance);
- **force curve**: the punch's force against travel, resampled, with noise.

Shear is signed as the measurement spec says: 90° minus the angle between the tows' +x (warp)
and +y (weft) directions. Bundles, case files and STL files are written by hand here.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

TOL = 1e-6


# --------------------------------------------------------------------------------------------
# Reading a forming run's output


def _times(group) -> list[str]:
    return sorted(group.keys(), key=lambda s: float(s.replace("_", ".")))


@dataclasses.dataclass
class Sheet:
    """One ply's formed net, the whole sheet, as a lattice along its tows.

    ``X``/``x``: flat and formed node positions (n, 3); ``ij``: lattice indices (n, 2);
    ``cells``: corner nodes (m, 4) in the order (i, j), (i+1, j), (i, j+1), (i+1, j+1);
    ``origin``, ``e1``, ``e2``, ``delta``: the lattice in the flat plane (node (0, 0), unit
    warp and weft, cell sides).
    """

    X: np.ndarray
    x: np.ndarray
    ij: np.ndarray
    cells: np.ndarray
    origin: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    delta: tuple[float, float]
    ply: int = 1

    def __post_init__(self) -> None:
        self.node = {(int(i), int(j)): k for k, (i, j) in enumerate(self.ij)}
        self.cell = {(int(self.ij[c[0], 0]), int(self.ij[c[0], 1])): m
                     for m, c in enumerate(self.cells)}

    # -- the lattice coordinates of flat points
    def local(self, P: np.ndarray) -> np.ndarray:
        """(ξ, η) in cells of flat plan points (n, 2)."""
        d = np.asarray(P, float)[:, :2] - self.origin
        return np.column_stack([d @ self.e1 / self.delta[0], d @ self.e2 / self.delta[1]])

    def flat(self, xi_eta: np.ndarray) -> np.ndarray:
        """Flat plan points (n, 2) of lattice coordinates."""
        q = np.asarray(xi_eta, float)
        return (self.origin + q[:, :1] * self.delta[0] * self.e1
                + q[:, 1:2] * self.delta[1] * self.e2)

    def formed(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Formed positions (n, 3) of the material points at flat plan positions P (n, 2).

        Returns the positions and a mask of the points that lie in a cell of the net (a point
        on a cell's side belongs to either cell).
        """
        q = self.local(P)
        base = np.floor(q + 1e-9).astype(int)
        out = np.full((len(q), 3), np.nan)
        ok = np.zeros(len(q), bool)
        for k in range(len(q)):
            for di, dj in ((0, 0), (-1, 0), (0, -1), (-1, -1)):
                i, j = int(base[k, 0] + di), int(base[k, 1] + dj)
                s, t = q[k, 0] - i, q[k, 1] - j
                m = self.cell.get((i, j))
                if m is not None and -1e-9 <= s <= 1 + 1e-9 and -1e-9 <= t <= 1 + 1e-9:
                    a, b, c, d = self.x[self.cells[m]]
                    out[k] = ((1 - s) * (1 - t) * a + s * (1 - t) * b + (1 - s) * t * c
                              + s * t * d)
                    ok[k] = True
                    break
        return out, ok

    # -- per cell
    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """The cells' flat and formed centres (m, 3) each."""
        return self.X[self.cells].mean(axis=1), self.x[self.cells].mean(axis=1)

    def cell_shear_deg(self) -> np.ndarray:
        """Each cell's own shear angle: 90° minus the angle between its mean warp and weft."""
        a, b, c, d = (self.x[self.cells[:, k]] for k in range(4))
        return shear_of(b - a + d - c, c - a + d - b)

    def boundary(self) -> np.ndarray:
        """The cell sides on the blank's edge (k, 2) as node pairs, in no particular order."""
        count: dict[tuple, list] = {}
        for a, b, c, d in self.cells:
            for pair in ((a, b), (c, d), (a, c), (b, d)):
                count.setdefault(tuple(sorted(pair)), []).append(pair)
        return np.array([v[0] for v in count.values() if len(v) == 1], int)


def shear_of(warp: np.ndarray, weft: np.ndarray) -> np.ndarray:
    """90° minus the angle (degrees) between warp and weft directions (n, 3)."""
    cos = np.einsum("ni,ni->n", warp, weft) / (np.linalg.norm(warp, axis=1)
                                                * np.linalg.norm(weft, axis=1))
    return 90.0 - np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def read_run(folder: str | Path) -> list[Sheet]:
    """The formed sheet of each ply of a ``drape form`` output folder (the whole sheet).

    A run of a symmetric part holds its modelled part only: it is mirrored through the planes
    ``summary.json`` names, as the part is.
    """
    import h5py

    folder = Path(folder)
    planes = json.loads((folder / "summary.json").read_text()).get("symmetry") or []
    with h5py.File(folder / "fields.h5", "r") as f:
        X = f["Mesh/mesh/geometry"][:]
        bars = f["Mesh/mesh/topology"][:]
        last = _times(f["Function/displacement_mm"])[-1]
        u = f["Function/displacement_mm"][last][:]
        kind = np.rint(f["Function/kind"][last][:].ravel()).astype(int)
        ply = (np.rint(f["Function/ply"][last][:].ravel()).astype(int)
               if "ply" in f["Function"] else np.ones(len(bars), int))
    return [_lattice(X, X + u, bars[ply == p], kind[ply == p], planes, int(p))
            for p in sorted(set(ply.tolist()))]


def _unit(v: np.ndarray) -> np.ndarray:
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    v = v * np.sign(v @ v[0])[:, None]
    m = v.mean(axis=0)
    return m / np.linalg.norm(m)


def _lattice(X, x, bars, kind, planes, ply) -> Sheet:
    nodes = np.unique(bars)
    Xp = X[:, :2]
    warp = Xp[bars[kind == 1, 1]] - Xp[bars[kind == 1, 0]]
    weft = Xp[bars[kind == 2, 1]] - Xp[bars[kind == 2, 0]]
    e1, e2 = _unit(warp), _unit(weft)
    if e1[0] < 0:
        e1 = -e1
    if e1[0] * e2[1] - e1[1] * e2[0] < 0:  # the weft to the warp's left
        e2 = -e2
    delta = (float(np.median(np.abs(warp @ e1))), float(np.median(np.abs(weft @ e2))))
    ref = nodes[np.argmin(np.linalg.norm(Xp[nodes], axis=1))]
    origin = Xp[ref].copy()
    d = Xp - origin
    ij = np.column_stack([np.rint(d @ e1 / delta[0]), np.rint(d @ e2 / delta[1])]).astype(int)
    diag = bars[kind >= 3]
    keep = {int(n): k for k, n in enumerate(nodes)}
    XX, xx, IJ = X[nodes].copy(), x[nodes].copy(), ij[nodes].copy()
    D = np.array([[keep[a], keep[b]] for a, b in diag], int).reshape(-1, 2)
    for axis, plane in ((0, "x"), (1, "y")):
        if plane not in planes:
            continue
        # The tows are along x and y on a symmetric part: mirror every node off the plane.
        off = np.abs(XX[:, axis]) > TOL
        index = np.full(len(XX), -1)
        index[~off] = np.flatnonzero(~off)
        index[off] = len(XX) + np.arange(off.sum())
        flip = np.ones(3)
        flip[axis] = -1.0
        XX = np.vstack([XX, XX[off] * flip])
        xx = np.vstack([xx, xx[off] * flip])
        f = np.ones(2, int)
        f[axis] = -1
        IJ = np.vstack([IJ, IJ[off] * f])
        D = np.vstack([D, index[D]])
    by_ij = {(int(i), int(j)): k for k, (i, j) in enumerate(IJ)}
    corners = sorted({(int(min(IJ[a, 0], IJ[b, 0])), int(min(IJ[a, 1], IJ[b, 1])))
                      for a, b in D})
    cells = np.array([[by_ij[(i, j)], by_ij[(i + 1, j)], by_ij[(i, j + 1)],
                       by_ij[(i + 1, j + 1)]] for i, j in corners], int)
    return Sheet(XX, xx, IJ, cells, origin, e1, e2, delta, ply)


def read_forces(folder: str | Path) -> dict[str, np.ndarray]:
    """``tool_forces.csv`` of a forming run: its columns by name."""
    path = Path(folder) / "tool_forces.csv"
    lines = [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("#")]
    head = lines[0].split(",")
    data = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    return {h: data[:, k] for k, h in enumerate(head)}


# --------------------------------------------------------------------------------------------
# Measuring lines on the flat blank


def line_points(sheet: Sheet, line_mm: tuple[str, tuple, tuple], spacing_mm: float,
                reach_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Flat plan points along a line given in mm in the tows' frame from the blank's origin.

    ``line_mm`` = (name, (a, b) start in mm along warp and weft, (u, v) direction); points
    every ``spacing_mm`` up to ``reach_mm``. Returns the points (n, 2) and their s_mm.
    """
    _, (a, b), (u, v) = line_mm
    n = np.array([u, v], float) / math.hypot(u, v)
    s = np.arange(0.0, reach_mm + 1e-9, spacing_mm)
    tow = np.array([a, b]) + s[:, None] * n
    P = sheet.origin + tow[:, :1] * sheet.e1 + tow[:, 1:2] * sheet.e2
    return P, s


# --------------------------------------------------------------------------------------------
# The measurements (each a dict of columns)


def grid(sheet: Sheet, spacing_mm: float, rng, sd_mm: float, offset=(0.0, 0.0),
         quarter: bool = False) -> dict[str, np.ndarray]:
    """The nodes of a grid drawn on the flat blank along x and y, tracked after forming.

    ``offset``: where the blank lay relative to where the lab meant it (the grid is drawn on
    the blank, so ``x0_mm, y0_mm`` are the lab's intended flat positions).
    """
    X = sheet.X[:, :2]
    lo, hi = X.min(axis=0), X.max(axis=0)
    o = np.asarray(offset, float)
    i = np.arange(math.floor((lo[0] - o[0]) / spacing_mm), math.ceil((hi[0] - o[0])
                                                                      / spacing_mm) + 1)
    j = np.arange(math.floor((lo[1] - o[1]) / spacing_mm), math.ceil((hi[1] - o[1])
                                                                      / spacing_mm) + 1)
    ii, jj = (a.ravel() for a in np.meshgrid(i, j, indexing="ij"))
    if quarter:
        ii, jj = ii[(ii >= 0) & (jj >= 0)], jj[(ii >= 0) & (jj >= 0)]
    flat = np.column_stack([ii * spacing_mm, jj * spacing_mm])
    pos, ok = sheet.formed(flat + o)
    pos = pos[ok] + rng.normal(0.0, sd_mm, (ok.sum(), 3))
    return {"i": ii[ok], "j": jj[ok], "x0_mm": flat[ok, 0], "y0_mm": flat[ok, 1],
            "x_mm": pos[:, 0], "y_mm": pos[:, 1], "z_mm": pos[:, 2]}


def shear_cells(sheet: Sheet, lines, spacing_mm: float, reach_mm: float, rng, sd_deg: float,
                flat: bool = False, offset=(0.0, 0.0)) -> dict[str, np.ndarray]:
    """Each cell's own shear at its centre, for the cells the measuring lines cross."""
    flat_c, formed_c = sheet.cell_centres()
    gamma = sheet.cell_shear_deg()
    rows = []
    for line in lines:
        P, s = line_points(sheet, line, spacing_mm, reach_mm)
        q = np.floor(sheet.local(P) + 1e-9).astype(int)
        seen = set()
        for (i, j), sk in zip(q, s, strict=True):
            m = sheet.cell.get((int(i), int(j)))
            if m is None or m in seen:
                continue
            seen.add(m)
            rows.append((line[0], sk, m))
    m = np.array([r[2] for r in rows], int)
    out = {}
    if flat:
        out["x0_mm"] = flat_c[m, 0] - offset[0]
        out["y0_mm"] = flat_c[m, 1] - offset[1]
    else:
        out.update(x_mm=formed_c[m, 0], y_mm=formed_c[m, 1], z_mm=formed_c[m, 2])
    out["shear_deg"] = gamma[m] + rng.normal(0.0, sd_deg, len(m))
    out["line"] = np.array([r[0] for r in rows])
    out["s_mm"] = np.array([r[1] for r in rows])
    return out


def shear_differences(sheet: Sheet, lines, spacing_mm: float, reach_mm: float, h_mm: float,
                      rng, sd_mm: float) -> tuple[dict[str, np.ndarray], float]:
    """Shear by central differences of tracked points ±h along each tow, along the lines.

    Each of the five points (the point and its four neighbours) is measured with position
    noise ``sd_mm``; returned with the table: the lab's own estimate of the shear's noise,
    propagated from the position noise.
    """
    rows = []
    for line in lines:
        P, s = line_points(sheet, line, spacing_mm, reach_mm)
        e1, e2 = sheet.e1 * h_mm, sheet.e2 * h_mm
        pts = [P + e1, P - e1, P + e2, P - e2]
        got = [sheet.formed(p) for p in pts]
        centre, ok0 = sheet.formed(P)
        ok = ok0 & np.all([g[1] for g in got], axis=0)
        for k in np.flatnonzero(ok):
            rows.append((line[0], s[k], centre[k], [g[0][k] for g in got]))
    n = len(rows)
    noisy = [np.array([r[3][q] for r in rows]) + rng.normal(0.0, sd_mm, (n, 3))
             for q in range(4)]
    gamma = shear_of(noisy[0] - noisy[1], noisy[2] - noisy[3])
    c = np.array([r[2] for r in rows]) + rng.normal(0.0, sd_mm, (n, 3))
    # The lab's noise estimate: each tow's direction over 2h from two points of noise sd
    # turns by sd·√2 / 2h in the plane, and the shear is the difference of two of them.
    spread = math.degrees(sd_mm / h_mm)
    return ({"x_mm": c[:, 0], "y_mm": c[:, 1], "z_mm": c[:, 2], "shear_deg": gamma,
             "line": np.array([r[0] for r in rows]), "s_mm": np.array([r[1] for r in rows])},
            float(spread))


def scan(sheet: Sheet, n_points: int, rng, sd_mm: float, holes=()) -> dict[str, np.ndarray]:
    """Points of the formed ply's surface, uniform over its material, noise, holes in plan."""
    m = rng.integers(0, len(sheet.cells), 3 * n_points)
    st = rng.random((3 * n_points, 2))
    a, b, c, d = (sheet.x[sheet.cells[m, k]] for k in range(4))
    s, t = st[:, :1], st[:, 1:]
    p = (1 - s) * (1 - t) * a + s * (1 - t) * b + (1 - s) * t * c + s * t * d
    keep = np.ones(len(p), bool)
    for cx, cy, r in holes:
        keep &= np.hypot(p[:, 0] - cx, p[:, 1] - cy) > r
    p = p[keep][:n_points] + rng.normal(0.0, sd_mm, (min(n_points, keep.sum()), 3))
    return {"x_mm": p[:, 0], "y_mm": p[:, 1], "z_mm": p[:, 2]}


def edge(sheet: Sheet, n_points: int, rng, sd_mm: float, with_z: bool = False,
         draw_in: bool = False, centre=(0.0, 0.0)) -> dict[str, np.ndarray]:
    """Points along the formed blank's edge, about evenly spaced along it, with noise."""
    sides = sheet.boundary()
    A, B = sheet.x[sides[:, 0]], sheet.x[sides[:, 1]]
    FA, FB = sheet.X[sides[:, 0], :2], sheet.X[sides[:, 1], :2]
    length = np.linalg.norm((B - A)[:, :2], axis=1)
    spots = np.sort(rng.random(n_points)) * length.sum()
    k = np.searchsorted(np.cumsum(length), spots).clip(0, len(sides) - 1)
    t = ((spots - (np.cumsum(length) - length)[k]) / np.maximum(length[k], 1e-12))[:, None]
    p = A[k] + t * (B[k] - A[k])
    f = FA[k] + t * (FB[k] - FA[k])
    noise = rng.normal(0.0, sd_mm, (n_points, 3))
    q = p + noise
    c = np.asarray(centre, float)
    out = {"x_mm": q[:, 0], "y_mm": q[:, 1]}
    if with_z:
        out["z_mm"] = q[:, 2]
    if draw_in:
        out["draw_in_mm"] = (np.linalg.norm(f - c, axis=1)
                             - np.linalg.norm(q[:, :2] - c, axis=1))
    return out


def force_curve(forces: dict[str, np.ndarray], rows: int, rng, sd_rel: float,
                tool: str = "punch") -> tuple[dict[str, np.ndarray], float]:
    """The tool's force against travel, at ``rows`` evenly spread travels, with noise.

    Returns the table and the noise's standard deviation (N): ``sd_rel`` of the peak force.
    """
    travel, force, time = forces["travel_mm"], forces[tool], forces["time_s"]
    at = np.linspace(travel[0], travel[-1], rows)
    sd = sd_rel * float(np.max(np.abs(force)))
    value = np.interp(at, travel, force) + rng.normal(0.0, sd, rows)
    return {"time_s": np.interp(at, travel, time), "travel_mm": at, "force_N": value}, sd


# --------------------------------------------------------------------------------------------
# Writing, by hand


def write_csv(path: Path, columns: dict[str, np.ndarray], comment: str = "") -> Path:
    """A CSV table: ``#`` comment lines, one header row, one row per entry."""
    names = list(columns)
    n = len(next(iter(columns.values())))
    lines = [f"# {c}" for c in comment.splitlines() if c]
    lines.append(",".join(names))
    for k in range(n):
        cells = []
        for name in names:
            v = columns[name][k]
            if isinstance(v, (str, np.str_)):
                cells.append(str(v))
            elif isinstance(v, (int, np.integer)) or name in ("i", "j"):
                cells.append(str(int(v)))
            else:
                cells.append(f"{float(v):.6g}")
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


def toml_value(v) -> str:
    """A TOML literal of a number, string, bool or list of them."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(toml_value(e) for e in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(e)}" for k, e in v.items()) + " }"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))


def toml_table(header: str, keys: dict) -> str:
    """A TOML table (``[header]`` or ``[[header]]``) of simple keys."""
    lines = [header]
    lines += [f"{k} = {toml_value(v)}" for k, v in keys.items() if v is not None]
    return "\n".join(lines) + "\n"


def write_stl(path: Path, triangles: np.ndarray, name: str = "tool") -> Path:
    """A binary STL of triangles (m, 3, 3), normals from the vertices' order."""
    t = np.asarray(triangles, np.float32)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    rows = np.zeros(len(t), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rows["n"], rows["v"] = n, t
    header = f"{name}: a lab's copy of the tool".encode()[:80].ljust(80, b" ")
    path.write_bytes(header + np.uint32(len(t)).tobytes() + rows.tobytes())
    return path
