"""deadbeat_controller as a process, on real topics: decisions, the stride's motor commands."""

from __future__ import annotations

import math
import signal
import time

import pytest

from conftest import spin_until


def stamp(seconds: float):
    from builtin_interfaces.msg import Time

    sec = math.floor(seconds)
    return Time(sec=int(sec), nanosec=int(round((seconds - sec) * 1e9)))


def test_controller_decides_at_apex_and_drives_the_stride(rclpy_session, hopper_cli):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from std_msgs.msg import Float64

    from hopper_ros.msg import ApexState, GaitEvent, MotorCommand, StrideCommand
    from hopper_ros.physics.flight import touchdown_time
    from hopper_ros.physics.params import load_params

    node_process = hopper_cli("run", "deadbeat_controller")
    node_process.wait_for_line(r"closed_loop: predictor corrected, adaptation on")
    node = rclpy_session.create_node("controller_test")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    setpoint = node.create_publisher(ApexState, "apex_setpoint", latched)
    apex = node.create_publisher(ApexState, "apex", 10)
    events = node.create_publisher(GaitEvent, "gait_event", 10)
    clock = node.create_publisher(Float64, "clock_offset", 10)
    commands, strides = [], []
    best_effort = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
    node.create_subscription(MotorCommand, "motor_command", commands.append, best_effort)
    node.create_subscription(StrideCommand, "stride_command", strides.append, 10)

    def key(command: MotorCommand) -> tuple:
        """What a command asks for (a ramp's stamp is when it starts; a hold's is only when it was sent)."""
        start = command.header.stamp.sec, command.header.stamp.nanosec
        ramp = command.mode == MotorCommand.MODE_RAMP
        return (command.mode, command.setpoint, command.duration) + (start if ramp else ())

    def tick(after: MotorCommand | None = None) -> MotorCommand:
        """The next command of the stream (sent on every change, repeated every keep_alive); with `after`,
        the first one that differs from it (a repeat of the previous command still in flight is skipped)."""
        commands.clear()
        fresh = lambda: [c for c in commands if after is None or key(c) != key(after)]  # noqa: E731
        assert spin_until(executor, fresh, timeout=10.0)
        return fresh()[0]

    try:
        assert spin_until(executor, lambda: apex.get_subscription_count()
                          and events.get_subscription_count() and setpoint.get_subscription_count()
                          and clock.get_subscription_count() and node.count_publishers("motor_command"))
        idle = tick()
        assert idle.mode == MotorCommand.MODE_DISABLED                # nothing to do without a setpoint
        setpoint.publish(ApexState(apex_height=0.39, forward_speed=2.0))
        spin_until(executor, lambda: False, timeout=0.3)
        ready = tick(after=idle)
        assert ready.mode == MotorCommand.MODE_POSITION             # leg held, ready for the throw
        apex.publish(ApexState(stride_index=3, apex_height=0.39, forward_speed=2.0))
        assert spin_until(executor, lambda: strides)
        decision = strides[-1]
        assert decision.feasible and decision.stride_index == 3 and decision.target_apex_height == 0.39
        assert 0.0 < decision.tau_0 < 12.5 and 0.2 < decision.touchdown_angle < 0.6
        assert decision.predicted_apex_height == pytest.approx(0.39, abs=2e-3)
        flight = tick(after=ready)
        assert (flight.mode, flight.setpoint) == (MotorCommand.MODE_POSITION, pytest.approx(decision.touchdown_angle))
        # pre-touchdown, heard ahead of its time: at that time the leg is let go and the ramp goes out,
        # stamped with the touchdown predicted from the event's state
        clock.publish(Float64(data=5.0))            # the sensing clock's mapping before the stand-still below
        pre_touchdown = GaitEvent(type=GaitEvent.PRE_TOUCHDOWN)
        soon = time.time() + 0.3                  # host clock: a prediction in the past would be cancelled
        pre_touchdown.header.stamp = stamp(soon)
        state = pre_touchdown.state
        state.z, state.z_dot, state.leg_angle, state.leg_angle_rate = 0.205 * math.cos(0.4) + 0.02, -2.3, 0.4, 0.0
        events.publish(pre_touchdown)
        spin_until(executor, lambda: False, timeout=0.2)
        ahead = tick(after=flight)          # at the event's time (test_control: not before it)
        params = load_params()
        expected = soon + touchdown_time(state.z, state.z_dot, 0.4, 0.0, params.rest_length, params.gravity,
                                          params.flight_damping_vertical)
        assert (ahead.mode, ahead.setpoint) == (MotorCommand.MODE_RAMP, pytest.approx(decision.tau_0))
        assert ahead.header.stamp.sec + ahead.header.stamp.nanosec * 1e-9 == pytest.approx(expected, abs=1e-6)
        assert soon < expected < soon + 0.01
        # the sensing clock re-anchors by an 80 ms stand-still (state_estimator's clock_offset): the ramp
        # predicted on the robot's clock follows at once, and the command says which mapping it is on
        # (at once: the ramp is cancelled touchdown_grace + 80 ms after the predicted touchdown, some 10 ms away)
        clock.publish(Float64(data=5.08))
        moved = tick(after=ahead)
        assert moved.mode == MotorCommand.MODE_RAMP and moved.clock_offset == 5.08
        assert moved.header.stamp.sec + moved.header.stamp.nanosec * 1e-9 == pytest.approx(expected + 0.08, abs=1e-6)
        touchdown = GaitEvent(type=GaitEvent.TOUCHDOWN)
        touchdown.header.stamp = stamp(soon + 0.01)
        events.publish(touchdown)
        spin_until(executor, lambda: False, timeout=0.2)
        ramp = tick(after=moved)          # the driver runs the ramp, from the touchdown's stamp
        assert (ramp.mode, ramp.setpoint, ramp.duration) == (
            MotorCommand.MODE_RAMP, pytest.approx(decision.tau_0), pytest.approx(decision.predicted_liftoff_time))
        assert (ramp.header.stamp.sec, ramp.header.stamp.nanosec) == (touchdown.header.stamp.sec,
                                                                      touchdown.header.stamp.nanosec)
        liftoff = GaitEvent(type=GaitEvent.LIFTOFF)
        liftoff.state.leg_angle = -0.31
        events.publish(liftoff)
        spin_until(executor, lambda: False, timeout=0.2)
        swing = tick(after=ramp)
        assert (swing.mode, swing.setpoint) == (MotorCommand.MODE_POSITION, pytest.approx(-0.31))

        apex.publish(ApexState(stride_index=4, apex_height=0.12, forward_speed=2.0))   # toe in the ground
        assert spin_until(executor, lambda: len(strides) == 2)
        assert not strides[-1].feasible and "no touchdown angle" in strides[-1].reason and strides[-1].tau_0 == 0.0
        held = tick()
        assert held.mode == MotorCommand.MODE_POSITION

        # a predicted touchdown that does not come: the ramp is cancelled, zero current
        apex.publish(ApexState(stride_index=5, apex_height=0.39, forward_speed=2.0))
        assert spin_until(executor, lambda: len(strides) == 3 and strides[-1].feasible)
        missed = GaitEvent(type=GaitEvent.PRE_TOUCHDOWN)
        missed.header.stamp = stamp(time.time() - 0.1)          # 0.1 s ago: beyond touchdown_grace
        missed.state.z, missed.state.z_dot, missed.state.leg_angle = 0.205 * math.cos(0.4) + 0.02, -2.3, 0.4
        events.publish(missed)
        assert spin_until(executor, lambda: commands and commands[-1].mode == MotorCommand.MODE_CURRENT, timeout=5.0)
        assert commands[-1].setpoint == 0.0
        node_process.wait_for_line(r"no touchdown within 20 ms of the predicted one: stance ramp cancelled")
    finally:
        node_process.signal(signal.SIGINT)
        assert node_process.wait() == 0
        executor.shutdown()
        node.destroy_node()


