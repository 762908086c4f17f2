"""A model: which effects are on, the parameter values, user plugins and fixed parameters.

A :class:`Model` is what ``MODEL.toml`` holds (measurement spec)::

    effects = ["rate_dependence", "strain_dependent_viscosity", "decrimping", "tow_buckling"]
    plugins = ["my_laws.py"]        # relative to MODEL.toml; they register user laws
    [parameters]                    # starting or fixed values; the rest from Table 2
    sigma_o = 0.0262
    [fit]
    fixed = ["E_p"]
    [noise]                         # optional: the noise of tables that carry none
    force_sd_rel = 0.02             # (one standard deviation: force_sd_N in N, or this
                                    #  fraction of each coupon test's peak force)

:meth:`Model.laws` builds the law of each role (``tow``, ``shear``, ``friction``): the paper's
law, unless a registered user law whose name is among the effects replaces it. Parameters
default to :func:`default_parameters` (Table 2, ``fenicsx_drape/data/table2.toml``) and to the
defaults a user law declares. Parameter values may be NumPy arrays of one shape ``(k,)``: the
model then stands for ``k`` parameter sets evaluated together (vectorised fitting).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import re
import sys
import tomllib
import types
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fenicsx_drape.effects import (
    COUPON_KINDS,
    EFFECTS,
    EXTRA_PARAMETERS,
    ParameterInfo,
    describe_effect,
    effect_names,
)
from fenicsx_drape.errors import DrapeInputError, ParameterError
from fenicsx_drape.materials import (
    BUILT_IN_LAWS,
    ROLES,
    MaterialLaw,
    build_law,
    fields_of,
    get_law,
    registered_laws,
)
from fenicsx_drape.trust import require_trust

PAPER_EFFECTS = ("rate_dependence", "strain_dependent_viscosity", "decrimping", "tow_buckling",
                 "holder_friction")
"""The effects of the paper: its four coupon effects and the blank-holder friction."""

_TABLE2 = Path(__file__).parent / "data" / "table2.toml"

NOISE_KEYS = ("force_sd_N", "force_sd_rel")
"""MODEL.toml [noise] keys (an addition to the spec): a declared noise for coupon tables."""


@functools.cache
def _table2() -> dict[str, dict[str, Any]]:
    with open(_TABLE2, "rb") as f:
        return tomllib.load(f)


def default_parameters() -> dict[str, float]:
    """The paper's material (Table 2) plus the defaults of the extra effects, by name."""
    return {name: float(entry["value"]) for name, entry in _table2().items()}


def parameter_info(name: str) -> ParameterInfo:
    """Unit, allowed range, description and default of a parameter of any law or effect."""
    entry = _table2().get(name, {})
    laws = sorted(registered_laws().values(),
                  key=lambda c: not c.__module__.startswith("fenicsx_drape."))
    for law in laws:
        for f in fields_of(law, "parameter"):
            if f.name == name:
                default = entry.get("value", None if f.default is dataclasses.MISSING
                                    else f.default)
                return ParameterInfo(name, f.metadata["unit"], f.metadata["bounds"],
                                     entry.get("description", f.metadata["doc"]),
                                     None if default is None else float(default))
    if name in EXTRA_PARAMETERS:
        info = EXTRA_PARAMETERS[name]
        return dataclasses.replace(info, default=entry.get("value", info.default))
    raise ParameterError(f"unknown parameter {name!r} (known: {', '.join(known_parameters())})")


def known_parameters() -> tuple[str, ...]:
    """Every parameter name a model may set (Table 2, extra effects, registered laws)."""
    names = dict.fromkeys(_table2())
    for law in registered_laws().values():
        names.update(dict.fromkeys(f.name for f in fields_of(law, "parameter")))
    names.update(dict.fromkeys(EXTRA_PARAMETERS))
    return tuple(names)


_PLUGINS: dict[Path, Any] = {}


