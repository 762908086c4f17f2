"""The user-material interface: a law is a dataclass with a vectorised update.

A law knows nothing of DOLFINx. Its dataclass fields are of three kinds, declared with
:func:`parameter`, :func:`condition` and :func:`effect`:

- *parameters*: named material constants with a unit and an allowed range, checked on
  construction (a :class:`~fenicsx_drape.errors.ParameterError` names the bad one);
- *conditions*: test conditions such as ``temperature_C``, filled from a test's conditions;
- *effects*: boolean switches named exactly like the effects of the measurement spec
  (``rate_dependence``, ``tow_buckling``, ...), set from a model's effect list.

The update works on arrays shaped ``(n_points,)`` with a state shaped
``(n_points, len(state_names))``::

    stress, tangent, state_new = law.update(strain, dt, state_old)

``strain`` is the Green-Lagrange strain at the end of the step, ``dt`` the step length in s,
``stress`` the force per tow (N/tow), ``tangent`` the consistent algorithmic tangent
dσ/dε (N/tow). The previous strain, if a law needs it for a rate, is part of its state.

Users register a law by name with :func:`register_law`; the name can then appear in a model's
effect list and the law replaces the built-in law of its ``role`` everywhere (unit-cell tests,
the FE solver, diagnosis).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping
from typing import Any, ClassVar, TypeVar

import numpy as np

from fenicsx_drape.errors import DrapeInputError, ParameterError

ROLES = ("tow", "shear", "friction")

_KIND = "fenicsx_drape.kind"


def parameter(
    default: float | Any = dataclasses.MISSING,
    *,
    unit: str,
    bounds: tuple[float, float] = (0.0, math.inf),
    doc: str = "",
) -> Any:
    """A material parameter field: finite, within ``bounds`` (inclusive), in ``unit``.

    A parameter is a float, or an array that broadcasts over the points of an update.
    """
    meta = {_KIND: "parameter", "unit": unit, "bounds": bounds, "doc": doc}
    return dataclasses.field(default=default, metadata=meta)


def condition(default: float, *, unit: str, doc: str = "") -> Any:
    """A test-condition field (e.g. ``temperature_C``), filled from a test's conditions."""
    return dataclasses.field(default=default, metadata={_KIND: "condition", "unit": unit,
                                                        "doc": doc})


def effect(default: bool = True, *, doc: str = "") -> Any:
    """A boolean effect switch; the field name is the effect's name."""
    return dataclasses.field(default=default, metadata={_KIND: "effect", "doc": doc})


def fields_of(cls_or_law: Any, kind: str) -> list[dataclasses.Field]:
    """The dataclass fields of one kind ("parameter", "condition" or "effect")."""
    return [f for f in dataclasses.fields(cls_or_law) if f.metadata.get(_KIND) == kind]


