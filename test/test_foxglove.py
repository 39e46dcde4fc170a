"""Foxglove opens our bags: every message of a bag recorded live from the node graph and of a
`hopper collect` bag decoded with Foxglove's own libraries (@mcap/core's indexed reader,
@foxglove/rosmsg's ROS 2 definition parser, @foxglove/rosmsg2-serialization's CDR reader, what the
Foxglove app uses; pinned in test/foxglove/, installed by `make setup` with npm into
.venv/foxglove), a few fields compared with what was published, and the independent `rosbags` as
the second reader. Skipped only where Node.js is absent."""

from __future__ import annotations

import collections
import json
import math
import os
import shutil
import signal
import socket
import subprocess

import pytest
import yaml

from conftest import REPO, SAFETY_TIMEOUT, free_port, spin_until

NODE = shutil.which("node")
FOXGLOVE_MODULES = REPO / ".venv" / "foxglove" / "node_modules"
DECODE = REPO / "test" / "foxglove" / "decode_bag.cjs"

pytestmark = pytest.mark.skipif(NODE is None, reason="Node.js is not installed here: Foxglove's libraries cannot run")


def foxglove_decode(mcap_file, *topics: str) -> dict:
    """What Foxglove's libraries make of an MCAP file (decode_bag.cjs): per topic the schema and
    the count of decoded messages, and every decoded message of `topics`."""
    if not FOXGLOVE_MODULES.is_dir():
        pytest.fail(f"Foxglove's libraries are not installed in {FOXGLOVE_MODULES}: run `make setup` "
                    f"(it installs test/foxglove/package-lock.json with npm)")
    result = subprocess.run([NODE, str(DECODE), str(mcap_file), *topics], capture_output=True, text=True,
                            env={**os.environ, "NODE_PATH": str(FOXGLOVE_MODULES)}, timeout=600)
    assert result.returncode in (0, 1) and result.stdout, result.stderr
    return json.loads(result.stdout)


def rosbags_counts(bag) -> dict[str, int]:
    """Messages per topic as the independent `rosbags` reads them, every one decoded from the bag's
    own definitions."""
    from test_recording_live import rosbags_messages

    return dict(collections.Counter(topic for topic, _, _ in rosbags_messages(bag)))


def assert_everything_decoded(result: dict, bag) -> dict[str, int]:
    """Every message decoded by Foxglove, as many as metadata.yaml and rosbags count; returns the counts."""
    problems = {topic: t["error"] for topic, t in result["topics"].items() if t["error"]}
    assert not problems, problems
    assert result["profile"] == "ros2" and result["failed"] == 0
    assert result["decoded"] == result["messages"] == result["statistics_message_count"] > 0
    undescribed = {topic: t["undescribed_bytes"] for topic, t in result["topics"].items() if t["undescribed_bytes"]}
    assert not undescribed, undescribed        # schema and payload agree exactly (up to alignment padding)
    assert all(t["schema_encoding"] == "ros2msg" and t["message_encoding"] == "cdr" for t in result["topics"].values())
    counts = {topic: t["count"] for topic, t in result["topics"].items() if t["count"]}
    metadata = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert metadata["message_count"] == result["messages"]
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in metadata["topics_with_message_count"]
            if t["message_count"]} == counts
    assert rosbags_counts(bag) == counts
    return counts


def stamp_ns(stamp) -> int:
    """A header stamp (rclpy message, or Foxglove's decoded {sec, nanosec}) in nanoseconds."""
    if isinstance(stamp, dict):
        return int(stamp["sec"]) * 1_000_000_000 + int(stamp["nanosec"])
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def same_float(foxglove_value, ours: float) -> bool:
    value = float(foxglove_value)          # NaN and infinities come as strings from JSON
    return (math.isnan(value) and math.isnan(ours)) or value == ours


# ---------------------------------------------------------------------------- hopper collect


