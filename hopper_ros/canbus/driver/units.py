"""SI at the driver's edges, drive units (mA, qc, rpm) only in the frames: the conversions."""

from __future__ import annotations

import math

from hopper_ros.hardware.motor import RPM_PER_RAD_S

from .settings import DriveConfig


class DriveUnits:
    """Hip torque <-> motor current, leg angle <-> motor encoder counts, motor rpm -> leg rate."""

    def __init__(self, drive: DriveConfig):
        self.motor, self.encoder = drive.motor, drive.encoder
        self.current_limit = drive.current_limit

    def current_for_torque(self, torque: float) -> tuple[float, bool]:
        """Motor current [A] for a hip torque [N m], clamped to the current limit; (current, clamped)."""
        current = self.motor.current(torque)
        limit = self.current_limit
        if abs(current) > limit:
            return math.copysign(limit, current), True
        return current, False

    def current_setting(self, torque: float) -> tuple[int, bool]:
        """The current mode setting value [mA] for a hip torque; (setting, clamped)."""
        current, clamped = self.current_for_torque(torque)
        milliamps = round(current * 1000.0)
        limit_ma = int(self.current_limit * 1000.0)     # the limit holds after rounding too
        return max(-limit_ma, min(limit_ma, milliamps)), clamped

    def counts_for_angle(self, angle: float) -> int:
        """Motor encoder count [qc] at a leg angle [rad] (nearest count)."""
        encoder = self.encoder
        return encoder.offset_counts + round(encoder.direction * angle * encoder.counts_per_turn / (2.0 * math.pi))

    def position_setting(self, angle: float) -> int:
        """The position mode setting value [qc] for a leg angle, within the int32 range."""
        return max(-(1 << 31), min((1 << 31) - 1, self.counts_for_angle(angle)))

    def leg_rate_for_rpm(self, rpm: float) -> float:
        """Leg angular velocity [rad/s] for a motor speed [rpm] (inverse of HipMotor.motor_speed_rpm)."""
        return rpm / (self.motor.gear_ratio * RPM_PER_RAD_S * self.motor.direction)

    def angle(self, counts: int) -> float:
        """Leg angle [rad] at a motor encoder count."""
        return self.encoder.angle(counts)

    def torque(self, current: float) -> float:
        """Hip torque [N m] of a motor current [A]."""
        return self.motor.torque(current)
