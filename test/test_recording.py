"""Bags: our writer read back by the independent `rosbags` library, the column decoder, damaged
and unfinished files, the lockstep collection. (Live recording: test_recording_live.py.)"""

from __future__ import annotations

import array
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from hopper_ros.recording.bag import BagError, BagReader, BagWriter, bag_info, recover_bag

MESSAGE_TYPES = ("ApexState", "BodyMeasurement", "BodyState", "EncoderSample", "GaitEvent", "GroundReactionForce",
                 "MotorCommand", "MotorStatus", "StrideCommand")


def filled(cls, seed: float):
    """A message with every field set to a value derived from its name and `seed`."""
    msg = cls()
    for index, (name, type_text) in enumerate(cls.get_fields_and_field_types().items()):
        value = getattr(msg, name)
        token = seed + index + 1
        if type_text == "std_msgs/Header":
            value.stamp.sec, value.stamp.nanosec, value.frame_id = int(token), int(token * 1000) % 10**9, f"frame{index}"
        elif hasattr(value, "get_fields_and_field_types"):
            setattr(msg, name, filled(type(value), token * 10))
        elif type_text == "boolean":
            setattr(msg, name, index % 2 == 0)
        elif type_text == "string":
            setattr(msg, name, f"{name} {token:g}")
        elif type_text.startswith("sequence<string"):
            setattr(msg, name, [f"{name}{k}" for k in range(3)])
        elif type_text.startswith("sequence<uint64"):
            setattr(msg, name, [int(token) + k for k in range(3)])
        elif type_text.startswith("sequence<double"):
            setattr(msg, name, [token + 0.25 * k for k in range(3)])
        elif type_text.startswith("double["):
            setattr(msg, name, [token + 0.5 * k for k in range(len(value))])
        elif type_text in ("double", "float"):
            setattr(msg, name, token + 0.125)
        elif type_text.startswith("int") or type_text.startswith("uint"):
            bits = int("".join(ch for ch in type_text if ch.isdigit()))
            setattr(msg, name, int(token) % (2 ** (bits - 1)))
        else:
            raise AssertionError(f"filled() does not know {type_text} ({cls.__name__}.{name})")
    return msg


def same(ours, theirs, where: str) -> None:
    """Our message object equals the one rosbags decoded, field by field."""
    for name in ours.get_fields_and_field_types():
        a, b = getattr(ours, name), getattr(theirs, name)
        if hasattr(a, "get_fields_and_field_types"):
            same(a, b, f"{where}.{name}")
        elif isinstance(a, (list, tuple, array.array, np.ndarray)):
            assert list(np.asarray(a).tolist()) == list(np.asarray(b).tolist()), f"{where}.{name}"
        else:
            assert a == b, f"{where}.{name}: {a!r} != {b!r}"


