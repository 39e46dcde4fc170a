"""sim_robot: the simulated robot behind the real wire protocols (hopper_ros.sim).

Steps the physics once per 1 ms period in a thread of its own and, like the robot:
- sends the microcontroller's UDP packet (docs/encoder_packet.md) to the encoder bridge's
  address (`microcontroller.host/port` of config/hardware.yaml);
- runs an emulated EPOS2 on a CAN bus that the motor driver reaches exactly as the real drive:
  `can:=hub` serves the socketcand protocol on 127.0.0.1 (hardware.yaml `can.port`),
  `can:=virtual:CHANNEL` joins python-can's in-process virtual bus, `can:=none` has no drive
  (motor off);
- publishes the force plate on `force_plate` (GroundReactionForce, 1 kHz).
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
import socket
import threading
import time

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from builtin_interfaces.msg import Time as TimeMsg

from hopper_ros.canbus.driver.bus import open_drive_side, sim_transport
from hopper_ros.config_schemas import load_hardware
from hopper_ros.hardware import packet as packet_format
from hopper_ros.msg import ApexState, BodyState, GaitEvent, GroundReactionForce
from hopper_ros.nodes.common import run_node
from hopper_ros.nodes.diagnostics import OK, WARN, DiagnosticsReporter
from hopper_ros.sim.config import load_sim_config
from hopper_ros.sim.experiment import ExperimentSeries
from hopper_ros.sim.robot import SimRobot, SimSample

EVENT_TYPES = {"apex": GaitEvent.APEX, "touchdown": GaitEvent.TOUCHDOWN, "bottom": GaitEvent.BOTTOM,
               "liftoff": GaitEvent.LIFTOFF}
DIAGNOSTICS_PERIOD = 1.0   # [s] wall time
RESYNC_LATENESS = 0.05     # [s] further behind than this, real-time mode stops catching up


def open_drive(can_setting: str, hardware: dict, port: int):
    """The emulated EPOS2 on the transport `can_setting` names (canbus.driver.bus.sim_transport, the
    motor driver's own selection); returns (drive, closer, hub or None), (None, None, None) for none."""
    transport = sim_transport(can_setting, hardware["can"], port)
    if transport is None:
        return None, None, None
    from hopper_ros.canbus.epos2_emulator import Epos2Emulator

    bus, close, hub = open_drive_side(transport)
    return Epos2Emulator(bus, hardware), close, hub


class SimRobotNode(Node):
    def __init__(self, **node_kwargs):
        super().__init__("sim_robot", **node_kwargs)
        param = lambda name, default, text: self.declare_parameter(  # noqa: E731
            name, default, ParameterDescriptor(description=text, read_only=True)).value
        sim_file = param("sim_file", "sim.yaml", "simulated robot configuration (YAML)")
        hardware_file = param("hardware_file", "hardware.yaml", "hardware configuration (YAML)")
        self.mode = param("mode", "realtime", "realtime or lockstep")
        can_setting = param("can", "hub", "hub, virtual:CHANNEL or none")
        hardware = load_hardware(hardware_file)
        can_port = param("can_port", int(hardware["can"]["port"]), "TCP port of the CAN hub on 127.0.0.1")
        udp_host = param("udp_host", str(hardware["microcontroller"]["host"]), "where the encoder packets go")
        udp_port = param("udp_port", int(hardware["microcontroller"]["port"]), "UDP port of the encoder packets")
        enable = param("enable_effects", [""], "effects to switch on")
        disable = param("disable_effects", [""], "effects to switch off")
        config = load_sim_config(sim_file)
        switches = {name: True for name in enable if name} | {name: False for name in disable if name}
        config = config.with_effects(**switches)
        period = param("period", 0.0, "[s] sample and control period (0: the sim file's, 1 ms)")
        if period:
            config = dataclasses.replace(config, period=float(period))
        apex = config.initial_apex
        apex_height = param("apex_height", apex["apex_height"], "initial apex height [m]")
        forward_speed = param("forward_speed", apex["forward_speed"], "initial forward speed [m/s]")
        leg_angle = param("leg_angle", apex["leg_angle"], "initial leg angle [rad]")
        self.duration = param("duration", 0.0, "simulated time to run [s], 0: until stopped")
        experiments = param("experiments", False, "run built-in single-stride experiments (can:=none)")
        hold = param("hold", False, "hold the robot at its first throw until sim/throw")
        self.publish_truth = param("publish_truth", True, "publish sim/truth at 1 kHz")
        self.publish_force = param("force_plate", True, "publish the force plate at 1 kHz")
        self.throw_lead = param("throw_lead", 0.05, "throws start this long before the apex [s]")
        if self.mode not in ("realtime", "lockstep"):
            raise ValueError(f"mode must be realtime or lockstep, got {self.mode!r}")
        if udp_host not in ("127.0.0.1", "localhost"):
            raise ValueError(f"udp_host {udp_host!r}: the simulated robot only sends on loopback (127.0.0.1)")

        if experiments and can_setting != "none":
            raise ValueError("experiments:=true runs the hip itself: it needs can:=none (no drive on a bus)")
        self.drive, self._close_drive, self.hub = open_drive(can_setting, hardware, can_port)
        self.robot = SimRobot(config, hardware, drive=self.drive)
        self.robot.throw(apex_height, forward_speed, leg_angle, lead_time=self.throw_lead, hold=hold)
        self.series = ExperimentSeries(self.robot, seed=config.seed) if experiments else None
        self._udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._udp.bind(("127.0.0.1", 0))            # a sender on loopback only, not on 0.0.0.0
        self._udp_address = ("127.0.0.1", int(udp_port))
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
        self._lock = threading.Lock()
        self._pending_throw = None
        self._stop = threading.Event()
        self.counters = {"periods": 0, "deadline_misses": 0, "udp_errors": 0, "falls": 0, "strides": 0,
                         "throws": 0}
        self._stamp_origin_ns = self.get_clock().now().nanoseconds
        self._wall_start = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="sim-robot", daemon=True)
        effects = [f"{name} {value:g}" for name, value in config.enabled_effects().items()]
        self.get_logger().info(
            f"{self.mode} at {1.0 / config.period:.0f} Hz, packets to {self._udp_address[0]}:{self._udp_address[1]}, "
            f"CAN {can_setting}{f' on 127.0.0.1:{can_port}' if can_setting == 'hub' else ''}, effects on: {', '.join(effects) or 'none'}; thrown to apex "
            f"{apex_height:.3f} m at {forward_speed:.2f} m/s, leg {leg_angle:.3f} rad")
        self._thread.start()

    # ------------------------------------------------------------------ stepping thread
    def _run(self) -> None:
        period = self.robot.period
        deadline = time.monotonic()
        realtime = self.mode == "realtime"
        while not self._stop.is_set():
            if self.duration and self.robot.t >= self.duration - 1e-9:
                self.get_logger().info(f"simulated {self.robot.t:.3f} s: done, real-time factor "
                                       f"{self.realtime_factor():.2f}")
                self.finished = True
                return
            if self.series is not None and (self.robot.experiment is None or self.robot.experiment.done):
                self.series.start_next()
            with self._lock:
                throw, self._pending_throw = self._pending_throw, None
            if throw is not None:
                self.robot.throw(*throw, lead_time=self.throw_lead)
                self.counters["throws"] += 1
            self._emit(self.robot.step())
            if realtime:
                deadline += period
                wait = deadline - time.monotonic()
                if wait > 0.0:
                    time.sleep(wait)
                else:
                    self.counters["deadline_misses"] += 1
                    if wait < -RESYNC_LATENESS:
                        deadline = time.monotonic()

    def _stamp(self, t: float, stamp=None):
        """Header stamp of simulation time t: the node's start time plus t (messages are reused)."""
        nanoseconds = self._stamp_origin_ns + int(round(t * 1e9))
        stamp = stamp if stamp is not None else TimeMsg()
        stamp.sec, stamp.nanosec = divmod(nanoseconds, 1_000_000_000)
        return stamp

    def _emit(self, sample: SimSample) -> None:
        """Send one period's packet and publish its force plate and truth (1 kHz: messages reused)."""
        self.counters["periods"] += 1
        try:
            self._udp.sendto(packet_format.encode(sample.packet), self._udp_address)
        except OSError:
            self.counters["udp_errors"] += 1
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
        for event in sample.events:
            if event.kind == "fall":
                self.counters["falls"] += 1
                self.get_logger().warning(f"the robot fell at t = {event.t:.3f} s")
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
        with self._lock:
            self._pending_throw = (msg.apex_height, msg.forward_speed, msg.leg_angle, msg.y)
        self.get_logger().info(f"thrown to apex {msg.apex_height:.3f} m at {msg.forward_speed:.2f} m/s")

    def realtime_factor(self) -> float:
        wall = time.monotonic() - self._wall_start
        return self.robot.t / wall if wall > 0 else 0.0

    def _report(self) -> None:
        counters = dict(self.counters)
        if self.drive is not None:
            counters.update({f"drive_{k}": v for k, v in dataclasses.asdict(self.drive.counters).items()})
        if self.hub is not None:         # clients dropped for not reading, garbage, ...
            counters.update({f"hub_{k}": v for k, v in dataclasses.asdict(self.hub.counters).items()})
        self._diagnostics.report(counters, {"sim_time_s": self.robot.t, "realtime_factor": self.realtime_factor()},
                                 "the robot fell" if counters["falls"] else "", WARN if counters["falls"] else OK)

    def destroy_node(self):
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        self._udp.close()
        if self._close_drive is not None:
            self._close_drive()
        return super().destroy_node()


def main(args=None):
    return run_node(SimRobotNode, args)