def load_plugin(path: str | Path) -> Any:
    """Import a Python file that registers user laws (once per resolved path)."""
    path = Path(path).resolve()
    if path in _PLUGINS:
        return _PLUGINS[path]
    if not path.is_file():
        raise DrapeInputError(f"plugin {path} does not exist")
    digest = hashlib.sha1(str(path).encode()).hexdigest()[:10]
    stem = re.sub(r"\W", "_", path.stem)
    name = f"fenicsx_drape_plugin_{stem}_{digest}"
    module = types.ModuleType(name)
    module.__file__ = str(path)
    sys.modules[name] = module
    try:
        # Compiled from its text: no __pycache__ written into the input's folder.
        exec(compile(path.read_text(encoding="utf-8"), str(path), "exec"), module.__dict__)
    except Exception as err:
        del sys.modules[name]
        raise DrapeInputError(f"plugin {path} failed to load: {type(err).__name__}: {err}") \
            from err
    _PLUGINS[path] = module
    return module


def _as_value(name: str, value: Any) -> float | np.ndarray:
    if isinstance(value, bool):
        raise ParameterError(f"parameter {name} = {value!r} is not a number")
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"parameter {name} = {value!r} is not a number") from None
    if array.ndim > 1:
        raise ParameterError(f"parameter {name}: arrays of parameter sets must be 1-D, got "
                             f"shape {array.shape}")
    return float(array) if array.ndim == 0 else array


