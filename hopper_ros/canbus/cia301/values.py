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
