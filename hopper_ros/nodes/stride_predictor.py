"""stride_predictor: the model's prediction of every stride, and how far the robot is from it.

Subscribes `apex` (ApexState, from the event detector) and `stride_command` (StrideCommand,
from the controller or an experiment); for each stride with both it publishes the predicted
next apex on `predicted_apex` (ApexState, stamped with the predicted apex time), and when that
apex arrives it logs E_p, E_v, E_t (4.1)-(4.3) and publishes them with running means on
`/diagnostics` (DiagnosticArray; then, and every second).

Parameters (read only):
  model_file (string): model parameters, default `model.yaml` (config/model.yaml, Table 4.1)
  predictor (string): "corrected" (default), "aas" or "exact"

The logic lives in hopper_ros.control.stride_monitor; this node only connects it to ROS.
"""

from __future__ import annotations

import math

from rclpy.node import Node

from hopper_ros.msg import ApexState, StrideCommand
from hopper_ros.nodes.common import read_only_parameters, run_node
from hopper_ros.config.schemas import load_model
from hopper_ros.nodes.diagnostics import DiagnosticsReporter
from hopper_ros.nodes.stamps import to_seconds, to_stamp
from hopper_ros.physics.predictors import DEFAULT_PREDICTOR
from hopper_ros.control.stride_monitor import Apex, Command, StrideMonitor


class StridePredictor(Node):
    def __init__(self, **node_kwargs):
        super().__init__("stride_predictor", **node_kwargs)
        param = read_only_parameters(self)
        model_file = param("model_file", "model.yaml", "model parameters (YAML)")
        method = param("predictor", DEFAULT_PREDICTOR, "corrected, aas or exact")
        self._monitor = StrideMonitor(load_model(model_file), method)
        self._predicted = self.create_publisher(ApexState, "predicted_apex", 10)
        self._diagnostics = DiagnosticsReporter(self)
        self._problem = ""
        self.create_timer(1.0, self._on_timer)
        self.create_subscription(ApexState, "apex", self._on_apex, 10)
        self.create_subscription(StrideCommand, "stride_command", self._on_command, 10)
        self.get_logger().info(f"predicting strides with the {method} predictor, model {model_file}")

    def _on_apex(self, msg: ApexState) -> None:
        apex = Apex(msg.stride_index, to_seconds(msg.header.stamp), msg.y, msg.apex_height, msg.forward_speed)
        score, prediction = self._monitor.on_apex(apex)
        if score is not None:
            self.get_logger().info(
                f"stride {score.stride_index - 1}: E_p {score.position_error_pct:.2f} %, "
                f"E_v {score.velocity_error_pct:.2f} %, E_t {score.time_error_pct:.2f} %")
            self._report("")
        self._publish(prediction)

    def _on_command(self, msg: StrideCommand) -> None:
        ramp = msg.predicted_liftoff_time if msg.predicted_liftoff_time > 0.0 else None
        self._publish(self._monitor.on_command(Command(msg.stride_index, msg.tau_0, msg.touchdown_angle, ramp)))

    def _publish(self, prediction) -> None:
        if prediction is None:
            return
        if not prediction.ok:
            self.get_logger().warning(f"stride {prediction.stride_index - 1} predicted to fail: {prediction.failure}")
            self._report(f"stride {prediction.stride_index - 1}: {prediction.failure}")
            return
        msg = ApexState()
        msg.header.stamp = to_stamp(prediction.time)
        msg.header.frame_id = "ground"
        msg.stride_index = prediction.stride_index
        msg.apex_height, msg.forward_speed, msg.y = prediction.apex_height, prediction.forward_speed, prediction.y
        self._predicted.publish(msg)

    def _on_timer(self) -> None:
        # not the timer's callback itself: rclpy hands a callback with a parameter its TimerInfo
        self._report()

    def _report(self, problem: str | None = None) -> None:
        """E_p, E_v, E_t of the last stride and their means; WARN while the last stride was predicted to fail."""
        if problem is not None:
            self._problem = problem
        monitor = self._monitor
        counters = {"strides_predicted": monitor.predicted, "strides_scored": len(monitor.scores),
                    "strides_predicted_infeasible": monitor.infeasible}
        means = monitor.mean_errors()
        last = monitor.scores[-1] if monitor.scores else None
        values = dict(zip(["last_Ep_pct", "last_Ev_pct", "last_Et_pct", "mean_Ep_pct", "mean_Ev_pct", "mean_Et_pct"],
                          [last.position_error_pct if last else math.nan, last.velocity_error_pct if last else math.nan,
                           last.time_error_pct if last else math.nan, *means]))
        self._diagnostics.report(counters, values, self._problem)


def main(args=None) -> int:
    return run_node(StridePredictor, args)


if __name__ == "__main__":
    raise SystemExit(main())