@dataclasses.dataclass(frozen=True)
class Model:
    """Effects, parameters, plugins and fixed parameters of a model (see the module doc).

    Args:
        effects: Effect names (catalogue names and registered user laws), order kept.
        parameters: Values by name; missing ones take their defaults.
        plugins: Python files that register user laws; imported on construction.
        fixed: Parameters held at their value when fitting.
        noise: A declared measurement noise for coupon tables without ``force_sd_N`` (and
            without a declaration in bundle.toml): ``force_sd_N`` (N) or ``force_sd_rel``
            (fraction of each test's peak force). An addition to the spec's MODEL.toml.

    Raises:
        DrapeInputError: an unknown effect, parameter or fixed name, two user laws of one
            role, or a plugin that does not load.
        ParameterError: a parameter that is not a number or is outside its range.
    """

    effects: tuple[str, ...] = ()
    parameters: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    plugins: tuple[Path, ...] = ()
    fixed: tuple[str, ...] = ()
    noise: Mapping[str, float] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        if isinstance(self.effects, str) or isinstance(self.fixed, str):
            raise DrapeInputError("effects and fixed are lists of names, not one string")
        plugins = tuple(Path(p).resolve() for p in self.plugins)
        for path in plugins:
            load_plugin(path)
        effects = tuple(dict.fromkeys(self.effects))
        known = effect_names()
        for name in effects:
            if name not in known:
                raise DrapeInputError(f"unknown effect {name!r} (known: {', '.join(known)})")
        object.__setattr__(self, "effects", effects)
        object.__setattr__(self, "plugins", plugins)
        classes = self.law_classes()  # checks one law per role
        values = default_parameters()
        # An effect's parameters outside Table 2 (the inter-ply law's) exist with the effect.
        for name in effects:
            for p in EFFECTS[name].parameters if name in EFFECTS else ():
                if p not in values and p in EXTRA_PARAMETERS:
                    values[p] = EXTRA_PARAMETERS[p].default
        for cls in classes.values():
            for f in fields_of(cls, "parameter"):
                if f.name not in values and f.default is not dataclasses.MISSING:
                    values[f.name] = f.default
        allowed = set(known_parameters())
        for name, value in self.parameters.items():
            if name not in allowed:
                raise ParameterError(f"unknown parameter {name!r} "
                                     f"(known: {', '.join(known_parameters())})")
            values[name] = _as_value(name, value)
        shapes = {np.shape(v) for v in values.values()} - {()}
        if len(shapes) > 1:
            raise ParameterError(f"parameter arrays of different shapes {sorted(shapes)}")
        object.__setattr__(self, "parameters", values)
        fixed = tuple(dict.fromkeys(self.fixed))
        for name in fixed:
            if name not in values:
                raise ParameterError(f"fixed parameter {name!r} is not a parameter of the "
                                     "model")
        object.__setattr__(self, "fixed", fixed)
        noise = dict(self.noise)
        for key, value in noise.items():
            if key not in NOISE_KEYS:
                raise DrapeInputError(f"unknown [noise] key {key!r} (expected "
                                      f"{' or '.join(NOISE_KEYS)})")
            if isinstance(value, bool) or not (isinstance(value, (int, float))
                                               and 0 < value < np.inf):
                raise DrapeInputError(f"[noise] {key} = {value!r} must be a positive number")
        if len(noise) > 1:
            raise DrapeInputError("[noise]: give force_sd_N or force_sd_rel, not both")
        object.__setattr__(self, "noise", {k: float(v) for k, v in noise.items()})
        for name in (n for n in EXTRA_PARAMETERS if n in values):
            lo, hi = parameter_info(name).bounds
            value = np.asarray(values[name])
            if not (np.isfinite(value).all() and ((lo <= value) & (value <= hi)).all()):
                raise ParameterError(f"parameter {name} = {values[name]} "
                                     f"{parameter_info(name).unit} is outside its allowed "
                                     f"range [{lo:g}, {hi:g}]")
        self.laws()  # every law checks its parameters' ranges

    @property
    def n_sets(self) -> int | None:
        """The number k of parameter sets when parameters are arrays of shape (k,), else None."""
        shapes = {np.shape(v) for v in self.parameters.values()} - {()}
        return next(iter(shapes))[0] if shapes else None

    def law_classes(self) -> dict[str, type[MaterialLaw]]:
        """The law class of each role: a user law named in the effects, else the paper's."""
        chosen = {role: get_law(name) for role, name in BUILT_IN_LAWS.items()}
        replaced: dict[str, str] = {}
        for name in self.effects:
            if name in EFFECTS:
                continue
            cls = get_law(name)
            if cls.role in replaced:
                raise DrapeInputError(f"effects {replaced[cls.role]!r} and {name!r} are both "
                                      f"{cls.role} laws; a model takes one law per role")
            replaced[cls.role] = name
            chosen[cls.role] = cls
        return {role: chosen[role] for role in ROLES}

    def laws(self, conditions: Mapping[str, float] | None = None) -> dict[str, MaterialLaw]:
        """The law of each role built with this model's parameters and effects.

        Args:
            conditions: A test's conditions (e.g. ``temperature_C``); others are ignored.
        """
        return {role: build_law(cls, self.parameters, self.effects, conditions)
                for role, cls in self.law_classes().items()}

    def with_effects(self, *names: str) -> Model:
        """This model with more effects switched on."""
        return dataclasses.replace(self, effects=(*self.effects, *names))

    def without_effects(self, *names: str) -> Model:
        """This model with effects switched off (unknown names are an error)."""
        for name in names:
            if name not in effect_names():
                raise DrapeInputError(f"unknown effect {name!r}")
        return dataclasses.replace(self, effects=tuple(e for e in self.effects
                                                       if e not in names))

    def with_parameters(self, **values: Any) -> Model:
        """This model with some parameter values replaced."""
        return dataclasses.replace(self, parameters={**self.parameters, **values})

    def active_parameters(self, kinds: Iterable[str] | None = None) -> tuple[str, ...]:
        """The parameters that shape this model's response, minus the fixed ones.

        The union of each law's ``active_parameters(effects)`` and the parameters of the
        model's effects that act outside the laws (contact, the cell coupling).

        Args:
            kinds: Only parameters that tests of these kinds can exercise (e.g.
                ``("tensile", "bias_extension")`` leaves out the friction parameters).
        """
        kinds = set(kinds) if kinds is not None else None
        names: dict[str, None] = {}
        for role, cls in self.law_classes().items():
            if kinds is not None and role == "friction" and not kinds - set(COUPON_KINDS):
                continue
            names.update(dict.fromkeys(cls.active_parameters(self.effects)))
        for name in self.effects:
            effect = describe_effect(name)
            if kinds is not None and not kinds & set(effect.test_kinds):
                continue
            names.update(dict.fromkeys(p for p in effect.parameters if p in EXTRA_PARAMETERS))
        return tuple(n for n in names if n not in self.fixed)

    def to_toml(self, relative_to: str | Path | None = None) -> str:
        """The model as MODEL.toml text, loadable by :func:`load_model`.

        Args:
            relative_to: Folder the TOML file will be in: plugin paths are written relative
                to it (absolute otherwise).
        """
        if self.n_sets is not None:
            raise ValueError("a model with arrays of parameter sets has no single MODEL.toml")
        from fenicsx_drape.provenance import toml_text

        data: dict = {"effects": list(self.effects)}
        if self.plugins:
            data["plugins"] = [str(_relative(p, relative_to)) for p in self.plugins]
        data["parameters"] = {n: float(v) for n, v in self.parameters.items()}
        if self.fixed:
            data["fit"] = {"fixed": list(self.fixed)}
        if self.noise:
            data["noise"] = dict(self.noise)
        units = {("parameters", n): _unit(n) for n in self.parameters if _unit(n)}
        return toml_text(data, comment="fenicsx_drape model (MODEL.toml)", notes=units)


