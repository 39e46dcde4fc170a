"""The hip motor driver: CANopen master of the maxon EPOS2, as plain Python (no ROS).

`MotorDriver(bus, hardware, settings, clock)` owns one python-can bus and one drive (node id from
config/hardware.yaml). The caller drives it:

- `cycle()` once per `settings.sync_period` (1 ms): timeouts (SDO, heartbeat, command watchdog),
  the start-up sequence, the CiA 402 controlword, the RPDO and the SYNC, our own heartbeat;
- `handle(frame)` for every received frame (TPDOs, SDO answers, EMCY, heartbeats); never raises:
  a malformed frame is counted (`counters["malformed_frames"]`) and ignored;
- `command(mode, setpoint)` for each motor command (MotorCommand.MODE_*: 0 disabled, 1 hip
  torque [N m], 2 leg angle [rad]); the RPDO goes out at once when the drive is running;
- `shutdown()` at the end: power stage off (confirmed by the drive), our heartbeat consumer in the
  drive switched off, NMT pre-operational. It pumps the bus itself.

Start-up (non-blocking, one SDO at a time): NMT pre-operational, controlword "disable voltage",
device type check, the drive's last error code, heartbeat producer (0x1017) and consumer of our
heartbeat (0x1016: the drive faults by itself if this process dies), current limits (0x6410),
position regulator gains (0x60FB), operating mode, the PDO layout below, NMT start.

PDOs (RPDOs event-driven so a command acts when it arrives; TPDOs on every SYNC):
  RPDO1 controlword, modes of operation, current mode setting value [mA]    (current and disabled)
  RPDO2 controlword, modes of operation, position mode setting value [qc]   (position)
  TPDO1 statusword, position actual value [qc], current actual value [mA]
  TPDO2 velocity actual value [rpm], modes of operation display, error code
Exactly one RPDO per SYNC period unless commands arrive faster.

Safety: the drive is enabled only while valid commands keep arriving (`command_timeout`; a stale
stream ends with the current setpoint zeroed and a quick stop in the same RPDO, then disable
voltage as soon as the drive reports QUICK STOP ACTIVE, `quick_stop_time` after the trip at the
latest), the drive's heartbeat is alive and the bus has
been free of errors for `bus_error_holdoff`. A fault is reset at start-up and after the command
stream acknowledged it with a disable command. Units: SI at this module's edges, drive units
(mA, qc, rpm) only in the frames.
"""

from __future__ import annotations

import logging
import math
import socket
import struct
import time
from dataclasses import dataclass, fields
from enum import Enum
from typing import Any, Callable, Mapping

import can

from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.epos2_objects import Command, NmtCommand, NmtState, OperationMode, State
from hopper_ros.canbus.master import (
    HeartbeatConsumer,
    MalformedFrame,
    PdoEntry,
    PdoMapping,
    SdoClient,
    SdoError,
    SdoTransfer,
    decode_emcy,
    heartbeat_frame,
    nmt_frame,
    nmt_state_name,
    sync_frame,
)
from hopper_ros.hardware.encoders import Encoder
from hopper_ros.hardware.motor import RPM_PER_RAD_S, HipMotor

# MotorCommand modes (the message's constants, repeated here to stay ROS-free)
MODE_DISABLED, MODE_CURRENT, MODE_POSITION, MODE_RAMP = 0, 1, 2, 3
MODE_NAMES = {MODE_DISABLED: "disabled", MODE_CURRENT: "current", MODE_POSITION: "position", MODE_RAMP: "ramp"}
RAMP_RESTAMP = 0.0005   # [s] a MODE_RAMP stamp moved by more than this re-anchors the running ramp (repeats of
                        #   one stamp differ by the command's transit jitter only)

# ------------------------------------------------------------------------------- PDO layout

_CW = PdoEntry(eo.CONTROLWORD, 0, 16, False, "controlword")
_MODE = PdoEntry(eo.MODES_OF_OPERATION, 0, 8, True, "modes_of_operation")
RPDO_MAPPINGS: dict[int, PdoMapping] = {
    1: PdoMapping.of([_CW, _MODE, PdoEntry(eo.CURRENT_MODE_SETTING_VALUE, 0, 16, True, "current_setting_mA")]),
    2: PdoMapping.of([_CW, _MODE, PdoEntry(eo.POSITION_MODE_SETTING_VALUE, 0, 32, True, "position_setting_qc")]),
}
TPDO_MAPPINGS: dict[int, PdoMapping] = {
    1: PdoMapping.of([PdoEntry(eo.STATUSWORD, 0, 16, False, "statusword"),
                      PdoEntry(eo.POSITION_ACTUAL_VALUE, 0, 32, True, "position_qc"),
                      PdoEntry(eo.CURRENT_ACTUAL_VALUE, 0, 16, True, "current_mA")]),
    2: PdoMapping.of([PdoEntry(eo.VELOCITY_ACTUAL_VALUE, 0, 32, True, "velocity_rpm"),
                      PdoEntry(eo.MODES_OF_OPERATION_DISPLAY, 0, 8, True, "modes_of_operation_display"),
                      PdoEntry(eo.ERROR_CODE, 0, 16, False, "error_code")]),
}
RPDO_TRANSMISSION = eo.TRANSMISSION_EVENT   # 255: applied on reception
TPDO_TRANSMISSION = 1                       # sent after every SYNC

# CiA 402 states with the power stage off: what "disabled" means for this driver
DISABLED_STATES = frozenset({State.START, State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED,
                             State.READY_TO_SWITCH_ON, State.FAULT})
FAULT_STATES = frozenset({State.FAULT, State.FAULT_REACTION_ACTIVE_DISABLED, State.FAULT_REACTION_ACTIVE_ENABLED})

