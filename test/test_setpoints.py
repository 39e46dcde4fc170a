"""Setpoint schedules: parsing, validation, advancing (no ROS), and the setpoint_scheduler node."""

from __future__ import annotations

import pytest

from hopper_ros.control.setpoints import ScheduleError, ScheduleRunner, load_schedule, parse_schedule


def schedule(*segments, **top):
    return parse_schedule({"segments": list(segments), **top}, source="test.yaml")


def test_fig5_5_schedule_matches_the_thesis():
    fig = load_schedule("setpoints/fig5_5.yaml")
    assert [(s.apex_height, s.forward_speed) for s in fig.segments] == [(0.39, 2.0), (0.42, 2.0), (0.38, 2.5)]
    assert all(s.strides == 10 for s in fig.segments)
    assert not fig.repeat


@pytest.mark.parametrize(
    "segments, message",
    [
        ([{"apex_height": -0.3, "forward_speed": 2.0, "strides": 3}], "segment 1: 'apex_height' must be positive"),
        ([{"apex_height": 0.4, "forward_speed": 2.0, "strides": 3}, {"forward_speed": 2.0}], "segment 2: missing 'apex_height'"),
        ([{"apex_height": 0.4, "strides": 3}], "segment 1: missing 'forward_speed'"),
        ([{"apex_height": "high", "forward_speed": 2.0}], "segment 1: 'apex_height' must be a number"),
        ([{"apex_height": 0.4, "forward_speed": float("nan")}], "segment 1: 'forward_speed' must be finite"),
        ([{"apex_height": 0.4, "forward_speed": 2.0, "strides": 0}], "segment 1: 'strides' must be an integer >= 1"),
        ([{"apex_height": 0.4, "forward_speed": 2.0, "strides": 2.5}], "segment 1: 'strides' must be an integer >= 1"),
        ([{"apex_height": 0.4, "forward_speed": 2.0, "seconds": -1}], "segment 1: 'seconds' must be positive"),
        ([{"apex_height": 0.4, "forward_speed": 2.0, "strides": 1, "seconds": 1}], "segment 1: give either"),
        ([{"apex_height": 0.4, "forward_speed": 2.0, "stride": 1}], "segment 1: unknown key(s) 'stride'"),
        ([{"apex_height": 0.4, "forward_speed": 2.0}, {"apex_height": 0.4, "forward_speed": 2.0}], "segment 1: missing 'strides' or 'seconds'"),
        (["0.4"], "segment 1: expected a mapping"),
        ([], "'segments' must be a non-empty list"),
    ],
)
def test_invalid_schedules_name_the_entry(segments, message):
    with pytest.raises(ScheduleError) as info:
        schedule(*segments)
    assert str(info.value).startswith("test.yaml")
    assert message in str(info.value)


def test_invalid_top_level(tmp_path):
    with pytest.raises(ScheduleError, match="unknown key"):
        parse_schedule({"segments": [{"apex_height": 0.4, "forward_speed": 1.0}], "loop": True}, "t")
    with pytest.raises(ScheduleError, match="'repeat' must be true or false"):
        parse_schedule({"segments": [{"apex_height": 0.4, "forward_speed": 1.0, "strides": 1}], "repeat": "yes"}, "t")
    with pytest.raises(ScheduleError, match="only the last segment"):  # repeat needs an end to every segment
        parse_schedule({"segments": [{"apex_height": 0.4, "forward_speed": 1.0}], "repeat": True}, "t")
    broken = tmp_path / "broken.yaml"
    broken.write_text("segments: [\n")
    with pytest.raises(ValueError, match="broken.yaml: not valid YAML"):
        load_schedule(broken)


def test_missing_schedule_file():
    with pytest.raises(FileNotFoundError, match="nope.yaml"):
        load_schedule("setpoints/nope.yaml")


def test_runner_advances_on_apexes_and_holds_the_last():
    runner = ScheduleRunner(
        schedule(
            {"apex_height": 0.39, "forward_speed": 2.0, "strides": 2},
            {"apex_height": 0.42, "forward_speed": 2.0, "strides": 1},
        ),
        start_time=0.0,
    )
    assert runner.index == 0 and runner.deadline() is None
    assert not runner.on_apex(1.0)
    assert runner.on_apex(2.0) and runner.index == 1
    assert not runner.on_apex(3.0)  # the last segment ends: held
    assert runner.finished and runner.index == 1
    assert not runner.on_apex(4.0) and runner.segment.apex_height == 0.42
    assert not runner.on_time(1e9)


