"""Object dictionary values <-> bytes by CiA 301 data type (little endian; VISIBLE_STRING as latin-1)."""

from __future__ import annotations

import struct

from hopper_ros.canbus.epos2_objects import DATA_TYPE_FORMAT, DataType


def encode(data_type: DataType, value: int | str) -> bytes:
    if data_type == DataType.VISIBLE_STRING:
        return str(value).encode("latin-1")
    return struct.pack(DATA_TYPE_FORMAT[DataType(data_type)], int(value))


def decode(data_type: DataType, payload: bytes) -> int | str:
    if data_type == DataType.VISIBLE_STRING:
        return payload.decode("latin-1")
    return struct.unpack(DATA_TYPE_FORMAT[DataType(data_type)], payload)[0]


def wrap_i32(value: int) -> int:
    """An INTEGER32 counter that wraps (a position in counts)."""
    return (value + (1 << 31)) % (1 << 32) - (1 << 31)


def saturate(value: int, bits: int) -> int:
    """A signed INTEGER of `bits` bits held at its range (a velocity, a current)."""
    return max(-(1 << (bits - 1)), min((1 << (bits - 1)) - 1, int(value)))
