"""ROS 2 message definitions as rosbag2 embeds them in MCAP schemas (encoding "ros2msg").

The text is exactly what rosbag2's `LocalMessageDefinitionSource`
(rosbag2_cpp/src/rosbag2_cpp/message_definitions/local_message_definition_source.cpp) writes
for the same type: the type's own .msg file as it is on disk, then, depth first, for every
message type a definition uses (found with rosbag2's field regex, each definition's
dependencies in sorted order, each type once) a newline, a separator line of 80 '=',
"MSG: " and the type as the field names it (`std_msgs/Header`, or `pkg/Type` for a type of the
same package), a newline and that type's .msg file. Readers resolve a field's type by that
name: Foxglove (@foxglove/rosmsg) finds nothing for `std_msgs/Header` under a
`MSG: std_msgs/msg/Header` heading and rejects the whole schema.

Definitions are read from the installed interface packages (`<prefix>/share/<pkg>/msg/<Type>.msg`,
found through the ament index); hopper_ros's own come from the repository's msg/ when the
package is not installed. Type hashes (RIHS01) come from the generated `<Type>.json` next to
the .msg when present.
"""

from __future__ import annotations

import json
import re
from functools import lru_cache
from pathlib import Path

from hopper_ros.runtime.messages import split_type_name

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


# rosbag2's MSG_FIELD_TYPE_REGEX and PRIMITIVE_TYPES (plus wstring, which rosbag2 cannot resolve)
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")


def _dependencies(text: str, package: str) -> list[str]:
    """The message types one .msg text uses, named as rosbag2 names them, sorted (a std::set)."""
    found = set()
    for match in _FIELD_TYPE.finditer(text):
        name = match.group(1)
        if name in PRIMITIVES:
            continue
        found.add(name if "/" in name else f"{package}/{name}")
    return sorted(found)


@lru_cache(maxsize=None)
def message_definition(type_name: str) -> str:
    """The rosbag2 ("ros2msg") definition of a message type, its dependencies appended."""
    package, interface, name = split_type_name(type_name)
    seen: set[str] = set()

    def append(type_text: str, dependency_package: str, depth: int) -> str:
        if depth <= 0:
            raise SchemaError(f"message definition of {type_name!r} nests too deep")
        text = msg_file(type_text).read_text(encoding="utf-8")
        out = text
        for dependency in _dependencies(text, dependency_package):
            if dependency not in seen:
                seen.add(dependency)
                out += f"\n{SEPARATOR}\nMSG: {dependency}\n" + append(dependency, dependency.split("/")[0], depth - 1)
        return out

    return append(f"{package}/{interface}/{name}", package, 50)


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
