"""setpoint_scheduler: publishes the apex setpoints of a schedule file.

Publishes `apex_setpoint` (hopper_ros/msg/ApexState: apex_height [m], forward_speed [m/s]) with
a latched QoS (reliable, transient local, depth 1): a subscriber that starts later still gets the
setpoint in force. A new message goes out whenever the schedule advances: after a number of
apexes (counted on `apex`, ApexState, from the event detector) or after a number of seconds.
`/diagnostics` (DiagnosticArray, every second): setpoints published, apexes counted, the segment
and setpoint in force.

Parameters:
  schedule_file (string, read only): the schedule, a path or relative to the config directory;
      default `setpoints/fig5_5.yaml` (config/setpoints/fig5_5.yaml, the thesis's Fig. 5.5 run).
      Format and validation: hopper_ros.control.setpoints.

The schedule logic lives in hopper_ros.control.setpoints; this node only connects it to ROS.
"""

from __future__ import annotations

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hopper_ros.msg import ApexState
from hopper_ros.nodes.common import read_only_parameters, run_node
from hopper_ros.nodes.diagnostics import OK, DiagnosticsReporter
from hopper_ros.nodes.stamps import now_seconds
from hopper_ros.control.setpoints import ScheduleRunner, load_schedule

DEFAULT_SCHEDULE = "setpoints/fig5_5.yaml"
SETPOINT_TOPIC = "apex_setpoint"
APEX_TOPIC = "apex"
DIAGNOSTICS_PERIOD = 1.0  # [s]

# Latched: the last setpoint is kept for late-joining subscribers (they must ask for
# TRANSIENT_LOCAL too).
SETPOINT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


class SetpointScheduler(Node):
    def __init__(self, **node_kwargs):
        super().__init__("setpoint_scheduler", **node_kwargs)
        schedule_file = read_only_parameters(self)("schedule_file", DEFAULT_SCHEDULE, "apex setpoint schedule (YAML)")
        self._runner = ScheduleRunner(load_schedule(schedule_file), self._now())
        self._stride_index = 0
        self._timer = None
        self._finished_reported = False
        self._publisher = self.create_publisher(ApexState, SETPOINT_TOPIC, SETPOINT_QOS)
        self._subscription = self.create_subscription(ApexState, APEX_TOPIC, self._on_apex, 10)
        self._counters = {"setpoints_published": 0, "apexes": 0}
        self._diagnostics = DiagnosticsReporter(self)
        self.create_timer(DIAGNOSTICS_PERIOD, self._report)
        self.get_logger().info(
            f"schedule {schedule_file}: {len(self._runner.schedule.segments)} segments"
            + (", repeated" if self._runner.schedule.repeat else "")
        )
        self._publish()

    def _now(self) -> float:
        return now_seconds(self)

    def _on_apex(self, msg: ApexState) -> None:
        self._stride_index = msg.stride_index
        self._counters["apexes"] += 1
        if self._runner.on_apex(self._now()):
            self._publish()
        elif self._runner.finished and self._runner.segment.strides is not None:
            self._report_finished()

    def _on_timer(self) -> None:
        if self._runner.on_time(self._now()):
            self._publish()
        else:
            self._arm_timer()  # early wake-up, or the schedule just finished
            if self._runner.finished:
                self._report_finished()

    def _publish(self) -> None:
        segment = self._runner.segment
        msg = ApexState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.stride_index = self._stride_index
        msg.apex_height = segment.apex_height
        msg.forward_speed = segment.forward_speed
        self._publisher.publish(msg)
        self._counters["setpoints_published"] += 1
        count = len(self._runner.schedule.segments)
        self.get_logger().info(f"setpoint {self._runner.index + 1}/{count}: {segment.describe()}")
        self._arm_timer()

    def _report(self) -> None:
        segment = self._runner.segment
        self._diagnostics.report(self._counters, {"segment": self._runner.index + 1, "apex_height_m": segment.apex_height,
                                                  "forward_speed_m_s": segment.forward_speed},
                                 "schedule finished" if self._runner.finished else "", OK)

    def _report_finished(self) -> None:
        if not self._finished_reported:
            self._finished_reported = True
            self.get_logger().info("schedule finished; the last setpoint stays in force")

    def _arm_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None
        deadline = self._runner.deadline()
        if deadline is not None:
            self._timer = self.create_timer(max(deadline - self._now(), 1e-3), self._on_timer)


def main(args=None) -> int:
    return run_node(SetpointScheduler, args)


if __name__ == "__main__":
    raise SystemExit(main())
