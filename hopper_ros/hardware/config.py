"""config/hardware.yaml as one frozen, typed object, `HardwareConfig`. No ROS import.

`load_hardware(name)` is the one place the file is read: checked by its schema
(`hopper_ros.config.schemas.HARDWARE`: types, ranges with units, unknown keys refused; a bad
file is one `ConfigError` line naming the file, the key and what is wrong), then built into the
dataclasses below. Field names are the file's keys; values are SI (m, s, A, N m, kg m^2) unless
a name says otherwise (counts, lines, the drive's own gain units).
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, replace
from typing import Any, Mapping

from hopper_ros.hardware.encoders import Encoder


@dataclass(frozen=True)
class Boom:
    """The planarizer's geometry (appendix A)."""

    length: float            # [m] pivot to body
    parallel_height: float   # [m] body height above the floor at zero elevation
    leg_offset: float        # [m] forward position is measured at length + leg_offset
    ground_height: float     # [m] the running surface above the floor


@dataclass(frozen=True)
class Encoders:
    """The three quadrature encoders (`Encoder`: lines, quadrature, transmission, direction, offset)."""

    azimuth: Encoder         # planarizer, forward
    elevation: Encoder       # planarizer, vertical
    motor: Encoder           # hip motor, before the gear


@dataclass(frozen=True)
class Motor:
    """The hip motor and its gear."""

    gear_ratio: float        # motor turns per leg turn
    torque_constant: float   # [N m/A] at the motor shaft
    direction: int           # +1: positive current increases the leg angle
    rotor_inertia: float     # [kg m^2] at the motor shaft
    leg_inertia: float       # [kg m^2] leg and toe about the hip
    viscous_friction: float  # [N m s/rad] at the motor shaft


@dataclass(frozen=True)
class DriveGains:
    """The EPOS2 position regulator's gains in the drive's own units (object 0x60FB sub 1..3)."""

    p: int
    i: int
    d: int


@dataclass(frozen=True)
class Drive:
    """The EPOS2 on CAN."""

    node_id: int
    current_limit: float       # [A] output current limit (peak)
    continuous_current: float  # [A]
    position_gains: DriveGains
    heartbeat_period: float    # [s] the drive's heartbeat producer time


@dataclass(frozen=True)
class Microcontroller:
    """Where the encoder packets go and how often."""

    host: str
    port: int
    sample_period: float     # [s]


@dataclass(frozen=True)
class CanBus:
    """How the nodes reach the drive: python-can's bus arguments (None: not given)."""

    interface: str
    channel: str | None = None
    host: str | None = None
    port: int | None = None
    bitrate: int | None = None          # [bit/s]
    connect_timeout: float | None = None  # [s]

    def given(self) -> dict[str, Any]:
        """The arguments the file gives, by python-can's names."""
        return {key: value for key, value in asdict(self).items() if value is not None}


@dataclass(frozen=True)
class HardwareConfig:
    """config/hardware.yaml (or a variant): boom, encoders, hip motor, drive, microcontroller, CAN bus."""

    boom: Boom
    encoders: Encoders
    motor: Motor
    drive: Drive
    microcontroller: Microcontroller
    can: CanBus

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> "HardwareConfig":
        """Built from values the HARDWARE schema has checked and converted (`validate`)."""
        drive = dict(values["drive"], position_gains=DriveGains(**values["drive"]["position_gains"]))
        return cls(Boom(**values["boom"]),
                   Encoders(**{name: Encoder(name, **section) for name, section in values["encoders"].items()}),
                   Motor(**values["motor"]), Drive(**drive), Microcontroller(**values["microcontroller"]),
                   CanBus(**values["can"]))

    def with_offsets(self, **offset_counts: int) -> "HardwareConfig":
        """The same hardware with encoders homed elsewhere: `offset_counts` by encoder name."""
        homed = {name: replace(getattr(self.encoders, name), offset_counts=int(count))
                 for name, count in offset_counts.items()}
        return replace(self, encoders=replace(self.encoders, **homed))


def load_hardware(name: str | os.PathLike = "hardware.yaml") -> HardwareConfig:
    """config/hardware.yaml (a config/ name or a path; `base:` variants merged), checked and typed."""
    from hopper_ros.config.schemas import HARDWARE
    from hopper_ros.config.schema import load_config

    return HardwareConfig.from_values(load_config(name, HARDWARE))
