"""What a rosbag2 MCAP file says about its messages: type names, definitions, hashes.

- the message types' names (``pkg/msg/Type``), classes (imported on demand) and ``.msg`` texts as
  installed, concatenated with their dependencies as rosbag2 writes a schema
  (:func:`message_definition`), and their ``RIHS01_...`` type hashes (:func:`type_hash`);
- the constants of the rosbag2 MCAP profile and the library string of the files we write.

Imports no rclpy; :func:`message_class` imports the message's package.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import json
import os
import re
from pathlib import Path
from typing import Any

ROS2_PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
DEFINITION_SEPARATOR = "=" * 80
ROSBAG2_METADATA_VERSION = 9  # rosbag2 Jazzy writes bag metadata version 9

_PRIMITIVE_TYPES = frozenset(
    ["bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
     "uint32", "int64", "uint64", "string", "wstring"])
_FIELD_TYPE_RE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:<=\d+)?(?:\[[^\]]*\])?\s+")
_TYPE_NAME_RE = re.compile(r"^([a-zA-Z][a-zA-Z0-9_]*)/(?:(msg|srv)/)?([a-zA-Z][a-zA-Z0-9_]*)$")


class RecordingError(ValueError):
    """A recording could not be written or read as asked; the message names the cause."""


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def library_string() -> str:
    """The MCAP header's library field: this writer and the mcap library under it."""
    return f"uam_sim/0.1.0 (mcap-python/{_version('mcap')})"


def split_type_name(type_name: str) -> tuple[str, str, str]:
    """``"pkg/msg/Type"`` or ``"pkg/Type"`` -> ``(pkg, "msg", Type)``; raises on anything else."""
    m = _TYPE_NAME_RE.match(type_name)
    if not m:
        raise RecordingError(f"msg_type: {type_name!r} is not of the form 'pkg/msg/Type'")
    return m.group(1), m.group(2) or "msg", m.group(3)


def type_name_of(msg_type: Any) -> str:
    """``"pkg/msg/Type"`` of a generated message class, instance or type-name string."""
    if isinstance(msg_type, str):
        pkg, ns, name = split_type_name(msg_type)
        return f"{pkg}/{ns}/{name}"
    cls = msg_type if isinstance(msg_type, type) else type(msg_type)
    parts = cls.__module__.split(".")  # e.g. uam_msgs.msg._flight_plan
    if len(parts) < 2 or parts[1] not in ("msg", "srv"):
        raise RecordingError(f"msg_type: {cls!r} is not a generated ROS 2 interface class")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


def message_class(type_name: str) -> type:
    """Import the generated Python class of ``pkg/msg/Type``."""
    pkg, ns, name = split_type_name(type_name)
    try:
        module = importlib.import_module(f"{pkg}.{ns}")
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise RecordingError(f"msg_type: cannot import {type_name!r} ({exc}); is the workspace "
                             "sourced (scripts/env.sh)?") from None


def _share_dir(pkg: str) -> Path:
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    try:
        return Path(get_package_share_directory(pkg))
    except PackageNotFoundError:
        raise RecordingError(f"msg_type: package {pkg!r} is not in the ament index "
                             f"(AMENT_PREFIX_PATH={os.environ.get('AMENT_PREFIX_PATH', '')!r})") from None


def _msg_text(pkg: str, ns: str, name: str) -> str:
    path = _share_dir(pkg) / ns / f"{name}.msg"
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RecordingError(f"msg_type: no definition for {pkg}/{ns}/{name} at {path} ({exc})") from None


def _dependencies(text: str, package: str) -> list[str]:
    """Non-primitive field types of a .msg text as ``pkg/Type``, sorted (rosbag2 uses a std::set)."""
    deps = set()
    for m in _FIELD_TYPE_RE.finditer(text):
        t = m.group(1)
        if t in _PRIMITIVE_TYPES:
            continue
        deps.add(t if "/" in t else f"{package}/{t}")
    return sorted(deps)


def message_definition(type_name: str) -> str:
    """The full ``ros2msg`` definition of a type as rosbag2 writes it into the MCAP schema.

    The root type's .msg text, then each dependency once (depth first, sorted per file) as
    ``"\\n" + 80*"=" + "\\nMSG: pkg/Type\\n" + text``. Reads the installed .msg files through the
    ament index. Raises :class:`RecordingError` if a definition is missing.
    """
    pkg, ns, name = split_type_name(type_name)
    seen: set[str] = set()

    def append(pkg_: str, ns_: str, name_: str, depth: int) -> str:
        if depth <= 0:
            raise RecordingError(f"msg_type: definition of {type_name!r} nests too deep")
        text = _msg_text(pkg_, ns_, name_)
        out = text
        for dep in _dependencies(text, pkg_):
            if dep in seen:
                continue
            seen.add(dep)
            dpkg, dns, dname = split_type_name(dep)
            out += f"\n{DEFINITION_SEPARATOR}\nMSG: {dep}\n" + append(dpkg, dns, dname, depth - 1)
        return out

    return append(pkg, ns, name, 50)


def type_hash(type_name: str) -> str | None:
    """The ``RIHS01_...`` type hash of an installed interface, or None if it is not available."""
    pkg, ns, name = split_type_name(type_name)
    path = _share_dir(pkg) / ns / f"{name}.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    full = f"{pkg}/{ns}/{name}"
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == full:
            return entry.get("hash_string")
    return None
