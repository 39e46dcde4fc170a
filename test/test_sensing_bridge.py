"""The encoder bridge as a plain module: checks, counters, unwrapping, appendix A conversions."""

from __future__ import annotations

import dataclasses
import math
import zlib

import pytest

from hopper_ros.config import load_yaml
from hopper_ros.hardware import packet as packet_format
from hopper_ros.hardware.config import load_hardware
from hopper_ros.hardware.encoders import BoomKinematics, to_register
from hopper_ros.hardware.packet import EncoderPacket
from hopper_ros.sensing.bridge import COUNTER_NAMES, EncoderBridge
from hopper_ros.sensing.config import SensingConfig, load_sensing_config

HARDWARE = load_hardware()
CONFIG = load_sensing_config()
KINEMATICS = BoomKinematics.from_config(HARDWARE)
PERIOD_US = 1000


def packet(sequence: int, y: float = 0.3, z: float = 0.35, leg_angle: float = 0.2, current: float = 1.5,
           clock_us: int | None = None, offsets=(0, 0, 0), **changes) -> EncoderPacket:
    """A packet of the robot at (y, z, leg angle); counter registers include `offsets` (homing)."""
    counts = KINEMATICS.counts(y, z, leg_angle)
    registers = [to_register(c + o) for c, o in zip(counts, offsets)]
    fields = dict(sequence=sequence & 0xFFFFFFFF,
                  mcu_time_us=clock_us if clock_us is not None else 1_000_000 + sequence * PERIOD_US,
                  azimuth_counts=registers[0], elevation_counts=registers[1], motor_counts=registers[2],
                  motor_current_ma=round(current * 1000))
    fields.update(changes)
    return EncoderPacket(**fields)


def bridge(hardware=HARDWARE, **settings) -> EncoderBridge:
    return EncoderBridge.from_config(hardware, dataclasses.replace(CONFIG.bridge, **settings))


def feed(b: EncoderBridge, packets) -> list:
    return [b.process(p if isinstance(p, bytes) else packet_format.encode(p), 0.0) for p in packets]


def accepted_sequences(results) -> list[int]:
    return [r.packet.sequence for r in results if r is not None]


def test_a_packet_becomes_positions_within_one_count_and_hip_torque_from_the_current():
    b = bridge()
    sample = b.process(packet_format.encode(packet(7, y=0.41, z=0.3127, leg_angle=-0.31, current=-2.25)), 12.5)
    resolution_y, resolution_z = KINEMATICS.position_resolution(0.31)
    assert sample.receive_time == 12.5 and sample.mcu_time == pytest.approx(1.007)
    assert abs(sample.position.y - 0.41) <= resolution_y
    assert abs(sample.position.z - 0.3127) <= resolution_z
    assert abs(sample.position.leg_angle + 0.31) <= KINEMATICS.motor.resolution
    # section 4.1: torque = current x torque constant x gear (config/hardware.yaml)
    assert sample.hip_torque == pytest.approx(-2.25 * 0.02411 * 26.0)
    measurement = sample.measurement()
    assert (measurement.sequence, measurement.y, measurement.z) == (7, sample.position.y, sample.position.z)
    assert b.counters["samples_accepted"] == 1 and b.rejected == 0


def test_a_current_flagged_invalid_gives_nan_torque():
    sample = bridge().process(packet_format.encode(packet(1, flags=0)), 0.0)
    assert math.isnan(sample.motor_current) and math.isnan(sample.hip_torque)


def test_malformed_packets_are_counted_by_reason_and_never_returned():
    b = bridge()
    good = packet_format.encode(packet(1))
    bad_crc = bytearray(packet_format.encode(packet(2)))
    bad_crc[20] ^= 0x01                                   # one bit of the elevation counter
    wrong_version = packet_format.encode(packet(3, version=2))
    wrong_magic = b"XX" + packet_format.encode(packet(4))[2:]
    garbage = bytes(range(36))
    results = feed(b, [good, good[:20], b"", good + b"\x00", bytes(bad_crc), wrong_version, wrong_magic, garbage,
                       packet(5)])
    assert accepted_sequences(results) == [1, 5]
    c = b.counters
    assert (c["malformed_size"], c["malformed_checksum"], c["malformed_version"], c["malformed_magic"]) == (3, 1, 1, 2)
    assert c["packets_received"] == 9 and b.malformed == 7
    assert c["packets_lost"] == 3                           # sequences 2, 3, 4 never arrived intact
    assert "expected b'HP'" in b.last_problem               # the latest rejection, in words


def test_sequence_gaps_duplicates_and_reordering():
    b = bridge()
    order = [1, 2, 3, 3, 6, 4, 5, 7, 2, 8, 4]
    results = feed(b, [packet(n) for n in order])
    assert accepted_sequences(results) == [1, 2, 3, 6, 7, 8]
    c = b.counters
    assert c["duplicates"] == 3          # the second 3; 2 again (older, not missing); 4 again after its late copy
    assert c["reordered"] == 2           # 4 and 5 were missing when 6 came, then arrived late
    assert c["packets_lost"] == 2        # counted at the gap, late arrivals included
    assert c["samples_accepted"] + c["packets_lost"] == 8   # every sequence number 1..8 accounted for
    assert results[4].lost_before == 2


