"""stride_predictor: the monitor logic, and the node in its own process on real topics."""

import math

import pytest

from conftest import SAFETY_TIMEOUT, spin_until
from hopper_ros.physics.exact import simulate_stride
from hopper_ros.physics.params import ModelParams
from hopper_ros.physics.predictors import predict_stride
from hopper_ros.control.stride_monitor import Apex, Command, StrideMonitor

PARAMS = ModelParams()
H, V, THETA, TAU = 0.35, 2.0, math.radians(20.0), 5.0


def _true_strides():
    ramp = predict_stride(PARAMS, H, V, THETA, TAU).ramp_duration
    stride = simulate_stride(PARAMS, H, V, THETA, TAU, ramp, y0=1.0, t0=10.0)
    opening = Apex(4, 10.0, 1.0, H, V)
    closing = Apex(5, stride.next_apex.t, stride.next_apex.y, stride.next_apex_height, stride.next_forward_speed)
    return ramp, opening, closing


def test_monitor_pairs_apex_and_command_in_either_order_and_scores():
    ramp, opening, closing = _true_strides()
    for method, bound in (("corrected", 0.5), ("aas", 20.0)):
        monitor = StrideMonitor(PARAMS, method)
        assert monitor.on_command(Command(4, TAU, THETA, ramp)) is None      # no apex yet
        score, prediction = monitor.on_apex(opening)
        assert score is None and prediction.ok and prediction.stride_index == 5
        assert monitor.on_command(Command(4, TAU, THETA, ramp)) is None      # already predicted
        score, _ = monitor.on_apex(closing)
        assert score.stride_index == 5 and 0.0 <= score.velocity_error_pct < bound
        assert monitor.mean_errors()[1] == score.velocity_error_pct
    monitor = StrideMonitor(PARAMS)
    monitor.on_apex(Apex(0, 0.0, 0.0, 0.15, 2.0))                           # apex below touchdown
    assert not monitor.on_command(Command(0, TAU, THETA, None)).ok and monitor.infeasible == 1
    with pytest.raises(ValueError, match="unknown predictor"):
        StrideMonitor(PARAMS, "oracle")


def test_node_predicts_and_scores_on_real_topics(rclpy_session, hopper_cli):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.time import Time

    from diagnostic_msgs.msg import DiagnosticArray

    from hopper_ros.msg import ApexState, StrideCommand
    from hopper_ros.nodes.diagnostics import OK, level_of, status_of, status_values

    ramp, opening, closing = _true_strides()
    node_process = hopper_cli("run", "stride_predictor")
    node_process.wait_for_line(r"predicting strides with the corrected predictor")
    test_node = rclpy_session.create_node("stride_predictor_test")
    executor = SingleThreadedExecutor()
    executor.add_node(test_node)
    received = {"predicted": [], "diagnostics": []}
    test_node.create_subscription(ApexState, "predicted_apex", received["predicted"].append, 10)
    test_node.create_subscription(DiagnosticArray, "/diagnostics", received["diagnostics"].append, 10)
    apex_pub = test_node.create_publisher(ApexState, "apex", 10)
    command_pub = test_node.create_publisher(StrideCommand, "stride_command", 10)
    try:
        assert spin_until(executor, lambda: apex_pub.get_subscription_count() and command_pub.get_subscription_count())

        def apex_msg(apex):
            msg = ApexState()
            msg.header.stamp = Time(nanoseconds=int(round(apex.time * 1e9))).to_msg()
            msg.stride_index, msg.y, msg.apex_height, msg.forward_speed = apex.stride_index, apex.y, apex.apex_height, apex.forward_speed
            return msg

        apex_pub.publish(apex_msg(opening))
        command = StrideCommand()
        command.stride_index, command.tau_0, command.touchdown_angle, command.predicted_liftoff_time = 4, TAU, THETA, ramp
        command.feasible = True
        command_pub.publish(command)
        assert spin_until(executor, lambda: received["predicted"], SAFETY_TIMEOUT)
        predicted = received["predicted"][0]
        expected = predict_stride(PARAMS, H, V, THETA, TAU, ramp)
        assert predicted.stride_index == 5
        assert predicted.apex_height == pytest.approx(expected.next_apex_height, rel=1e-12)
        assert predicted.y == pytest.approx(1.0 + expected.stride_length, rel=1e-12)
        assert predicted.header.stamp.sec + predicted.header.stamp.nanosec * 1e-9 == pytest.approx(10.0 + expected.stride_time, abs=1e-8)

        apex_pub.publish(apex_msg(closing))
        def scored():
            reports = [status_of(array, "/stride_predictor") for array in received["diagnostics"]]
            return [r for r in reports if r is not None and status_values(r)["strides_scored"] == 1]

        assert spin_until(executor, scored, SAFETY_TIMEOUT)
        report = scored()[-1]
        values = status_values(report)
        assert level_of(report) == OK and report.message == "OK"
        assert 0.0 <= values["last_Ev_pct"] < 0.5 and 0.0 <= values["last_Ep_pct"] < 0.5
        node_process.wait_for_line(r"stride 4: E_p \d+\.\d+ %, E_v")
        # and every second without a stride too, the last stride's errors kept
        received["diagnostics"].clear()
        assert spin_until(executor, lambda: len(scored()) >= 2, SAFETY_TIMEOUT)
        assert node_process.process.poll() is None and level_of(scored()[-1]) == OK
    finally:
        executor.shutdown()
        test_node.destroy_node()
