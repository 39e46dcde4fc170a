"""Boom kinematics and encoder conversions of appendix A (Orhon 2018, A.1.1 lines 57-92).

Appendix A turns the microcontroller's counts into positions:

    azimuth   = counts * 2 pi / (6 * 4 * 2048)            [rad]   (line 59, in degrees there)
    elevation = counts * 2 pi / (6 * 4 * 2048)            [rad]   (line 63)
    z_floor   = parallel_height + boom_length sin(elevation)      (line 73)
    y         = (boom_length + leg_offset) azimuth                (line 80)
    leg angle = counts * 2 pi / (26 * 4 * 500)            [rad]   (line 88)

Here z is the model's height above the running surface: z = z_floor - ground_height (the thesis
"subtracts the height of the non-slip ground (2 cm)", section 4.1). Counters are the
microcontroller's 32-bit registers: they wrap, so `CounterUnwrapper` turns a stream of raw
values into a continuous count. Offsets (homing) and count directions come from
config/hardware.yaml. `forward` (positions -> counts) is the simulated robot's side, `inverse`
(counts -> positions) the encoder bridge's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

COUNTER_MODULUS = 1 << 32
_HALF = 1 << 31


def to_register(count: int) -> int:
    """A continuous count as the signed 32-bit counter register holds it (wraps)."""
    return ((int(count) + _HALF) % COUNTER_MODULUS) - _HALF


class CounterUnwrapper:
    """Continuous count from successive 32-bit register values (any step below 2^31 counts)."""

    def __init__(self) -> None:
        self._last: int | None = None
        self.count = 0
        self.wraps = 0

    def update(self, register: int) -> int:
        if self._last is None:
            self.count = register
        else:
            step = ((register - self._last + _HALF) % COUNTER_MODULUS) - _HALF
            if step != register - self._last:
                self.wraps += 1
            self.count += step
        self._last = register
        return self.count

    def reset(self) -> None:
        self.__init__()


@dataclass(frozen=True)
class Encoder:
    """One quadrature encoder: counts per turn of the measured axis, direction, offset."""

    name: str
    lines: int
    quadrature: int
    transmission: float
    direction: int
    offset_counts: int

    @property
    def counts_per_turn(self) -> float:
        """Counts per turn of the measured axis (boom or leg), after the belt or gear."""
        return self.lines * self.quadrature * self.transmission

    def angle(self, count: float) -> float:
        """Axis angle [rad] of a continuous count."""
        return self.direction * (count - self.offset_counts) * 2.0 * math.pi / self.counts_per_turn

    def count(self, angle: float) -> int:
        """The integer count an encoder shows at axis angle `angle` [rad] (quantised down)."""
        return self.offset_counts + math.floor(self.direction * angle * self.counts_per_turn / (2.0 * math.pi))

    @property
    def resolution(self) -> float:
        """One count in radians of the measured axis."""
        return 2.0 * math.pi / self.counts_per_turn


@dataclass(frozen=True)
class BoomPosition:
    """Positions from one sample of the three encoders."""

    boom_azimuth: float   # [rad]
    boom_elevation: float  # [rad]
    y: float              # forward position on the boom circle [m]
    z: float              # body height above the running surface [m]
    leg_angle: float      # [rad], positive toe ahead of the body


class HardwareSections(Protocol):
    """What `BoomKinematics.from_config` reads of a hardware configuration (`hardware.config.HardwareConfig`;
    named structurally, so that this module does not import the configuration that imports it)."""

    @property
    def boom(self) -> Any: ...

    @property
    def encoders(self) -> Any: ...


@dataclass(frozen=True)
class BoomKinematics:
    """Boom geometry and the three encoders of appendix A."""

    boom_length: float
    parallel_height: float
    leg_offset: float
    ground_height: float
    azimuth: Encoder
    elevation: Encoder
    motor: Encoder

    @classmethod
    def from_config(cls, hardware: HardwareSections) -> "BoomKinematics":
        boom, encoders = hardware.boom, hardware.encoders
        return cls(boom.length, boom.parallel_height, boom.leg_offset, boom.ground_height,
                   encoders.azimuth, encoders.elevation, encoders.motor)

    @property
    def forward_radius(self) -> float:
        """Radius of the circle the forward position is measured on, appendix A line 80."""
        return self.boom_length + self.leg_offset

    # positions -> counts (the simulated robot)
    def counts(self, y: float, z: float, leg_angle: float) -> tuple[int, int, int]:
        """Continuous (unwrapped) counts of azimuth, elevation and motor encoders."""
        sine = (z + self.ground_height - self.parallel_height) / self.boom_length
        if not -1.0 <= sine <= 1.0:
            raise ValueError(f"height {z} m is out of the boom's reach")
        return (self.azimuth.count(y / self.forward_radius), self.elevation.count(math.asin(sine)),
                self.motor.count(leg_angle))

    # counts -> positions (the encoder bridge)
    def position(self, azimuth_count: float, elevation_count: float, motor_count: float) -> BoomPosition:
        """Appendix A lines 57-92 on continuous counts, in SI units and model coordinates."""
        azimuth = self.azimuth.angle(azimuth_count)
        elevation = self.elevation.angle(elevation_count)
        return BoomPosition(
            boom_azimuth=azimuth, boom_elevation=elevation,
            y=self.forward_radius * azimuth,
            z=self.parallel_height + self.boom_length * math.sin(elevation) - self.ground_height,
            leg_angle=self.motor.angle(motor_count),
        )

    def position_resolution(self, z: float = 0.3) -> tuple[float, float]:
        """One count in y and in z [m] at height z: the quantisation the filters see."""
        elevation = math.asin((z + self.ground_height - self.parallel_height) / self.boom_length)
        return (self.forward_radius * self.azimuth.resolution,
                self.boom_length * math.cos(elevation) * self.elevation.resolution)
