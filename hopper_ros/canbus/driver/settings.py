"""The motor driver's settings (config/motor_driver.yaml, section `motor_driver`), the drive as
hardware.yaml describes it (`DriveConfig`), the command modes, counters and event levels."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Mapping

from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.hardware.encoders import Encoder
from hopper_ros.hardware.motor import HipMotor

# MotorCommand modes (the message's constants, repeated here to stay ROS-free)
MODE_DISABLED, MODE_CURRENT, MODE_POSITION, MODE_RAMP = 0, 1, 2, 3
MODE_NAMES = {MODE_DISABLED: "disabled", MODE_CURRENT: "current", MODE_POSITION: "position", MODE_RAMP: "ramp"}

COUNTER_NAMES = (
    "frames_sent", "frames_received", "sync_sent", "tpdo_received", "tpdo_missed",
    "commands_received", "commands_rejected", "current_clamped", "malformed_frames",
    "sdo_aborts", "sdo_timeouts", "bus_errors", "emcy_received", "faults", "fault_resets",
    "watchdog_stops", "heartbeat_losses", "drive_bootups", "startup_failures", "ramp_held_syncs",
    "ramps_begun_late",
)

INFO, WARN, ERROR = 0, 1, 2   # event / health levels (DiagnosticStatus OK, WARN, ERROR)

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
        from hopper_ros.config.schemas import MOTOR_DRIVER_SECTION
        from hopper_ros.config.schema import validate

        validate(MOTOR_DRIVER_SECTION, {f.name: getattr(self, f.name) for f in fields(self)}, "motor_driver")

    @classmethod
    def from_mapping(cls, section: Mapping[str, Any], source: str = "motor_driver", **overrides: Any) -> "DriverSettings":
        """Settings from a `motor_driver` section (validated by its schema) and overrides (node parameters)."""
        from hopper_ros.config.schemas import MOTOR_DRIVER_SECTION
        from hopper_ros.config.schema import validate

        merged = {**dict(section), **{k: v for k, v in overrides.items() if v is not None}}
        checked = validate(MOTOR_DRIVER_SECTION, merged, source)
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in checked.items() if k in known})


@dataclass(frozen=True)
class MotorDriverConfig:
    """config/motor_driver.yaml: the driver's settings and the node's own keys (NODE_KEYS)."""

    driver: DriverSettings
    hardware_file: str = "hardware.yaml"
    status_period: float = 0.1          # [s] motor_status at most this often while the drive is not enabled
    status_decimation: int = 1          # motor_status on every Nth TPDO set
    diagnostics_period: float = 0.5     # [s]


def load_motor_driver(name: str = "motor_driver.yaml") -> MotorDriverConfig:
    """The `motor_driver` section of a config file (config/ name or path), checked and typed."""
    from hopper_ros.config.schemas import MOTOR_DRIVER
    from hopper_ros.config.schema import load_config

    section = load_config(name, MOTOR_DRIVER)["motor_driver"]
    node = {key: section[key] for key in NODE_KEYS if key in section}
    return MotorDriverConfig(DriverSettings.from_mapping(section), **node)


@dataclass(frozen=True)
class DriveConfig:
    """The drive as hardware.yaml describes it (sections `drive`, `motor`, `encoders.motor`)."""

    node_id: int
    continuous_current: float           # [A]
    position_gains: tuple[int, int, int]  # P, I, D of the EPOS2 position regulator
    heartbeat_period: float             # [s] the drive's heartbeat
    motor: HipMotor
    encoder: Encoder

    @property
    def current_limit(self) -> float:
        return self.motor.current_limit

    @classmethod
    def from_hardware(cls, hardware: HardwareConfig) -> "DriveConfig":
        """The drive's part of config/hardware.yaml (checked there: continuous_current <= current_limit)."""
        drive = hardware.drive
        gains = drive.position_gains
        return cls(drive.node_id, drive.continuous_current, (gains.p, gains.i, gains.d), drive.heartbeat_period,
                   HipMotor.from_config(hardware), hardware.encoders.motor)
