"""Generic ROS message helpers that need no node: load a message class by its type name, turn a
message into plain data or into the YAML `ros2 topic echo` prints.

Works for any message package importable in this interpreter (std_msgs, hopper_ros.msg, ...)
through the generated classes' `get_fields_and_field_types()`; rosidl_runtime_py is not needed.
"""

from __future__ import annotations

import array
import importlib
import sys
from typing import Any

DEFAULT_TRUNCATE_LENGTH = 128  # as `ros2 topic echo`: longer strings and arrays end in '...'


def split_type_name(type_name: str) -> tuple[str, str, str]:
    """'pkg/msg/Type' or 'pkg/Type' -> (pkg, 'msg', Type)."""
    parts = type_name.strip("/").split("/")
    if len(parts) == 2:
        parts.insert(1, "msg")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"{type_name!r} is not a message type name (expected package/msg/Type)")
    return parts[0], parts[1], parts[2]


def message_class(type_name: str) -> type:
    """Import the Python class of a message type, e.g. 'hopper_ros/msg/ApexState'."""
    package, interface, name = split_type_name(type_name)
    module_name = f"{package}.{interface}"
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise LookupError(
            f"cannot load message type {type_name!r}: module {module_name!r} is not importable ({exc}); "
            "is its package built and installed in this environment?"
        ) from exc
    cls = getattr(module, name, None)
    if cls is None or not hasattr(cls, "get_fields_and_field_types"):
        raise LookupError(f"cannot load message type {type_name!r}: {module_name} has no message {name!r}")
    return cls


def type_name_of(msg_or_class: Any) -> str:
    """'pkg/msg/Type' of a message instance or class."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    package, interface = cls.__module__.split(".")[:2]
    return f"{package}/{interface}/{cls.__name__}"


def is_message(value: Any) -> bool:
    return hasattr(value, "get_fields_and_field_types") and not isinstance(value, type)


def message_to_dict(msg: Any, truncate_length: int | None = None) -> dict[str, Any]:
    """The message's fields, in declaration order, as plain Python data (constants excluded)."""
    return {
        name: _convert(getattr(msg, name), truncate_length)
        for name in msg.get_fields_and_field_types()
    }


def _convert(value: Any, truncate_length: int | None) -> Any:
    too_long = truncate_length is not None and len_or_zero(value) > truncate_length
    if isinstance(value, bytes):  # byte/octet values: characters, as rosidl_runtime_py does
        text = "".join(chr(c) for c in (value[:truncate_length] if too_long else value))
        return text + "..." if too_long else text
    if isinstance(value, str):
        return value[:truncate_length] + "..." if too_long else value
    if isinstance(value, array.array) or type(value).__module__ == "numpy":
        if not hasattr(value, "tolist"):
            return value
        items = value.tolist()
        if not isinstance(items, list):  # a numpy scalar
            return items
        return items[:truncate_length] + ["..."] if too_long else items
    if isinstance(value, (list, tuple)):
        items = [_convert(v, truncate_length) for v in (value[:truncate_length] if too_long else value)]
        return items + ["..."] if too_long else items
    if is_message(value):
        return message_to_dict(value, truncate_length)
    return value


def len_or_zero(value: Any) -> int:
    try:
        return len(value)
    except TypeError:
        return 0


def message_to_yaml(msg: Any, truncate_length: int | None = None) -> str:
    """The YAML `ros2 topic echo` prints for one message (without the '---' separator)."""
    import yaml

    return yaml.safe_dump(
        message_to_dict(msg, truncate_length),
        sort_keys=False,
        allow_unicode=True,
        width=sys.maxsize,
        default_flow_style=False,
    )
