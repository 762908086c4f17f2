"""Prescribed rigid motion of a forming tool: a table of time → translation and rotation.

A tool's geometry is given in its own frame (the coordinates of its geometry file). At time t
a material point X of the tool is at

    x = R(t) (X − c) + c + T(t),

with T(t) = (x_mm, y_mm, z_mm) the translation, R(t) the rotation by ``rotation_deg`` about
the fixed unit ``axis`` through ``centre_mm`` (Rodrigues' formula), c = ``centre_mm``. Both
are piecewise linear in time between the rows of the table (the angle is interpolated, so a
rotation row by row is a turn at constant angular speed) and constant before the first and
after the last row: the tool rests there. A tool without a table does not move
(:meth:`RigidMotion.fixed`).

The tool friction of :mod:`~fenicsx_drape.forming.terms.contact` measures the slip of a node
relative to the tool's material point under it, :meth:`RigidMotion.displacement`; for a rigid
motion this displacement is an affine function of x.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import numpy as np

from fenicsx_drape.errors import ParameterError

_COLUMNS = ("x_mm", "y_mm", "z_mm", "rotation_deg")


def rotation_matrix(axis: Sequence[float], angle_deg: float) -> np.ndarray:
    """The rotation by ``angle_deg`` about the unit vector along ``axis`` (Rodrigues)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    θ = math.radians(angle_deg)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(θ) * K + (1.0 - math.cos(θ)) * (K @ K)


