"""Hyperparameters: one declaration per parameter, shared by the core and the ROS nodes.

Each :class:`Param` carries its default (Table 2 of the paper where it gives one), its
valid range and a description. The core validates a parameter dict with
:func:`resolve`; the ROS nodes declare the same names with descriptors built from the same
declarations (so a range is written once). Defaults live in ``config/*.yaml`` in the ROS 2
parameter-file format and are read with :func:`load_yaml`; a value there that breaks its
range is refused with the file, the parameter name and the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

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


def resolve(specs: Iterable[Param], overrides: Mapping[str, Any] | None = None,
            where: str = "") -> dict[str, Any]:
    """Defaults of ``specs`` updated by ``overrides``, every value checked.

    An override naming no declared parameter is refused (a typo must not pass silently).
    """
    specs = list(specs)
    by_name = {p.name: p for p in specs}
    overrides = dict(overrides or {})
    unknown = sorted(set(overrides) - set(by_name))
    if unknown:
        loc = f"{where}: " if where else ""
        raise ParamError(f"{loc}unknown parameter(s) {unknown}; known: {sorted(by_name)}")
    return {p.name: p.check(overrides.get(p.name, p.default), where) for p in specs}


def load_yaml(path: str | Path, section: str | None = None) -> dict[str, Any]:
    """Read a ROS 2 parameter file (``/**: ros__parameters: ...``) into a flat dict.

    Nested mappings are flattened with dots, as ROS 2 does. With ``section`` only the keys
    under that prefix are returned, without the prefix.
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ParamError(f"{path}: cannot read parameter file: {exc}") from exc
    if not isinstance(data, dict):
        raise ParamError(f"{path}: expected a mapping of node names to ros__parameters")
    flat: dict[str, Any] = {}
    for node, body in data.items():
        if not isinstance(body, dict) or "ros__parameters" not in body:
            raise ParamError(f"{path}: entry {node!r} has no 'ros__parameters' mapping")
        _flatten(body["ros__parameters"] or {}, "", flat)
    if section is None:
        return flat
    prefix = section + "."
    return {k[len(prefix):]: v for k, v in flat.items() if k.startswith(prefix)}


def _flatten(d: Mapping[str, Any], prefix: str, out: dict[str, Any]) -> None:
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            _flatten(v, key + ".", out)
        else:
            out[key] = v


def config_params(specs: Iterable[Param], file: str, section: str,
                  overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Defaults from ``config/<file>`` section ``section``, then ``overrides``, checked."""
    from tmgwr_common.share import share_file

    path = share_file("tmgwr_agent", "config", file)
    values = load_yaml(path, section)
    specs = list(specs)
    merged = resolve(specs, values, where=f"{path} [{section}]")
    merged.update(overrides or {})
    return resolve(specs, merged, where=f"{section} parameters")
