"""The microcontroller's UDP packet: one per millisecond, little-endian, 36 bytes (version 1).

    offset size type     field
    0      2    bytes    magic b"HP"
    2      1    uint8    format version (1)
    3      1    uint8    flags (bit 0: motor current valid)
    4      4    uint32   sequence number, +1 per packet, wraps at 2^32
    8      8    uint64   microcontroller clock at sampling [us]
    16     4    int32    azimuth counter register (x4 quadrature, wraps)
    20     4    int32    elevation counter register
    24     4    int32    hip motor encoder counter register
    28     4    int32    motor current [mA]
    32     4    uint32   CRC-32 (zlib/IEEE 802.3) of bytes 0..31

Full description: docs/encoder_packet.md. `decode` raises `PacketError` naming what is wrong;
it never returns a sample from a damaged packet.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

MAGIC = b"HP"
VERSION = 1
FLAG_CURRENT_VALID = 0x01
_BODY = struct.Struct("<2sBBIQiiii")
_CRC = struct.Struct("<I")
SIZE = _BODY.size + _CRC.size  # 36


class PacketError(ValueError):
    """A packet that cannot be trusted; `reason` is a short counter name."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class EncoderPacket:
    sequence: int
    mcu_time_us: int
    azimuth_counts: int      # signed 32-bit register values
    elevation_counts: int
    motor_counts: int
    motor_current_ma: int
    flags: int = FLAG_CURRENT_VALID
    version: int = VERSION

    @property
    def motor_current(self) -> float:
        """[A]"""
        return self.motor_current_ma * 1e-3


def encode(packet: EncoderPacket) -> bytes:
    body = _BODY.pack(MAGIC, packet.version, packet.flags, packet.sequence & 0xFFFFFFFF,
                      packet.mcu_time_us & 0xFFFFFFFFFFFFFFFF, packet.azimuth_counts, packet.elevation_counts,
                      packet.motor_counts, packet.motor_current_ma)
    return body + _CRC.pack(zlib.crc32(body))


def decode(data: bytes) -> EncoderPacket:
    if len(data) != SIZE:
        raise PacketError("malformed_size", f"packet of {len(data)} bytes, expected {SIZE}")
    if data[:2] != MAGIC:
        raise PacketError("malformed_magic", f"packet starts with {data[:2]!r}, expected {MAGIC!r}")
    if data[2] != VERSION:
        raise PacketError("malformed_version", f"packet format version {data[2]}, this bridge reads {VERSION}")
    (crc,) = _CRC.unpack_from(data, _BODY.size)
    if zlib.crc32(data[:_BODY.size]) != crc:
        raise PacketError("malformed_checksum", "packet checksum (CRC-32) does not match its contents")
    _, version, flags, sequence, mcu_time_us, azimuth, elevation, motor, current = _BODY.unpack_from(data)
    return EncoderPacket(sequence, mcu_time_us, azimuth, elevation, motor, current, flags, version)
