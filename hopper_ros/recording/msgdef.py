"""Any ROS 2 message of a bag decoded from the definition the bag carries (no message package needed).

rosbag2's MCAP files (and rosbags', Foxglove's) store each type's definition as `ros2msg` text: the
message's fields, then each type it uses after a line of `=` and `MSG: pkg/Type`. `MessageDecoder`
parses that text once and decodes CDR (little- or big-endian XCDR1, as rmw_fastrtps writes it) into
plain Python: a message is a dict of its fields, a sequence or array of numbers a numpy array, of
strings or messages a list. No ROS import: `hopper import` reads bags of sensor_msgs, geometry_msgs,
nav_msgs or the user's own types on a machine that has none of them.

    decoder = MessageDecoder("sensor_msgs/msg/JointState", schema_text)
    msg = decoder.decode(cdr_bytes)      # {"header": {...}, "name": [...], "position": array, ...}
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

import numpy as np

PRIMITIVES = {                       # ros2msg type -> (struct code, size)
    "bool": ("?", 1), "byte": ("B", 1), "char": ("B", 1), "uint8": ("B", 1), "int8": ("b", 1),
    "uint16": ("H", 2), "int16": ("h", 2), "uint32": ("I", 4), "int32": ("i", 4),
    "uint64": ("Q", 8), "int64": ("q", 8), "float32": ("f", 4), "float64": ("d", 8),
}
_DTYPES = {"?": "?", "B": "u1", "b": "i1", "H": "u2", "h": "i2", "I": "u4", "i": "i4", "Q": "u8", "q": "i8",
           "f": "f4", "d": "f8"}
_SEPARATOR = re.compile(r"^={10,}\s*$", re.M)
_FIELD = re.compile(r"^(?P<type>[A-Za-z_][\w/]*(?:<=\d+)?)(?P<array>\[(?:<=)?\d*\])?\s+(?P<name>[A-Za-z_]\w*)"
                    r"(?P<rest>.*)$")


class MessageDefinitionError(ValueError):
    """A definition that cannot be parsed, or a message that does not fit its definition."""


@dataclass(frozen=True)
class Field:
    name: str
    type: str            # primitive, "string", "wstring" or a full message name pkg/msg/Type
    array: str | None    # None, "[]" (sequence), "[N]" (fixed), "[<=N]" (bounded sequence)

    @property
    def length(self) -> int | None:
        """N of a fixed array, None otherwise."""
        if self.array and self.array[1:-1].isdigit():
            return int(self.array[1:-1])
        return None


def full_name(type_name: str, package: str = "") -> str:
    """pkg/msg/Type for `pkg/Type`, `pkg/msg/Type` or `Type` (of `package`)."""
    parts = type_name.split("/")
    if len(parts) == 3:
        return type_name
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if type_name == "Header":
        return "std_msgs/msg/Header"
    return f"{package}/msg/{type_name}"


def parse_definitions(type_name: str, text: str) -> dict[str, list[Field]]:
    """{full type name: fields} of a ros2msg definition text (the main type first)."""
    main = full_name(type_name)
    blocks = _SEPARATOR.split(text)
    out: dict[str, list[Field]] = {}
    for index, block in enumerate(blocks):
        lines = block.strip("\n").splitlines()
        if index == 0:
            name = main
        else:
            header = next((line for line in lines if line.strip()), "")
            if not header.startswith("MSG:"):
                raise MessageDefinitionError(f"{type_name}: definition block {index} does not start with 'MSG: pkg/Type'")
            name = full_name(header[4:].strip())
            lines = lines[lines.index(header) + 1:]
        package = name.split("/")[0]
        fields = []
        for raw in lines:
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            match = _FIELD.match(line)
            if match is None:
                raise MessageDefinitionError(f"{name}: cannot read the field line {raw.strip()!r}")
            rest = match.group("rest").strip()
            if rest.startswith("="):
                continue                                   # a constant, not serialized
            base = match.group("type").split("<=")[0]      # string<=N is a string
            if base not in PRIMITIVES and base not in ("string", "wstring"):
                base = full_name(base, package)
            fields.append(Field(match.group("name"), base, match.group("array")))
        out[name] = fields
    for fields in out.values():
        for f in fields:
            if f.type not in PRIMITIVES and f.type not in ("string", "wstring") and f.type not in out:
                raise MessageDefinitionError(f"{type_name}: the definition lacks the type {f.type} (field {f.name})")
    return out


class _Reader:
    __slots__ = ("data", "pos", "endian")

    def __init__(self, data: bytes, endian: str) -> None:
        self.data, self.pos, self.endian = data, 4, endian

    def align(self, size: int) -> None:
        offset = (self.pos - 4) % size
        if offset:
            self.pos += size - offset

    def primitive(self, code: str, size: int):
        self.align(size)
        value = struct.unpack_from(self.endian + code, self.data, self.pos)[0]
        self.pos += size
        return value

    def array(self, code: str, size: int, count: int) -> np.ndarray:
        if count:
            self.align(size)
        end = self.pos + size * count
        if end > len(self.data):
            raise MessageDefinitionError(f"message ends before its {count} elements")
        values = np.frombuffer(self.data, dtype=np.dtype(_DTYPES[code]).newbyteorder(self.endian), count=count,
                               offset=self.pos)
        self.pos = end
        return values.astype(_DTYPES[code])

    def string(self, wide: bool = False) -> str:
        length = self.primitive("I", 4)
        if wide:
            text = self.data[self.pos:self.pos + 4 * length].decode("utf-32-le" if self.endian == "<" else "utf-32-be")
            self.pos += 4 * length
            return text
        end = self.pos + length
        if end > len(self.data):
            raise MessageDefinitionError("message ends inside a string")
        text = self.data[self.pos:end - 1 if length else end].decode("utf-8", errors="replace")
        self.pos = end
        return text


class MessageDecoder:
    """Decodes the CDR of one message type, given the definition text a bag stores with it."""

    def __init__(self, type_name: str, definition: str) -> None:
        self.type_name = full_name(type_name)
        self.types = parse_definitions(type_name, definition)

    def fields(self, type_name: str | None = None) -> list[Field]:
        return self.types[type_name or self.type_name]

    def decode(self, data: bytes) -> dict:
        if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
            raise MessageDefinitionError(f"{self.type_name}: not CDR (encapsulation {bytes(data[:4]).hex()})")
        reader = _Reader(bytes(data), "<" if data[1] == 1 else ">")
        try:
            return self._message(reader, self.type_name)
        except struct.error:
            raise MessageDefinitionError(f"{self.type_name}: the message is shorter than its definition") from None

    def _message(self, reader: _Reader, type_name: str) -> dict:
        fields = self.types[type_name]
        if not fields:                                     # an empty message carries one byte
            reader.primitive("B", 1)
            return {}
        return {f.name: self._field(reader, f) for f in fields}

    def _field(self, reader: _Reader, f: Field):
        if f.array is None:
            return self._one(reader, f.type)
        count = f.length
        if count is None:
            count = reader.primitive("I", 4)
        if f.type in PRIMITIVES:
            return reader.array(*PRIMITIVES[f.type], count)
        return [self._one(reader, f.type) for _ in range(count)]

    def _one(self, reader: _Reader, type_name: str):
        if type_name in PRIMITIVES:
            return reader.primitive(*PRIMITIVES[type_name])
        if type_name in ("string", "wstring"):
            return reader.string(type_name == "wstring")
        return self._message(reader, type_name)
