"""The EPOS2 Position Mode regulator: a PID from position error to motor current. No CAN, no ROS.

The EPOS2 runs its position loop at 1 kHz and feeds the current loop directly with the PID's
output (Position Mode, operating mode -1). maxon publishes the gains of object 0x60FB (P, I,
D) as plain integers without their scaling, and we found no public source giving it. This
module therefore uses one documented interpretation, a fixed-point PID per 1 ms sample:

    i [mA] = P * e / 4  +  I * sum(e) / 1024  -  D * (q[k] - q[k-1])

with e = setpoint - position [qc] and the sum over the samples since the last reset. In SI:
Kp = P / 4 [mA/qc], Ki = I / (1024 Ts) [mA/(qc s)], Kd = D Ts [mA s/qc]. The derivative acts
on the measured position (no derivative kick on setpoint steps), the integral stops while the
output saturates towards the error's sign (anti-windup) and its share is bounded by the
current limit. With the thesis's auto-tuned gains (P 537, I 2179, D 705) and the leg plus
reflected rotor inertia (about 7.7e-3 kg m^2 at the leg) this gives closed-loop poles near
-227 +/- 174j and -17 rad/s: a 10 degree leg step settles (2 %) in about 33 ms with about 9 %
overshoot (current-limited), and a constant load torque is integrated away (test:
test/test_canbus_epos2.py). See docs/canopen.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hopper_ros.hardware.config import HardwareConfig

#: EPOS2 position loop period [s] (the regulator's sample time)
POSITION_LOOP_PERIOD = 1.0e-3
#: Our interpretation of the 0x60FB gain scaling (see the module docstring)
P_GAIN_DIVISOR = 4.0        # P [1] -> mA per qc of error
I_GAIN_DIVISOR = 1024.0     # I [1] -> mA per qc of error summed over 1 ms samples
D_GAIN_FACTOR = 1.0         # D [1] -> mA per qc of position change per 1 ms sample

_MILLIAMPERE = 1.0e-3       # [A/mA]


@dataclass(frozen=True)
class PositionGains:
    """Position regulator gains in EPOS2 units (object 0x60FB sub 1..3)."""

    p: int
    i: int
    d: int

    def si(self, sample_period: float = POSITION_LOOP_PERIOD) -> tuple[float, float, float]:
        """(Kp [A/qc], Ki [A/(qc s)], Kd [A s/qc]) under this module's interpretation."""
        kp = self.p / P_GAIN_DIVISOR * _MILLIAMPERE
        ki = self.i / (I_GAIN_DIVISOR * sample_period) * _MILLIAMPERE
        kd = self.d * D_GAIN_FACTOR * sample_period * _MILLIAMPERE
        return kp, ki, kd


class PositionRegulator:
    """EPOS2-like Position Mode PID, one `update` per position-loop sample (1 ms)."""

    def __init__(self, gains: PositionGains, current_limit: float, counts_per_radian: float | None = None):
        self.gains = gains
        self.current_limit = float(current_limit)   # [A] output current limit (0x6410 sub 2)
        self.counts_per_radian = counts_per_radian  # [qc/rad] at the leg, for `current()`
        self.reset()

    @classmethod
    def from_hardware(cls, hardware: HardwareConfig) -> "PositionRegulator":
        """Build from config/hardware.yaml (drive.position_gains, drive.current_limit,
        encoders.motor for the leg-angle conversion of `current()`)."""
        drive, enc = hardware.drive, hardware.encoders.motor
        g = drive.position_gains
        cpr = float(enc.lines) * float(enc.quadrature) * enc.transmission / (2.0 * math.pi)
        return cls(PositionGains(g.p, g.i, g.d), drive.current_limit, counts_per_radian=cpr * enc.direction)

    def reset(self, position_qc: int | None = None) -> None:
        """Forget the integral and the previous position (on enable, mode change, fault)."""
        self._error_sum = 0.0                      # [qc * samples]
        self._previous_position = None if position_qc is None else int(position_qc)
        self.output = 0.0                          # [A] last demand

    @property
    def error_sum(self) -> float:
        return self._error_sum

    def update(self, setpoint_qc: int, position_qc: int) -> float:
        """One sample: the current demand [A], clipped to +/- current_limit."""
        g = self.gains
        error = int(setpoint_qc) - int(position_qc)
        previous = position_qc if self._previous_position is None else self._previous_position
        self._previous_position = int(position_qc)
        limit_ma = self.current_limit / _MILLIAMPERE
        p_term = g.p * error / P_GAIN_DIVISOR
        d_term = -g.d * D_GAIN_FACTOR * (int(position_qc) - previous)
        candidate_sum = self._error_sum + error
        i_term = g.i * candidate_sum / I_GAIN_DIVISOR
        unclipped = p_term + i_term + d_term
        saturated_with_error = abs(unclipped) > limit_ma and (unclipped > 0) == (error > 0)
        if not saturated_with_error and g.i != 0:
            # integrate; bound the integral's own share by the current limit
            bound = limit_ma * I_GAIN_DIVISOR / abs(g.i)
            self._error_sum = max(-bound, min(bound, candidate_sum))
        i_term = g.i * self._error_sum / I_GAIN_DIVISOR
        demand_ma = max(-limit_ma, min(limit_ma, p_term + i_term + d_term))
        self.output = demand_ma * _MILLIAMPERE
        return self.output

    def current(self, setpoint_angle: float, leg_angle: float, leg_rate: float | None = None,
                period: float | None = None, motor=None) -> float:
        """One sample in leg angles [rad] (for a simulation without CAN): the demand [A].

        The drive differentiates its own encoder, so `leg_rate`, `period` and `motor` are not
        used; call once per position-loop period (1 ms). Counts are truncated like an encoder's.
        """
        if self.counts_per_radian is None:
            raise ValueError("counts_per_radian unknown: build the regulator with from_hardware()")
        setpoint = round(setpoint_angle * self.counts_per_radian)
        position = math.floor(leg_angle * self.counts_per_radian)
        return self.update(setpoint, position)