def _unit(name: str) -> str:
    try:
        return parameter_info(name).unit
    except ParameterError:
        return ""


def _relative(path: Path, folder: str | Path | None) -> Path:
    if folder is None:
        return path
    try:
        return path.relative_to(Path(folder).resolve())
    except ValueError:
        return path


def default_model() -> Model:
    """The paper's model: its four coupon effects, holder friction, Table 2 values."""
    return Model(effects=PAPER_EFFECTS, parameters=default_parameters())


def load_model(path: str | Path, origin: str | None = None) -> Model:
    """Read a MODEL.toml (measurement spec). Plugins are relative to the file.

    A model the user names runs its plugins; one that comes with data (``origin``, e.g. the
    case of a measurement bundle) runs them only when trusted (:mod:`fenicsx_drape.trust`).

    Raises:
        DrapeInputError: naming the file (and line) for a missing file, bad TOML, an unknown
            key, effect or parameter, or a bad value.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise DrapeInputError(f"{path}: cannot read the model: {err.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise DrapeInputError(f"{path}: not valid TOML: {err}") from None

    def fail(key: str, problem: str) -> DrapeInputError:
        line = _line_of(text, key)
        where = f"{path}:{line}" if line else f"{path}"
        return DrapeInputError(f"{where}: {problem}")

    for key in data:
        if key not in ("effects", "plugins", "parameters", "fit", "noise"):
            raise fail(key, f"unknown key {key!r} (expected effects, plugins, parameters, fit, "
                            "noise)")
    effects = data.get("effects", [])
    plugins = data.get("plugins", [])
    parameters = data.get("parameters", {})
    fit = data.get("fit", {})
    noise = data.get("noise", {})
    for key, value, kind in (("effects", effects, list), ("plugins", plugins, list),
                             ("parameters", parameters, dict), ("fit", fit, dict),
                             ("noise", noise, dict)):
        if not isinstance(value, kind):
            raise fail(key, f"{key} must be a {'list' if kind is list else 'table'}")
    for key in fit:
        if key != "fixed":
            raise fail(key, f"unknown key [fit] {key!r} (expected fixed)")
    fixed = fit.get("fixed", [])
    for key, names in (("effects", effects), ("plugins", plugins), ("fixed", fixed)):
        if not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
            raise fail(key, f"{key} must be a list of strings")
    plugin_paths = tuple(path.parent / p for p in plugins)
    for given, full in zip(plugins, plugin_paths):
        if not full.is_file():
            raise fail(given, f"plugin {given!r} not found (looked for {full.resolve()})")
    for path_ in plugin_paths:
        require_trust(path_, f"a plugin of the model {path}", origin)
        try:
            load_plugin(path_)
        except DrapeInputError as err:
            raise fail(path_.name, str(err)) from err.__cause__
    known = effect_names()
    for name in effects:
        if name not in known:
            raise fail(name, f"unknown effect {name!r} (known: {', '.join(known)})")
    allowed = set(known_parameters())
    for name in (*parameters, *fixed):
        if name not in allowed:
            raise fail(name, f"unknown parameter {name!r} "
                             f"(known: {', '.join(known_parameters())})")
    try:
        return Model(tuple(effects), parameters, plugin_paths, tuple(fixed), noise)
    except DrapeInputError as err:
        name = re.search(r"parameter (\w+)|\[noise\] (\w+)", str(err))
        key = (name.group(1) or name.group(2)) if name else (
            "noise" if "[noise]" in str(err) else "parameters")
        raise fail(key, str(err)) from None


def _line_of(text: str, key: str) -> int | None:
    """The first line of ``text`` that mentions ``key`` as a key or a quoted name."""
    pattern = re.compile(rf'^\s*{re.escape(key)}\s*=|"{re.escape(key)}"')
    for number, line in enumerate(text.splitlines(), start=1):
        if pattern.search(line.split("#", 1)[0]):
            return number
    return None


__all__ = [
    "PAPER_EFFECTS",
    "Model",
    "default_model",
    "default_parameters",
    "known_parameters",
    "load_model",
    "load_plugin",
    "parameter_info",
]