@dataclasses.dataclass
class MaterialLaw:
    """Base of every law (built-in or user). Subclasses are dataclasses (``@dataclass``).

    Subclasses set ``role`` (one of :data:`ROLES`) and ``state_names``, and implement
    :meth:`_update`. The base checks parameters on construction and the inputs and outputs
    of every update, so a user law gets the same clear errors as a built-in one.
    """

    role: ClassVar[str] = ""
    state_names: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        name = type(self).__name__
        for f in fields_of(self, "parameter"):
            value = getattr(self, f.name)
            try:
                array = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                raise ParameterError(f"{name}: parameter {f.name} = {value!r} is not a number") \
                    from None
            lo, hi = f.metadata["bounds"]
            if not np.isfinite(array).all():
                raise ParameterError(f"{name}: parameter {f.name} = {value} is not finite")
            if not ((lo <= array) & (array <= hi)).all():
                raise ParameterError(
                    f"{name}: parameter {f.name} = {value} {f.metadata['unit']} is outside "
                    f"its allowed range [{lo:g}, {hi:g}]"
                )
            # Scalars stay floats; arrays broadcast over the points (e.g. one parameter set
            # per point, to evaluate many parameter sets in one vectorised update).
            setattr(self, f.name, float(array) if array.ndim == 0 else array)
        for f in fields_of(self, "condition"):
            value = getattr(self, f.name)
            try:
                array = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                raise ParameterError(f"{name}: condition {f.name} = {value!r} is not a number") \
                    from None
            if not np.isfinite(array).all():
                raise ParameterError(f"{name}: condition {f.name} = {array} is not finite")
            setattr(self, f.name, float(array) if array.ndim == 0 else array)

    @classmethod
    def active_parameters(cls, effects: Iterable[str] = ()) -> tuple[str, ...]:
        """The parameters that shape the response with these effects on (default: all).

        Laws override this when an effect switches parameters off (e.g. the linear tow
        without ``decrimping`` uses only ``E_inf``); fitting varies exactly these.
        """
        return tuple(f.name for f in fields_of(cls, "parameter"))

    @property
    def parameters(self) -> dict[str, float]:
        """The law's parameters by name."""
        return {f.name: getattr(self, f.name) for f in fields_of(self, "parameter")}

    @property
    def effects(self) -> frozenset[str]:
        """The names of the effects switched on in this law."""
        return frozenset(f.name for f in fields_of(self, "effect") if getattr(self, f.name))

    def initial_state(self, n: int) -> np.ndarray:
        """The virgin state of ``n`` points, shaped ``(n, len(state_names))``."""
        return np.zeros((n, len(self.state_names)))

    def update(
        self, strain: np.ndarray, dt: float, state: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stress, consistent tangent and new state at the end of a step of length ``dt`` (s).

        Raises:
            ValueError: on NaN or infinite strains, a negative step or a wrong state shape,
                and when the law itself returns a non-finite stress or tangent.
        """
        strain = np.asarray(strain, dtype=float)
        state = np.asarray(state, dtype=float)
        name = type(self).__name__
        if strain.ndim != 1:
            raise ValueError(f"{name}.update: strain must be shaped (n_points,), "
                             f"got {strain.shape}")
        bad = ~np.isfinite(strain)
        if bad.any():
            raise ValueError(f"{name}.update: strain is not finite at {bad.sum()} point(s), "
                             f"first at index {int(np.argmax(bad))}")
        if not (math.isfinite(dt) and dt >= 0.0):
            raise ValueError(f"{name}.update: time step dt = {dt} s must be finite and >= 0")
        expected = (strain.shape[0], len(self.state_names))
        if state.shape != expected:
            raise ValueError(f"{name}.update: state shaped {state.shape}, expected {expected} "
                             f"({', '.join(self.state_names) or 'no internal variables'})")
        stress, tangent, new_state = self._update(strain, float(dt), state)
        for what, arr in (("stress", stress), ("tangent", tangent), ("state", new_state)):
            bad = ~np.isfinite(arr)
            if bad.any():
                raise ValueError(f"{name}.update: the law returned a non-finite {what} "
                                 f"(e.g. at point {int(np.argwhere(bad)[0][0])})")
        return stress, tangent, new_state

    def _update(
        self, strain: np.ndarray, dt: float, state: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError


L = TypeVar("L", bound=type[MaterialLaw])

_REGISTRY: dict[str, type[MaterialLaw]] = {}


def register_law(name: str, *, replace: bool = False) -> Callable[[L], L]:
    """Class decorator registering a law under ``name`` (its effect name in a model).

    Example::

        @register_law("power_law_viscosity")
        @dataclass
        class PowerLawShear(MaterialLaw):
            role = "shear"
            ...
    """

    def decorate(cls: L) -> L:
        if not (isinstance(cls, type) and issubclass(cls, MaterialLaw)):
            raise TypeError(f"register_law({name!r}): {cls!r} is not a MaterialLaw subclass")
        if not dataclasses.is_dataclass(cls):
            raise TypeError(f"register_law({name!r}): {cls.__name__} must be a @dataclass")
        if cls.role not in ROLES:
            raise TypeError(f"register_law({name!r}): role {cls.role!r} not in {ROLES}")
        old = _REGISTRY.get(name)
        if old is not None and old is not cls and not replace:
            same = (old.__module__, old.__qualname__) == (cls.__module__, cls.__qualname__)
            if not same:  # re-loading the same plugin file is fine
                raise ValueError(f"a law named {name!r} is already registered ({old.__name__})")
        _REGISTRY[name] = cls
        return cls

    return decorate


def get_law(name: str) -> type[MaterialLaw]:
    """The law class registered under ``name``."""
    try:
        return _REGISTRY[name]
    except KeyError:
        known = ", ".join(sorted(_REGISTRY)) or "none"
        raise DrapeInputError(f"unknown law {name!r} (registered laws: {known})") from None


def registered_laws(role: str | None = None) -> dict[str, type[MaterialLaw]]:
    """The registered laws by name, optionally only those of one role."""
    return {n: c for n, c in _REGISTRY.items() if role is None or c.role == role}


def build_law(
    cls: type[MaterialLaw] | str,
    parameters: Mapping[str, float],
    effects: Iterable[str] = (),
    conditions: Mapping[str, float] | None = None,
) -> MaterialLaw:
    """Construct a law from a model's parameters, effect names and a test's conditions.

    Parameters the law does not use are ignored; a parameter it needs and that has no
    default is an error naming it.
    """
    if isinstance(cls, str):
        cls = get_law(cls)
    effects = set(effects)
    conditions = dict(conditions or {})
    kwargs: dict[str, Any] = {}
    for f in fields_of(cls, "parameter"):
        if f.name in parameters:
            kwargs[f.name] = parameters[f.name]
        elif f.default is dataclasses.MISSING:
            raise ParameterError(f"{cls.__name__}: missing parameter {f.name} "
                                 f"({f.metadata['unit']})")
    for f in fields_of(cls, "condition"):
        if f.name in conditions:
            kwargs[f.name] = conditions[f.name]
    for f in fields_of(cls, "effect"):
        kwargs[f.name] = f.name in effects
    return cls(**kwargs)
