"""Message definitions for the MCAP ``ros2`` profile (schema encoding ``ros2msg``).

A ``ros2msg`` schema is the type's own ``.msg`` text followed, for every type it depends on
(transitively, each once), by a line of 80 ``=``, a line ``MSG: pkg/Type`` and that type's
``.msg`` text. We use the short ``MSG: pkg/Type`` form on purpose: Foxglove's parser
(``@foxglove/rosmsg``) rejects the long ``MSG: pkg/msg/Type`` form, while rosbag2, mcap_ros2
and rosbags accept both.

The ``.msg`` files and the RIHS01 type hashes (``.json``) come from the packages' share
directories (the wheels install them under ``$VIRTUAL_ENV/share/<pkg>/msg``, colcon under
``install/<pkg>/share/<pkg>/msg``), found through the ament index. ROS-free apart from
``ament_index_python``.
"""

from __future__ import annotations

import functools
import json
import re
from pathlib import Path

SEPARATOR = "=" * 80

# Primitive field types of the ROS 2 IDL (.msg) that are not message dependencies.
PRIMITIVES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
})

_ARRAY = re.compile(r"\[[^\]]*\]$")          # T[], T[3], T[<=3]
_BOUNDED_STRING = re.compile(r"^(w?string)<=\d+$")


class DefinitionError(LookupError):
    """A message type whose definition cannot be found or parsed."""


def split_type(type_name: str) -> tuple[str, str]:
    """``pkg/msg/Type`` or ``pkg/Type`` -> ``(pkg, Type)``."""
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise DefinitionError(f"not a message type name: {type_name!r} (expected pkg/msg/Type)")


@functools.lru_cache(maxsize=None)
def _msg_dir(package: str) -> Path:
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    try:
        return Path(get_package_share_directory(package)) / "msg"
    except PackageNotFoundError:
        raise DefinitionError(f"package {package!r} is not in the ament index "
                              f"(AMENT_PREFIX_PATH): cannot find its .msg files") from None


@functools.lru_cache(maxsize=None)
def msg_text(type_name: str) -> str:
    """The ``.msg`` file text of ``pkg/msg/Type`` as installed."""
    package, name = split_type(type_name)
    path = _msg_dir(package) / f"{name}.msg"
    if not path.is_file():
        raise DefinitionError(f"no definition for {type_name}: {path} does not exist")
    return path.read_text()


def field_dependencies(text: str, package: str) -> list[str]:
    """Message types (``pkg/msg/Type``) used by the fields of a ``.msg`` text, in order."""
    deps: list[str] = []
    for raw_line in text.splitlines():
        line = raw_line.split("#", 1)[0].strip()
        if not line:
            continue
        # "TYPE NAME [DEFAULT]" or a constant "TYPE NAME=VALUE" (constants are primitive)
        field_type = _ARRAY.sub("", line.split()[0])
        if field_type in PRIMITIVES or _BOUNDED_STRING.match(field_type):
            continue
        if field_type == "Header":                   # ROS 1 shorthand, still accepted
            dep = "std_msgs/msg/Header"
        elif "/" in field_type:
            pkg, name = split_type(field_type)
            dep = f"{pkg}/msg/{name}"
        else:                                        # same package
            dep = f"{package}/msg/{field_type}"
        if dep not in deps:
            deps.append(dep)
    return deps


@functools.lru_cache(maxsize=None)
def ros2msg_definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text of ``pkg/msg/Type`` (dependencies in short ``MSG:`` form).

    Dependencies are listed depth-first in order of first use, each once.
    """
    package, name = split_type(type_name)
    root = f"{package}/msg/{name}"
    text = msg_text(root)
    order: list[str] = []

    def visit(t: str) -> None:
        pkg, _ = split_type(t)
        for dep in field_dependencies(msg_text(t), pkg):
            if dep != root and dep not in order:
                order.append(dep)
                visit(dep)

    visit(root)
    parts = [text.rstrip("\n")]
    for dep in order:
        dpkg, dname = split_type(dep)
        parts.append(f"{SEPARATOR}\nMSG: {dpkg}/{dname}\n{msg_text(dep).rstrip(chr(10))}")
    return "\n".join(parts) + "\n"


@functools.lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """The RIHS01 type hash of ``pkg/msg/Type`` from its installed ``.json`` ('' if none)."""
    package, name = split_type(type_name)
    path = _msg_dir(package) / f"{name}.json"
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return ""
    full = f"{package}/msg/{name}"
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == full:
            return str(entry.get("hash_string", ""))
    return ""


def import_message(type_name: str):
    """The generated Python class of ``pkg/msg/Type`` (needs the ROS environment)."""
    import importlib
    package, name = split_type(type_name)
    try:
        module = importlib.import_module(f"{package}.msg")
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise DefinitionError(f"cannot import the Python class of {type_name}: {exc}") from None
