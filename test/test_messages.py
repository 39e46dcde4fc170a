"""Every hopper_ros message type through a real publisher and subscriber, and the YAML that
`hopper topic echo` prints for messages."""

from __future__ import annotations

import array
import re
from pathlib import Path

import pytest
import yaml

from hopper_ros.runtime.messages import message_class, message_to_dict, message_to_yaml, type_name_of

REPO = Path(__file__).resolve().parent.parent
MESSAGE_NAMES = sorted(path.stem for path in (REPO / "msg").glob("*.msg"))

_INT_BITS = {"int8": 8, "int16": 16, "int32": 32, "int64": 64, "uint8": 8, "uint16": 16, "uint32": 32, "uint64": 64}


def value_for(field_type: str, seed: int):
    """A non-default value of a field type as get_fields_and_field_types() spells it."""
    match = re.fullmatch(r"(.+)\[(\d+)\]", field_type)  # fixed-size array
    if match:
        return [value_for(match.group(1), seed + i) for i in range(int(match.group(2)))]
    match = re.fullmatch(r"sequence<(.+?)(?:, (\d+))?>", field_type)  # bounded or not
    if match:
        size = min(3, int(match.group(2) or 3))
        return [value_for(match.group(1), seed + i) for i in range(size)]
    base = re.sub(r"<\d+>$", "", field_type)  # bounded strings
    if base in _INT_BITS:
        bits = _INT_BITS[base]
        if base.startswith("u"):
            return (2 ** bits - 1) - seed % 50  # near the top of the range: catches narrowing
        return -(2 ** (bits - 1)) + 1 + seed % 50  # negative, near the bottom
    if base == "double":
        return seed + 0.123456789012345  # exact in float64, not in float32
    if base == "float":
        return seed + 0.375  # exact in float32
    if base == "boolean":
        return True
    if base == "octet":
        return bytes([seed % 255 + 1])
    if base == "char":
        return chr(ord("a") + seed % 26)
    if base in ("string", "wstring"):
        return f"value {seed}: ü"[: int(field_type[7:-1]) if field_type.startswith("string<") else None]
    if "/" in base:  # nested message, e.g. std_msgs/Header
        return filled(message_class(base), seed)
    raise AssertionError(f"no value generator for field type {field_type!r}")


def filled(cls, seed: int = 1):
    """An instance of `cls` with a non-default value in every field (recursively)."""
    msg = cls()
    for index, (name, field_type) in enumerate(cls.get_fields_and_field_types().items()):
        setattr(msg, name, value_for(field_type, seed * 100 + index + 1))
    return msg


def assert_same(sent, got, path: str) -> None:
    """Compare two messages field by field (recursively), naming the field that differs."""
    if hasattr(sent, "get_fields_and_field_types"):
        assert type(sent) is type(got), path
        for name in sent.get_fields_and_field_types():
            assert_same(getattr(sent, name), getattr(got, name), f"{path}.{name}")
        return
    if isinstance(sent, (list, tuple, array.array)) or type(sent).__name__ == "ndarray":
        sent_items, got_items = list(sent), list(got)
        assert len(sent_items) == len(got_items), f"{path}: length {len(got_items)} != {len(sent_items)}"
        for i, (a, b) in enumerate(zip(sent_items, got_items)):
            assert_same(a, b, f"{path}[{i}]")
        return
    assert sent == got, f"{path}: received {got!r}, sent {sent!r}"


def hopper_message(name: str):
    return message_class(f"hopper_ros/msg/{name}")


def test_all_message_types_are_covered():
    assert len(MESSAGE_NAMES) == 9          # health goes out as diagnostic_msgs/DiagnosticArray
    for name in MESSAGE_NAMES:
        assert type_name_of(hopper_message(name)) == f"hopper_ros/msg/{name}"


def test_generated_values_differ_from_defaults():
    for name in MESSAGE_NAMES:
        cls = hopper_message(name)
        default, msg = message_to_dict(cls()), message_to_dict(filled(cls))
        for field in cls.get_fields_and_field_types():
            assert msg[field] != default[field], f"{name}.{field} keeps its default value"


