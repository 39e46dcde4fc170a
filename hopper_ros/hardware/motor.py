"""Hip motor conversions: leg torque <-> motor current, leg angle <-> motor counts and speed.

    hip torque = direction * torque_constant * gear_ratio * current        [N m]

with the torque constant read as section 4.1's "396" speed constant (see config/hardware.yaml).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hopper_ros.hardware.config import HardwareConfig

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


@dataclass(frozen=True)
class HipMotor:
    gear_ratio: float
    torque_constant: float      # [N m/A] at the motor shaft
    direction: int
    current_limit: float        # [A] the drive's output current limit
    rotor_inertia: float        # [kg m^2] at the motor shaft
    leg_inertia: float          # [kg m^2] about the hip
    viscous_friction: float     # [N m s/rad] at the motor shaft

    @classmethod
    def from_config(cls, hardware: "HardwareConfig") -> "HipMotor":
        motor = hardware.motor
        return cls(motor.gear_ratio, motor.torque_constant, motor.direction, hardware.drive.current_limit,
                   motor.rotor_inertia, motor.leg_inertia, motor.viscous_friction)

    @property
    def torque_per_amp(self) -> float:
        """Hip torque per ampere of motor current, with the direction [N m/A]."""
        return self.direction * self.torque_constant * self.gear_ratio

    def torque(self, current: float) -> float:
        return current * self.torque_per_amp

    def current(self, torque: float) -> float:
        return torque / self.torque_per_amp

    @property
    def torque_limit(self) -> float:
        """Largest hip torque the drive's current limit allows [N m]."""
        return self.current_limit * abs(self.torque_per_amp)

    @property
    def leg_inertia_total(self) -> float:
        """Leg plus rotor reflected through the gear, about the hip [kg m^2]."""
        return self.leg_inertia + self.rotor_inertia * self.gear_ratio ** 2

    @property
    def leg_friction(self) -> float:
        """Motor viscous friction reflected to the hip [N m s/rad]."""
        return self.viscous_friction * self.gear_ratio ** 2

    def motor_speed_rpm(self, leg_rate: float) -> float:
        return leg_rate * self.gear_ratio * RPM_PER_RAD_S * self.direction
