"""ROS 2 message definitions as rosbag2 embeds them in MCAP schemas (encoding "ros2msg").

A schema is the type's own .msg text followed, for every message type it uses (recursively),
by a separator line of 80 '=' and "MSG: pkg/msg/Type" and that type's .msg text, as rosbag2
writes it. Definitions are read from the installed interface packages
(`<prefix>/share/<pkg>/msg/<Type>.msg`, found through the ament index); hopper_ros's own come
from the repository's msg/ when the package is not installed. Type hashes (RIHS01) come from
the generated `<Type>.json` next to the .msg when present.
"""

from __future__ import annotations

import json
import re
from functools import lru_cache
from pathlib import Path

from hopper_ros.messages import split_type_name

SEPARATOR = "=" * 80
PRIMITIVES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
    "int64", "uint64", "string", "wstring",
})
_REPO_MSG_DIR = Path(__file__).resolve().parent.parent.parent / "msg"


class SchemaError(LookupError):
    """A message definition that cannot be found or parsed."""


def _share_directories(package: str) -> list[Path]:
    found = []
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        try:
            found.append(Path(get_package_share_directory(package)))
        except PackageNotFoundError:
            pass
    except ImportError:  # no ament index: only the repository's own messages
        pass
    if package == "hopper_ros":
        found.append(_REPO_MSG_DIR.parent)
    return found


@lru_cache(maxsize=None)
def msg_file(type_name: str) -> Path:
    """Path of the .msg file defining `type_name` ('pkg/msg/Type' or 'pkg/Type')."""
    package, interface, name = split_type_name(type_name)
    for share in _share_directories(package):
        candidate = share / interface / f"{name}.msg"
        if candidate.is_file():
            return candidate
    raise SchemaError(f"no message definition for {type_name!r}: {package}/{interface}/{name}.msg is not in "
                      f"the ament index (is the package installed?)")


def _field_types(text: str, package: str) -> list[str]:
    """Message types (pkg/msg/Type) that the fields of one .msg text use."""
    used = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        if len(parts) < 2 or "=" in parts[1] or (len(parts) > 2 and parts[2].startswith("=")):
            continue  # a constant
        base = re.sub(r"\[.*\]$", "", parts[0])          # arrays: T[], T[N], T[<=N]
        base = re.sub(r"<=\d+$", "", base)                 # bounded strings
        if base in PRIMITIVES:
            continue
        if base == "Header":
            used.append("std_msgs/msg/Header")
        elif "/" in base:
            pkg, _, name = base.partition("/")
            used.append(f"{pkg}/msg/{name.split('/')[-1]}")
        else:
            used.append(f"{package}/msg/{base}")
    return used


@lru_cache(maxsize=None)
def message_definition(type_name: str) -> str:
    """The rosbag2 ("ros2msg") definition of a message type, its dependencies appended."""
    package, interface, name = split_type_name(type_name)
    root = f"{package}/{interface}/{name}"
    text = msg_file(root).read_text(encoding="utf-8")
    parts = [text.rstrip("\n")]
    seen = {root}
    queue = _field_types(text, package)
    while queue:
        dependency = queue.pop(0)
        if dependency in seen:
            continue
        seen.add(dependency)
        dep_text = msg_file(dependency).read_text(encoding="utf-8")
        parts.append(f"{SEPARATOR}\nMSG: {dependency}\n{dep_text.rstrip(chr(10))}")
        queue.extend(_field_types(dep_text, dependency.split("/")[0]))
    return "\n".join(parts) + "\n"


@lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """RIHS01 type hash of a message type from its generated .json, "" when unknown."""
    package, interface, name = split_type_name(type_name)
    root = f"{package}/{interface}/{name}"
    try:
        description = msg_file(root).with_suffix(".json")
        hashes = json.loads(description.read_text(encoding="utf-8"))["type_hashes"]
    except (SchemaError, OSError, KeyError, ValueError):
        return ""
    return next((h["hash_string"] for h in hashes if h.get("type_name") == root), "")