COUNTER_NAMES = (
    "frames_sent", "frames_received", "sync_sent", "tpdo_received", "tpdo_missed",
    "commands_received", "commands_rejected", "current_clamped", "malformed_frames",
    "sdo_aborts", "sdo_timeouts", "bus_errors", "emcy_received", "faults", "fault_resets",
    "watchdog_stops", "heartbeat_losses", "drive_bootups", "startup_failures",
)

INFO, WARN, ERROR = 0, 1, 2   # event / health levels (DiagnosticStatus OK, WARN, ERROR)


class Phase(str, Enum):
    STARTING = "starting"       # start-up sequence (NMT, SDO configuration) in progress
    RUNNING = "running"         # operational: SYNC, PDOs, state machine
    FAILED = "failed"           # start-up failed; retried after settings.startup_retry
    SHUTTING_DOWN = "shutting_down"
    STOPPED = "stopped"


#: keys of the config section that are the node's, not the driver's
NODE_KEYS = frozenset({"hardware_file", "status_period", "status_decimation", "diagnostics_period"})


@dataclass(frozen=True)
class DriverSettings:
    """Timing and safety settings (config/motor_driver.yaml, section `motor_driver`)."""

    sync_period: float = 0.001          # [s] SYNC / PDO exchange period
    rpdo_refresh: float = 0.01          # [s] an unchanged RPDO is sent again this often (else every change)
    max_ramp_age: float = 0.005         # [s] MODE_RAMP: a ramp command older than this starts this far back
    command_timeout: float = 0.01       # [s] no valid command this long: current 0, quick stop, then disable
    quick_stop_time: float = 0.001      # [s] quick stop at most this long after the watchdog tripped, then
                                        #   disable voltage (at once when the drive reports QUICK STOP ACTIVE)
    heartbeat_timeout: float = 0.3      # [s] drive heartbeat missing this long: lost
    master_node_id: int = 0x7F          # our heartbeat's node id (COB-ID 0x700 + id)
    master_heartbeat_period: float = 0.02  # [s] our heartbeat; 0: none
    drive_consumer_time: float = 0.2    # [s] the drive faults if our heartbeat stops this long; 0: off
    sdo_timeout: float = 0.05           # [s]
    startup_retry: float = 0.2          # [s] wait before a failed start-up is retried
    bus_error_holdoff: float = 0.1      # [s] drive kept disabled after a bus error
    fault_reset_attempts: int = 3       # fault reset edges per acknowledgement
    fault_reset_interval: float = 0.02  # [s] between fault reset edges
    shutdown_timeout: float = 0.5       # [s] bound on shutdown()

    def __post_init__(self) -> None:
        from hopper_ros.config_schemas import MOTOR_DRIVER_SECTION
        from hopper_ros.schema import validate

        validate(MOTOR_DRIVER_SECTION, {f.name: getattr(self, f.name) for f in fields(self)}, "motor_driver")

    @classmethod
    def from_mapping(cls, section: Mapping[str, Any], source: str = "motor_driver", **overrides: Any) -> "DriverSettings":
        """Settings from a `motor_driver` section (validated by its schema) and overrides (node parameters)."""
        from hopper_ros.config_schemas import MOTOR_DRIVER_SECTION
        from hopper_ros.schema import validate

        merged = {**dict(section), **{k: v for k, v in overrides.items() if v is not None}}
        checked = validate(MOTOR_DRIVER_SECTION, merged, source)
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in checked.items() if k in known})


def load_section(name: str = "motor_driver.yaml") -> dict[str, Any]:
    """The `motor_driver` section of a config file (driver settings plus the NODE_KEYS), validated."""
    from hopper_ros.config_schemas import MOTOR_DRIVER
    from hopper_ros.schema import load_config

    return dict(load_config(name, MOTOR_DRIVER)["motor_driver"])


CONNECT_TIMEOUT = 30.0   # [s] for a socketcand server to accept (the simulated robot may start later)


def wait_for_server(host: str, port: int, timeout: float, cancelled: Callable[[], bool] = lambda: False) -> None:
    """Wait until a TCP server accepts on host:port (python-can's own retry spins a core for 10 s)."""
    end = time.monotonic() + timeout
    while not cancelled():
        try:
            socket.create_connection((host, port), timeout=1.0).close()
            return
        except OSError as exc:
            if time.monotonic() > end:
                raise OSError(f"no CAN server (socketcand) accepts on {host}:{port} after {timeout:.0f} s: {exc}") from None
            time.sleep(0.1)
    raise InterruptedError(f"stopped while waiting for the CAN server on {host}:{port}")


def open_bus(can_config: Mapping[str, Any], cancelled: Callable[[], bool] = lambda: False, **overrides: Any) -> can.BusABC:
    """A python-can bus from the `can:` section of hardware.yaml (values in `overrides` win).

    socketcan (robot: can0), socketcand (the simulated robot's loopback hub: host, port), virtual
    (one process). udp_multicast is refused: its packets leave the machine.
    """
    cfg = dict(can_config)
    cfg.update({k: v for k, v in overrides.items() if v not in (None, "", 0)})
    interface = str(cfg.get("interface", ""))
    channel = cfg.get("channel")
    if interface == "udp_multicast":
        raise ValueError("CAN interface udp_multicast is not allowed (it leaves loopback)")
    if interface == "socketcand":
        # python-can warns on every frame split across two TCP reads, a normal event: not ours to log
        logging.getLogger("can.interfaces.socketcand").setLevel(logging.ERROR)
        host, port = str(cfg["host"]), int(cfg["port"])
        wait_for_server(host, port, float(cfg.get("connect_timeout", CONNECT_TIMEOUT)), cancelled)
        return can.Bus(interface=interface, channel=channel, host=host, port=port, tcp_tune=True)
    if interface in ("socketcan", "virtual"):
        return can.Bus(interface=interface, channel=channel)
    if not interface:
        raise ValueError("CAN config lacks `interface`")
    return can.Bus(interface=interface, channel=channel, bitrate=int(cfg.get("bitrate", 1000000)))