def test_the_microcontroller_clock_must_advance_with_the_sequence():
    b = bridge()
    results = feed(b, [packet(1), packet(2),
                       packet(3, clock_us=1_000_000 + 1 * PERIOD_US),      # clock went backwards
                       packet(3, clock_us=1_000_000 + 2 * PERIOD_US),      # did not advance
                       packet(3, clock_us=1_000_000 + 9 * PERIOD_US),      # 7 periods for one step
                       packet(3), packet(6)])                              # good again, then a gap of 2
    assert accepted_sequences(results) == [1, 2, 3, 6]
    assert b.counters["clock_backwards"] == 2 and b.counters["clock_inconsistent"] == 1
    assert b.counters["packets_lost"] == 2                 # 4 and 5


def test_counters_and_sequence_wrap_around_without_a_jump():
    """Registers crossing 2^31 -> -2^31 and the sequence crossing 2^32 -> 0, homing offsets applied."""
    start_elevation = KINEMATICS.counts(0.0, 0.35, 0.0)[1]
    offsets = (2 ** 31 - 40, -2 ** 31 - start_elevation + 8, 2 ** 31 - 5)   # homing: counter values at angle zero
    hardware = load_hardware().with_offsets(**dict(zip(("azimuth", "elevation", "motor"), offsets)))
    b = bridge(hardware)
    start = 2 ** 32 - 3
    samples = []
    for i in range(8):
        y, z, leg = 0.002 * i, 0.35 - 0.0005 * i, 0.01 - 0.002 * i      # moving across the wrap points
        p = packet(start + i, y=y, z=z, leg_angle=leg, offsets=offsets, mcu_time_us=5_000_000 + i * PERIOD_US)
        samples.append((b.process(packet_format.encode(p), 0.0), (y, z, leg)))
    assert all(sample is not None for sample, _ in samples)
    assert [s.packet.sequence for s, _ in samples] == [2 ** 32 - 3, 2 ** 32 - 2, 2 ** 32 - 1, 0, 1, 2, 3, 4]
    resolution_y, resolution_z = KINEMATICS.position_resolution(0.35)
    for sample, (y, z, leg) in samples:
        assert abs(sample.position.y - y) <= resolution_y
        assert abs(sample.position.z - z) <= resolution_z
        assert abs(sample.position.leg_angle - leg) <= KINEMATICS.motor.resolution
    assert b.counters["counter_wraps"] >= 2 and b.counters["packets_lost"] == 0 and b.rejected == 0


def test_a_restarted_microcontroller_is_followed_after_a_consistent_run():
    b = bridge(resync_after=5)
    before = feed(b, [packet(n) for n in range(100, 120)])
    restarted = feed(b, [packet(n, clock_us=10 + n * PERIOD_US) for n in range(1, 12)])   # sequence and clock restart
    assert accepted_sequences(before) == list(range(100, 120))
    assert accepted_sequences(restarted) == list(range(5, 12))   # the 5th consistent packet is taken
    assert b.counters["stream_resyncs"] == 1
    assert b.counters["duplicates"] + b.counters["sequence_jump"] + b.counters["clock_backwards"] == 4


def test_interleaved_bad_packets_never_restart_the_stream():
    """A duplicated stream (every packet twice) is consistent among its rejects but never resyncs."""
    b = bridge(resync_after=3)
    stream = [packet(n) for n in range(1, 50) for _ in range(2)]
    results = feed(b, stream)
    assert accepted_sequences(results) == list(range(1, 50))
    assert b.counters["duplicates"] == 49 and b.counters["stream_resyncs"] == 0


def test_every_counter_is_reported_and_settings_are_validated():
    assert set(bridge().counters) == set(COUNTER_NAMES)
    raw = load_yaml("sensing.yaml")
    raw["sensing"]["bridge"]["resync_after"] = 1
    with pytest.raises(ValueError, match="resync_after"):
        SensingConfig.from_dict(raw)
    raw = load_yaml("sensing.yaml")
    raw["sensing"]["bridge"]["clock_tolerence"] = 1e-4
    with pytest.raises(ValueError, match="clock_tolerence: unknown key"):
        SensingConfig.from_dict(raw)
    raw = load_yaml("sensing.yaml")
    del raw["sensing"]["estimator"]["outlier_gate"]
    with pytest.raises(ValueError, match="outlier_gate: missing"):
        SensingConfig.from_dict(raw)
    raw = load_yaml("sensing.yaml")
    raw["sensing"]["estimator"]["measurement_noise"] = "guess"
    with pytest.raises(ValueError, match="measurement_noise"):
        SensingConfig.from_dict(raw)


def test_crc_is_the_ieee_crc32_of_the_first_32_bytes():
    """The bridge rejects exactly what zlib.crc32 rejects (docs/encoder_packet.md)."""
    data = bytearray(packet_format.encode(packet(1)))
    assert int.from_bytes(data[32:], "little") == zlib.crc32(bytes(data[:32]))
    data[32:] = (zlib.crc32(bytes(data[:32])) ^ 1).to_bytes(4, "little")
    b = bridge()
    assert b.process(bytes(data), 0.0) is None and b.counters["malformed_checksum"] == 1
