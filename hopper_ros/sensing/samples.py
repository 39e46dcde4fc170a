"""The data the sensing modules pass on, as plain dataclasses (no ROS).

`Measurement` is what the encoder bridge makes of one packet and the state estimator consumes
(BodyMeasurement on the topic); `Estimate` what the estimator makes of it and the event detector
consumes (BodyState); `DetectedEvent` a gait event (GaitEvent, and ApexState for apexes).
Times: `mcu_time` is the microcontroller's clock [s], `stamp` and `receive_time` the host's [s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum


@dataclass(frozen=True)
class Measurement:
    """Positions converted from one accepted packet (appendix A), no filtering."""

    sequence: int
    mcu_time: float       # [s] microcontroller clock at sampling
    receive_time: float   # [s] host clock when the packet arrived
    y: float              # [m] forward, on the boom circle
    z: float              # [m] body height above the running surface
    leg_angle: float      # [rad]


# covariance_diagonal order of BodyState: y, z, y', z', y'', z'', leg angle, leg rate
VARIANCE_NAMES = ("y", "z", "y_dot", "z_dot", "y_ddot", "z_ddot", "leg_angle", "leg_angle_rate")


@dataclass(frozen=True)
class Estimate:
    """The estimated body state after one sample (BodyState)."""

    sequence: int           # microcontroller sequence number of the last sample used
    mcu_time: float         # [s] microcontroller time the state refers to
    stamp: float            # [s] the same instant on the host clock
    y: float
    z: float
    y_dot: float
    z_dot: float
    y_ddot: float
    z_ddot: float
    leg_angle: float
    leg_angle_rate: float
    variances: tuple[float, ...]   # 8 values, VARIANCE_NAMES order
    measurement_used: bool = True  # False: pure prediction (sample dropped or rejected)
    outlier_rejected: bool = False  # the sample's innovation failed the gate

    @property
    def z_dot_std(self) -> float:
        return math.sqrt(self.variances[3])


class EventType(IntEnum):
    """GaitEvent's constants."""

    APEX = 0
    PRE_TOUCHDOWN = 1
    TOUCHDOWN = 2
    BOTTOM = 3
    LIFTOFF = 4


@dataclass(frozen=True)
class DetectedEvent:
    """A gait event: its own time (interpolated between samples) and the state there."""

    kind: EventType
    time: float             # [s] host clock (the estimates' stamp clock) of the event itself
    stride_index: int       # the stride it belongs to; an apex opens the stride it carries
    state: Estimate         # estimated state at the event (interpolated); sequence: the detecting sample
    detected_at: float      # [s] stamp of the estimate on which it was detected

    @property
    def detection_lag(self) -> float:
        """Time from the event to the sample that revealed it [s] (negative: predicted ahead)."""
        return self.detected_at - self.time