def test_runner_advances_on_time_and_repeats():
    runner = ScheduleRunner(
        schedule(
            {"apex_height": 0.39, "forward_speed": 2.0, "seconds": 1.0},
            {"apex_height": 0.42, "forward_speed": 2.0, "seconds": 2.0},
            {"apex_height": 0.38, "forward_speed": 2.5, "strides": 1},
            repeat=True,
        ),
        start_time=10.0,
    )
    assert runner.deadline() == 11.0
    assert not runner.on_apex(10.5)  # apexes do not end a timed segment
    assert not runner.on_time(10.9)
    assert runner.on_time(11.0) and runner.index == 1 and runner.deadline() == 13.0
    assert not runner.on_time(12.5)
    assert runner.on_time(13.5) and runner.index == 2 and runner.deadline() is None
    assert runner.on_apex(14.0) and runner.index == 0 and runner.deadline() == 15.0
    # A late look passes every segment whose time is up, each timed from the previous end.
    assert runner.on_time(20.0) and runner.index == 2


# --------------------------------------------------------------------------- the node


def test_node_publishes_latched_setpoint_and_advances(rclpy_session, tmp_path):
    from conftest import spin_until
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from hopper_ros.msg import ApexState
    from hopper_ros.nodes.setpoint_scheduler import SETPOINT_QOS, SetpointScheduler

    path = tmp_path / "schedule.yaml"
    path.write_text(
        "segments:\n"
        "  - {apex_height: 0.39, forward_speed: 2.0, strides: 2}\n"
        "  - {apex_height: 0.42, forward_speed: 2.0, seconds: 0.2}\n"
        "  - {apex_height: 0.38, forward_speed: 2.5}\n"
    )
    rclpy = rclpy_session
    scheduler = SetpointScheduler(parameter_overrides=[Parameter("schedule_file", value=str(path))])
    # The test node appears after the first setpoint was published: it must still get it.
    probe = rclpy.create_node("setpoint_probe")
    executor = SingleThreadedExecutor()
    try:
        executor.add_node(scheduler)
        executor.add_node(probe)
        received = []
        probe.create_subscription(ApexState, "apex_setpoint", received.append, SETPOINT_QOS)
        apex = probe.create_publisher(ApexState, "apex", 10)

        assert spin_until(executor, lambda: len(received) >= 1)
        assert (received[0].apex_height, received[0].forward_speed) == (0.39, 2.0)

        def send_apex(index):
            msg = ApexState(stride_index=index, apex_height=0.4, forward_speed=2.0)
            apex.publish(msg)

        wait_for_subscriber = lambda: scheduler.count_publishers("apex") >= 1 and apex.get_subscription_count() >= 1  # noqa: E731
        assert spin_until(executor, wait_for_subscriber)
        send_apex(7)
        assert spin_until(executor, lambda: scheduler._runner._apexes == 1)
        assert len(received) == 1  # one apex of two: no change yet
        send_apex(8)
        assert spin_until(executor, lambda: len(received) >= 2)
        assert (received[1].apex_height, received[1].forward_speed, received[1].stride_index) == (0.42, 2.0, 8)
        # The timed segment ends by itself; the last one is then held.
        assert spin_until(executor, lambda: len(received) >= 3)
        assert (received[2].apex_height, received[2].forward_speed) == (0.38, 2.5)
        assert received[2].header.stamp.sec > 0
    finally:
        executor.shutdown()
        scheduler.destroy_node()
        probe.destroy_node()


def test_node_rejects_a_bad_schedule(rclpy_session, tmp_path):
    from rclpy.parameter import Parameter

    from hopper_ros.nodes.setpoint_scheduler import SetpointScheduler

    path = tmp_path / "bad.yaml"
    path.write_text("segments:\n  - {apex_height: -0.1, forward_speed: 2.0}\n")
    with pytest.raises(ScheduleError, match=r"bad.yaml: segments\[0\].apex_height: must be > 0 m, got -0.1"):
        SetpointScheduler(parameter_overrides=[Parameter("schedule_file", value=str(path))])
