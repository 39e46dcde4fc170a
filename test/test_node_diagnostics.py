"""The one helper that builds every node's diagnostic_msgs/DiagnosticArray (hopper_ros/nodes/diagnostics.py)."""

from __future__ import annotations

import math

import pytest

from hopper_ros.nodes.diagnostics import (ERROR, OK, WARN, diagnostic_array, diagnostic_status, level_of, split_node_name,
                                          status_of, status_values)


def test_one_status_counters_first_then_values_that_read_back_exactly():
    status = diagnostic_status("/hopper/encoder_bridge", {"packets_received": 12, "packets_lost": 0},
                               {"loss_ratio": 0.1 + 0.2, "latency_s": math.nan, "subscribers": 2.0},
                               hardware_id="microcontroller udp 127.0.0.1:15800")
    assert (status.name, level_of(status), status.message) == ("/hopper/encoder_bridge", OK, "OK")
    assert status.hardware_id == "microcontroller udp 127.0.0.1:15800"
    assert [(v.key, v.value) for v in status.values] == [
        ("packets_received", "12"), ("packets_lost", "0"), ("loss_ratio", "0.30000000000000004"),
        ("latency_s", "nan"), ("subscribers", "2.0")]
    values = status_values(status)
    assert values["packets_received"] == 12 and isinstance(values["packets_received"], int)
    assert values["loss_ratio"] == 0.1 + 0.2 and math.isnan(values["latency_s"])
    assert isinstance(values["subscribers"], float)


def test_level_from_the_problem_unless_given():
    assert level_of(diagnostic_status("/n", {}, {}, "3 packets lost")) == WARN
    fault = diagnostic_status("/n", {"faults": 1}, {}, "EMCY 0x8611", ERROR)
    assert (level_of(fault), fault.message) == (ERROR, "EMCY 0x8611")
    assert diagnostic_status("/n", {}, {}, level=ERROR).message == "ERROR"
    with pytest.raises(ValueError, match="not OK, WARN, ERROR or STALE"):
        diagnostic_status("/n", {}, {}, level=7)


def test_array_stamp_and_lookup():
    array = diagnostic_array(1_700_000_000.25, [diagnostic_status("/a", {}, {}), diagnostic_status("/ns/b", {}, {})])
    assert (array.header.stamp.sec, array.header.stamp.nanosec) == (1_700_000_000, 250_000_000)
    assert status_of(array, "/ns/b").name == "/ns/b" and status_of(array, "/b") is None
    assert split_node_name("/ns/sub/motor_driver") == ("/ns/sub", "motor_driver")
    assert split_node_name("/motor_driver") == ("/", "motor_driver")
