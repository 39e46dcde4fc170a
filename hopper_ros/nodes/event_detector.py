"""event_detector: apex, pre-touchdown, touchdown, bottom and lift-off from the state estimate.

Subscribes `body_state` (BodyState, from state_estimator); publishes every event it detects on
`gait_event` (GaitEvent: stamped with the event's own time, interpolated between samples; the
stride index; detection_delay = host time of publication minus the event's time, negative for a
pre-touchdown published ahead; the state at the event, `state.sequence` the sample that revealed
it) and each apex also on `apex` (ApexState: height, forward speed, y, leg angle; stride_index n
opens stride n), which stride_predictor and setpoint_scheduler consume. `/diagnostics`
(DiagnosticArray, every `diagnostics_period`): counters (samples, untrusted_samples, track_lost,
track_acquired, strides, one per event type, late_samples: states that arrived more than
`sample_deadline` after their sample's instant, i.e. the loop's missed deadlines; 0 there: the hardware file's
sample period, the loop's own) and values (detection_delay_max_s, sample_age_max_s and process_time_max_s over the
period).

Parameters (read only):
  sensing_file (string): default `sensing.yaml` (config/sensing.yaml, section detector)
  model_file (string): rho_0, k, d, g, flight damping ("" = the sensing file's, model.yaml)
  hardware_file (string): the microcontroller's sample period, the deadline where the sensing file's is 0
    ("" = the sensing file's)
  diagnostics_period (double) [s]: 0 = sensing file's

The logic lives in hopper_ros.sensing.events; this node only connects it to ROS.
"""

from __future__ import annotations

import time

from rclpy.node import Node

from hopper_ros.msg import ApexState, BodyState, GaitEvent
from hopper_ros.nodes.common import run_node, sensing_parameters
from hopper_ros.config.schemas import load_model
from hopper_ros.hardware.config import load_hardware
from hopper_ros.nodes.diagnostics import DiagnosticsReporter
from hopper_ros.sensing.events import EventDetector
from hopper_ros.nodes.sensing_messages import (CounterDeltas, any_of, apex_state_msg,
                                         estimate_from_msg, gait_event_msg, sample_qos, to_seconds)
from hopper_ros.sensing.samples import EventType

EVENT_DEPTH = 100   # events are rare: a late subscriber of the last 0.1 s still gets them all


class EventDetectorNode(Node):
    def __init__(self, **node_kwargs):
        node_kwargs.setdefault("start_parameter_services", False)
        super().__init__("event_detector", **node_kwargs)
        param, config, period = sensing_parameters(self)
        model_file = param("model_file", "", "model parameters (YAML), '' = the sensing file's") or config.model_file
        self.detector = EventDetector(load_model(model_file), config.detector)
        self._events = self.create_publisher(GaitEvent, "gait_event", sample_qos(EVENT_DEPTH))
        self._apexes = self.create_publisher(ApexState, "apex", 10)
        self._diagnostics = DiagnosticsReporter(self)
        self.create_subscription(BodyState, "body_state", self._on_state, sample_qos(config.queue_depth))
        self.create_timer(period, self._report)
        self._deltas = CounterDeltas()
        self._delay_max = 0.0
        self._process_time_max = 0.0
        hardware_file = param("hardware_file", "", "hardware (YAML), '' = the sensing file's: its sample period is "
                              "the deadline where the sensing file's is 0") or config.hardware_file
        self._deadline = (config.detector.sample_deadline
                          or load_hardware(hardware_file).microcontroller.sample_period)
        self.late_samples = 0
        self._age_max = 0.0
        s = config.detector
        self.get_logger().info(f"detecting gait events: rest length {self.detector.rest_length:g} m, "
                               f"pre-touchdown {s.pre_touchdown_height * 1e2:g} cm above touchdown")

    def _on_state(self, msg: BodyState) -> None:
        started = time.perf_counter()
        age = time.time() - to_seconds(msg.header.stamp)      # since the sample's packet arrived (earliest)
        if age > self._deadline:
            self.late_samples += 1
        if age > self._age_max:
            self._age_max = age
        for event in self.detector.update(estimate_from_msg(msg)):
            delay = time.time() - event.time
            self._events.publish(gait_event_msg(event, delay))
            if event.kind is EventType.APEX:
                self._apexes.publish(apex_state_msg(event))
            self._delay_max = max(self._delay_max, delay)
        elapsed = time.perf_counter() - started
        if elapsed > self._process_time_max:
            self._process_time_max = elapsed

    def _report(self) -> None:
        now = time.time()
        counters = dict(self.detector.counters, late_samples=self.late_samples)
        deltas, _ = self._deltas.update(counters, now)
        values = {"detection_delay_max_s": self._delay_max, "process_time_max_s": self._process_time_max,
                  "sample_age_max_s": self._age_max}
        self._delay_max = self._process_time_max = self._age_max = 0.0
        problem = self.detector.last_problem if any_of(deltas, ("track_lost",)) else ""
        if not problem and deltas["late_samples"]:
            problem = (f"{deltas['late_samples']} of {deltas['samples']} states came more than "
                       f"{self._deadline * 1e3:g} ms after their sample (the loop misses its deadline)")
        self._diagnostics.report(counters, values, problem, stamp=now)


def main(args=None) -> int:
    return run_node(EventDetectorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