def test_every_message_type_is_read_back_by_rosbags_from_the_embedded_definitions(tmp_path):
    import hopper_ros.msg as msgs
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    written = {}
    with BagWriter(tmp_path / "bag", chunk_size=4096) as bag:
        for k in range(40):
            for name in MESSAGE_TYPES:
                msg = filled(getattr(msgs, name), seed=k)
                bag.write_message(f"/test/{name.lower()}", msg, 1_700_000_000_000_000_000 + k * 1_000_000)
                written.setdefault(f"/test/{name.lower()}", []).append(msg)
    # chunked, compressed and indexed: several chunks, each with message indexes, and a summary
    with open(tmp_path / "bag" / "bag_0.mcap", "rb") as handle:
        summary = make_reader(handle).get_summary()
    assert len(summary.chunk_indexes) > 5
    assert all(c.compression == "zstd" and c.message_index_offsets for c in summary.chunk_indexes)
    assert summary.statistics.message_count == 40 * len(MESSAGE_TYPES)
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}

    store = get_typestore(Stores.EMPTY)      # knows nothing: every type comes from the bag itself
    with Reader(tmp_path / "bag") as reader:
        types = {}
        for connection in reader.connections:
            assert connection.msgdef.format.name == "MSG"
            types.update(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        store.register(types)
        assert {"std_msgs/msg/Header", "builtin_interfaces/msg/Time", "hopper_ros/msg/BodyState"} <= set(types)
        counts = {}
        for connection, timestamp, raw in reader.messages():
            decoded = store.deserialize_cdr(raw, connection.msgtype)
            index = counts.get(connection.topic, 0)
            same(written[connection.topic][index], decoded, connection.topic)
            assert timestamp == 1_700_000_000_000_000_000 + index * 1_000_000
            counts[connection.topic] = index + 1
        assert counts == {topic: 40 for topic in written}
        assert reader.message_count == 40 * len(MESSAGE_TYPES)


def test_column_decoder_matches_rclpy_and_declines_what_it_cannot_decode():
    from rclpy.serialization import serialize_message

    import hopper_ros.msg as msgs
    from hopper_ros.recording.cdr import decode_columns

    for name in ("BodyMeasurement", "BodyState", "GroundReactionForce", "EncoderSample", "ApexState"):
        cls = getattr(msgs, name)
        messages = [filled(cls, seed=k * 1.5) for k in range(5)]
        for m in messages:
            m.header.frame_id = "ground"
        columns = decode_columns(cls, [serialize_message(m) for m in messages])
        assert columns is not None, name
        for field in cls.get_fields_and_field_types():
            if field == "header":
                assert columns["stamp_sec"].tolist() == [m.header.stamp.sec for m in messages]
                assert columns["stamp_nanosec"].tolist() == [m.header.stamp.nanosec for m in messages]
                continue
            expected = np.array([np.asarray(getattr(m, field)) for m in messages])
            assert np.array_equal(np.asarray(columns[field]), expected), f"{name}.{field}"
    # strings, nested messages, sequences: not flat, left to rclpy
    assert decode_columns(msgs.GaitEvent, [serialize_message(msgs.GaitEvent())]) is None
    assert decode_columns(msgs.StrideCommand, [serialize_message(msgs.StrideCommand())]) is None
    mixed = [msgs.GroundReactionForce(), msgs.GroundReactionForce()]
    mixed[1].header.frame_id = "force_plate"
    assert decode_columns(msgs.GroundReactionForce, [serialize_message(m) for m in mixed]) is None


def chunk_offsets(file) -> list[int]:
    """Byte offsets of the chunk records of an MCAP file (walking its records)."""
    data = file.read_bytes()
    offsets, position = [], 8
    while position + 9 <= len(data):
        opcode, length = data[position], int.from_bytes(data[position + 1:position + 9], "little")
        if opcode == 0x06:
            offsets.append(position)
        position += 9 + length
    return offsets


def _write_force_bag(path, count: int, chunk_size: int = 2048):
    from hopper_ros.msg import GroundReactionForce

    bag = BagWriter(path, chunk_size=chunk_size, chunk_interval=0.0)
    for k in range(count):
        msg = GroundReactionForce(force_vertical=float(k))
        msg.header.stamp.sec = 100 + k
        bag.write_message("/force_plate", msg, 10**18 + k * 10**6)
    return bag


def test_an_unfinished_bag_reads_up_to_its_last_chunk_and_recovers(tmp_path):
    from rosbags.rosbag2 import Reader

    bag = _write_force_bag(tmp_path / "bag", 2000)
    bag.flush()                      # what a chunk interval does while recording
    file = tmp_path / "bag" / "bag_0.mcap"
    # the recorder dies: no summary, no footer, no metadata.yaml (the writer is simply dropped)
    info = bag_info(tmp_path / "bag")
    assert not info.complete and info.message_count == 2000
    assert any("interrupted" in p for p in info.problems) and any("metadata.yaml" in p for p in info.problems)
    assert "UNFINISHED" in info.format()
    with pytest.raises(FileNotFoundError):          # rosbags needs the metadata (and the footer)
        Reader(tmp_path / "bag").open()
    # cut the file inside its last chunk, as a kill during a write would
    cut = chunk_offsets(file)[-1] + 50
    with open(file, "r+b") as handle:
        handle.truncate(cut)
    reader = BagReader(tmp_path / "bag")
    values = [msg.force_vertical for _, _, msg in reader.messages()]
    assert values == [float(k) for k in range(len(values))]          # in order, nothing missing before the cut
    lost = 2000 - len(values)
    assert 0 < lost <= 2048 // 20                                      # at most one chunk (messages are ~80 bytes)
    assert "cut short" in reader.scans[0].problem
    result = recover_bag(tmp_path / "bag")
    assert result.messages == len(values) and result.kept_original.exists()
    assert result.kept_original.stat().st_size == cut                  # the unfinished original is kept as it was
    assert result.dropped_bytes == cut - chunk_offsets(result.kept_original)[-1]
    with Reader(tmp_path / "bag") as rosbags_reader:
        assert rosbags_reader.message_count == len(values)
        assert rosbags_reader.connections[0].msgtype == "hopper_ros/msg/GroundReactionForce"
    assert bag_info(tmp_path / "bag").complete
    assert recover_bag(tmp_path / "bag").already_complete


def test_a_damaged_chunk_ends_the_readable_part_with_a_clear_reason(tmp_path):
    bag = _write_force_bag(tmp_path / "bag", 1000)
    bag.close()
    file = tmp_path / "bag" / "bag_0.mcap"
    data = bytearray(file.read_bytes())
    offsets = chunk_offsets(file)
    data[offsets[len(offsets) // 2] + 100] ^= 0xFF    # one flipped byte in the compressed data of a middle chunk
    file.write_bytes(bytes(data))
    reader = BagReader(tmp_path / "bag")
    values = [msg.force_vertical for _, _, msg in reader.messages()]
    assert 0 < len(values) < 1000 and values == [float(k) for k in range(len(values))]
    assert "damaged" in reader.scans[0].problem


def test_nothing_recorded_is_ever_overwritten(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "notes.txt").write_text("keep me")
    with pytest.raises(BagError, match="not an empty folder"):
        BagWriter(folder)
    assert (folder / "notes.txt").read_text() == "keep me"
    with BagWriter(tmp_path / "ok") as bag:
        bag.add_topic("/force_plate", "hopper_ros/msg/GroundReactionForce")
        with pytest.raises(BagError, match="is recorded as"):
            bag.add_topic("force_plate", "hopper_ros/msg/BodyState")
        with pytest.raises(BagError, match="not declared"):
            bag.write("/nothing", b"", 0)
    with pytest.raises(BagError, match="closed"):
        bag.write("/force_plate", b"", 0)
    with pytest.raises(BagError, match="not a bag"):
        bag_info(tmp_path / "run")
    # nor a CSV export
    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.harness.collect import CollectionSettings, collect
    from hopper_ros.recording.recordings import RecordingError, load_csv, write_csv
    from hopper_ros.sim.config import load_sim_config

    table = tmp_path / "strides.csv"
    table.write_text("t,y,z,theta,tau\n0,0,0.3,0.1,0\n0.001,0,0.3,0.1,0\n")
    with pytest.raises(RecordingError, match="never written over"):
        write_csv(table, load_csv(table))
    with pytest.raises(ValueError, match="never written over"):
        collect(tmp_path / "new_bag", load_sim_config(), load_hardware(), CollectionSettings(experiments=1),
                csv_path=table)
    assert not (tmp_path / "new_bag").exists() and len(load_csv(table)) == 2


def test_lockstep_collection_records_what_a_live_recording_holds(tmp_path):
    from rosbags.rosbag2 import Reader

    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.harness.collect import CollectionSettings, collect
    from hopper_ros.recording.recordings import load_bag, load_csv
    from hopper_ros.sim.config import load_sim_config

    config = load_sim_config().with_sensors(encoder_noise=True)
    hardware = load_hardware()
    result = collect(tmp_path / "bag", config, hardware, CollectionSettings(experiments=12, seed=4),
                     csv_path=tmp_path / "strides.csv")
    kept = len(result.kept)
    assert 0 < kept < 12 and sum(result.discarded.values()) == 12 - kept     # some fail at these ranges, as on the robot
    with Reader(tmp_path / "bag") as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts["/stride_command"] == kept
        assert counts["/sim/events"] == 5 * kept           # apex, touchdown, bottom, lift-off, apex
        assert counts["/body_measurement"] == counts["/force_plate"] == counts["/sim/truth"] > 300 * kept
        assert BagReader(tmp_path / "bag").custom_data["hopper_ros.effects"] == ""          # no effect: the robot is the model
    recording = load_bag(tmp_path / "bag")
    truth = recording.truth
    assert np.array_equal(truth["t"], recording.t)
    # measured through the encoders: quantised (0.22 mm) plus one count of noise, never more than a few counts off
    assert 0 < np.max(np.abs(recording.z - truth["z"])) < 2e-3
    assert np.max(np.abs(recording.theta - truth["theta"])) < 1e-3
    # the CSV holds the same samples and the commanded torque: the ramp (2.32) in each stance
    table = load_csv(tmp_path / "strides.csv")
    assert np.allclose(table.y, recording.y) and np.allclose(table.t, recording.t, atol=1e-6)
    first = result.kept[0]
    stance = (recording.phase == 1) | (recording.phase == 2)
    first_stance = np.flatnonzero(stance)[: int(first.ramp_duration * 1000) - 2]
    assert np.all(table.tau[first_stance] < 0.0) and np.min(table.tau[first_stance]) >= -first.tau_0 - 1e-9
    gaps = np.diff(recording.t)
    assert np.sum(gaps > 0.1) == kept - 1                  # separate throws, separated on the clock
    assert math.isclose(float(np.median(gaps)), 1e-3, rel_tol=1e-6)


def test_a_copied_bag_without_metadata_still_reads(tmp_path):
    bag = _write_force_bag(tmp_path / "bag", 50)
    bag.close()
    shutil.copy(tmp_path / "bag" / "bag_0.mcap", tmp_path / "alone.mcap")
    assert bag_info(tmp_path / "alone.mcap").message_count == 50
    (tmp_path / "bag" / "metadata.yaml").unlink()
    result = recover_bag(tmp_path / "bag")
    assert not result.already_complete and result.kept_original is None and result.messages == 50
    assert bag_info(tmp_path / "bag").complete


def test_schema_text_is_what_rosbag2_writes():
    """rosbag2's LocalMessageDefinitionSource: the .msg files verbatim, each dependency once, depth
    first in sorted order, under "MSG: pkg/Type" as the field names it (not pkg/msg/Type)."""
    from ament_index_python.packages import get_package_share_directory

    from hopper_ros.recording.schemas import SEPARATOR, message_definition

    def text(package, name):
        return (Path(get_package_share_directory(package)) / "msg" / f"{name}.msg").read_text()

    def section(type_name):
        package, name = type_name.split("/")
        return f"\n{SEPARATOR}\nMSG: {type_name}\n{text(package, name)}"

    expected = (text("diagnostic_msgs", "DiagnosticArray") + section("diagnostic_msgs/DiagnosticStatus")
                + section("diagnostic_msgs/KeyValue") + section("std_msgs/Header") + section("builtin_interfaces/Time"))
    assert message_definition("diagnostic_msgs/msg/DiagnosticArray") == expected
    # our own: GaitEvent uses BodyState (same package, named without one) and Header, both use Header
    expected = (text("hopper_ros", "GaitEvent") + section("hopper_ros/BodyState") + section("std_msgs/Header")
                + section("builtin_interfaces/Time"))
    assert message_definition("hopper_ros/msg/GaitEvent") == expected
    assert "MSG: std_msgs/msg/" not in expected


def test_metadata_is_what_rosbag2_kilted_writes(tmp_path):
    """metadata.yaml as rosbag2 (Kilted: metadata version 9) writes it with yaml-cpp: its keys in
    its order, sequences indented, `~` for no custom data, `""` for empty strings, the QoS
    profiles as a list, the type hash; the MCAP channel carries the same QoS and hash."""
    import yaml
    from mcap.reader import make_reader

    from hopper_ros.msg import ApexState
    from hopper_ros.recording.schemas import type_hash

    with BagWriter(tmp_path / "bag") as bag:
        bag.write_message("/apex", ApexState(apex_height=0.4), 1_700_000_000_000_000_000)
        bag.write_message("/apex", ApexState(apex_height=0.5), 1_700_000_000_500_000_000)
    text = (tmp_path / "bag" / "metadata.yaml").read_text()
    digest = type_hash("hopper_ros/msg/ApexState")
    assert digest.startswith("RIHS01_") and len(digest) == 7 + 64
    assert text.startswith("rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n  duration:\n"
                           "    nanoseconds: 500000000\n  starting_time:\n    nanoseconds_since_epoch: 1700000000000000000\n"
                           "  message_count: 2\n  topics_with_message_count:\n    - topic_metadata:\n"
                           "        name: /apex\n        type: hopper_ros/msg/ApexState\n        serialization_format: cdr\n"
                           "        offered_qos_profiles:\n          - history: keep_last\n")
    assert (f"        type_description_hash: {digest}\n      message_count: 2\n  compression_format: \"\"\n"
            f"  compression_mode: \"\"\n  relative_file_paths:\n    - bag_0.mcap\n  files:\n    - path: bag_0.mcap\n") in text
    assert text.endswith("      message_count: 2\n  custom_data: ~\n  ros_distro: kilted")   # yaml-cpp: no final newline
    document = yaml.safe_load(text)["rosbag2_bagfile_information"]
    assert list(document) == ["version", "storage_identifier", "duration", "starting_time", "message_count",
                              "topics_with_message_count", "compression_format", "compression_mode",
                              "relative_file_paths", "files", "custom_data", "ros_distro"]
    with open(tmp_path / "bag" / "bag_0.mcap", "rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        [channel] = summary.channels.values()
        assert channel.metadata["topic_type_hash"] == digest
        assert yaml.safe_load(channel.metadata["offered_qos_profiles"]) == document["topics_with_message_count"][0][
            "topic_metadata"]["offered_qos_profiles"]
        [record] = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        assert yaml.safe_load(record.metadata["serialized_metadata"]) == document
