"""motor_driver: the CANopen master of the hip's maxon EPOS2 (the only thing that talks to it).

Subscribes `motor_command` (MotorCommand: disabled, hip torque [N m] or leg angle [rad]);
publishes `motor_status` (MotorStatus) after every `status_decimation`-th SYNC's TPDOs (1: 1 kHz),
at least every `status_period`, and `/diagnostics` (DiagnosticArray) every `diagnostics_period` and at once on a
new problem. A thread of its own runs the 1 kHz CAN cycle (SYNC, PDOs, state machine, watchdog);
commands reach the bus from the subscription callback at once.

Parameters (read only, given at start: the node offers no parameter services):
  config_file (string): driver settings, default `motor_driver.yaml` (config/motor_driver.yaml)
  hardware_file (string): drive, motor and bus, default from config_file (`hardware.yaml`)
  interface, channel, host (string), port (int): override hardware.yaml's `can:` section
      ("" / 0: keep it); e.g. interface=socketcan channel=can0 on the robot
  command_timeout (double) [s]: no command this long -> quick stop, disable (default 0.02)
  sync_period (double) [s]: SYNC period (default 0.001)

On SIGINT/SIGTERM the drive is disabled (confirmed by the drive) before the node goes away. A bus
whose connection was closed by its other end (the simulated robot's socketcand hub killed) ends the
node with status 1: respawned by its launch file, it connects again and configures the new drive. The
logic lives in hopper_ros.canbus.driver (the driver and its 1 kHz CycleLoop); this node only
connects it to ROS.
"""

from __future__ import annotations

import dataclasses
import sys
import threading

from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from hopper_ros.canbus.epos2_objects import State
from hopper_ros.canbus.driver import (COUNTER_NAMES, ERROR, INFO, WARN, MotorDriver, load_motor_driver,
                                     select_transport)
from hopper_ros.canbus.driver.bus import open_transport
from hopper_ros.canbus.driver.cycle import CycleLoop
from hopper_ros.hardware.config import load_hardware
from hopper_ros.msg import MotorCommand, MotorStatus
from hopper_ros.nodes import diagnostics
from hopper_ros.nodes.common import read_only_parameters, run_node, stop_requested
from hopper_ros.nodes.diagnostics import DiagnosticsReporter
from hopper_ros.nodes.stamps import now_seconds, stamp_of_ns, to_seconds

TRANSPORT_CHECK = 0.1    # [s] how often the node looks whether its bus's connection closed for good
#: commands: the latest one matters (a stale one is worse than none); matches reliable publishers too
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)

STATE_CODES = {
    None: MotorStatus.STATE_UNKNOWN,
    State.START: MotorStatus.STATE_NOT_READY_TO_SWITCH_ON,
    State.NOT_READY_TO_SWITCH_ON: MotorStatus.STATE_NOT_READY_TO_SWITCH_ON,
    State.SWITCH_ON_DISABLED: MotorStatus.STATE_SWITCH_ON_DISABLED,
    State.READY_TO_SWITCH_ON: MotorStatus.STATE_READY_TO_SWITCH_ON,
    State.SWITCHED_ON: MotorStatus.STATE_SWITCHED_ON,
    State.REFRESH: MotorStatus.STATE_SWITCHED_ON,         # EPOS2 steps while switching on
    State.MEASURE_INIT: MotorStatus.STATE_SWITCHED_ON,
    State.OPERATION_ENABLED: MotorStatus.STATE_OPERATION_ENABLED,
    State.QUICK_STOP_ACTIVE: MotorStatus.STATE_QUICK_STOP_ACTIVE,
    State.FAULT_REACTION_ACTIVE_DISABLED: MotorStatus.STATE_FAULT_REACTION_ACTIVE,
    State.FAULT_REACTION_ACTIVE_ENABLED: MotorStatus.STATE_FAULT_REACTION_ACTIVE,
    State.FAULT: MotorStatus.STATE_FAULT,
}


