"""sim_robot: the simulated robot behind the real wire protocols (hopper_ros.sim).

Steps the physics once per 1 ms period in a thread of its own and, like the robot:
- sends the microcontroller's UDP packet (docs/encoder_packet.md) to the encoder bridge's
  address (`microcontroller.host/port` of config/hardware.yaml);
- runs an emulated EPOS2 on a CAN bus that the motor driver reaches exactly as the real drive:
  `can:=hub` serves the socketcand protocol on 127.0.0.1 (hardware.yaml `can.port`),
  `can:=virtual:CHANNEL` joins python-can's in-process virtual bus, `can:=none` has no drive
  (motor off);
- publishes the force plate on `force_plate` (GroundReactionForce, 1 kHz);
- watches each stance's ramp as the leg felt it (hopper_ros.sim.stance: `stances`,
  `stances_without_torque`, `stances_torque_late`, `torque_onset_max_s` on `/diagnostics`, a warning
  per stance without the ramp or with it more than 5 ms late).
For tests and the mismatch tool it also publishes the ground truth: `sim/truth` (BodyState,
1 kHz) and `sim/events` (GaitEvent, true event times). `sim/throw` (ApexState: apex_height,
forward_speed, leg_angle, y) throws the robot to a new apex, as the researcher does by hand
(an apex_height of 0 releases the held robot as it is).

Parameters (read only):
  sim_file, hardware_file: configuration (default sim.yaml, hardware.yaml)
  mode: "realtime" (1 kHz wall clock, default) or "lockstep" (as fast as it goes, same packets)
  can: "hub" (default), "virtual:CHANNEL" or "none"; can_port: the hub's TCP port
  udp_host, udp_port: override hardware.yaml's microcontroller destination
  enable_effects, disable_effects: effects to switch on/off, by their names in the effect library
      (hopper_ros/physics/effects.py) with config/sim.yaml's magnitudes
  apex_height, forward_speed, leg_angle: the initial throw (default: sim.yaml initial_apex)
  publish_truth, force_plate: publish sim/truth, force_plate (default true; sim/events always)
  throw_lead: throws start this long before their apex, rising, so the apex is a natural one
      the sensing sees (default 0.05 s); hold: the robot is held at its first throw's start
      until the first `sim/throw` (as the researcher holds it until the graph is up)
  duration: simulated time to run [s], then the node ends (0: run until stopped)
  period: the sample and control period [s] (0: sim.yaml's 1 ms)
  experiments: run section 4.1's single-stride experiments itself, one after another, inputs
      drawn from the thesis's ranges (data collection without a controller; needs can:=none)
"""

from __future__ import annotations

import dataclasses

from rclpy.node import Node

from hopper_ros.hardware.config import load_hardware
from hopper_ros.msg import ApexState, BodyState, GaitEvent, GroundReactionForce
from hopper_ros.nodes.common import log_event, read_only_parameters, run_node
from hopper_ros.nodes.diagnostics import OK, WARN, DiagnosticsReporter
from hopper_ros.nodes.stamps import stamp_of_ns
from hopper_ros.sim.config import load_sim_config
from hopper_ros.sim.robot import SimSample
from hopper_ros.sim.runner import SimRunner
from hopper_ros.sim.stance import SAID_AFTER, StanceTorque

EVENT_TYPES = {"apex": GaitEvent.APEX, "touchdown": GaitEvent.TOUCHDOWN, "bottom": GaitEvent.BOTTOM,
               "liftoff": GaitEvent.LIFTOFF}
DIAGNOSTICS_PERIOD = 1.0   # [s] wall time