@dataclasses.dataclass(frozen=True)
class RigidMotion:
    """A piecewise-linear rigid motion (see the module docstring).

    Args:
        time_s: Times of the rows (s), strictly increasing, at least one.
        x_mm, y_mm, z_mm: Translation at each time (mm); missing columns are zero.
        rotation_deg: Rotation angle at each time (degrees) about ``axis``; None: no rotation.
        axis: Rotation axis (any length but zero).
        centre_mm: A point of the rotation axis (mm).
        where: Prefix of error messages (e.g. ``"case.toml: [[tool]] 2 [tool.motion]"``).

    Raises:
        ParameterError: naming the offending key (lengths, order of times, non-finite values).
    """

    time_s: tuple[float, ...] = (0.0,)
    x_mm: tuple[float, ...] | None = None
    y_mm: tuple[float, ...] | None = None
    z_mm: tuple[float, ...] | None = None
    rotation_deg: tuple[float, ...] | None = None
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    centre_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    where: str = dataclasses.field(default="motion", compare=False)

    def __post_init__(self) -> None:
        w = self.where
        t = self._column("time_s", self.time_s)
        if len(t) == 0:
            raise ParameterError(f"{w}: 'time_s' is empty")
        if np.any(np.diff(t) <= 0.0):
            k = int(np.flatnonzero(np.diff(t) <= 0.0)[0])
            raise ParameterError(f"{w}: 'time_s' must increase strictly ({t[k]:g} s is "
                                 f"followed by {t[k + 1]:g} s)")
        object.__setattr__(self, "time_s", tuple(float(v) for v in t))
        for name in _COLUMNS:
            value = getattr(self, name)
            if value is None:
                if name != "rotation_deg":
                    object.__setattr__(self, name, (0.0,) * len(t))
                continue
            col = self._column(name, value)
            if len(col) != len(t):
                raise ParameterError(f"{w}: '{name}' has {len(col)} values, 'time_s' has "
                                     f"{len(t)}")
            object.__setattr__(self, name, tuple(float(v) for v in col))
        for name, n in (("axis", 3), ("centre_mm", 3)):
            v = self._column(name, getattr(self, name))
            if len(v) != n:
                raise ParameterError(f"{w}: '{name}' needs {n} numbers, got {len(v)}")
            object.__setattr__(self, name, tuple(float(c) for c in v))
        if self.rotation_deg is not None and not np.linalg.norm(self.axis) > 0.0:
            raise ParameterError(f"{w}: 'axis' = {list(self.axis)} has no direction")

    def _column(self, name: str, value) -> np.ndarray:
        try:
            a = np.atleast_1d(np.asarray(value, dtype=float))
        except (TypeError, ValueError):
            raise ParameterError(f"{self.where}: '{name}' must be a list of numbers, got "
                                 f"{value!r}") from None
        if a.ndim != 1:
            raise ParameterError(f"{self.where}: '{name}' must be a flat list of numbers")
        if not np.all(np.isfinite(a)):
            raise ParameterError(f"{self.where}: '{name}' has a value that is not a finite "
                                 f"number: {a.tolist()}")
        return a

    @classmethod
    def fixed(cls) -> RigidMotion:
        """The identity motion: the tool stays where its geometry file puts it."""
        return cls()

    @classmethod
    def from_table(cls, table: Mapping, where: str = "motion") -> RigidMotion:
        """A motion from a case file's ``[tool.motion]`` table; unknown keys are errors."""
        known = {"time_s", *_COLUMNS, "axis", "centre_mm"}
        unknown = sorted(set(table) - known)
        if unknown:
            raise ParameterError(f"{where}: unknown key(s) {unknown} (known: {sorted(known)})")
        if "time_s" not in table:
            raise ParameterError(f"{where}: 'time_s' is missing")
        return cls(**dict(table), where=where)

    @property
    def is_fixed(self) -> bool:
        """True when the tool never moves."""
        cols = [self.x_mm, self.y_mm, self.z_mm, self.rotation_deg or (0.0,)]
        return all(not np.any(np.asarray(c)) for c in cols)

    def angle_deg(self, t: float) -> float:
        """The rotation angle (degrees) at time ``t`` (s)."""
        if self.rotation_deg is None:
            return 0.0
        return float(np.interp(t, self.time_s, self.rotation_deg))

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The rotation R (3, 3) and translation T (3,) at time ``t``: x = R (X − c) + c + T."""
        T = self._translation(t).copy()
        if self.rotation_deg is None:
            return np.eye(3), T
        return rotation_matrix(self.axis, self.angle_deg(t)), T

    def _translation(self, t: float) -> np.ndarray:
        """T(t) (read only), kept for the last few times asked.

        A load step asks for the same few times at every contact evaluation.
        """
        known = self.__dict__.setdefault("_known", {})  # not a field: no part of eq, replace()
        T = known.get(t)
        if T is None:
            if len(known) >= 8:
                known.clear()
            T = known[t] = np.array([np.interp(t, self.time_s, c)
                                     for c in (self.x_mm, self.y_mm, self.z_mm)])
        return T

    def apply(self, X: np.ndarray, t: float) -> np.ndarray:
        """Positions (n, 3) at time ``t`` of the tool's material points ``X`` (its own frame)."""
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        if self.rotation_deg is None:
            return X + self._translation(t)
        R, T = self.at(t)
        c = np.asarray(self.centre_mm)
        return (X - c) @ R.T + c + T

    def inverse(self, x: np.ndarray, t: float) -> np.ndarray:
        """The tool-frame coordinates X (n, 3) of the points at ``x`` at time ``t``."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        if self.rotation_deg is None:
            return x - self._translation(t)
        R, T = self.at(t)
        c = np.asarray(self.centre_mm)
        return (x - c - T) @ R + c  # Rᵀ (x − c − T) + c, row by row

    def translation(self, t: float) -> np.ndarray:
        """T(t) (mm)."""
        return self.at(t)[1]

    def max_speed_mm_per_s(self, reach_mm: float = 0.0) -> float:
        """Fastest travel (mm/s) of a point within ``reach_mm`` of the rotation centre."""
        dt = np.diff(self.time_s)
        if not len(dt):
            return 0.0
        d = np.diff(np.column_stack([self.x_mm, self.y_mm, self.z_mm]), axis=0)
        v = np.linalg.norm(d, axis=1) / dt
        if self.rotation_deg is not None:
            v = v + np.radians(np.abs(np.diff(self.rotation_deg))) / dt * reach_mm
        return float(v.max(initial=0.0))

    def travel_mm(self, t: float, reach_mm: float = 0.0) -> float:
        """Distance travelled since t = 0: |T(t) − T(0)| (+ the arc at ``reach_mm``)."""
        d = float(np.linalg.norm(self.translation(t) - self.translation(0.0)))
        return d + math.radians(abs(self.angle_deg(t) - self.angle_deg(0.0))) * reach_mm

    def scaled(self, time: float = 1.0, travel: float = 1.0) -> RigidMotion:
        """The same motion with times × ``time`` and translations and rotations × ``travel``."""
        rot = None if self.rotation_deg is None else tuple(travel * a for a in self.rotation_deg)
        return dataclasses.replace(
            self, time_s=tuple(time * v for v in self.time_s),
            x_mm=tuple(travel * v for v in self.x_mm), y_mm=tuple(travel * v for v in self.y_mm),
            z_mm=tuple(travel * v for v in self.z_mm), rotation_deg=rot)

    def displacement(self, x: np.ndarray, t0: float, t1: float) -> np.ndarray:
        """How far (n, 3) the tool's material point at ``x`` at time ``t1`` moved since ``t0``."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        if self.rotation_deg is None:
            d = self._translation(t1) - self._translation(t0)
            return np.broadcast_to(d, x.shape).copy()
        return x - self.apply(self.inverse(x, t1), t0)