def test_controller_stops_on_its_own_motor_drivers_error_only(rclpy_session, hopper_cli):
    """/diagnostics carries every node of every namespace: an ERROR of another namespace's motor
    driver changes nothing, one of the controller's own namespace puts it in its safe state,
    which its own status then says."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from hopper_ros.msg import ApexState, StrideCommand
    from hopper_ros.nodes.diagnostics import ERROR, OK, WARN, diagnostic_array, diagnostic_status, level_of, status_of

    node_process = hopper_cli("run", "deadbeat_controller", "--ros-args", "-r", "__ns:=/robot")
    node_process.wait_for_line(r"closed_loop: predictor corrected")
    node = rclpy_session.create_node("controller_diagnostics_test")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    reports = []
    node.create_subscription(DiagnosticArray, "/diagnostics", reports.append, 100)
    publisher = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    setpoint = node.create_publisher(ApexState, "/robot/apex_setpoint", latched)
    apex = node.create_publisher(ApexState, "/robot/apex", 10)
    strides = []
    node.create_subscription(StrideCommand, "/robot/stride_command", strides.append, 10)

    def own_status():
        statuses = [status_of(array, "/robot/deadbeat_controller") for array in reports]
        return [s for s in statuses if s is not None]

    def drive_fault(name: str) -> None:
        publisher.publish(diagnostic_array(time.time(), [diagnostic_status(name, {"faults": 1}, {}, "EMCY 0x8611",
                                                                         ERROR, "EPOS2 node 1")]))

    try:
        assert spin_until(executor, lambda: publisher.get_subscription_count() >= 2 and own_status())
        assert level_of(own_status()[-1]) == OK
        # a stride under way (before the first apex a drive error latches nothing: test_graph_under_load.py)
        setpoint.publish(ApexState(apex_height=0.39, forward_speed=2.0))
        assert spin_until(executor, lambda: apex.get_subscription_count())
        spin_until(executor, lambda: False, timeout=0.3)
        apex.publish(ApexState(stride_index=1, apex_height=0.39, forward_speed=2.0))
        assert spin_until(executor, lambda: strides)
        drive_fault("/other/motor_driver")
        reports.clear()
        assert spin_until(executor, lambda: len(own_status()) >= 2)          # two reports later, still fine
        assert all(level_of(s) == OK for s in own_status())
        drive_fault("/robot/motor_driver")
        node_process.wait_for_line(r"motor driver: EMCY 0x8611")
        reports.clear()
        assert spin_until(executor, lambda: own_status())
        status = own_status()[-1]
        assert level_of(status) == WARN and "motor driver: EMCY 0x8611" in status.message
        assert {v.key: v.value for v in status.values}["faults"] == "1"
    finally:
        node_process.signal(signal.SIGINT)
        assert node_process.wait() == 0
        executor.shutdown()
        node.destroy_node()


def test_a_warning_after_an_error_does_not_kill_the_controller(rclpy_session):
    """Issue 29, in-process: under load the drive's start-up timed out once (the motor driver's ERROR:
    the controller logged it as an error), and the first infeasible stride's warning then came from
    the same logging line: rclpy raised "Logger severity cannot be changed between calls", the
    controller died and the robot fell."""
    from hopper_ros.msg import ApexState
    from hopper_ros.nodes.deadbeat_controller import DeadbeatControllerNode
    from hopper_ros.nodes.diagnostics import ERROR, diagnostic_array, diagnostic_status

    node = DeadbeatControllerNode()
    try:
        node._on_setpoint(ApexState(apex_height=0.39, forward_speed=2.0))
        node._on_diagnostics(diagnostic_array(time.time(), [diagnostic_status(
            "/motor_driver", {}, {}, "drive start-up failed: SDO 0x1016:01 timed out", ERROR)]))
        assert node.policy.counters["faults"] == 1
        node._on_apex(ApexState(stride_index=1, apex_height=0.02, forward_speed=9.0))     # out of reach
        assert node.policy.counters["infeasible"] == 1
        node._on_apex(ApexState(stride_index=2, apex_height=0.39, forward_speed=2.0))    # and on it goes
        assert node.policy.counters["strides"] == 2 and node.policy.last_decision.feasible
    finally:
        node.destroy_node()