class SimRobotNode(Node):
    def __init__(self, **node_kwargs):
        super().__init__("sim_robot", **node_kwargs)
        param = read_only_parameters(self)
        sim_file = param("sim_file", "sim.yaml", "simulated robot configuration (YAML)")
        hardware = load_hardware(param("hardware_file", "hardware.yaml", "hardware configuration (YAML)"))
        mode = param("mode", "realtime", "realtime or lockstep")
        can_setting = param("can", "hub", "hub, virtual:CHANNEL or none")
        can_port = param("can_port", int(hardware.can.port), "TCP port of the CAN hub on 127.0.0.1 (0: hardware.yaml)") \
            or int(hardware.can.port)
        udp_host = param("udp_host", hardware.microcontroller.host, "where the encoder packets go")
        udp_port = param("udp_port", hardware.microcontroller.port, "UDP port of the encoder packets (0: hardware.yaml)") \
            or hardware.microcontroller.port
        enable = param("enable_effects", [""], "effects to switch on")
        disable = param("disable_effects", [""], "effects to switch off")
        switches = {name: True for name in enable if name} | {name: False for name in disable if name}
        config = load_sim_config(sim_file).with_effects(**switches)
        period = param("period", 0.0, "[s] sample and control period (0: the sim file's, 1 ms)")
        if period:
            config = dataclasses.replace(config, period=float(period))
        apex = config.initial_apex
        apex_height = param("apex_height", apex.apex_height, "initial apex height [m]")
        forward_speed = param("forward_speed", apex.forward_speed, "initial forward speed [m/s]")
        leg_angle = param("leg_angle", apex.leg_angle, "initial leg angle [rad]")
        duration = param("duration", 0.0, "simulated time to run [s], 0: until stopped")
        experiments = param("experiments", False, "run built-in single-stride experiments (can:=none)")
        hold = param("hold", False, "hold the robot at its first throw until sim/throw")
        self.publish_truth = param("publish_truth", True, "publish sim/truth at 1 kHz")
        self.publish_force = param("force_plate", True, "publish the force plate at 1 kHz")
        throw_lead = param("throw_lead", 0.05, "throws start this long before the apex [s]")
        self.runner = SimRunner(config, hardware, mode=mode, can=can_setting, can_port=can_port, udp_host=udp_host,
                                udp_port=udp_port, duration=duration, experiments=experiments, throw_lead=throw_lead,
                                on_sample=self._emit, on_done=self._done, on_failure=self._failed)
        self.robot = self.runner.robot
        self.robot.throw(apex_height, forward_speed, leg_angle, lead_time=throw_lead, hold=hold)
        self._force_msg = GroundReactionForce()
        self._force_msg.header.frame_id = "force_plate"
        self._truth_msg = BodyState(measurement_used=True)
        self._truth_msg.header.frame_id = "ground"
        self._force = self.create_publisher(GroundReactionForce, "force_plate", 100)
        self._truth = self.create_publisher(BodyState, "sim/truth", 100)
        self._events = self.create_publisher(GaitEvent, "sim/events", 100)
        self._diagnostics = DiagnosticsReporter(self, "simulated robot")
        self.create_subscription(ApexState, "sim/throw", self._on_throw, 10)
        self.create_timer(DIAGNOSTICS_PERIOD, self._report)

        self.finished = False                       # run_node ends the process once set
        self.failed = False                         # ... with status 1 (the stepping thread raised)
        self.counters = self.runner.counters
        self.stances = StanceTorque()
        self._freezes_said = 0
        self._stamp_origin_ns = self.get_clock().now().nanoseconds
        effects = [f"{name} {value:g}" for name, value in config.enabled_effects().items()]
        address = self.runner.udp_address
        self.get_logger().info(
            f"{mode} at {1.0 / config.period:.0f} Hz, packets to {address[0]}:{address[1]}, "
            f"CAN {can_setting}{f' on 127.0.0.1:{can_port}' if can_setting == 'hub' else ''}, effects on: {', '.join(effects) or 'none'}; thrown to apex "
            f"{apex_height:.3f} m at {forward_speed:.2f} m/s, leg {leg_angle:.3f} rad")
        self.runner.start()

    # ------------------------------------------------------------------ the stepping thread's callbacks
    def _failed(self, exc: BaseException) -> None:
        """The stepping thread raised and ended: the robot no longer moves, so the node ends (status 1)
        and the launcher stops or respawns it; the drive's watchdog disables the motor meanwhile."""
        import traceback

        self.get_logger().error(f"the simulated robot stopped at t = {self.robot.t:.3f} s: "
                                f"{type(exc).__name__}: {exc}\n{''.join(traceback.format_exception(exc))}")
        self.failed = self.finished = True

    def _done(self) -> None:
        self.get_logger().info(f"simulated {self.robot.t:.3f} s: done, real-time factor "
                               f"{self.runner.realtime_factor():.2f}, {self.runner.counters['resyncs']} freezes")
        self.finished = True

    def _stamp(self, t: float, stamp=None):
        """Header stamp of simulation time t: the node's start time plus t (messages are reused)."""
        return stamp_of_ns(self._stamp_origin_ns + int(round(t * 1e9)), stamp)

    def _emit(self, sample: SimSample) -> None:
        """Publish one period's force plate and truth (1 kHz: messages reused) and its events."""
        force, state, truth = self._force_msg, self._truth_msg, sample.truth
        if self.publish_force:
            self._stamp(truth.t, force.header.stamp)
            force.force_forward, force.force_vertical = sample.force.forward, sample.force.vertical
            force.center_of_pressure = sample.force.center_of_pressure
            force.contact = sample.force.contact
            self._force.publish(force)
        if self.publish_truth:
            self._stamp(truth.t, state.header.stamp)
            state.sequence = sample.packet.sequence
            state.y, state.z, state.y_dot, state.z_dot = truth.y, truth.z, truth.ydot, truth.zdot
            state.leg_angle, state.leg_angle_rate = truth.leg_angle, truth.leg_rate
            self._truth.publish(state)
        if self.runner.counters["resyncs"] != self._freezes_said:
            self._freezes_said = self.runner.counters["resyncs"]
            at, length = self.runner.last_freeze
            self.get_logger().info(f"the world stood still for {length * 1e3:.1f} ms at t = {at:.3f} s (this process "
                                   "was stopped or starved: sim/runner.py RESYNC_AFTER)")
        stances = self.stances
        closed = stances.stances
        stances.add(sample, self.robot.current_mode, self.runner.behind)
        if stances.early > SAID_AFTER and any(event.kind == "touchdown" for event in sample.events):
            log_event(self.get_logger(), "warning" if stances.early > stances.late_after else "info",
                      f"touchdown at t = {truth.t:.3f} s: the ramp torque reached the leg {stances.early * 1e3:.1f} ms "
                      "before it (in the flight)")
        if stances.stances > closed and not stances.onsets[-1] <= SAID_AFTER:
            onset, behind = stances.onsets[-1], stances.behind
            level = "info" if onset <= stances.late_after else "warning"
            log_event(self.get_logger(), level, f"stance ending at t = {truth.t:.3f} s: " + (
                "no ramp torque reached the leg" if onset != onset else
                f"the ramp torque reached the leg {onset * 1e3:.1f} ms after the touchdown (the robot ran "
                f"{behind * 1e3:.1f} ms behind its clock at most until then)"))
        for event in sample.events:
            if event.kind == "fall":
                self.counters["falls"] += 1
                self.get_logger().warning(f"the robot fell at t = {event.t:.3f} s (simulated time; "
                                          f"{self.runner.counters['resyncs']} resyncs, "
                                          f"{self.runner.counters['deadline_misses']} deadline misses so far)")
                continue
            if event.kind == "apex":
                self.counters["strides"] += 1
            msg = GaitEvent()
            msg.header.stamp, msg.header.frame_id = self._stamp(event.t), "ground"
            msg.type = EVENT_TYPES[event.kind]
            msg.stride_index = self.counters["strides"]
            msg.state.header.stamp = msg.header.stamp
            msg.state.y, msg.state.z, msg.state.y_dot, msg.state.z_dot = event.y, event.z, event.ydot, event.zdot
            msg.state.leg_angle = event.leg_angle
            self._events.publish(msg)

    # ------------------------------------------------------------------ ROS side
    def _on_throw(self, msg: ApexState) -> None:
        if msg.apex_height == 0.0:
            self.robot.plant.release()
            self.get_logger().info("released")
            return
        self.runner.throw(msg.apex_height, msg.forward_speed, msg.leg_angle, msg.y)
        self.get_logger().info(f"thrown to apex {msg.apex_height:.3f} m at {msg.forward_speed:.2f} m/s")

    def _report(self) -> None:
        counters = self.runner.all_counters() | self.stances.counters()
        self._diagnostics.report(counters, {"sim_time_s": self.robot.t, "realtime_factor": self.runner.realtime_factor(),
                                            "torque_onset_max_s": self.stances.onset_max,
                                            "torque_early_max_s": self.stances.early_max},
                                 "the robot fell" if counters["falls"] else "", WARN if counters["falls"] else OK)

    def destroy_node(self):
        self.runner.close()
        return super().destroy_node()


def main(args=None):
    return run_node(SimRobotNode, args)