def test_every_message_type_round_trips(rclpy_session):
    from conftest import spin_until
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rclpy = rclpy_session
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    sender = rclpy.create_node("roundtrip_sender")
    receiver = rclpy.create_node("roundtrip_receiver")
    executor = SingleThreadedExecutor()
    executor.add_node(sender)
    executor.add_node(receiver)
    try:
        cases = []
        for seed, name in enumerate(MESSAGE_NAMES, start=1):
            cls = hopper_message(name)
            inbox = []
            receiver.create_subscription(cls, f"roundtrip/{name}", inbox.append, qos)
            publisher = sender.create_publisher(cls, f"roundtrip/{name}", qos)
            cases.append((name, filled(cls, seed), publisher, inbox))
        assert spin_until(executor, lambda: all(p.get_subscription_count() >= 1 for _, _, p, _ in cases))
        for _, msg, publisher, _ in cases:
            publisher.publish(msg)
        assert spin_until(executor, lambda: all(inbox for *_, inbox in cases))
        for name, sent, _, inbox in cases:
            assert len(inbox) == 1
            assert_same(sent, inbox[0], name)
    finally:
        executor.shutdown()
        sender.destroy_node()
        receiver.destroy_node()


# --------------------------------------------------------------------------- YAML


GAIT_EVENT_YAML = """\
header:
  stamp:
    sec: 12
    nanosec: 500
  frame_id: ground
type: 2
stride_index: 7
detection_delay: 0.0015
state:
  header:
    stamp:
      sec: 0
      nanosec: 0
    frame_id: ''
  sequence: 3
  mcu_time: 0.0
  y: 1.25
  z: 0.4
  y_dot: 2.0
  z_dot: -1.0e-05
  y_ddot: 0.0
  z_ddot: -9.81
  leg_angle: 0.2
  leg_angle_rate: 0.0
  covariance_diagonal:
  - 0.1
  - 0.0
  - 0.0
  - 0.0
  - 0.0
  - 0.0
  - 0.0
  - 8.0
  measurement_used: true
  outlier_rejected: false
"""


def test_yaml_is_that_of_ros2_topic_echo():
    GaitEvent = hopper_message("GaitEvent")
    msg = GaitEvent(type=GaitEvent.TOUCHDOWN, stride_index=7, detection_delay=0.0015)
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 12, 500, "ground"
    state = msg.state
    state.sequence, state.y, state.z, state.y_dot, state.z_dot, state.z_ddot = 3, 1.25, 0.4, 2.0, -1e-5, -9.81
    state.leg_angle, state.measurement_used = 0.2, True
    state.covariance_diagonal[0], state.covariance_diagonal[7] = 0.1, 8.0
    assert message_to_yaml(msg) == GAIT_EVENT_YAML  # nested, header, fixed array; no constants


def test_yaml_of_sequences_strings_and_truncation():
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    status = DiagnosticStatus(level=DiagnosticStatus.WARN, name="encoder_bridge", message="crc: 3 bad",
                              values=[KeyValue(key=f"k{i}", value=str(i)) for i in range(200)])
    msg = DiagnosticArray(status=[status])
    text = message_to_yaml(msg, truncate_length=3)
    data = yaml.safe_load(text)
    assert list(data) == list(DiagnosticArray.get_fields_and_field_types())
    (reported,) = data["status"]
    assert reported["level"] == "\x01"                 # a byte, shown as its character (rosidl_runtime_py)
    assert reported["name"] == "enc..."
    assert reported["message"] == "crc..."
    assert reported["values"] == [{"key": "k0", "value": "0"}, {"key": "k1", "value": "1"},
                                  {"key": "k2", "value": "2"}, "..."]
    assert "message: 'crc: 3 bad'" in message_to_yaml(msg)  # quoted when needed, not truncated by default


@pytest.mark.parametrize("name", MESSAGE_NAMES)
def test_yaml_round_trips_every_field(name):
    msg = filled(hopper_message(name))
    assert yaml.safe_load(message_to_yaml(msg, truncate_length=None)) == message_to_dict(msg)


def test_message_class_errors():
    with pytest.raises(LookupError, match="no_such_pkg"):
        message_class("no_such_pkg/msg/Thing")
    with pytest.raises(LookupError, match="has no message 'Nope'"):
        message_class("std_msgs/msg/Nope")
    with pytest.raises(ValueError, match="not a message type name"):
        message_class("std_msgs")
    assert message_class("std_msgs/String").__name__ == "String"
