"""deadbeat_controller: chapter 5's controller (Fig 5.3), or the single-stride experiment of Fig 4.1.

Closed loop (`experiment:=closed_loop`, default): at each apex (`apex`, ApexState, from the
event detector) it decides tau_0 by the energy balance (5.1)-(5.5) and theta_td by the
inversion (5.6) for the setpoint in force (`apex_setpoint`, latched, e.g. from
setpoint_scheduler), publishes the decision on `stride_command` (StrideCommand), and drives the
hip through the stride (hopper_ros.control.stride_machine): leg to theta_td (position), zero
current 2 cm above touchdown, the ramp from touchdown (current), the lift-off angle held after
lift-off. An infeasible stride holds the leg and applies no torque, and the command says why.
A drive problem (the motor driver's ERROR diagnostics) also ends in that safe state until the
next apex.

Single stride (`experiment:=single_stride`, with `tau_0` and `touchdown_angle`): Fig 4.1 for
data collection; the ramp ends at the model's predicted lift-off for the apex the robot is
thrown to; after the second apex the leg is held and then the drive disabled.

Stance ramp timing (control.yaml `stride`, beyond the thesis: `ramp_ahead`, `touchdown_grace`,
`stand_still_step`): see hopper_ros/control/stride_policy.py. The ramp's instants are kept on the
robot's clock: each gait event's state (stamp minus `mcu_time`) and `clock_offset` (std_msgs/Float64,
from state_estimator, each time its clock mapping re-anchors) give the mapping, and MotorCommand's
`clock_offset` says which one a command's stamp is on.

A MotorCommand goes out at once when an input changes it (apex, gait event, setpoint, fault) and
is repeated every `keep_alive` otherwise, which feeds the motor driver's watchdog: from a thread
of its own (hopper_ros.runtime.periodic, SCHED_FIFO `keep_alive_priority_boost` above the node), on time
whatever the executor is busy with, as long as the executor itself ran within `executor_timeout`
(control.yaml; a stuck executor stops the stream and the driver disables the drive). The node
needs no state estimates, so it wakes at 333 Hz instead of with every 1 kHz sample. In
stance it is MODE_RAMP stamped with the touchdown time: the driver computes the ramp's current
every SYNC period itself, so delays and jitter of the command stream (seven Python processes on
two cores) neither shift nor stretch it; the stride phase advances on `gait_event`. The whole
policy is hopper_ros.control.stride_policy (no ROS); this node only wires the topics to it.

Parameters (read only): model_file (model.yaml), config_file (control.yaml), experiment,
tau_0, touchdown_angle, adaptation (overrides control.yaml), keep_alive (an unchanged command is
repeated this often; default control.yaml `stride.keep_alive`, 3 ms, chosen with the driver's
10 ms `command_timeout`: one lost repeat never trips it, a lost stream has the drive disabled
within 20 ms).
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64

from hopper_ros.config.schemas import load_model
from hopper_ros.control.config import load_control
from hopper_ros.control.deadbeat import DeadbeatController, StrideDecision
from hopper_ros.control.stride_machine import Phase
from hopper_ros.control.stride_policy import StridePolicy
from hopper_ros.runtime.gaps import GapHistogram
from hopper_ros.runtime.periodic import PeriodicThread
from hopper_ros.msg import ApexState, GaitEvent, MotorCommand, StrideCommand
from hopper_ros.nodes.common import log_event, read_only_parameters, run_node
from hopper_ros.nodes.diagnostics import (DIAGNOSTICS_TOPIC, ERROR, OK, WARN, DiagnosticsReporter, level_of,
                                          split_node_name, status_values)
from hopper_ros.nodes.stamps import now_seconds, to_seconds, to_stamp

SETPOINT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
WARM_UP_SETPOINT = (0.39, 2.0)   # [m, m/s] a typical stride, decided once at start-up and forgotten


class DeadbeatControllerNode(Node):
    def __init__(self, **node_kwargs):
        super().__init__("deadbeat_controller", **node_kwargs)
        param = read_only_parameters(self)
        model_file = param("model_file", "model.yaml", "model parameters (YAML)")
        config_file = param("config_file", "control.yaml", "controller settings (YAML)")
        self.experiment = param("experiment", "closed_loop", "closed_loop or single_stride")
        tau_0 = param("tau_0", math.nan, "single stride: initial torque [N m]")
        touchdown_angle = param("touchdown_angle", math.nan, "single stride: touchdown angle [rad]")
        adaptation = param("adaptation", "", "override control.yaml: true or false")
        config = load_control(config_file)
        keep_alive = param("keep_alive", config.stride.keep_alive,
                           "[s] an unchanged motor command is repeated this often (control.yaml stride.keep_alive)")
        settings = config.deadbeat
        if adaptation:
            if adaptation not in ("true", "false"):
                raise ValueError(f"adaptation must be true or false, got {adaptation!r}")
            settings = dataclasses.replace(settings, adaptation=adaptation == "true")
        self.params = load_model(model_file)
        self.controller = DeadbeatController(self.params, settings)
        # the decision's first call pays for imports and first uses (~10 ms, 0.3 s on a starved CPU): paid
        # here, on a controller of its own, before the command stream begins
        DeadbeatController(self.params, settings).prime(*WARM_UP_SETPOINT)
        if self.experiment == "single_stride":
            if not (math.isfinite(tau_0) and math.isfinite(touchdown_angle)):
                raise ValueError("experiment:=single_stride needs the parameters tau_0 and touchdown_angle")
        elif self.experiment != "closed_loop":
            raise ValueError(f"experiment must be closed_loop or single_stride, got {self.experiment!r}")
        self.policy = StridePolicy(self.controller, dataclasses.replace(config.stride, keep_alive=keep_alive),
                                   (tau_0, touchdown_angle) if self.experiment == "single_stride" else None)

        self._command_pub = self.create_publisher(MotorCommand, "motor_command", COMMAND_QOS)
        self._stride_pub = self.create_publisher(StrideCommand, "stride_command", 10)
        self._diagnostics = DiagnosticsReporter(self)
        self.create_subscription(ApexState, "apex_setpoint", self._on_setpoint, SETPOINT_QOS)
        self.create_subscription(ApexState, "apex", self._on_apex, 10)
        self.create_subscription(GaitEvent, "gait_event", self._on_event, 10)
        self.create_subscription(Float64, "clock_offset", self._on_clock, 10)
        self.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diagnostics, 10)
        self.create_timer(1.0, self._report)
        self._command = MotorCommand()
        self.published_gaps = GapHistogram()       # the command stream as this node sends it
        self._published = math.nan
        # The repeats come from a thread of their own (hopper_ros.runtime.periodic): an executor timer waited
        # behind every callback of the process (in the demo's container, the 1 kHz sensing chain's) and
        # the stream had gaps of 10-30 ms under load. They go on only while this node's executor is
        # alive (`_tick`, every quarter of executor_timeout): a stuck executor stops them.
        self._lock = threading.RLock()             # the policy and the publisher: callbacks and the thread
        self._executor_timeout = self.policy.settings.executor_timeout
        self._executor_seen = time.monotonic()
        self._stale = False
        self.create_timer(self._executor_timeout / 4, self._tick)
        self._repeater = PeriodicThread(keep_alive, self._repeat, self.policy.settings.keep_alive_priority_boost,
                                        "command-repeat", self._repeat_failed)
        s = self.controller.settings
        self.get_logger().info(
            f"{self.experiment}: predictor {s.predictor}, adaptation {'on' if s.adaptation else 'off'}, model {model_file}")

    # ------------------------------------------------------------------ inputs
    def _on_setpoint(self, msg: ApexState) -> None:
        with self._lock:
            self.policy.on_setpoint(msg.apex_height, msg.forward_speed)
            self.get_logger().info(f"setpoint: apex {msg.apex_height:.3f} m at {msg.forward_speed:.2f} m/s")
            self._send()

    def _on_apex(self, msg: ApexState) -> None:
        with self._lock:
            self.policy.on_sensing(now_seconds(self))
            decision = self.policy.on_apex(msg.apex_height, msg.forward_speed, msg.stride_index)
            if decision is not None:
                self._publish_decision(decision)
            self._send()

    def _on_clock(self, msg: Float64) -> None:
        """The sensing clock re-anchored (state_estimator): a ramp scheduled on the robot's clock follows."""
        with self._lock:
            self.policy.on_clock(msg.data)
            self._send()

    def _on_event(self, msg: GaitEvent) -> None:
        when, s = to_seconds(msg.header.stamp), msg.state
        with self._lock:
            self.policy.on_sensing(now_seconds(self))
            if s.mcu_time > 0.0:                # the state's robot time: the clock mapping its stamp is on
                self.policy.on_clock(to_seconds(s.header.stamp) - s.mcu_time)
            if msg.type == GaitEvent.PRE_TOUCHDOWN:
                self.policy.on_pre_touchdown(when, s.z, s.z_dot, s.leg_angle, s.leg_angle_rate)
            elif msg.type == GaitEvent.TOUCHDOWN:
                self.policy.on_touchdown(when, msg.header.stamp)
            elif msg.type == GaitEvent.LIFTOFF:
                self.policy.on_liftoff(s.leg_angle)
            else:
                return
            self._send()

    def _on_diagnostics(self, msg) -> None:
        """The motor driver reports a drive fault or a lost drive at once: hold the leg, no torque;
        and a drive that stands still (`drive_silent`, `drive_frozen_s`: the robot's time, for the
        stance ramp's grace).

        Every node of every namespace reports on /diagnostics: only a motor driver of our own
        namespace counts (its node name ends in "motor_driver")."""
        for status in msg.status:
            namespace, name = split_node_name(status.name)
            if namespace != self.get_namespace() or not name.endswith("motor_driver"):
                continue
            values = status_values(status)
            frozen = values.get("drive_frozen_s")
            with self._lock:
                if isinstance(frozen, float):
                    self.policy.on_drive_silence(values.get("drive_silent") == 1, frozen)
                if level_of(status) == ERROR and self.policy.on_drive_fault(status.message):
                    self._send()
            return

    # ------------------------------------------------------------------ the repeats
    def spinning(self) -> None:
        """Its executor runs (run_node, the container): the repeats begin."""
        self._executor_seen = time.monotonic()
        self._repeater.start()

    def _tick(self) -> None:
        """The executor runs: the repeats may go on."""
        self._executor_seen = time.monotonic()
        if self._stale:
            self._stale = False
            self.get_logger().info("executor running again: motor commands resume")

    def _repeat(self) -> None:
        """The command for now, from the repeating thread, while the executor is alive."""
        with self._lock:
            if time.monotonic() - self._executor_seen > self._executor_timeout:
                if not self._stale:
                    self._stale = True
                    self.get_logger().error(f"executor silent for more than {self._executor_timeout * 1e3:.0f} ms: "
                                            "motor commands stop (the drive's watchdog disables it)")
                return
            self._send()

    def _repeat_failed(self, exc: BaseException) -> None:
        self.get_logger().error(f"motor command repeats ended: {type(exc).__name__}: {exc} (the drive's watchdog "
                                "disables it)")

    def destroy_node(self):
        self._repeater.stop()
        return super().destroy_node()

    # ------------------------------------------------------------------ outputs
    def _send(self) -> None:
        """The command for now, published when it changed and otherwise every `keep_alive` seconds."""
        stamp = self.get_clock().now().to_msg()
        now = to_seconds(stamp)
        command = self.policy.command(now, stamp)
        if self.policy.due(command, now):
            msg = self._command
            msg.header.stamp = command.stamp if command.stamp is not None else to_stamp(command.time)
            msg.mode, msg.setpoint, msg.duration = command.mode, command.setpoint, command.duration
            msg.clock_offset = command.clock_offset
            self._command_pub.publish(msg)
            published = time.monotonic()
            if self._published == self._published:
                self.published_gaps.add(published - self._published)
            self._published = published
        for level, text in self.policy.drain_events():
            log_event(self.get_logger(), level, text)

    def _publish_decision(self, decision: StrideDecision) -> None:
        msg = StrideCommand()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.stride_index = decision.stride_index
        msg.feasible, msg.reason = decision.feasible, decision.reason
        msg.tau_0, msg.touchdown_angle = decision.tau_0, decision.touchdown_angle
        msg.predicted_liftoff_time = decision.ramp_duration
        msg.predicted_apex_height = decision.predicted_apex_height
        msg.predicted_forward_speed = decision.predicted_forward_speed
        msg.predicted_stride_time = decision.predicted_stride_time
        msg.target_apex_height, msg.target_forward_speed = decision.target_height, decision.target_speed
        self._stride_pub.publish(msg)

    def _report(self) -> None:
        with self._lock:
            self._report_locked()

    def _report_locked(self) -> None:
        decision, policy = self.policy.last_decision, self.policy
        values = {"bias_height_m": self.controller.bias_height, "bias_speed_m_s": self.controller.bias_speed,
                  "decision_time_s": decision.first_compute_time if decision else math.nan,
                  "refine_time_s": decision.compute_time if decision else math.nan,
                  "command_gap_p99_s": self.published_gaps.quantile(0.99), "command_gap_max_s": self.published_gaps.max,
                  "command_gap_period_max_s": self.published_gaps.take_recent(),
                  "repeat_late_max_s": self._repeater.late_max, "repeat_priority": self._repeater.priority,
                  "touchdown_predicted_late_max_s": policy.prediction_late_max,
                  "touchdown_predicted_early_max_s": policy.prediction_early_max}
        safe = policy.phase is Phase.SAFE
        self._diagnostics.report(policy.counters, values, policy.machine.reason if safe else "", WARN if safe else OK)


def main(args=None):
    return run_node(DeadbeatControllerNode, args)
