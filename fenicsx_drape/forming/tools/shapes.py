"""Rigid forming tools as exact surfaces of revolution: signed gap, normal and curvature.

Frame (``docs/measurements.md``): origin on the punch axis, z along the punch travel,
z = 0 the plane of the undeformed sheet, the punch moving towards +z; x is the warp, y the weft.

A tool is a *profile* in the meridian half-plane (r, h), r = √(x² + y²) the distance from the
axis and h = z − z_tool(t) the height above the tool's reference plane, revolved about the
z axis and translated along z with a prescribed motion. The profile is a chain of circular
arcs and straight segments, joined with continuous tangents (G1), traced so that the tool's
material lies on the right of the direction of travel. For a G1 chain the closest point of
any sheet node lies inside one piece, so the signed distance φ (positive outside the tool)
is exact, and so are its gradient (the outward normal) and its Hessian (the curvature), which
the penalty contact needs for its consistent Jacobian:

    φ(x) = φ₂(r, h),   ∇φ = φ_r e_r + φ_h e_z,
    ∇∇φ = φ₂'' (in the meridian plane) + (φ_r / r) (I − e_r⊗e_r − e_z⊗e_z)   (hoop term).

Only the punch of the paper's hemisphere (section 4.1: radius 60 mm, fillet 20 mm) and its
matched die are built here (:class:`HemisphereTools`); the blank holder is a plane and lives
in :mod:`fenicsx_drape.forming.terms.holder`.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from fenicsx_drape.errors import ParameterError

_TINY = 1e-12
_EYE_XY = np.eye(3) - np.outer([0.0, 0.0, 1.0], [0.0, 0.0, 1.0])  # I − e_z⊗e_z


@dataclasses.dataclass(frozen=True)
class Arc:
    """A circular arc of the profile.

    It runs from angle ``start`` to ``end`` (radians about ``centre``, counter-clockwise
    positive; ``end < start`` runs clockwise).
    """

    centre: tuple[float, float]  # (r, h) in mm
    radius: float  # mm
    start: float  # rad
    end: float  # rad

    @property
    def material_inside(self) -> bool:
        """Clockwise arcs have the material (on the right) inside the circle: convex."""
        return self.end < self.start

    def point(self, angle: float) -> np.ndarray:
        """The profile point at ``angle`` (rad)."""
        return np.asarray(self.centre) + self.radius * np.array([math.cos(angle), math.sin(angle)])

    def closest(self, p: np.ndarray):
        """Distance, signed distance, outward normal and curvature for points ``p`` (n, 2).

        Returns ``d`` (n,) the distance to the arc, ``φ`` (n,) the signed distance (positive
        on the normal's side), ``n`` (n, 2) the outward normal at the closest point and ``c``
        (n,) in 1/mm: the Hessian of φ in the meridian plane is ``c t⊗t`` with ``t`` the
        tangent.
        """
        d, φ, n, c = _Arcs([self]).closest(p)
        return d[0], φ[0], n[0], c[0]


@dataclasses.dataclass(frozen=True)
class Segment:
    """A straight piece of the profile from ``a`` to ``b`` ((r, h) in mm)."""

    a: tuple[float, float]
    b: tuple[float, float]

    def closest(self, p: np.ndarray):
        """See :meth:`Arc.closest`; a segment has no curvature."""
        d, φ, n, c = _Segments([self]).closest(p)
        return d[0], φ[0], n[0], c[0]


Piece = Arc | Segment


class _Arcs:
    """Several arcs as arrays: :meth:`Arc.closest` for all of them in one pass of NumPy.

    The same arithmetic element by element (the same numbers to the last bit): at the few
    dozen nodes of a call, NumPy's cost is per operation, not per node.
    """

    def __init__(self, arcs: list[Arc]) -> None:
        column = lambda v: np.array(v, dtype=float)[:, None]  # noqa: E731  (A, 1)
        pair = lambda v: np.array(v, dtype=float)[:, None, :]  # noqa: E731  (A, 1, 2)
        self.sign = column([1.0 if q.material_inside else -1.0 for q in arcs])
        self.radius, self.start = column([q.radius for q in arcs]), column([q.start for q in arcs])
        self.span = column([q.end - q.start for q in arcs])
        self.centre = pair([q.centre for q in arcs])
        # The end points and the outward normals there (beyond the ends the closest point).
        self.a = pair([q.point(q.start) for q in arcs])
        self.b = pair([q.point(q.end) for q in arcs])
        self.n_a = self.sign[:, :, None] / self.radius[:, :, None] * (self.a - self.centre)
        self.n_b = self.sign[:, :, None] / self.radius[:, :, None] * (self.b - self.centre)

    def closest(self, p: np.ndarray):
        """:meth:`Arc.closest` of every arc: ``d``, ``φ``, ``c`` (A, n) and ``n`` (A, n, 2)."""
        d = p - self.centre
        ρ = np.maximum(np.hypot(d[..., 0], d[..., 1]), _TINY)
        n = (self.sign / ρ)[..., None] * d
        φ = self.sign * (ρ - self.radius)
        δ = np.mod(np.arctan2(d[..., 1], d[..., 0]) - self.start + math.pi, 2 * math.pi) - math.pi
        s = δ / self.span
        inside = (s >= 0.0) & (s <= 1.0)
        curv = np.where(inside, self.sign / ρ, 0.0)
        pa, pb = p - self.a, p - self.b
        da, db = np.hypot(pa[..., 0], pa[..., 1]), np.hypot(pb[..., 0], pb[..., 1])
        use_a = (da <= db)[..., None]
        n_end = np.where(use_a, self.n_a, self.n_b)
        d_end = np.minimum(da, db)
        φ_end = np.copysign(d_end, np.einsum("aij,aij->ai", np.where(use_a, pa, pb), n_end))
        n = np.where(inside[..., None], n, n_end)
        return np.where(inside, np.abs(φ), d_end), np.where(inside, φ, φ_end), n, curv


class _Segments:
    """Several segments as arrays: :meth:`Segment.closest` of all of them in one pass."""

    def __init__(self, segments: list[Segment]) -> None:
        a = np.array([q.a for q in segments], dtype=float)
        self.τ = np.array([q.b for q in segments], dtype=float) - a  # (S, 2)
        self.a = a[:, None, :]  # (S, 1, 2)
        self.ττ = np.array([τ @ τ for τ in self.τ])[:, None]  # (S, 1)
        self.n = np.array([np.array([-τ[1], τ[0]]) / np.linalg.norm(τ) for τ in self.τ])

    def closest(self, p: np.ndarray):
        """``d``, ``φ``, ``c`` (S, n) and ``n`` (S, n, 2) of every segment."""
        pa = p - self.a
        s = np.clip(np.matmul(pa, self.τ[:, :, None])[..., 0] / self.ττ, 0.0, 1.0)
        e = pa - s[..., None] * self.τ[:, None, :]
        d = np.hypot(e[..., 0], e[..., 1])
        φ = np.copysign(d, np.matmul(e, self.n[:, :, None])[..., 0])
        n = np.broadcast_to(self.n[:, None, :], pa.shape)
        return d, φ, n, np.zeros(d.shape)


@dataclasses.dataclass(frozen=True)
class Gap:
    """Signed gap of nodes to a tool, its gradient and its Hessian.

    ``phi`` (n,) in mm (negative = penetration), the outward normal ``normal`` (n, 3) = ∇φ
    and the curvature ``hessian`` (n, 3, 3) = ∇∇φ in 1/mm.
    """

    phi: np.ndarray
    normal: np.ndarray
    hessian: np.ndarray


@dataclasses.dataclass(frozen=True)
class RevolvedTool:
    """A rigid tool: a G1 profile revolved about a vertical axis, translated along z in time.

    The profile's reference plane h = 0 sits at ``z = z0_mm + speed_mm_per_s · t``; the axis
    passes through ``axis_mm`` = (x, y) (the z axis unless a punch is misaligned).
    """

    name: str
    profile: tuple[Piece, ...]
    z0_mm: float = 0.0
    speed_mm_per_s: float = 0.0
    axis_mm: tuple[float, float] = (0.0, 0.0)

    def z_offset(self, t: float) -> float:
        """Height (mm) of the tool's reference plane at time ``t`` (s)."""
        return self.z0_mm + self.speed_mm_per_s * t

    def displacement(self, x: np.ndarray, t0: float, t1: float) -> np.ndarray:
        """How far (n, 3) the tool's material point at ``x`` at ``t1`` moved since ``t0`` (mm)."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        d = np.zeros_like(x)
        d[:, 2] = self.z_offset(t1) - self.z_offset(t0)
        return d

    def moved_mm(self, t0, t1):
        """The farthest any point of the tool moves from ``t0`` to ``t1`` (arrays allowed).

        ``gap`` is the exact signed distance, so at a point x' within r of x, and from t0 to
        t1, φ differs by at most r + this: the contact skips the nodes that cannot reach it.
        """
        return np.abs(self.speed_mm_per_s * (np.asarray(t1) - np.asarray(t0)))

    def gap(self, x: np.ndarray, t: float) -> Gap:
        """Signed gap, normal and curvature at the positions ``x`` (n, 3) in mm at time ``t``."""
        x = np.asarray(x, dtype=float).reshape(-1, 3) - [*self.axis_mm, 0.0]
        r = np.hypot(x[:, 0], x[:, 1])
        p = np.column_stack([r, x[:, 2] - self.z_offset(t)])
        D, PHI = np.empty((len(self.profile), len(x))), np.empty((len(self.profile), len(x)))
        N, C = np.empty((*D.shape, 2)), np.empty(D.shape)
        for batch, rows in self._batches:
            D[rows], PHI[rows], N[rows], C[rows] = batch.closest(p)
        k = np.argmin(D, axis=0)  # the first piece of a tie, in the profile's order
        i = np.arange(len(x))
        phi, n, c = PHI[k, i], N[k, i], C[k, i]
        # φ_r / r: for arcs centred on the axis this is c itself (finite on the axis).
        hoop = np.where(self._on_axis[k], c, n[:, 0] / np.maximum(r, _TINY))
        # The meridian-plane basis: e_r (radial, any unit vector on the axis) and e_z.
        e_r = np.zeros_like(x)
        e_r[:, 0] = 1.0
        off = r > _TINY
        e_r[off, :2] = x[off, :2] / r[off, None]
        e_z = np.array([0.0, 0.0, 1.0])
        normal = n[:, :1] * e_r + n[:, 1:] * e_z
        tangent = n[:, 1:] * e_r - n[:, :1] * e_z
        hessian = c[:, None, None] * (tangent[:, :, None] * tangent[:, None, :])
        hoop_proj = _EYE_XY - e_r[:, :, None] * e_r[:, None, :]
        hessian += hoop[:, None, None] * hoop_proj
        return Gap(phi, normal, hessian)

    @functools.cached_property
    def _batches(self) -> list:
        """The profile's arcs in one batch and its segments in another, with their places."""
        out = []
        for kind, batch in ((Arc, _Arcs), (Segment, _Segments)):
            rows = [k for k, q in enumerate(self.profile) if isinstance(q, kind)]
            if rows:
                out.append((batch([self.profile[k] for k in rows]), rows))
        return out

    @functools.cached_property
    def _on_axis(self) -> np.ndarray:
        """Which pieces are arcs centred on the axis (their hoop curvature is their own)."""
        return np.array([isinstance(q, Arc) and abs(q.centre[0]) < _TINY
                         for q in self.profile])


@dataclasses.dataclass(frozen=True)
class FlatHolder:
    """The paper's blank holder: the plane z = ``z_mm`` outside a circular opening (fixed).

    A clamping surface for :class:`~fenicsx_drape.forming.terms.holder.BlankHolder`:
    φ = z − z_mm (normal +z), and it covers the nodes farther than ``opening_radius_mm`` from
    the z axis.
    """

    opening_radius_mm: float
    z_mm: float = 0.0
    name: str = "holder"
    flat = True  # a plane: the clamping and friction stiffness are symmetric

    def __post_init__(self) -> None:
        if not (np.isfinite(self.opening_radius_mm) and self.opening_radius_mm >= 0.0):
            raise ParameterError(f"FlatHolder: opening_radius_mm = {self.opening_radius_mm} "
                                 "must be finite and >= 0")

    def gap(self, x: np.ndarray, t: float) -> Gap:
        """Signed distance to the plane, its normal +z and zero curvature."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        normal = np.zeros_like(x)
        normal[:, 2] = 1.0
        return Gap(x[:, 2] - self.z_mm, normal, np.zeros((len(x), 3, 3)))

    def covers(self, x: np.ndarray, t: float) -> np.ndarray:
        """The nodes outside the opening (r > R_o)."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        return np.hypot(x[:, 0], x[:, 1]) > self.opening_radius_mm

    def displacement(self, x: np.ndarray, t0: float, t1: float) -> np.ndarray:
        """The holder does not move."""
        return np.zeros((len(x), 3))


@dataclasses.dataclass(frozen=True)
class HemisphereTools:
    """The paper's hemisphere tool set (section 4.1) built from its parameters.

    The punch is a spherical cap of radius ``punch_radius_mm`` (R) whose centre lies
    c = R_f − ``cap_centre_drop_mm`` above the punch base plane, joined to the flat base
    (shoulder) by a concave fillet of radius ``fillet_radius_mm`` (R_f) tangent to both,
    centred at r_b = √((R + R_f)² − (R_f − c)²), h = R_f; the shoulder runs out to
    ``shoulder_radius_mm`` (just inside the holder opening) where a small edge round
    ``edge_radius_mm`` turns it into the punch's cylindrical side. Apex-to-base height is
    R + c, the fillet's foot (the base of the part) at r_b.

    The paper gives R = 60 mm and R_f = 20 mm but not where the cap's centre sits (docs/forming.md).
    The default drop 0 (c = R_f) makes the cap a whole hemisphere meeting the fillet at its
    equator: height 80 mm (the travel), base at r_b = 80 mm, 125.7 mm of meridian from apex to
    base; the kinematic drape then gives the paper's 61° (62.5°, Fig. 11a). A drop of R_f puts
    the sphere's centre on the base plane (the fillet cuts the sphere 15 mm above it): height
    60 mm, base at r_b = 77.5 mm, 105.5 mm of meridian, and a kinematic drape of 45.4°.
    The punch starts with its apex at z = 0 and moves ``travel_mm`` towards +z, so its base
    reaches the sheet plane at the end when the travel equals its height (the defaults; give
    a lowered cap the travel R + c).

    The die (not given in the paper) is the matched female tool: the punch surface offset by
    the ply thickness, stationary at the punch's final position and contacted from above. Its
    flat face (z = ply thickness) covers the shoulder region inside the holder opening, and
    its convex lip (the offset fillet) is the entry radius the sheet is drawn over.

    The blank holder is two plates at z = 0 with a circular opening ``holder_opening_mm`` in
    diameter (:class:`~fenicsx_drape.forming.terms.holder.BlankHolder`).
    """

    punch_radius_mm: float = 60.0
    fillet_radius_mm: float = 20.0
    shoulder_radius_mm: float = 84.0
    edge_radius_mm: float = 1.0
    holder_opening_mm: float = 170.0
    sheet_mm: float = 240.0
    travel_mm: float = 80.0
    ply_thickness_mm: float = 0.3
    cap_centre_drop_mm: float = 0.0  # the cap's centre below the fillet's centre
    # The punch's misalignment: its axis at (x, y) while die and holder stay on the z axis.
    punch_x_mm: float = 0.0
    punch_y_mm: float = 0.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in ("punch_x_mm", "punch_y_mm"):
                if not math.isfinite(value):
                    raise ParameterError(f"HemisphereTools: {f.name} = {value} is not a number")
                continue
            if f.name == "cap_centre_drop_mm":
                if not (math.isfinite(value) and 0.0 <= value <= self.fillet_radius_mm):
                    raise ParameterError(f"HemisphereTools: cap_centre_drop_mm = {value} must "
                                         f"lie in [0, fillet_radius_mm = "
                                         f"{self.fillet_radius_mm}]")
                continue
            if not (math.isfinite(value) and value > 0.0):
                raise ParameterError(f"HemisphereTools: {f.name} = {value} must be positive")
        base = self.base_radius_mm
        if not base + self.edge_radius_mm <= self.shoulder_radius_mm <= self.opening_radius_mm:
            raise ParameterError(
                f"HemisphereTools: shoulder_radius_mm = {self.shoulder_radius_mm} must lie "
                f"between the fillet's foot plus the edge radius ({base + self.edge_radius_mm}) "
                f"and the holder opening's radius ({self.opening_radius_mm})")
        if self.ply_thickness_mm >= self.fillet_radius_mm:
            raise ParameterError("HemisphereTools: ply_thickness_mm must be below the fillet "
                                 "radius (the die's lip is the fillet offset by it)")

    @property
    def cap_centre_mm(self) -> float:
        """Height c of the cap's centre above the punch's base plane (mm)."""
        return self.fillet_radius_mm - self.cap_centre_drop_mm

    @property
    def height_mm(self) -> float:
        """Apex-to-base height of the punch (mm)."""
        return self.punch_radius_mm + self.cap_centre_mm

    @property
    def base_radius_mm(self) -> float:
        """Radius r_b of the fillet's foot, where the part meets the base plane (mm)."""
        R, Rf = self.punch_radius_mm, self.fillet_radius_mm
        return math.sqrt((R + Rf) ** 2 - (Rf - self.cap_centre_mm) ** 2)

    @property
    def meridian_mm(self) -> float:
        """Length of the part's meridian from the apex to the fillet's foot (mm)."""
        β = math.asin((self.fillet_radius_mm - self.cap_centre_mm)
                      / (self.punch_radius_mm + self.fillet_radius_mm))
        return (self.punch_radius_mm + self.fillet_radius_mm) * (0.5 * math.pi - β)

    @property
    def opening_radius_mm(self) -> float:
        """Radius of the holder opening (mm)."""
        return 0.5 * self.holder_opening_mm

    def part_profile(self, offset: float = 0.0) -> tuple[Piece, ...]:
        """The formed part's profile (cap, fillet, flange plane) from the apex outwards.

        Offset outward by ``offset`` mm; the material (the punch) lies on the right.
        """
        R, Rf, t, c = self.punch_radius_mm, self.fillet_radius_mm, offset, self.cap_centre_mm
        base = self.base_radius_mm
        β = math.atan2(Rf - c, base)  # the tangent point of cap and fillet, seen from (0, c)
        return (
            Arc((0.0, c), R + t, math.pi / 2, β),
            Arc((base, Rf), Rf - t, math.pi + β, 1.5 * math.pi),
            Segment((base, t), (1e4, t)),
        )

    def punch_profile(self) -> tuple[Piece, ...]:
        """The punch's profile: cap, fillet, shoulder, edge round and cylindrical side.

        Traced from the apex outwards, the material on the right.
        """
        rs, re = self.shoulder_radius_mm, self.edge_radius_mm
        sphere, fillet, _ = self.part_profile()
        base = self.base_radius_mm
        return (
            sphere,
            fillet,
            Segment((base, 0.0), (rs - re, 0.0)),
            Arc((rs - re, -re), re, math.pi / 2, 0.0),
            Segment((rs, -re), (rs, -1e4)),
        )

    def punch(self, duration_s: float) -> RevolvedTool:
        """The punch moving ``travel_mm`` in ``duration_s`` at constant speed.

        Its apex is at z = 0 at t = 0.
        """
        if not duration_s > 0.0:
            raise ParameterError(f"punch: duration_s = {duration_s} must be positive")
        return RevolvedTool("punch", self.punch_profile(), z0_mm=-self.height_mm,
                            speed_mm_per_s=self.travel_mm / duration_s,
                            axis_mm=(self.punch_x_mm, self.punch_y_mm))

    def die(self) -> RevolvedTool:
        """The matched die, fixed at the punch's final position, material above its surface.

        Its profile is the punch's offset by the ply thickness, traced from outside inwards
        so that the die's material lies on the right.
        """
        pieces = []
        for piece in reversed(self.part_profile(self.ply_thickness_mm)):
            if isinstance(piece, Arc):
                pieces.append(Arc(piece.centre, piece.radius, piece.end, piece.start))
            else:
                pieces.append(Segment(piece.b, piece.a))
        return RevolvedTool("die", tuple(pieces), z0_mm=self.travel_mm - self.height_mm)

    def formed_part(self) -> RevolvedTool:
        """The formed part's surface, the one the kinematic drape maps the net onto.

        The punch at its final position, continued by the holder plane z = 0.
        """
        return RevolvedTool("part", self.part_profile(), z0_mm=self.travel_mm - self.height_mm,
                            axis_mm=(self.punch_x_mm, self.punch_y_mm))


class MeshedTool:
    """A rigid tool given by a triangle surface, moving with a rigid motion.

    The gap is the smooth signed distance field of the surface in the tool's own frame
    (:mod:`~fenicsx_drape.forming.tools.distance`: a cubic B-spline of exact distances, C², so the
    penalty Jacobian stays consistent and symmetric), carried along by the motion
    (:mod:`~fenicsx_drape.forming.tools.motion`): with X = R(t)ᵀ (x − c − T(t)) + c,

        φ(x, t) = φ₀(X),   ∇φ = R ∇φ₀,   ∇∇φ = R ∇∇φ₀ Rᵀ.

    Args:
        name: The tool's name.
        surface: Its :class:`~fenicsx_drape.forming.tools.surfaces.TriangleSurface` (normals out of
            the tool, towards the sheet).
        motion: Its :class:`~fenicsx_drape.forming.tools.motion.RigidMotion` (default: fixed).
        spacing_mm: Grid spacing h of the distance field (default: the tool mesh size).
        band_mm: Band of exact distances (default 3 mm + 2h).
        cache: Keep the built field on disk.
        comm: MPI communicator for building the field once (default: the world).
    """

    def __init__(self, name: str, surface, motion=None, *, spacing_mm: float | None = None,
                 band_mm: float | None = None, cache: bool = True, comm=None) -> None:
        from fenicsx_drape.forming.tools.distance import distance_field
        from fenicsx_drape.forming.tools.motion import RigidMotion

        if comm is None:
            try:
                from mpi4py import MPI

                comm = MPI.COMM_WORLD
            except ImportError:
                comm = None
        self.name = str(name)
        self.surface = surface
        self.motion = motion if motion is not None else RigidMotion.fixed()
        self.field = distance_field(surface, spacing_mm, band_mm, cache=cache, comm=comm)
        self._flat: bool | None = None

    def __repr__(self) -> str:
        return (f"MeshedTool({self.name!r}, {self.surface!r}, h = {self.field.h:g} mm, "
                f"band = {self.field.band_mm:g} mm)")

    @property
    def flat(self) -> bool:
        """Whether the surface is a plane (then a holder on it has a symmetric stiffness).

        A flat clamping surface is solved as the closed-form plate is (symmetric LDLᵀ,
        :func:`~fenicsx_drape.forming.running.run.run_case`); its field is then linear up to the
        float32 rounding of the coefficients (open edges continued, ``forming.distance``).
        """
        if self._flat is None:
            nf = self.surface.face_normals
            nf = nf[np.linalg.norm(nf, axis=1) > 0.5]
            self._flat = bool(len(nf)) and bool(np.all(nf @ nf[0] > 1.0 - 1e-9))
        return self._flat

    def gap(self, x: np.ndarray, t: float) -> Gap:
        """Signed gap, normal and curvature at the positions ``x`` (n, 3) in mm at time ``t``."""
        X = self.motion.inverse(x, t)
        phi, grad, hess = self.field.evaluate(X)
        if self.motion.rotation_deg is not None:
            R, _ = self.motion.at(t)
            grad = grad @ R.T
            hess = np.einsum("ij,njk,lk->nil", R, hess, R)
        return Gap(phi, grad, hess)

    def displacement(self, x: np.ndarray, t0: float, t1: float) -> np.ndarray:
        """How far (n, 3) the tool's material point at ``x`` at ``t1`` moved since ``t0`` (mm)."""
        return self.motion.displacement(x, t0, t1)

    def closest(self, x: np.ndarray, t: float):
        """Exact closest points (n, 3) at time ``t``, distances (n,) and ``on_boundary`` (n,)."""
        q, d, on_boundary = self.surface.closest(self.motion.inverse(x, t))
        return self.motion.apply(q, t), d, on_boundary

    def covers(self, x: np.ndarray, t: float, reach_mm: float | None = None) -> np.ndarray:
        """The nodes *under* the surface: near it, and their closest point not on its edge.

        For a clamping surface these are the nodes between its plates, not beyond its edge
        or in its opening, nor far from it (farther than ``reach_mm``, default the field's
        band, ≥ 3 mm). Exact (closest-point search, for the nodes within reach): meant for
        once per converged step, not every iterate.
        """
        X = self.motion.inverse(x, t)
        reach = self.field.band_mm if reach_mm is None else float(reach_mm)
        near = np.abs(self.field.evaluate(X, order=0)[0]) < min(reach, self.field.band_mm)
        if reach > self.field.band_mm:  # beyond the band the field cannot tell: measure
            near = np.ones(len(X), dtype=bool)
        out = np.zeros(len(X), dtype=bool)
        if near.any():
            _, d, on_boundary = self.surface.closest(X[near])
            out[near] = ~on_boundary & (d < reach)
        return out

    def signed_distance(self, x: np.ndarray, t: float) -> np.ndarray:
        """The exact signed distance (n,) in mm (no smoothing; see ``gap`` for contact)."""
        return self.surface.signed_distance(self.motion.inverse(x, t))