def test_foxglove_decodes_every_message_of_a_collected_bag(hopper_cli, tmp_path):
    from hopper_ros.recording.bag import BagReader

    collect = hopper_cli("collect", "-n", "8", "--noise", "--seed", "3", "-o", str(tmp_path / "bag"))
    assert collect.wait() == 0, collect.stderr
    result = foxglove_decode(tmp_path / "bag" / "bag_0.mcap", "/sim/truth", "/stride_command", "/sim/events")
    counts = assert_everything_decoded(result, tmp_path / "bag")
    assert set(counts) == {"/body_measurement", "/force_plate", "/sim/truth", "/stride_command", "/sim/events"}
    print(f"\nFoxglove decoded {result['decoded']} of {result['messages']} messages of a hopper collect bag: {counts}")

    # the fields against what the collection wrote, decoded by rclpy
    written: dict[str, list] = {}
    for topic, log_time, msg in BagReader(tmp_path / "bag").messages(["/sim/truth", "/stride_command", "/sim/events"]):
        written.setdefault(topic, []).append((log_time, msg))
    dumps = result["dumps"]
    for topic in ("/sim/truth", "/stride_command", "/sim/events"):
        assert len(dumps[topic]) == len(written[topic]) == counts[topic]
    for (log_time, ours), (fox_time, fox) in zip(written["/sim/truth"], dumps["/sim/truth"]):
        assert int(fox_time) == log_time and stamp_ns(fox["header"]["stamp"]) == stamp_ns(ours.header.stamp)
        assert fox["header"]["frame_id"] == ours.header.frame_id == "ground"
        assert (fox["z"], fox["y_dot"], fox["leg_angle"]) == (ours.z, ours.y_dot, ours.leg_angle)
        assert fox["covariance_diagonal"] == list(ours.covariance_diagonal)
    for (_, ours), (_, fox) in zip(written["/stride_command"], dumps["/stride_command"]):
        assert (fox["stride_index"], fox["tau_0"], fox["touchdown_angle"], fox["feasible"], fox["reason"]) == (
            ours.stride_index, ours.tau_0, ours.touchdown_angle, ours.feasible, ours.reason)
    for (_, ours), (_, fox) in zip(written["/sim/events"], dumps["/sim/events"]):
        assert (fox["type"], fox["stride_index"]) == (ours.type, ours.stride_index)
        assert (fox["state"]["z"], fox["state"]["y"]) == (ours.state.z, ours.state.y)        # a nested message


# ---------------------------------------------------------------------------- the live graph


