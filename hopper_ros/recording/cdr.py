"""Column-wise CDR decoding of many messages of one flat type with numpy (a fast path for the
1 kHz topics; rclpy's deserializer builds one Python object per message, ~20 us each).

A type qualifies when its fields are a std_msgs/Header followed by fixed-size primitives or
fixed arrays of them: then every message with the same frame_id has the same layout. Offsets
follow CDR's alignment (each primitive aligned to its size, counted from the end of the
4-byte encapsulation header). Anything else (strings besides the frame_id, sequences, nested
messages) returns None and the caller deserializes message by message.
"""

from __future__ import annotations

import re

import numpy as np

PRIMITIVES = {
    "boolean": ("?", 1), "octet": ("u1", 1), "byte": ("u1", 1), "char": ("u1", 1), "uint8": ("u1", 1), "int8": ("i1", 1),
    "uint16": ("u2", 2), "int16": ("i2", 2), "uint32": ("u4", 4), "int32": ("i4", 4), "float": ("f4", 4),
    "uint64": ("u8", 8), "int64": ("i8", 8), "double": ("f8", 8),
}
_ARRAY = re.compile(r"^(\w+)\[(\d+)\]$")
_HEADER = "std_msgs/Header"


def _layout(cls):
    """[(field, dtype code, size, count)] after the header, or None if not flat."""
    fields = list(cls.get_fields_and_field_types().items())
    if not fields or fields[0][1] != _HEADER:
        return None
    out = []
    for name, type_text in fields[1:]:
        count = 1
        match = _ARRAY.match(type_text)
        if match:
            type_text, count = match.group(1), int(match.group(2))
        if type_text not in PRIMITIVES:
            return None
        code, size = PRIMITIVES[type_text]
        out.append((name, code, size, count))
    return out


def decode_columns(cls, payloads: list[bytes]) -> dict[str, np.ndarray] | None:
    """{"stamp_sec": .., "stamp_nanosec": .., field: values...} of all `payloads` (CDR of `cls`),
    or None when the type is not flat or the messages differ in layout."""
    layout = _layout(cls)
    if layout is None or not payloads:
        return None
    length = len(payloads[0])
    if any(len(p) != length for p in payloads) or payloads[0][:2] != b"\x00\x01":   # little-endian CDR only
        return None
    data = np.frombuffer(b"".join(payloads), dtype=np.uint8).reshape(len(payloads), length)
    frame_length = data[:, 12:16].copy().view("<u4")[:, 0]
    if np.any(frame_length != frame_length[0]):
        return None
    position = 16 + int(frame_length[0])                  # after the frame_id's characters
    columns = {"stamp_sec": data[:, 4:8].copy().view("<i4")[:, 0].astype(np.int64),
               "stamp_nanosec": data[:, 8:12].copy().view("<u4")[:, 0].astype(np.int64)}
    for name, code, size, count in layout:
        body = position - 4
        position += (-body) % size                          # CDR alignment from the payload start
        width = size * count
        if position + width > length:
            return None
        block = data[:, position:position + width].copy().view("<" + code)
        columns[name] = block[:, 0] if count == 1 else block
        position += width
    if position > length or length - position >= 8:      # trailing bytes beyond padding: not our layout
        return None
    return columns
