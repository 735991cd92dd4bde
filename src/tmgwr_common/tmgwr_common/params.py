"""Hyperparameters: one declaration per parameter, shared by the core and the ROS nodes.

A module's hyperparameters are the fields of one frozen dataclass (the way cleanrl builds
its ``Args``); each field is declared once with :func:`param`: its default (Table 2 of the
paper where it gives one), its valid range and a description::

    @dataclass(frozen=True)
    class MotivationConfig(Config):
        gamma: float = param(0.97, "Eq. 5: discount factor (Table 2)", low=0.0, high=1.0,
                             low_open=True, high_open=True)

* the core's constructors take such a config (``MotivationEstimator(MotivationConfig())``),
  built by :func:`make_config` from a dict of overrides: every value is checked against
  its range and an unknown name is refused naming the nearest known one;
* :func:`specs` derives the :class:`Param` declarations from the fields; the ROS nodes
  declare them with descriptors built from the same declarations
  (:func:`tmgwr_common.node.declare_parameters`), so a default or a range is written once.

Parameter files are optional and hold only overrides, in the ROS 2 layout
(``/**: ros__parameters: {gamma: 0.9}`` or per-node sections); :func:`read_params_file`
reads one with ``file:line:col`` errors and refuses the old layout (values nested under a
``tmgwr:`` key) with the way to convert it.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, TypeVar

import yaml


class ParamError(ValueError):
    """An invalid parameter; the message names the parameter and where it came from."""


@dataclass(frozen=True)
class Param:
    name: str
    default: Any
    description: str
    low: float | None = None          # inclusive unless low_open
    high: float | None = None         # inclusive unless high_open
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] | None = None
    integer: bool = False

    def check(self, value: Any, where: str = "") -> Any:
        """Return the value converted to the declared type, or raise ParamError."""
        loc = f"{where}: " if where else ""
        if self.choices is not None:
            if value not in self.choices:
                raise ParamError(f"{loc}parameter '{self.name}' must be one of "
                                 f"{list(self.choices)}, got {value!r}")
            return value
        if isinstance(self.default, bool):
            if not isinstance(value, bool):
                raise ParamError(f"{loc}parameter '{self.name}' must be true or false, "
                                 f"got {value!r}")
            return value
        if isinstance(self.default, tuple):   # a list of strings (topic names...)
            if not (isinstance(value, (list, tuple))
                    and all(isinstance(v, str) for v in value)):
                raise ParamError(f"{loc}parameter '{self.name}' must be a list of strings, "
                                 f"got {value!r}")
            return tuple(value)
        if isinstance(self.default, str):     # free-form text (paths, names)
            if isinstance(value, int) and not isinstance(value, bool):
                value = str(value)            # `-p goal:=2` arrives as an integer
            if not isinstance(value, str):
                raise ParamError(f"{loc}parameter '{self.name}' must be a string, "
                                 f"got {value!r}")
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParamError(f"{loc}parameter '{self.name}' must be a number, got {value!r}")
        if self.integer:
            if float(value) != int(value):
                raise ParamError(f"{loc}parameter '{self.name}' must be an integer, "
                                 f"got {value!r}")
            value = int(value)
        else:
            value = float(value)
        if not math.isfinite(value):
            raise ParamError(f"{loc}parameter '{self.name}' must be finite, got {value!r}")
        if self.low is not None and (value < self.low or (self.low_open and value == self.low)):
            raise ParamError(f"{loc}parameter '{self.name}' = {value!r} is out of range "
                             f"{self.range_text()}")
        if self.high is not None and (value > self.high or
                                      (self.high_open and value == self.high)):
            raise ParamError(f"{loc}parameter '{self.name}' = {value!r} is out of range "
                             f"{self.range_text()}")
        return value

    def range_text(self) -> str:
        lo = "(" if self.low_open else "["
        hi = ")" if self.high_open else "]"
        a = "-inf" if self.low is None else f"{self.low:g}"
        b = "inf" if self.high is None else f"{self.high:g}"
        return f"{lo}{a}, {b}{hi}"


# ----------------------------------------------------------------------------- configs
_PARAM = "tmgwr_param"        # dataclasses.field metadata key of a param() field


def param(default: Any, description: str, *, low: float | None = None,
          high: float | None = None, low_open: bool = False, high_open: bool = False,
          choices: tuple[str, ...] | None = None, integer: bool = False) -> Any:
    """A config field: its default, description and range, declared once."""
    return dataclasses.field(default=default, metadata={_PARAM: dict(
        description=description, low=low, high=high, low_open=low_open,
        high_open=high_open, choices=choices, integer=integer)})


class Config:
    """Base of the hyperparameter dataclasses (declare them ``@dataclass(frozen=True)``).

    Every value is checked on construction, so ``XConfig(gamma=2.0)`` is refused like a
    bad parameter file; :func:`make_config` adds the refusal of unknown names.
    """

    def __post_init__(self):
        for p in specs(type(self)):
            object.__setattr__(self, p.name, p.check(getattr(self, p.name),
                                                     type(self).__name__))

    def as_dict(self) -> dict[str, Any]:
        return {p.name: getattr(self, p.name) for p in specs(type(self))}


C = TypeVar("C", bound=Config)


def specs(*groups: type[Config] | Iterable[Param]) -> tuple[Param, ...]:
    """The Param declarations of config classes (their param() fields, in order) and of
    plain Param tuples, concatenated."""
    out: list[Param] = []
    for g in groups:
        if isinstance(g, type) and dataclasses.is_dataclass(g):
            out += [Param(f.name, f.default, **f.metadata[_PARAM])
                    for f in dataclasses.fields(g) if _PARAM in f.metadata]
        else:
            out += list(g)
    return tuple(out)


def make_config(cls: type[C], overrides: Mapping[str, Any] | None = None,
                where: str = "") -> C:
    """``cls`` with its defaults updated by ``overrides``, every value checked and an
    unknown name refused (naming the nearest known one)."""
    return cls(**resolve(specs(cls), overrides, where))


# ----------------------------------------------------------------------------- names
def unknown_name_message(name: str, known: Iterable[str], where: str = "",
                         origin: str = "") -> str:
    """'unknown parameter 'gama' (did you mean 'gamma'?)', with the old-layout hint for
    a name nested under a section ('tmgwr.gamma'); ``origin`` says where it was set."""
    known = sorted(set(known))
    loc = f"{where}: " if where else ""
    section, dot, leaf = name.rpartition(".")
    if origin:
        origin = f" ({origin})"
    if dot and leaf in known:
        return (f"{loc}unknown parameter '{name}'{origin}: '{leaf}' is nested under "
                f"'{section}:' "
                f"(the old parameter-file layout); write '{leaf}' directly under "
                f"'ros__parameters:' (e.g. '/**:\\n  ros__parameters:\\n    {leaf}: ...')")
    close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    if close:
        return f"{loc}unknown parameter '{name}'{origin} (did you mean '{close[0]}'?)"
    return f"{loc}unknown parameter '{name}'{origin}; known: {', '.join(known)}"


def resolve(specs: Iterable[Param], overrides: Mapping[str, Any] | None = None,
            where: str = "") -> dict[str, Any]:
    """Defaults of ``specs`` updated by ``overrides``, every value checked.

    An override naming no declared parameter is refused (a typo must not pass silently).
    """
    specs = list(specs)
    by_name = {p.name: p for p in specs}
    overrides = dict(overrides or {})
    for name in overrides:
        if name not in by_name:
            raise ParamError(unknown_name_message(name, by_name, where))
    return {p.name: p.check(overrides.get(p.name, p.default), where) for p in specs}


# ----------------------------------------------------------------------------- files
def read_params_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """A ROS 2 parameter file as ``{node name or '/**': {parameter: value}}``.

    Nested mappings under ``ros__parameters`` are flattened with dots, as ROS 2 does.
    Refused with ``file:line:col`` when the YAML is malformed, and with the way to convert
    it when it uses the old layout (values nested under ``tmgwr:``).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ParamError(f"{path}: cannot read parameter file: {exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f":{mark.line + 1}:{mark.column + 1}" if mark is not None else ""
        what = getattr(exc, "problem", None) or str(exc)
        raise ParamError(f"{path}{at}: malformed parameter file (YAML): {what}") from None
    if not isinstance(data, dict):
        raise ParamError(f"{path}: expected a mapping of node names to 'ros__parameters' "
                         "(e.g. '/**:\\n  ros__parameters:\\n    gamma: 0.97')")
    out: dict[str, dict[str, Any]] = {}
    for node, body in data.items():
        if not isinstance(body, dict) or "ros__parameters" not in body:
            raise ParamError(f"{path}: entry {node!r} has no 'ros__parameters' mapping")
        values = body["ros__parameters"] or {}
        if not isinstance(values, dict):
            raise ParamError(f"{path}: '{node}: ros__parameters' is not a mapping")
        old = values.get("tmgwr")
        if isinstance(old, dict):
            first = next(iter(old), "gamma")
            raise ParamError(
                f"{path}: '{node}: ros__parameters: tmgwr:' is the old layout; move the keys "
                f"under 'tmgwr:' up one level (e.g. 'tmgwr: {{{first}: ...}}' becomes "
                f"'{first}: ...' directly under 'ros__parameters:') and delete 'tmgwr:'")
        flat: dict[str, Any] = {}
        _flatten(values, "", flat)
        out[str(node)] = flat
    return out


def params_for(path: str | Path, node: str | None = None) -> dict[str, Any]:
    """The values a node named ``node`` gets from a parameter file: the ``/**`` entry,
    then its own (``node`` or ``/node``) over it; ``node`` None merges every entry."""
    entries = read_params_file(path)
    out: dict[str, Any] = dict(entries.get("/**", {}))
    for name, values in entries.items():
        if node is None or name.lstrip("/") == node:
            out.update(values)
    return out


def check_params_file(path: str | Path) -> None:
    """Refuse a parameter file for the graph that is malformed, in the old layout, or names
    a parameter that no node of the graph declares (naming the nearest known name). The
    values are checked by the nodes themselves, against their ranges, at start."""
    known = graph_parameter_names()
    for entry, values in read_params_file(path).items():
        for name in values:
            if name not in known:
                raise ParamError(unknown_name_message(name, known, f"{path} [{entry}]"))


def _flatten(d: Mapping[str, Any], prefix: str, out: dict[str, Any]) -> None:
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            _flatten(v, key + ".", out)
        else:
            out[key] = v


# ----------------------------------------------------------------------------- registry
#: ament index resource type listing, per package, the ``module:attribute`` of the
#: parameter declarations of its nodes (Config classes or Param tuples), one a line.
#: The world the simulator hosts and the agent nodes sense and act in (maze_sim.worlds):
#: one parameter of every node that needs to know it (the simulator, and the agent nodes
#: that take the world's motor primitives).
WORLD_PARAM = Param("world", "grid", "the world the simulator hosts, by name (grid: our grid "
                    "world; pointmaze: MuJoCo's PointMaze built from the maze file); the "
                    "agent nodes take its senses (dimension, motor primitives)")

RESOURCE_TYPE = "tmgwr_parameters"


def graph_parameter_names() -> set[str]:
    """Every parameter name some node of the installed graph declares (packages register
    their declarations in the ament index under :data:`RESOURCE_TYPE`). A parameter file
    shared by all nodes (``/**``) may hold any of them."""
    import importlib

    from ament_index_python.resources import get_resource, get_resources

    names: set[str] = set()
    for package in sorted(get_resources(RESOURCE_TYPE)):
        content, _ = get_resource(RESOURCE_TYPE, package)
        for line in content.split():
            module, _, attribute = line.partition(":")
            declared = getattr(importlib.import_module(module), attribute)
            names.update(p.name for p in specs(declared))
    return names