def test_foxglove_decodes_every_message_of_a_bag_recorded_from_the_node_graph(rclpy_session, hopper_cli, tmp_path):
    """The sensing chain fed by the simulated robot, `hopper bag record -a`; a listener of this test
    keeps what was published on the event topics and /diagnostics to compare with."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from hopper_ros.msg import ApexState, GaitEvent
    from hopper_ros.nodes.diagnostics import level_of

    port = free_port(socket.SOCK_DGRAM)
    nodes = [hopper_cli("run", "encoder_bridge", "--ros-args", "-p", f"port:={port}", "-p", "diagnostics_period:=0.5"),
             hopper_cli("run", "state_estimator", "--ros-args", "-p", "diagnostics_period:=0.5"),
             hopper_cli("run", "event_detector", "--ros-args", "-p", "diagnostics_period:=0.5")]
    listener = rclpy_session.create_node("foxglove_test_listener")
    executor = EventsExecutor()
    executor.add_node(listener)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    published = {"/diagnostics": [], "/gait_event": [], "/apex": [], "/sim/events": []}
    listener.create_subscription(DiagnosticArray, "/diagnostics", published["/diagnostics"].append, qos)
    listener.create_subscription(GaitEvent, "/gait_event", published["/gait_event"].append, qos)
    listener.create_subscription(GaitEvent, "/sim/events", published["/sim/events"].append, qos)
    listener.create_subscription(ApexState, "/apex", published["/apex"].append, qos)
    recorder = sim = None
    try:
        for node in nodes:
            node.wait_for_line(r"started: pid")
        recorder = hopper_cli("bag", "record", "-a", "-o", str(tmp_path / "bag"))
        for topic in ("/body_state", "/gait_event", "/diagnostics", "/rosout"):
            recorder.wait_for_line(rf"subscribed to {topic} \[")
        sim = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=none", "-p", "experiments:=true",
                         "-p", f"udp_port:={port}", "-p", "duration:=4.0", "-p", "publish_truth:=false",
                         "-p", "force_plate:=false")
        recorder.wait_for_line(r"subscribed to /sim/events \[hopper_ros/msg/GaitEvent\]")
        assert spin_until(executor, lambda: sim.process.poll() is not None, SAFETY_TIMEOUT)
        assert sim.wait() == 0, sim.stderr
        spin_until(executor, lambda: False, 1.5)          # the last reports
        recorder.signal(signal.SIGINT)
        assert recorder.wait() == 0, recorder.stderr
    finally:
        for process in [*nodes, recorder, sim]:
            if process is not None and process.process.poll() is None:
                process.signal(signal.SIGINT)
        for node in nodes:
            assert node.wait() == 0, node.stderr
        executor.shutdown()
        listener.destroy_node()

    mcap = tmp_path / "bag" / "bag_0.mcap"
    result = foxglove_decode(mcap, *published)
    counts = assert_everything_decoded(result, tmp_path / "bag")
    print(f"\nFoxglove decoded {result['decoded']} of {result['messages']} messages recorded live: {counts}")
    types = {topic: t["schema"] for topic, t in result["topics"].items()}
    assert types["/diagnostics"] == "diagnostic_msgs/msg/DiagnosticArray"
    assert types["/rosout"] == "rcl_interfaces/msg/Log" and counts["/rosout"] > 0
    for topic in ("/body_measurement", "/encoder_sample", "/body_state", "/gait_event", "/apex", "/sim/events"):
        assert counts.get(topic, 0) > 0, topic
    assert counts["/body_state"] > 1000                     # 1 kHz for over a second (decoding, not throughput)

    dumps = result["dumps"]
    # every diagnostics report in the bag is one the listener got, field by field
    heard = {(stamp_ns(a.header.stamp), s.name): s for a in published["/diagnostics"] for s in a.status}
    reports = [(stamp_ns(fox["header"]["stamp"]), status) for _, fox in dumps["/diagnostics"] for status in fox["status"]]
    assert {status["name"] for _, status in reports} >= {"/encoder_bridge", "/state_estimator", "/event_detector",
                                                         "/sim_robot"}
    first_heard = min((stamp for stamp, _ in heard), default=0)
    compared = 0
    for stamp, status in reports:
        ours = heard.get((stamp, status["name"]))
        if ours is None:
            continue                  # published before the listener matched
        compared += 1
        assert status["level"] == level_of(ours) and status["message"] == ours.message
        assert status["hardware_id"] == ours.hardware_id
        assert [(v["key"], v["value"]) for v in status["values"]] == [(v.key, v.value) for v in ours.values]
    assert compared >= 0.8 * sum(stamp >= first_heard for stamp, _ in reports) > 0
    # the gait events with their nested state, and the apexes
    for topic in ("/gait_event", "/sim/events"):
        heard_events = {(stamp_ns(m.header.stamp), m.type): m for m in published[topic]}
        # the listener and the recorder each match a publisher in their own time: compare where both listened
        since = min((stamp for stamp, _ in heard_events), default=0)
        both = [fox for _, fox in dumps[topic] if stamp_ns(fox["header"]["stamp"]) >= since]
        matched = 0
        for fox in both:
            ours = heard_events.get((stamp_ns(fox["header"]["stamp"]), fox["type"]))
            if ours is None:
                continue
            matched += 1
            assert fox["stride_index"] == ours.stride_index
            assert same_float(fox["state"]["z"], ours.state.z) and same_float(fox["state"]["y_dot"], ours.state.y_dot)
        assert matched >= 0.8 * len(both) > 0, (topic, matched, len(both), len(dumps[topic]))
    heard_apex = {stamp_ns(m.header.stamp): m for m in published["/apex"]}
    for _, fox in dumps["/apex"]:
        ours = heard_apex.get(stamp_ns(fox["header"]["stamp"]))
        if ours is not None:
            assert (fox["apex_height"], fox["forward_speed"]) == (ours.apex_height, ours.forward_speed)
    # and rosbags reads the standard diagnostics too: the statuses as the nodes built them
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    with Reader(tmp_path / "bag") as reader:
        connections = [c for c in reader.connections if c.topic == "/diagnostics"]
        store.register(get_types_from_msg(connections[0].msgdef.data, connections[0].msgtype))
        names = {status.name for _, _, raw in reader.messages(connections=connections)
                 for status in store.deserialize_cdr(raw, "diagnostic_msgs/msg/DiagnosticArray").status}
    assert names >= {"/encoder_bridge", "/state_estimator", "/event_detector", "/sim_robot"}
    bridge = [s for _, fox in dumps["/diagnostics"] for s in fox["status"] if s["name"] == "/encoder_bridge"][-1]
    assert int({v["key"]: v["value"] for v in bridge["values"]}["packets_received"]) > 2000
