"""state_estimator: appendix A's Kalman filters on the converted encoder samples.

Subscribes `body_measurement` (BodyMeasurement, from encoder_bridge); for each sample publishes
`body_state` (BodyState): y, z and their velocities and accelerations (constant-acceleration
filters, A.1.1), the leg angle and its rate, the covariance diagonal, stamped with the sample's
instant on the host clock. `clock_offset` (std_msgs/Float64, [s], host minus microcontroller time)
each time that mapping re-anchors (the simulated robot stood still: the controller's ramp follows at
once, not at the next gait event). Samples missing from the stream are bridged by predictions (one
BodyState per missing sample, `measurement_used` false, dt from the microcontroller clock); a
sample whose innovation fails the Mahalanobis gate is not used (`outlier_rejected`).
`/diagnostics` (DiagnosticArray, every `diagnostics_period`): counters (measurements,
predicted_samples, outliers_y/_z/_leg_angle, reinitialisations, stale_measurements) and values
(sample_rate_hz, clock_offset_s, z_dot_std_m_per_s, process_time_max_s, state_subscribers: the
subscriptions body_state is matched with).

Parameters (read only):
  sensing_file (string): default `sensing.yaml` (config/sensing.yaml, section estimator)
  hardware_file (string): "" = the sensing file's (encoder resolutions, sample period)
  diagnostics_period (double) [s]: 0 = sensing file's

The filter lives in hopper_ros.sensing.estimator; this node only connects it to ROS.
"""

from __future__ import annotations

import math
import time

from rclpy.node import Node
from std_msgs.msg import Float64

from hopper_ros.hardware.config import load_hardware
from hopper_ros.msg import BodyMeasurement, BodyState
from hopper_ros.nodes.common import run_node, sensing_parameters
from hopper_ros.nodes.diagnostics import DiagnosticsReporter
from hopper_ros.sensing.estimator import StateEstimator
from hopper_ros.nodes.sensing_messages import (CounterDeltas, any_of, fill_body_state,
                                         measurement_from_msg, sample_qos)

PROBLEM_COUNTERS = ("predicted_samples", "outliers_y", "outliers_z", "outliers_leg_angle", "reinitialisations",
                    "stale_measurements")


class StateEstimatorNode(Node):
    def __init__(self, **node_kwargs):
        node_kwargs.setdefault("start_parameter_services", False)
        super().__init__("state_estimator", **node_kwargs)
        param, config, period = sensing_parameters(self)
        hardware = load_hardware(param("hardware_file", "", "hardware (YAML), '' = the sensing file's") or
                             config.hardware_file)
        self.estimator = StateEstimator.from_config(config.estimator, hardware)
        self._state_msg = BodyState()
        qos = sample_qos(config.queue_depth)
        self._states = self.create_publisher(BodyState, "body_state", qos)
        self._clock_offset = self.create_publisher(Float64, "clock_offset", 10)
        self._anchors = 0
        self._diagnostics = DiagnosticsReporter(self)
        self.create_subscription(BodyMeasurement, "body_measurement", self._on_measurement, qos)
        self.create_timer(period, self._report)
        self._deltas = CounterDeltas()
        self._process_time_max = 0.0
        self._last_z_dot_std = math.nan
        s = config.estimator
        self.get_logger().info(
            f"constant-acceleration filters sigma_w {s.vertical_process_noise:g} (z) / "
            f"{s.horizontal_process_noise:g} (y) m s^-2.5, measurement noise '{s.measurement_noise}', "
            f"gate {s.outlier_gate:g} sigma")

    def _on_measurement(self, msg: BodyMeasurement) -> None:
        started = time.perf_counter()
        state_msg = self._state_msg
        for estimate in self.estimator.update(measurement_from_msg(msg)):
            self._states.publish(fill_body_state(state_msg, estimate))
            self._last_z_dot_std = estimate.z_dot_std
        clock = self.estimator.clock
        if clock.anchors != self._anchors:
            self._anchors = clock.anchors
            self._clock_offset.publish(Float64(data=clock.offset))
        elapsed = time.perf_counter() - started
        if elapsed > self._process_time_max:
            self._process_time_max = elapsed

    def _report(self) -> None:
        now = time.time()
        counters = dict(self.estimator.counters, clock_anchors=self.estimator.clock.anchors)
        deltas, elapsed = self._deltas.update(counters, now)
        values = {
            "sample_rate_hz": deltas["measurements"] / elapsed if elapsed > 0 else math.nan,
            "clock_offset_s": self.estimator.clock.offset,
            "z_dot_std_m_per_s": self._last_z_dot_std,
            "process_time_max_s": self._process_time_max,
            "state_subscribers": float(self._states.get_subscription_count()),
        }
        self._process_time_max = 0.0
        problem = self.estimator.last_problem if any_of(deltas, PROBLEM_COUNTERS) else ""
        self._diagnostics.report(counters, values, problem, stamp=now)


def main(args=None) -> int:
    return run_node(StateEstimatorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
