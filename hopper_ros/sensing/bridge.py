"""The encoder bridge as plain Python: the microcontroller's UDP packets to checked, unwrapped,
converted samples. No ROS, no socket: the node feeds it datagrams.

`EncoderBridge.process(datagram, receive_time)` returns a `BridgeSample` or None; it never raises
on bad input. Checks, in order (docs/encoder_packet.md, "What a receiver must check"):

1. the packet itself: size, magic, version, CRC-32 (`hardware.packet.decode`, its
   `PacketError.reason` is the counter: malformed_size, _magic, _version, _checksum);
2. the sequence against the last accepted packet (modulo 2^32): the same number is a duplicate;
   a number skipped earlier that arrives late is `reordered` (dropped: the stream has moved on);
   an older number that was not missing is a duplicate too; a jump back beyond `reorder_window`
   is `sequence_jump`; a gap counts its numbers in `packets_lost` (late arrivals included);
3. the microcontroller clock: it must advance (`clock_backwards` otherwise) and by the sequence
   step times the sample period within `clock_tolerance` (`clock_inconsistent` otherwise).

A packet failing a check is counted and dropped; nothing from it is used (the counters are not
unwrapped with it). If the microcontroller restarts, its sequence and clock start again and every
packet fails check 2 or 3: after `resync_after` consecutive rejected packets that are consistent
among themselves (sequence +1, clock +1 period) the bridge follows the new stream
(`stream_resyncs`). Accepted packets: the 32-bit counters are unwrapped (`CounterUnwrapper`),
converted with appendix A (`BoomKinematics.position`, offsets = homing from hardware.yaml), and the
motor current turned into hip torque (`HipMotor.torque`); a current flagged invalid gives NaN.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from hopper_ros.hardware import packet as packet_format
from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.hardware.encoders import BoomKinematics, BoomPosition, CounterUnwrapper, to_register
from hopper_ros.hardware.motor import HipMotor
from hopper_ros.hardware.packet import EncoderPacket, PacketError

from .config import BridgeSettings
from .samples import Measurement

SEQUENCE_MODULUS = 1 << 32
_HALF = 1 << 31
MALFORMED = ("malformed_size", "malformed_magic", "malformed_version", "malformed_checksum")
ORDER = ("duplicates", "reordered", "sequence_jump", "clock_backwards", "clock_inconsistent")
COUNTER_NAMES = ("packets_received", "samples_accepted", "packets_lost", *MALFORMED, *ORDER,
                 "stream_resyncs", "counter_wraps")


@dataclass(frozen=True)
class BridgeSample:
    """One accepted packet: as received, unwrapped and converted."""

    packet: EncoderPacket
    receive_time: float       # [s] host clock
    azimuth_count: int        # unwrapped counts
    elevation_count: int
    motor_count: int
    position: BoomPosition
    motor_current: float      # [A], NaN if the packet flags it invalid
    hip_torque: float         # [N m], NaN likewise
    lost_before: int          # sequence numbers skipped just before this packet

    @property
    def mcu_time(self) -> float:
        """[s]"""
        return self.packet.mcu_time_us * 1e-6

    def measurement(self) -> Measurement:
        p = self.position
        return Measurement(self.packet.sequence, self.mcu_time, self.receive_time, p.y, p.z, p.leg_angle)


class EncoderBridge:
    def __init__(self, kinematics: BoomKinematics, motor: HipMotor, sample_period: float,
                 settings: BridgeSettings) -> None:
        if sample_period <= 0:
            raise ValueError(f"sample period must be positive, got {sample_period}")
        self.kinematics = kinematics
        self.motor = motor
        self.settings = settings
        self.period_us = sample_period * 1e6
        self.tolerance_us = settings.clock_tolerance * 1e6
        self.counters = dict.fromkeys(COUNTER_NAMES, 0)
        self.last_problem = ""         # the latest rejection, in words
        self._last: EncoderPacket | None = None
        self._missing: set[int] = set()
        self._missing_order: deque[int] = deque()
        self._candidate: EncoderPacket | None = None   # start of a run of rejected, self-consistent packets
        self._candidate_run = 0
        self._unwrappers = (CounterUnwrapper(), CounterUnwrapper(), CounterUnwrapper())
        self._encoders = (kinematics.azimuth, kinematics.elevation, kinematics.motor)

    @classmethod
    def from_config(cls, hardware: HardwareConfig, settings: BridgeSettings) -> "EncoderBridge":
        return cls(BoomKinematics.from_config(hardware), HipMotor.from_config(hardware),
                   hardware.microcontroller.sample_period, settings)

    # ------------------------------------------------------------------ one datagram
    def process(self, datagram: bytes, receive_time: float) -> BridgeSample | None:
        """The sample of one datagram, or None if it failed a check (counted, `last_problem` says why)."""
        self.counters["packets_received"] += 1
        try:
            packet = packet_format.decode(datagram)
        except PacketError as error:
            return self._reject(error.reason, str(error))
        reason = self._order_problem(packet)
        if reason is not None:
            if self._follows_candidate(packet):
                self.counters["stream_resyncs"] += 1
                self.last_problem = (f"followed a new packet stream from sequence {self._candidate.sequence} "
                                     f"(the microcontroller restarted?)")
                self._forget_missing()
                return self._accept(packet, receive_time, lost=0)
            if reason == "reordered":
                self._missing.discard(packet.sequence)   # a second copy of it is a duplicate
            return self._reject(reason, self._describe(reason, packet))
        step = (packet.sequence - self._last.sequence) % SEQUENCE_MODULUS if self._last is not None else 1
        self._note_missing(packet.sequence, step - 1)
        return self._accept(packet, receive_time, lost=step - 1)

    # ------------------------------------------------------------------ checks
    def _order_problem(self, packet: EncoderPacket) -> str | None:
        last = self._last
        if last is None:
            return None
        step = (packet.sequence - last.sequence) % SEQUENCE_MODULUS
        if step == 0:
            return "duplicates"
        if step >= _HALF:  # older than the last accepted packet
            if packet.sequence in self._missing:
                return "reordered"
            back = SEQUENCE_MODULUS - step
            return "duplicates" if back <= self.settings.reorder_window else "sequence_jump"
        clock_step = packet.mcu_time_us - last.mcu_time_us
        if clock_step <= 0:
            return "clock_backwards"
        if abs(clock_step - step * self.period_us) > self.tolerance_us:
            return "clock_inconsistent"
        return None

    def _follows_candidate(self, packet: EncoderPacket) -> bool:
        """Track runs of rejected packets consistent among themselves; True once a run is long enough."""
        candidate = self._candidate
        if (candidate is not None and (packet.sequence - candidate.sequence) % SEQUENCE_MODULUS == 1
                and abs(packet.mcu_time_us - candidate.mcu_time_us - self.period_us) <= self.tolerance_us):
            self._candidate_run += 1
        else:
            self._candidate_run = 1
        self._candidate = packet
        return self._candidate_run >= self.settings.resync_after

    def _describe(self, reason: str, packet: EncoderPacket) -> str:
        last = self._last
        if reason in ("clock_backwards", "clock_inconsistent"):
            return (f"{reason.replace('_', ' ')}: sequence {last.sequence} -> {packet.sequence}, "
                    f"clock {last.mcu_time_us} -> {packet.mcu_time_us} us")
        return f"{reason.replace('_', ' ')}: sequence {packet.sequence} after {last.sequence}"

    # ------------------------------------------------------------------ bookkeeping
    def _reject(self, reason: str, message: str) -> None:
        self.counters[reason] += 1
        self.last_problem = message
        return None

    def _note_missing(self, sequence: int, gap: int) -> None:
        window = self.settings.reorder_window
        for missing in range(sequence - min(gap, window), sequence):
            number = missing % SEQUENCE_MODULUS
            self._missing.add(number)
            self._missing_order.append(number)
        while len(self._missing_order) > window:
            self._missing.discard(self._missing_order.popleft())

    def _forget_missing(self) -> None:
        self._missing.clear()
        self._missing_order.clear()

    def _accept(self, packet: EncoderPacket, receive_time: float, lost: int) -> BridgeSample:
        self._last = packet
        self._candidate, self._candidate_run = None, 0
        self.counters["samples_accepted"] += 1
        self.counters["packets_lost"] += lost
        registers = (packet.azimuth_counts, packet.elevation_counts, packet.motor_counts)
        counts = tuple(unwrapper.update(register) for unwrapper, register in zip(self._unwrappers, registers))
        if self.counters["samples_accepted"] == 1:
            # The first register value is read as the count nearest the homing offset (offset plus
            # the signed 32-bit difference): a counter homed near the wrap point starts right.
            counts = tuple(self._seed(unwrapper, encoder.offset_counts, register) for unwrapper, encoder, register
                           in zip(self._unwrappers, self._encoders, registers))
        self.counters["counter_wraps"] = sum(unwrapper.wraps for unwrapper in self._unwrappers)
        if packet.flags & packet_format.FLAG_CURRENT_VALID:
            current = packet.motor_current
            torque = self.motor.torque(current)
        else:
            current = torque = math.nan
        return BridgeSample(packet, receive_time, *counts, self.kinematics.position(*counts), current, torque, lost)

    @staticmethod
    def _seed(unwrapper: CounterUnwrapper, offset: int, register: int) -> int:
        unwrapper.count = offset + to_register(register - offset)
        return unwrapper.count

    # ------------------------------------------------------------------ reporting
    @property
    def malformed(self) -> int:
        return sum(self.counters[name] for name in MALFORMED)

    @property
    def rejected(self) -> int:
        return self.malformed + sum(self.counters[name] for name in ORDER)