@dataclass
class DriveStatus:
    """What the driver knows of the drive, SI units."""

    stamp: float = math.nan             # time of the TPDO it comes from
    state: State | None = None          # CiA 402 state (None: not known yet)
    statusword: int = 0
    operation_mode: int = 0             # modes of operation display (EPOS2: -3 current, -1 position)
    commanded_mode: int = MODE_DISABLED  # command being executed (MODE_*)
    position: float = math.nan          # leg angle [rad]
    velocity: float = math.nan          # leg angular velocity [rad/s]
    current: float = math.nan           # motor current [A]
    torque: float = math.nan            # hip torque [N m]
    fault_code: int = 0                 # last error code seen (EMCY / 0x603F), 0: none
    fault_text: str = ""
    heartbeat_ok: bool = False
    nmt_state: int | None = None

    @property
    def state_name(self) -> str:
        return "UNKNOWN" if self.state is None else self.state.value.replace("_", " ")


class MotorDriver:
    """CANopen master of one EPOS2 (see the module docstring). Not thread-safe: one caller at a time."""

    def __init__(self, bus: can.BusABC, hardware: Mapping[str, Any], settings: DriverSettings = DriverSettings(),
                 clock: Callable[[], float] = time.monotonic):
        self.bus = bus
        self.settings = settings
        self.clock = clock
        self.motor = HipMotor.from_config(hardware)
        try:
            drive = hardware["drive"]
            self.encoder = Encoder.from_config("motor", hardware["encoders"]["motor"])
            self.node_id = int(drive["node_id"])
            self.continuous_current = float(drive["continuous_current"])
            gains = drive["position_gains"]
            self.position_gains = (int(gains["p"]), int(gains["i"]), int(gains["d"]))
            self.heartbeat_period = float(drive["heartbeat_period"])
        except KeyError as exc:
            raise ValueError(f"hardware config lacks {exc.args[0]!r} (drive: / encoders.motor:)") from None
        self.current_limit = self.motor.current_limit
        if not 0 < self.continuous_current <= self.current_limit:
            raise ValueError("hardware config: drive.continuous_current must be in (0, current_limit]")
        if not 0 < self.heartbeat_period < settings.heartbeat_timeout:
            raise ValueError("drive.heartbeat_period must be positive and below the heartbeat timeout")
        eo.tpdo_cob_id(1, self.node_id)  # validates the node id
        if settings.master_node_id == self.node_id:
            raise ValueError(f"motor_driver: master_node_id {settings.master_node_id} is the drive's node id")
        self.counters = dict.fromkeys(COUNTER_NAMES, 0)
        self.events: list[tuple[int, str]] = []     # (level, text) for the caller's log; drained by it
        self._event_times: dict[str, float] = {}
        self.status = DriveStatus()
        self.phase = Phase.STARTING
        self.startup_error = ""
        self.waiting_for_drive = False              # start-up: the drive has not answered any SDO yet
        self._startup_answered = False
        self.sdo = SdoClient(self.node_id, self._send, settings.sdo_timeout)
        self.heartbeat = HeartbeatConsumer(self.node_id, settings.heartbeat_timeout)
        self._cob = {
            eo.tpdo_cob_id(1, self.node_id): self._on_tpdo1,
            eo.tpdo_cob_id(2, self.node_id): self._on_tpdo2,
            eo.sdo_tx_cob_id(self.node_id): self._on_sdo,
            eo.emcy_cob_id(self.node_id): self._on_emcy,
            eo.heartbeat_cob_id(self.node_id): self._on_heartbeat,
        }
        self._rpdo_cob = {n: eo.rpdo_cob_id(n, self.node_id) for n in RPDO_MAPPINGS}
        now = clock()
        # command and safety state
        self._mode = MODE_DISABLED          # last valid command's mode
        self._current_ma = 0                # its drive setpoints
        self._position_qc = 0
        self._last_command: float | None = None
        self._want_enabled = False
        self._quick_stop = False
        self._watchdog_at = -math.inf       # when the command watchdog last tripped
        self._bus_error_at: float | None = None
        self._reset_armed = True            # a fault found at start-up is reset
        self._reset_edges = 0
        self._reset_edge_at = -math.inf
        self._last_cw: int | None = None
        # cyclic exchange
        self._sent_since_sync: tuple[int, bytes] | None = None
        self._ramp: tuple[float, float, float, float] | None = None   # MODE_RAMP: (tau_0, duration, start, stamp)
        self._last_rpdo: tuple[int, bytes] | None = None   # the last RPDO sent and when
        self._last_rpdo_time = -math.inf
        self._tpdo_seen = 0                 # TPDOs received since the last SYNC (bit n-1: TPDO n)
        self._sync_outstanding = False
        self._next_master_heartbeat = now
        self._nmt_start_sent_at = -math.inf
        # start-up / shutdown sequence
        self._steps: list[tuple] = []
        self._retry_at = now
        self._shutdown_confirmed = False
        self._begin_startup(now)

    # ================================================================== public API

    def command(self, mode: int, setpoint: float, duration: float = 0.0, age: float = 0.0) -> bool:
        """Take one motor command; False (counted, ignored) if it is invalid.

        MODE_RAMP: the stance ramp of (2.32), hip torque -setpoint (1 - t/duration) for t in
        [0, duration) from `age` seconds ago (its stamp: the touchdown), then 0; a negative age is a
        ramp scheduled ahead (a predicted touchdown: zero current until then). The driver's own
        1 kHz cycle computes the current of every period, so jitter in the command stream does
        not stretch or shift the ramp; repeats of the same ramp keep its start, and the same ramp
        under a stamp more than RAMP_RESTAMP away (the measured touchdown) moves to that stamp.
        """
        now = self.clock()
        if mode == MODE_RAMP and not (math.isfinite(duration) and duration > 0.0 and math.isfinite(age)):
            mode = -1                                       # rejected below
        if mode not in MODE_NAMES or (mode != MODE_DISABLED and not math.isfinite(setpoint)):
            self.counters["commands_rejected"] += 1
            self._event(WARN, f"rejected motor command: mode {mode}, setpoint {setpoint!r}", key="rejected")
            return False
        self.counters["commands_received"] += 1
        self._last_command = now
        self._mode = mode
        if mode == MODE_DISABLED:
            self._want_enabled = False
            self._quick_stop = False
            if self.status.state in FAULT_STATES and not self._reset_armed:
                self._reset_armed, self._reset_edges = True, 0   # the command stream acknowledges the fault
        else:
            self._want_enabled, self._quick_stop = True, False
            if mode == MODE_CURRENT:
                self._current_ma = self._current_setting(setpoint)
            elif mode == MODE_RAMP:
                stamp = now - age                      # the command's stamp on this clock
                if self._ramp is None or self._ramp[:2] != (setpoint, duration):
                    # anchored at its stamp (the touchdown, or one predicted ahead: zero current until
                    # then), unless the command came late: a ramp skipped is energy lost
                    self._ramp = (setpoint, duration, max(stamp, now - self.settings.max_ramp_age), stamp)
                elif abs(stamp - self._ramp[3]) > RAMP_RESTAMP:
                    # the same ramp under a new stamp (the measured touchdown after a predicted one):
                    # the running ramp moves to it
                    self._ramp = (setpoint, duration, stamp, stamp)
                self._current_ma = self._current_setting(self._ramp_torque(now))
            else:
                self._position_qc = self._position_setting(setpoint)
            if mode != MODE_RAMP:
                self._ramp = None
        if self.phase is Phase.RUNNING:
            self._send_rpdo(now, force=True)
        return True

    def cycle(self) -> None:
        """One SYNC period: timeouts, start-up progress, controlword, RPDO, SYNC, heartbeat."""
        now = self.clock()
        self._produce_heartbeat(now)
        transfer = self.sdo.poll(now)
        if transfer is not None:
            self.counters["sdo_timeouts"] += 1
            self._sdo_done(transfer, now)
        if self.heartbeat.check(now):
            self.counters["heartbeat_losses"] += 1
            self.status.heartbeat_ok = False
            self._event(ERROR, f"drive heartbeat lost (none for {self.settings.heartbeat_timeout * 1e3:.0f} ms): "
                               "drive disabled")
        if self.phase is Phase.FAILED and now >= self._retry_at:
            self._begin_startup(now)
        if self.phase is Phase.STARTING:
            self._advance(now)
            return
        if self.phase is Phase.SHUTTING_DOWN:
            self._shutdown_cycle(now)
            return
        if self.phase is not Phase.RUNNING:
            return
        self._trip_watchdog(now)
        if self._sync_outstanding and self._tpdo_seen != (1 << len(TPDO_MAPPINGS)) - 1:
            self.counters["tpdo_missed"] += 1
        self._send_rpdo(now, force=False)
        self._sent_since_sync = None
        self._tpdo_seen = 0
        if self._send(sync_frame()):
            self.counters["sync_sent"] += 1
            self._sync_outstanding = True

    def watchdog_deadline(self) -> float:
        """When the command watchdog trips unless a valid command comes first (inf: not armed)."""
        if self.phase is Phase.RUNNING and self._want_enabled and self._last_command is not None:
            return self._last_command + self.settings.command_timeout
        return math.inf

    def watchdog(self) -> bool:
        """Trip the command watchdog now if it is due (the RPDO goes out at once); True if it tripped.

        `cycle()` checks it every SYNC period; a caller that waits between cycles calls this at
        `watchdog_deadline()` so the trip is not up to a period late."""
        now = self.clock()
        if self.phase is not Phase.RUNNING or not self._trip_watchdog(now):
            return False
        self._send_rpdo(now, force=True)
        return True

    def _trip_watchdog(self, now: float) -> bool:
        if not (self._want_enabled and now - self._last_command > self.settings.command_timeout):
            return False
        self._want_enabled, self._quick_stop = False, True
        self._watchdog_at = now
        self._current_ma, self._ramp = 0, None           # the current command zeroed at once
        self.counters["watchdog_stops"] += 1
        self._event(WARN, f"no motor command for {(now - self._last_command) * 1e3:.1f} ms: current zeroed, "
                          "quick stop, then disable")
        return True

    def handle(self, frame: can.Message) -> bool:
        """Take one received frame; True when it completed the TPDOs of a SYNC (new status)."""
        now = self.clock()
        self.counters["frames_received"] += 1
        if frame.is_error_frame:
            self._bus_error(now, "error frame received")
            return False
        if frame.is_extended_id or frame.is_remote_frame:
            return False
        handler = self._cob.get(frame.arbitration_id)
        if handler is None:
            return False
        try:
            return bool(handler(bytes(frame.data), now))
        except MalformedFrame as exc:
            self.counters["malformed_frames"] += 1
            self._event(WARN, f"malformed frame 0x{frame.arbitration_id:03X} [{bytes(frame.data).hex()}]: {exc}",
                        key="malformed")
            return False

    def shutdown(self, timeout: float | None = None) -> bool:
        """Bring the drive to a safe stop, pumping the bus; True if the drive confirmed it is disabled.

        Power stage off (controlword "disable voltage" by PDO while running, then by SDO), the
        statusword read back, the drive's consumer of our heartbeat switched off, NMT
        pre-operational (no more PDOs). Bounded by `timeout` (default settings.shutdown_timeout).
        """
        timeout = self.settings.shutdown_timeout if timeout is None else timeout
        self.begin_shutdown()
        deadline = self.clock() + timeout
        next_cycle = self.clock()
        while self.phase is not Phase.STOPPED:
            now = self.clock()
            if now >= deadline:
                break
            if now >= next_cycle:
                self.cycle()
                next_cycle += self.settings.sync_period
                continue
            try:
                frame = self.bus.recv(timeout=min(next_cycle, deadline) - now)
            except (can.CanError, OSError) as exc:
                self._bus_error(self.clock(), f"receive failed: {exc}")
                frame = None
            if frame is not None:
                self.handle(frame)
        if self.phase is not Phase.STOPPED:
            self.sdo.abort()
            self._send(self._rpdo_frame(1, Command.DISABLE_VOLTAGE))   # last word, even unconfirmed
            self._send(nmt_frame(NmtCommand.ENTER_PRE_OPERATIONAL, self.node_id))
            self.phase = Phase.STOPPED
            self._event(ERROR, "shutdown: the drive did not confirm it is disabled")
        return self._shutdown_confirmed

    def begin_shutdown(self) -> None:
        """Start the shutdown sequence; `cycle()` and `handle()` carry it out (see `shutdown`)."""
        if self.phase in (Phase.SHUTTING_DOWN, Phase.STOPPED):
            return
        was_running = self.phase is Phase.RUNNING
        self.sdo.abort()
        self._want_enabled, self._quick_stop = False, False
        self._shutdown_confirmed = False
        self.phase = Phase.SHUTTING_DOWN
        self._steps = [("pdo_disable", self.clock() + 0.05)] if was_running else []
        self._steps += [
            ("download", eo.CONTROLWORD, 0, "<H", int(Command.DISABLE_VOLTAGE)),
            ("upload", eo.STATUSWORD, 0, self._check_disabled),
        ]
        if self.settings.drive_consumer_time:
            self._steps.append(("download", eo.CONSUMER_HEARTBEAT_TIME, 1, "<I", 0))
        self._steps += [("nmt", NmtCommand.ENTER_PRE_OPERATIONAL), ("stopped",)]

    @property
    def shutdown_confirmed(self) -> bool:
        """The drive confirmed (statusword) that its power stage is off, during the shutdown."""
        return self._shutdown_confirmed

    @property
    def enabled(self) -> bool:
        return self.status.state is State.OPERATION_ENABLED

    def health(self) -> tuple[int, str]:
        """(level, message) of the driver's present condition: OK/WARN/ERROR and words."""
        now = self.clock()
        status = self.status
        if self.phase is Phase.FAILED:
            if self.waiting_for_drive:
                return WARN, f"waiting for drive {self.node_id} to answer"
            return ERROR, f"start-up failed: {self.startup_error}"
        if self.phase is Phase.STARTING:
            return WARN, "starting: configuring the drive"
        if self.phase in (Phase.SHUTTING_DOWN, Phase.STOPPED):
            return WARN, "shut down: drive disabled" if self._shutdown_confirmed else "shutting down"
        if not self.heartbeat.alive:
            return ERROR, "drive heartbeat lost: drive disabled"
        if status.state in FAULT_STATES:
            return ERROR, f"drive fault 0x{status.fault_code:04X}: {status.fault_text}"
        if self._bus_error_recent(now):
            return ERROR, "CAN bus error: drive disabled"
        if self._quick_stop or (self._last_command is not None and self._mode != MODE_DISABLED
                                and not self._want_enabled):
            return WARN, "command timeout: drive stopped"
        return INFO, ""

    # ================================================================== conversions

    def current_for_torque(self, torque: float) -> tuple[float, bool]:
        """Motor current [A] for a hip torque [N m], clamped to the current limit; (current, clamped)."""
        current = self.motor.current(torque)
        limit = self.current_limit
        if abs(current) > limit:
            return math.copysign(limit, current), True
        return current, False

    def _current_setting(self, torque: float) -> int:
        current, clamped = self.current_for_torque(torque)
        if clamped:
            self.counters["current_clamped"] += 1
        milliamps = round(current * 1000.0)
        limit_ma = int(self.current_limit * 1000.0)     # the limit holds after rounding too
        return max(-limit_ma, min(limit_ma, milliamps))

    def counts_for_angle(self, angle: float) -> int:
        """Motor encoder count [qc] at a leg angle [rad] (nearest count)."""
        encoder = self.encoder
        return encoder.offset_counts + round(encoder.direction * angle * encoder.counts_per_turn / (2.0 * math.pi))

    def _position_setting(self, angle: float) -> int:
        return max(-(1 << 31), min((1 << 31) - 1, self.counts_for_angle(angle)))

    def leg_rate_for_rpm(self, rpm: float) -> float:
        """Leg angular velocity [rad/s] for a motor speed [rpm] (inverse of HipMotor.motor_speed_rpm)."""
        return rpm / (self.motor.gear_ratio * RPM_PER_RAD_S * self.motor.direction)

    # ================================================================== frames in

    def _on_tpdo1(self, data: bytes, now: float) -> bool:
        statusword, position, current_ma = TPDO_MAPPINGS[1].decode(data)
        status = self.status
        state = eo.decode_statusword(statusword)
        if state != status.state:
            self._on_state_change(status.state, state, now)
        status.stamp, status.statusword, status.state = now, statusword, state
        status.position = self.encoder.angle(position)
        status.current = current_ma / 1000.0
        status.torque = self.motor.torque(status.current)
        status.commanded_mode = self._mode if (self._want_enabled and state is State.OPERATION_ENABLED) else MODE_DISABLED
        return self._tpdo_received(1)

    def _on_tpdo2(self, data: bytes, now: float) -> bool:
        rpm, mode, error_code = TPDO_MAPPINGS[2].decode(data)
        status = self.status
        status.velocity = self.leg_rate_for_rpm(rpm)
        status.operation_mode = mode
        if error_code and error_code != status.fault_code:
            self._set_fault(error_code)
        return self._tpdo_received(2)

    def _tpdo_received(self, number: int) -> bool:
        self.counters["tpdo_received"] += 1
        self._tpdo_seen |= 1 << (number - 1)
        if self._sync_outstanding and self._tpdo_seen == (1 << len(TPDO_MAPPINGS)) - 1:
            self._sync_outstanding = False
            return True
        return False

    def _on_sdo(self, data: bytes, now: float) -> bool:
        try:
            transfer = self.sdo.on_frame(data)
        except MalformedFrame as exc:
            if exc.transfer is not None:
                self._sdo_done(exc.transfer, now)
            raise
        if transfer is not None:
            self._sdo_done(transfer, now)
        return False

    def _on_emcy(self, data: bytes, now: float) -> bool:
        emergency = decode_emcy(data)
        self.counters["emcy_received"] += 1
        if emergency.is_reset:
            self._event(INFO, "drive EMCY: error reset")
        else:
            self._set_fault(emergency.code)
            self._event(ERROR, f"drive EMCY 0x{emergency.code:04X}: {emergency.text} "
                               f"(error register 0x{emergency.register:02X})")
        return False

    def _on_heartbeat(self, data: bytes, now: float) -> bool:
        was_alive = self.heartbeat.alive and self.heartbeat.last_seen is not None
        state = self.heartbeat.on_frame(data, now)
        self.status.nmt_state = state
        self.status.heartbeat_ok = True
        if not was_alive and self.heartbeat.last_seen is not None and self.counters["heartbeat_losses"]:
            self._event(INFO, f"drive heartbeat back ({nmt_state_name(state)})")
        if state == NmtState.BOOTUP:
            self.counters["drive_bootups"] += 1
            if self.phase in (Phase.RUNNING, Phase.FAILED):
                self._event(WARN, "drive rebooted: configuring it again")
                self._begin_startup(now)
        elif (self.phase is Phase.RUNNING and state != NmtState.OPERATIONAL
              and now - self._nmt_start_sent_at > self.heartbeat_period):
            self._event(WARN, f"drive in NMT {nmt_state_name(state)}: starting it again")
            self._nmt_start_sent_at = now
            self._send(nmt_frame(NmtCommand.START, self.node_id))
        return False

    def _set_fault(self, code: int) -> None:
        self.status.fault_code = code
        self.status.fault_text = eo.error_text(code)

    def _on_state_change(self, old: State | None, new: State, now: float) -> None:
        self._event(INFO, f"drive state {old.value if old else 'UNKNOWN'} -> {new.value}")
        if new in FAULT_STATES and old not in FAULT_STATES:
            self.counters["faults"] += 1
            self._reset_edges = 0
            if old is not None or not self._reset_armed:
                self._reset_armed = False    # a fault in operation waits for an acknowledgement
            if not self.status.fault_code:
                self._request_error_code()
            self._event(ERROR, "drive fault" + (f" 0x{self.status.fault_code:04X}: {self.status.fault_text}"
                                                if self.status.fault_code else "") + ": drive disabled")
        elif old in FAULT_STATES and new not in FAULT_STATES:
            self.counters["fault_resets"] += 1
            self._reset_armed, self._reset_edges = False, 0
            self._event(INFO, "drive fault reset")

    def _request_error_code(self) -> None:
        if self.phase is Phase.RUNNING and not self.sdo.busy:
            self.sdo.upload(eo.ERROR_CODE, 0, self.clock(), tag=("error_code",))

    # ================================================================== frames out

    def _send(self, frame: can.Message) -> bool:
        try:
            self.bus.send(frame, timeout=self.settings.sync_period)
        except (can.CanError, OSError) as exc:
            self._bus_error(self.clock(), f"send of 0x{frame.arbitration_id:03X} failed: {exc}")
            return False
        self.counters["frames_sent"] += 1
        return True

    def bus_error(self, text: str) -> None:
        """Report a bus failure the caller saw (e.g. receiving failed): counted, drive disabled."""
        self._bus_error(self.clock(), text)

    def _bus_error(self, now: float, text: str) -> None:
        self.counters["bus_errors"] += 1
        if not self._bus_error_recent(now):
            self._event(ERROR, f"CAN bus error: {text}: drive disabled")
        self._bus_error_at = now

    def _bus_error_recent(self, now: float) -> bool:
        return self._bus_error_at is not None and now - self._bus_error_at < self.settings.bus_error_holdoff

    def _produce_heartbeat(self, now: float) -> None:
        period = self.settings.master_heartbeat_period
        if period and self.phase is not Phase.STOPPED and now >= self._next_master_heartbeat:
            self._next_master_heartbeat = max(self._next_master_heartbeat + period, now)
            self._send(heartbeat_frame(self.settings.master_node_id))

    def _enable_allowed(self, now: float) -> bool:
        return (self.phase is Phase.RUNNING and self.heartbeat.alive and self.heartbeat.last_seen is not None
                and not self._bus_error_recent(now))

    def _controlword(self, now: float) -> int:
        """The controlword for this instant: CiA 402 transitions towards the target state."""
        state = self.status.state
        if state in FAULT_STATES:
            return self._fault_reset_word(now) if state is State.FAULT and self.phase is Phase.RUNNING \
                else Command.DISABLE_VOLTAGE
        if self._want_enabled and self._enable_allowed(now):
            if state in (State.START, State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED, None):
                return Command.SHUTDOWN
            if state is State.QUICK_STOP_ACTIVE:
                return Command.DISABLE_VOLTAGE          # to SWITCH ON DISABLED, then up again
            return Command.SWITCH_ON_AND_ENABLE         # READY, REFRESH, MEASURE INIT, SWITCHED ON, ENABLED
        if (self._quick_stop and self._enable_allowed(now) and state is State.OPERATION_ENABLED
                and now - self._watchdog_at < self.settings.quick_stop_time):
            return Command.QUICK_STOP                   # until the drive reports it, briefly
        return Command.DISABLE_VOLTAGE

    def _fault_reset_word(self, now: float) -> int:
        """Rising edges of bit 7, `fault_reset_interval` apart, while a reset is armed."""
        if not self._reset_armed:
            return Command.DISABLE_VOLTAGE
        if self._last_cw is not None and self._last_cw & Command.FAULT_RESET:
            if now - self._reset_edge_at < self.settings.fault_reset_interval:
                return Command.FAULT_RESET
            return Command.DISABLE_VOLTAGE
        if self._reset_edges >= self.settings.fault_reset_attempts:
            self._reset_armed = False
            self._event(ERROR, f"fault reset failed after {self._reset_edges} attempts: "
                               "command disable to try again", key="reset_failed")
            return Command.DISABLE_VOLTAGE
        return Command.FAULT_RESET

    def _ramp_torque(self, now: float) -> float:
        tau_0, duration, start, _ = self._ramp
        elapsed = now - start
        return -tau_0 * (1.0 - elapsed / duration) if 0.0 <= elapsed < duration else 0.0   # (2.32)

    def _rpdo_frame(self, number: int, controlword: int) -> can.Message:
        if number == 1:
            if self._mode == MODE_RAMP and self._ramp is not None:
                self._current_ma = self._current_setting(self._ramp_torque(self.clock()))
            setting = self._current_ma if (self._want_enabled and self._mode in (MODE_CURRENT, MODE_RAMP)) else 0
            values = (controlword, OperationMode.CURRENT, setting)
        else:
            values = (controlword, OperationMode.POSITION, self._position_qc)
        return can.Message(arbitration_id=self._rpdo_cob[number], data=RPDO_MAPPINGS[number].encode(values),
                           is_extended_id=False)

    def _send_rpdo(self, now: float, force: bool) -> None:
        controlword = int(self._controlword(now))
        number = 2 if self._mode == MODE_POSITION else 1
        frame = self._rpdo_frame(number, controlword)
        key = (number, bytes(frame.data))
        if not force and (self._sent_since_sync == key or (
                key == self._last_rpdo and now - self._last_rpdo_time < self.settings.rpdo_refresh)):
            return          # this period's RPDO is out already, or the drive has it (applied on reception)
        if self._send(frame):
            if controlword & Command.FAULT_RESET and not (self._last_cw or 0) & Command.FAULT_RESET:
                self._reset_edges += 1
                self._reset_edge_at = now
            self._last_cw = controlword
            self._sent_since_sync = key
            self._last_rpdo, self._last_rpdo_time = key, now

    # ================================================================== start-up and shutdown

    def _begin_startup(self, now: float) -> None:
        self.sdo.abort()
        self._startup_answered = False
        self.phase = Phase.STARTING
        self._sync_outstanding = False
        self._reset_armed, self._reset_edges = True, 0
        self.status.state = None
        ms = lambda seconds: max(1, round(seconds * 1000.0))  # noqa: E731
        steps: list[tuple] = [
            ("nmt", NmtCommand.ENTER_PRE_OPERATIONAL),
            ("download", eo.CONTROLWORD, 0, "<H", int(Command.DISABLE_VOLTAGE)),
            ("upload", eo.DEVICE_TYPE, 0, self._check_device_type),
            ("upload", eo.ERROR_CODE, 0, self._record_error_code),
            ("download", eo.PRODUCER_HEARTBEAT_TIME, 0, "<H", ms(self.heartbeat_period)),
            ("download", eo.CONSUMER_HEARTBEAT_TIME, 1, "<I",
             (self.settings.master_node_id << 16 | ms(self.settings.drive_consumer_time))
             if self.settings.drive_consumer_time else 0),
            ("download", eo.MOTOR_DATA, eo.MOTOR_CONTINUOUS_CURRENT_LIMIT_SUB, "<H", round(self.continuous_current * 1000)),
            ("download", eo.MOTOR_DATA, eo.MOTOR_OUTPUT_CURRENT_LIMIT_SUB, "<H", round(self.current_limit * 1000)),
        ]
        for sub, gain in zip((eo.GAIN_P_SUB, eo.GAIN_I_SUB, eo.GAIN_D_SUB), self.position_gains):
            steps.append(("download", eo.POSITION_CONTROL_PARAMETERS, sub, "<h", gain))
        steps.append(("download", eo.MODES_OF_OPERATION, 0, "<b", int(OperationMode.CURRENT)))
        for kind, comm, mapping_base, mappings, transmission in (
                ("rpdo", eo.RPDO_COMMUNICATION, eo.RPDO_MAPPING, RPDO_MAPPINGS, RPDO_TRANSMISSION),
                ("tpdo", eo.TPDO_COMMUNICATION, eo.TPDO_MAPPING, TPDO_MAPPINGS, TPDO_TRANSMISSION)):
            cob_of = eo.rpdo_cob_id if kind == "rpdo" else eo.tpdo_cob_id
            for number in range(1, eo.PDO_COUNT + 1):
                cob = cob_of(number, self.node_id)
                steps.append(("download", comm + number - 1, eo.PDO_COB_ID_SUB, "<I", cob | eo.COB_ID_INVALID_BIT))
                mapping = mappings.get(number)
                if mapping is None:
                    continue                       # unused: stays disabled
                steps.append(("download", comm + number - 1, eo.PDO_TRANSMISSION_TYPE_SUB, "<B", transmission))
                steps.append(("download", mapping_base + number - 1, 0, "<B", 0))
                for sub, entry in enumerate(mapping.entries, start=1):
                    steps.append(("download", mapping_base + number - 1, sub, "<I", entry.mapping))
                steps.append(("download", mapping_base + number - 1, 0, "<B", len(mapping.entries)))
                steps.append(("download", comm + number - 1, eo.PDO_COB_ID_SUB, "<I", cob))
        steps += [("nmt", NmtCommand.START), ("running",)]
        self._steps = steps

    def _advance(self, now: float) -> None:
        """Run the sequence's steps until one waits for the drive (an SDO in flight)."""
        while self._steps and not self.sdo.busy and self.phase in (Phase.STARTING, Phase.SHUTTING_DOWN):
            step = self._steps[0]
            kind = step[0]
            if kind == "pdo_disable":
                if self.status.state in DISABLED_STATES or now >= step[1] or not self.heartbeat.alive:
                    self._shutdown_confirmed = self.status.state in DISABLED_STATES
                    self._steps.pop(0)
                    continue
                return                              # cycle() keeps sending "disable voltage"
            self._steps.pop(0)
            if kind == "nmt":
                self._send(nmt_frame(step[1], self.node_id))
                if step[1] == NmtCommand.START:
                    self._nmt_start_sent_at = now
            elif kind == "download":
                _, index, sub, fmt, value = step
                self.sdo.download(index, sub, struct.pack(fmt, value), now, tag=step)
            elif kind == "upload":
                self.sdo.upload(step[1], step[2], now, tag=step)
            elif kind == "running":
                self.phase = Phase.RUNNING
                self.waiting_for_drive = False
                self.heartbeat.arm(now)
                self._event(INFO, f"drive {self.node_id} configured and started (NMT operational, "
                                  f"SYNC every {self.settings.sync_period * 1e3:g} ms)")
            elif kind == "stopped":
                self.phase = Phase.STOPPED
                self._event(INFO, "shutdown: drive disabled, NMT pre-operational" if self._shutdown_confirmed
                            else "shutdown: NMT pre-operational, drive state not confirmed")

    def _sdo_done(self, transfer: SdoTransfer, now: float) -> None:
        tag = transfer.tag
        if transfer.error is not None:
            if not transfer.error.timed_out:
                self.counters["sdo_aborts"] += 1
            if self.phase is Phase.STARTING:
                if transfer.error.timed_out and not self._startup_answered:
                    self._wait_for_drive(now)
                else:
                    self._startup_failed(now, str(transfer.error))
            elif self.phase is Phase.SHUTTING_DOWN:
                self._event(WARN, f"shutdown: {transfer.error}")
                self._advance(now)
            else:
                self._event(WARN, str(transfer.error))
            return
        if self.phase is Phase.STARTING:
            self._startup_answered = True
        if isinstance(tag, tuple) and tag and tag[0] == "error_code":
            self._record_error_code(transfer)
        elif isinstance(tag, tuple) and tag and tag[0] == "upload":
            try:
                tag[3](transfer)
            except (SdoError, ValueError) as exc:
                if self.phase is Phase.STARTING:
                    self._startup_failed(now, str(exc))
                    return
                self._event(WARN, str(exc))
        self._advance(now)

    def _wait_for_drive(self, now: float) -> None:
        """The drive does not answer at all (yet): not an error until it answers wrongly."""
        if not self.waiting_for_drive:
            self._event(WARN, f"drive {self.node_id} does not answer (yet): trying every "
                              f"{self.settings.startup_retry:g} s")
        self.waiting_for_drive = True
        self.phase = Phase.FAILED
        self._retry_at = now + self.settings.startup_retry
        self._steps = []

    def _startup_failed(self, now: float, reason: str) -> None:
        self.waiting_for_drive = False
        self.counters["startup_failures"] += 1
        repeated = reason == self.startup_error
        self.startup_error = reason
        self.phase = Phase.FAILED
        self._retry_at = now + self.settings.startup_retry
        self._steps = []
        if not repeated:
            self._event(ERROR, f"drive start-up failed: {reason}; retrying every {self.settings.startup_retry:g} s")

    def _check_device_type(self, transfer: SdoTransfer) -> None:
        device_type = transfer.value("<I")
        if device_type & 0xFFFF != eo.DEVICE_TYPE_VALUE & 0xFFFF:
            raise ValueError(f"node {self.node_id} is not a CiA 402 drive (device type 0x{device_type:08X})")

    def _record_error_code(self, transfer: SdoTransfer) -> None:
        code = transfer.value("<H")
        if code:
            self._set_fault(code)
            self._event(WARN, f"drive reports error 0x{code:04X}: {self.status.fault_text}")

    def _check_disabled(self, transfer: SdoTransfer) -> None:
        state = eo.decode_statusword(transfer.value("<H"))
        self._shutdown_confirmed = state in DISABLED_STATES
        self._event(INFO if self._shutdown_confirmed else ERROR, f"shutdown: drive state {state.value}")

    def _shutdown_cycle(self, now: float) -> None:
        if self._steps and self._steps[0][0] == "pdo_disable":
            self._send_rpdo(now, force=False)
            self._sent_since_sync = None
            if self._send(sync_frame()):
                self.counters["sync_sent"] += 1
        self._advance(now)

    def _event(self, level: int, text: str, key: str | None = None) -> None:
        """Queue a log line for the caller; with `key`, at most one a second of that kind."""
        if key is not None:
            now = self.clock()
            if now - self._event_times.get(key, -math.inf) < 1.0:
                return
            self._event_times[key] = now
        self.events.append((level, text))
        if len(self.events) > 1000:
            del self.events[:500]

    def drain_events(self) -> list[tuple[int, str]]:
        events, self.events = self.events, []
        return events


def load_hardware(name: str = "hardware.yaml") -> Mapping[str, Any]:
    """config/hardware.yaml (or a variant), validated by its schema (hopper_ros.config_schemas)."""
    from hopper_ros.config_schemas import load_hardware as load

    return load(name)
