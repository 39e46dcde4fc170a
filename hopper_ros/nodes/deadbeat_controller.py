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

Stance ramp timing (control.yaml `stride`, beyond the thesis): with `ramp_ahead` the ramp is
sent at the pre-touchdown event already, stamped with the touchdown predicted from that event's
state (hopper_ros.physics.flight.touchdown_time); the driver keeps zero current until that
instant and then runs the ramp, and the measured touchdown re-stamps it. The touchdown event
itself reaches the node only after the sensing chain's latency. No touchdown within
`touchdown_grace` of the predicted one cancels the ramp (zero current, counted).

A MotorCommand goes out at once when an input changes it (apex, gait event, setpoint, fault) and
is repeated every `keep_alive` otherwise (a timer), which feeds the motor driver's watchdog; the
node needs no state estimates, so it wakes at 333 Hz instead of with every 1 kHz sample. In
stance it is MODE_RAMP stamped with the touchdown time: the driver computes the ramp's current
every SYNC period itself, so delays and jitter of the command stream (seven Python processes on
two cores) neither shift nor stretch it; the stride phase advances on `gait_event`. The logic is in
hopper_ros.control (no ROS); this node only connects it.

Parameters (read only): model_file (model.yaml), config_file (control.yaml), experiment,
tau_0, touchdown_angle, adaptation (overrides control.yaml), keep_alive (an unchanged command is
repeated this often; default control.yaml `stride.keep_alive`, 3 ms, chosen with the driver's
10 ms `command_timeout`: one lost repeat never trips it, a lost stream has the drive disabled
within 20 ms).
"""

from __future__ import annotations

import math

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hopper_ros.config import config_path
from hopper_ros.config_schemas import CONTROL, load_model
from hopper_ros.schema import load_config
from hopper_ros.control.closed_loop import decide_at_apex
from hopper_ros.control.deadbeat import DeadbeatController, DeadbeatSettings, StrideDecision
from hopper_ros.control.stride_machine import Phase, StrideMachine, StridePlan
from hopper_ros.msg import ApexState, GaitEvent, MotorCommand, StrideCommand
from hopper_ros.nodes.common import run_node
from hopper_ros.nodes.diagnostics import (DIAGNOSTICS_TOPIC, ERROR, OK, WARN, DiagnosticsReporter, level_of,
                                          split_node_name)
from hopper_ros.physics.flight import touchdown_time
from hopper_ros.physics.predictors import predict_stride
from hopper_ros.sensing.messages import to_time

SETPOINT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)


def _seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


class DeadbeatControllerNode(Node):
    def __init__(self, **node_kwargs):
        super().__init__("deadbeat_controller", **node_kwargs)
        param = lambda name, default, text: self.declare_parameter(  # noqa: E731
            name, default, ParameterDescriptor(description=text, read_only=True)).value
        model_file = param("model_file", "model.yaml", "model parameters (YAML)")
        config_file = param("config_file", "control.yaml", "controller settings (YAML)")
        self.experiment = param("experiment", "closed_loop", "closed_loop or single_stride")
        tau_0 = param("tau_0", math.nan, "single stride: initial torque [N m]")
        touchdown_angle = param("touchdown_angle", math.nan, "single stride: touchdown angle [rad]")
        adaptation = param("adaptation", "", "override control.yaml: true or false")
        self._last_sent = -math.inf
        self._touchdown_stamp = None
        config = load_config(config_file, CONTROL)
        settings = dict(config.get("deadbeat", {}))
        stride = config.get("stride", {})
        self.keep_alive = param("keep_alive", float(stride.get("keep_alive", 0.003)),
                                "[s] an unchanged motor command is repeated this often (control.yaml stride.keep_alive)")
        self.ramp_ahead = bool(stride.get("ramp_ahead", False))
        self.touchdown_grace = float(stride.get("touchdown_grace", 0.02))
        self._predicted_touchdown = math.nan
        self._cancelled_ramp = False
        if adaptation:
            if adaptation not in ("true", "false"):
                raise ValueError(f"adaptation must be true or false, got {adaptation!r}")
            settings["adaptation"] = adaptation == "true"
        self.params = load_model(model_file)
        self.controller = DeadbeatController(self.params, DeadbeatSettings.from_mapping(settings, str(config_path(config_file))))
        self.machine = StrideMachine()
        if self.experiment == "single_stride":
            if not (math.isfinite(tau_0) and math.isfinite(touchdown_angle)):
                raise ValueError("experiment:=single_stride needs the parameters tau_0 and touchdown_angle")
            self.single = (tau_0, touchdown_angle)
            self.machine.start_single_stride(StridePlan(tau_0, touchdown_angle, math.inf))
        elif self.experiment != "closed_loop":
            raise ValueError(f"experiment must be closed_loop or single_stride, got {self.experiment!r}")
        self.setpoint: tuple[float, float] | None = None
        self.counters = {"strides": 0, "infeasible": 0, "faults": 0, "commands": 0, "touchdowns_missed": 0}
        self.last_decision: StrideDecision | None = None
        self._brake_since = math.nan

        self._command_pub = self.create_publisher(MotorCommand, "motor_command", COMMAND_QOS)
        self._stride_pub = self.create_publisher(StrideCommand, "stride_command", 10)
        self._diagnostics = DiagnosticsReporter(self)
        self.create_subscription(ApexState, "apex_setpoint", self._on_setpoint, SETPOINT_QOS)
        self.create_subscription(ApexState, "apex", self._on_apex, 10)
        self.create_subscription(GaitEvent, "gait_event", self._on_event, 10)
        self.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diagnostics, 10)
        self.create_timer(1.0, self._report)
        self.create_timer(self.keep_alive, self._send)
        self._command = MotorCommand()
        s = self.controller.settings
        self.get_logger().info(
            f"{self.experiment}: predictor {s.predictor}, adaptation {'on' if s.adaptation else 'off'}, model {model_file}")

    # ------------------------------------------------------------------ inputs
    def _on_setpoint(self, msg: ApexState) -> None:
        self.setpoint = (msg.apex_height, msg.forward_speed)
        if self.experiment == "closed_loop":      # ready for the throw: the leg at the neutral angle
            self.controller.prime(*self.setpoint)
            self.machine.hold(self.controller.neutral_angle(msg.forward_speed))
        self.get_logger().info(f"setpoint: apex {msg.apex_height:.3f} m at {msg.forward_speed:.2f} m/s")
        self._send()

    def _on_apex(self, msg: ApexState) -> None:
        self._decide(msg)
        self._send()

    def _decide(self, msg: ApexState) -> None:
        if self.experiment == "single_stride":
            self._single_stride_apex(msg)
            return
        self.controller.observe(msg.apex_height, msg.forward_speed)
        if self.setpoint is None:
            return
        decision = decide_at_apex(self.controller, self.machine, msg.apex_height, msg.forward_speed, self.setpoint,
                                  msg.stride_index)
        self.last_decision = decision
        self.counters["strides"] += 1
        if not decision.feasible:
            self.counters["infeasible"] += 1
            self.get_logger().warning(f"stride {msg.stride_index}: infeasible ({decision.reason}); leg held, no torque")
        self._publish_decision(decision)

    def _single_stride_apex(self, msg: ApexState) -> None:
        if self.machine.phase is Phase.INITIALISE:
            tau_0, angle = self.single
            prediction = predict_stride(self.params, msg.apex_height, msg.forward_speed, angle, tau_0)
            ramp = prediction.ramp_duration if prediction.ok else 0.0
            self.machine.plan = StridePlan(tau_0, angle, ramp)
            decision = StrideDecision(msg.stride_index, bool(prediction.ok), prediction.failure, tau_0, angle, ramp,
                                      prediction.next_apex_height, prediction.next_forward_speed,
                                      prediction.stride_time, math.nan, math.nan)
            self._publish_decision(decision)
        self.machine.on_apex(None)
        if self.machine.phase is Phase.BRAKE:
            self.get_logger().info("single stride done: braking")

    def _on_event(self, msg: GaitEvent) -> None:
        when = _seconds(msg.header.stamp)
        if msg.type == GaitEvent.PRE_TOUCHDOWN:
            self.machine.on_pre_touchdown()
            self._predicted_touchdown = when + self._time_to_touchdown(msg) if self.ramp_ahead else math.nan
            self._cancelled_ramp = False
        elif msg.type == GaitEvent.TOUCHDOWN:
            self.machine.on_touchdown(when)
            self._touchdown_stamp = msg.header.stamp
        elif msg.type == GaitEvent.LIFTOFF:
            self.machine.on_liftoff(msg.state.leg_angle)
        else:
            return
        self._send()

    def _time_to_touchdown(self, msg: GaitEvent) -> float:
        """From the pre-touchdown event's state: the flight (2.14) until the toe meets the ground."""
        s, p = msg.state, self.params
        return touchdown_time(s.z, s.z_dot, s.leg_angle, s.leg_angle_rate, p.rest_length, p.gravity,
                              p.flight_damping_vertical)

    def _on_diagnostics(self, msg) -> None:
        """The motor driver reports a drive fault or a lost drive at once: hold the leg, no torque.

        Every node of every namespace reports on /diagnostics: only a motor driver of our own
        namespace counts (its node name ends in "motor_driver")."""
        if self.machine.phase is Phase.SAFE:
            return
        for status in msg.status:
            namespace, name = split_node_name(status.name)
            if namespace == self.get_namespace() and name.endswith("motor_driver") and level_of(status) == ERROR:
                self.counters["faults"] += 1
                self.machine.fault(f"motor driver: {status.message}")
                self.get_logger().error(self.machine.reason)
                self._send()
                return

    def _send(self) -> None:
        """The command for now, published when it changed and otherwise every `keep_alive` seconds."""
        stamp = self.get_clock().now().to_msg()
        now = _seconds(stamp)
        mode, setpoint = self.machine.command(now)
        if self.machine.phase is Phase.BRAKE:
            if math.isnan(self._brake_since):
                self._brake_since = now
            elif now - self._brake_since > 0.5:
                mode, setpoint = MotorCommand.MODE_DISABLED, 0.0     # the robot sits back: drive off
        command = self._command
        phase, plan = self.machine.phase, self.machine.plan
        if phase is Phase.STANCE and plan is not None:
            # the driver runs the ramp itself, from the touchdown time: jitter in this stream cannot shift it
            mode, setpoint = MotorCommand.MODE_RAMP, plan.tau_0
            command.duration = plan.ramp_duration
            stamp = self._touchdown_stamp
        elif phase is Phase.PRE_TOUCHDOWN and plan is not None and math.isfinite(self._predicted_touchdown):
            if now <= self._predicted_touchdown + self.touchdown_grace:
                # scheduled ahead: zero current until the predicted touchdown, then the ramp
                mode, setpoint = MotorCommand.MODE_RAMP, plan.tau_0
                command.duration = plan.ramp_duration
                stamp = to_time(self._predicted_touchdown)
            else:
                command.duration = 0.0
                if not self._cancelled_ramp:
                    self._cancelled_ramp = True
                    self.counters["touchdowns_missed"] += 1
                    self.get_logger().warning(f"no touchdown within {self.touchdown_grace * 1e3:.0f} ms of the "
                                              f"predicted one: stance ramp cancelled")
        else:
            command.duration = 0.0
        if ((mode, float(setpoint)) == (command.mode, command.setpoint)
                and now - self._last_sent < 0.5 * self.keep_alive):
            return
        command.header.stamp = stamp
        command.mode, command.setpoint = mode, float(setpoint)
        self._command_pub.publish(command)
        self._last_sent = now
        self.counters["commands"] += 1

    # ------------------------------------------------------------------ outputs
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
        decision = self.last_decision
        values = {"bias_height_m": self.controller.bias_height, "bias_speed_m_s": self.controller.bias_speed,
                  "decision_time_s": decision.first_compute_time if decision else math.nan,
                  "refine_time_s": decision.compute_time if decision else math.nan}
        safe = self.machine.phase is Phase.SAFE
        self._diagnostics.report(self.counters, values, self.machine.reason if safe else "", WARN if safe else OK)


def main(args=None):
    return run_node(DeadbeatControllerNode, args)