class MotorDriverNode(Node):
    def __init__(self, **node_kwargs):
        # No parameter services (all parameters are read-only): six fewer entities in every wait set, and
        # measurably fewer commands overtaken before the executor takes them (bench_motor_driver).
        node_kwargs.setdefault("start_parameter_services", False)
        super().__init__("motor_driver", **node_kwargs)
        param = read_only_parameters(self)
        config_file = param("config_file", "motor_driver.yaml", "driver settings (YAML)")
        config = load_motor_driver(config_file)
        hardware_file = param("hardware_file", config.hardware_file, "hardware (YAML)")
        bus_overrides = {name: param(name, "", f"CAN {name} ('' = hardware file)")
                         for name in ("interface", "channel", "host")}
        bus_overrides["port"] = param("port", 0, "CAN socketcand port (0 = hardware file)")
        command_timeout = param("command_timeout", config.driver.command_timeout,
                                "[s] no command this long: quick stop, then disable")
        sync_period = param("sync_period", config.driver.sync_period, "[s] SYNC period")
        status_decimation = param("status_decimation", config.status_decimation,
                                  "motor_status on every Nth TPDO set (1: every SYNC)")
        settings = dataclasses.replace(config.driver, command_timeout=command_timeout, sync_period=sync_period)
        hardware = load_hardware(hardware_file)

        # The CAN cycle thread must get the interpreter within a fraction of the SYNC period even
        # while a callback runs (the default switch interval is 5 ms).
        sys.setswitchinterval(min(sys.getswitchinterval(), settings.sync_period / 4))
        self._lock = threading.Lock()
        transport = select_transport(hardware.can, **bus_overrides)
        self._bus = open_transport(transport, cancelled=stop_requested)
        try:
            self._driver = MotorDriver(self._bus, hardware, settings)
        except Exception:
            self._bus.shutdown()
            raise
        self._status_pub = self.create_publisher(MotorStatus, "motor_status", 10)
        self._status_msg = MotorStatus()
        self._status_msg.header.frame_id = "hip"
        self._diagnostics = DiagnosticsReporter(self, f"EPOS2 node {self._driver.node_id} on CAN {transport.interface}")
        self.create_subscription(MotorCommand, "motor_command", self._on_command, COMMAND_QOS)
        self._silent_reported = False
        self._loop = CycleLoop(self._driver, self._lock, self._log, self._publish_status, self.get_logger().error,
                               status_decimation, config.status_period)
        self.create_timer(config.diagnostics_period, self._publish_diagnostics)
        self.create_timer(TRANSPORT_CHECK, self._check_transport)
        self.finished = self.failed = False
        self._loop.start()
        self.get_logger().info(
            f"motor driver on {self._bus.channel_info}: drive node {self._driver.node_id}, SYNC every "
            f"{settings.sync_period * 1e3:g} ms, command timeout {settings.command_timeout * 1e3:g} ms")

    # ------------------------------------------------------------------ ROS side

    def _on_command(self, msg: MotorCommand) -> None:
        age = 0.0
        if msg.mode == MotorCommand.MODE_RAMP:   # the ramp started at the stamp (touchdown), on the host clock
            age = now_seconds(self) - to_seconds(msg.header.stamp)
        with self._lock:
            self._driver.command(msg.mode, msg.setpoint, msg.duration, age, msg.clock_offset)

    def _check_transport(self) -> None:
        """The bus's connection closed for good (the simulated robot's hub went away, killed): this node
        ends (status 1); respawned, it connects to the hub again and configures the drive it finds."""
        if self._driver.transport_lost and not self.finished:
            self.get_logger().error(f"CAN transport {self._bus.channel_info} closed by its other end: the drive is "
                                    "out of reach, the node ends")
            self.finished = self.failed = True

    def _publish_status(self) -> None:
        # One message, refilled: this runs on the CAN cycle thread at up to 1 kHz, and every
        # microsecond it holds the interpreter is one a command callback may wait (publish copies it)
        msg = self._status_msg
        with self._lock:
            s = self._driver.status
            msg.state = STATE_CODES.get(s.state, MotorStatus.STATE_UNKNOWN)
            msg.state_name = s.state_name
            msg.statusword, msg.operation_mode, msg.commanded_mode = s.statusword, s.operation_mode, s.commanded_mode
            msg.position, msg.velocity, msg.current, msg.torque = s.position, s.velocity, s.current, s.torque
            msg.fault_code, msg.fault_text = s.fault_code, s.fault_text
            msg.heartbeat_ok = bool(s.heartbeat_ok and self._driver.heartbeat.alive)
        stamp_of_ns(self.get_clock().now().nanoseconds, msg.header.stamp)
        self._status_pub.publish(msg)

    def _publish_diagnostics(self) -> None:
        with self._lock:
            level, message = self._driver.health()
            counters = [self._driver.counters[name] for name in COUNTER_NAMES]
            status = self._driver.status
            gaps = self._driver.command_gaps
            values = [self._driver.settings.command_timeout, status.current, status.position, gaps.quantile(0.99),
                      gaps.max, gaps.take_recent(), self._driver.frozen_so_far(), self._driver.ramp_late_max]
            silent = int(self._driver.silent)
        self._diagnostics.report(
            {**dict(zip(COUNTER_NAMES, counters)), "cycle_overruns": self._loop.overruns, "drive_silent": silent},
            dict(zip(["command_timeout_s", "current_a", "position_rad", "command_gap_p99_s", "command_gap_max_s",
                      "command_gap_period_max_s", "drive_frozen_s", "ramp_late_max_s", "cycle_rate_hz"],
                         [*values, self._loop.rate])),
            message, {INFO: diagnostics.OK, WARN: diagnostics.WARN, ERROR: diagnostics.ERROR}[level])

    def _log(self, events) -> None:
        logger = self.get_logger()
        problem = False
        for level, text in events:
            if level == ERROR:
                logger.error(text)
            elif level == WARN:
                logger.warning(text)
            else:
                logger.info(text)
            problem = problem or level != INFO
        silent = self._driver.silent
        if problem or silent != self._silent_reported:     # the controller defers a ramp's cancel while silent
            self._silent_reported = silent
            self._publish_diagnostics()

    def destroy_node(self):
        """Disable the drive (and confirm it) before the node goes away."""
        if self._loop.close():
            self.get_logger().info("drive disabled (confirmed by the drive)")
        else:
            self.get_logger().error("drive NOT confirmed disabled")
        return super().destroy_node()


def main(args=None) -> int:
    return run_node(MotorDriverNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
