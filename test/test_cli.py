"""The `hopper` CLI: run, topic list, topic echo (subprocesses against a graph of this test)."""

from __future__ import annotations

import yaml

from hopper_ros.cli import COMMANDS, build_parser
from hopper_ros.nodes.registry import NODES


def test_subcommands_come_from_one_table():
    parser = build_parser()
    choices = next(a for a in parser._actions if a.dest == "command").choices
    assert list(choices) == list(COMMANDS)
    args = parser.parse_args(["run", "setpoint_scheduler", "--ros-args", "-p", "a:=1"])
    assert (args.node, args.node_args) == ("setpoint_scheduler", ["--ros-args", "-p", "a:=1"])


def test_run_unknown_node_lists_the_known_ones(hopper_cli):
    process = hopper_cli("run", "no_such_node")
    assert process.wait() == 2
    known = ", ".join(sorted(NODES))
    assert f"unknown node 'no_such_node'; registered nodes: {known}" in process.stderr


def test_topic_echo_and_list_see_a_running_graph(rclpy_session, hopper_cli):
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from hopper_ros.runtime.messages import message_class, message_to_dict
    from test_messages import GAIT_EVENT_YAML

    rclpy = rclpy_session
    GaitEvent = message_class("hopper_ros/msg/GaitEvent")
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node = rclpy.create_node("echo_source")
    try:
        publisher = node.create_publisher(GaitEvent, "test/gait_event", latched)
        msg = GaitEvent()
        for key, value in yaml.safe_load(GAIT_EVENT_YAML).items():
            if key not in ("header", "state"):
                setattr(msg, key, value)
        msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 12, 500, "ground"
        state = yaml.safe_load(GAIT_EVENT_YAML)["state"]
        for key, value in state.items():
            if key != "header":
                setattr(msg.state, key, value)
        assert message_to_dict(msg) == yaml.safe_load(GAIT_EVENT_YAML)
        publisher.publish(msg)  # before the echo starts: it gets it because both are latched

        # Both discover this process's participant (the DDS work happens in its own threads:
        # no spinning needed here). Run them side by side: discovery can take a few seconds.
        echo = hopper_cli("topic", "echo", "test/gait_event", "--once", "--timeout", "60")
        listing = hopper_cli("topic", "list", "-t")
        assert echo.wait() == 0, echo.stderr
        assert echo.stdout == GAIT_EVENT_YAML + "---\n"
        assert listing.wait() == 0, listing.stderr
        assert "/test/gait_event [hopper_ros/msg/GaitEvent]" in listing.stdout.splitlines()
    finally:
        node.destroy_node()


def test_topic_echo_gives_up_or_stops_on_request(hopper_cli):
    import signal

    timed = hopper_cli("topic", "echo", "/nobody/publishes/this", "--once", "--timeout", "0.5")
    waiting = hopper_cli("topic", "echo", "/nobody/publishes/that")
    assert timed.wait() == 1
    assert "no publisher on /nobody/publishes/this within 0.5 s" in timed.stderr
    waiting.wait_for_line(r"^waiting for a publisher on /nobody/publishes/that")
    waiting.signal(signal.SIGINT)
    assert waiting.wait() == 0, waiting.stderr


def test_topic_list_and_echo_show_the_standard_diagnostics(hopper_cli):
    """A running node reports on /diagnostics as diagnostic_msgs/DiagnosticArray, which `hopper
    topic list -t` and `hopper topic echo` show as ros2 topic would."""
    import signal

    node = hopper_cli("run", "setpoint_scheduler", "--ros-args", "-r", "__ns:=/robot")
    try:
        node.wait_for_line(r"started: pid")
        listing = hopper_cli("topic", "list", "-t")
        echo = hopper_cli("topic", "echo", "/diagnostics", "--once", "--timeout", "60")
        assert listing.wait() == 0, listing.stderr
        assert "/diagnostics [diagnostic_msgs/msg/DiagnosticArray]" in listing.stdout.splitlines()
        assert "/robot/diagnostics" not in listing.stdout          # absolute, whatever the namespace
        assert echo.wait() == 0, echo.stderr
        report = yaml.safe_load(echo.stdout.split("---")[0])
        [status] = report["status"]
        assert (status["name"], status["level"], status["message"]) == ("/robot/setpoint_scheduler", "\0", "OK")
        assert {pair["key"]: pair["value"] for pair in status["values"]} == {
            "setpoints_published": "1", "apexes": "0", "segment": "1", "apex_height_m": "0.39",
            "forward_speed_m_s": "2.0"}
    finally:
        node.signal(signal.SIGINT)
        assert node.wait() == 0
