"""Our messages <-> the sensing modules' dataclasses (hopper_ros.sensing), for the three sensing
nodes (and their tests). Stamps are host time in seconds on the module side and
builtin_interfaces/Time on the message side (nodes/stamps.py).
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from hopper_ros.msg import ApexState, BodyMeasurement, BodyState, EncoderSample, GaitEvent
from hopper_ros.nodes.stamps import to_seconds, to_stamp
from hopper_ros.sensing.bridge import BridgeSample
from hopper_ros.sensing.samples import DetectedEvent, Estimate, Measurement


def sample_qos(depth: int) -> QoSProfile:
    """QoS of the 1 kHz sample topics: reliable, the last `depth` samples (config: queue_depth)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE)


# ---------------------------------------------------------------------- encoder bridge
def fill_encoder_sample(msg: EncoderSample, sample: BridgeSample) -> EncoderSample:
    packet = sample.packet
    to_stamp(sample.receive_time, msg.header.stamp)
    msg.header.frame_id = "boom"
    msg.format_version = packet.version
    msg.sequence = packet.sequence
    msg.mcu_time_us = packet.mcu_time_us
    msg.azimuth_counts = packet.azimuth_counts
    msg.elevation_counts = packet.elevation_counts
    msg.motor_counts = packet.motor_counts
    msg.motor_current = sample.motor_current
    return msg


def fill_body_measurement(msg: BodyMeasurement, sample: BridgeSample) -> BodyMeasurement:
    position = sample.position
    to_stamp(sample.receive_time, msg.header.stamp)
    msg.header.frame_id = "ground"
    msg.sequence = sample.packet.sequence
    msg.mcu_time = sample.mcu_time
    msg.boom_azimuth = position.boom_azimuth
    msg.boom_elevation = position.boom_elevation
    msg.y, msg.z, msg.leg_angle = position.y, position.z, position.leg_angle
    msg.motor_current = sample.motor_current
    msg.hip_torque = sample.hip_torque
    return msg


def measurement_from_msg(msg: BodyMeasurement) -> Measurement:
    return Measurement(msg.sequence, msg.mcu_time, to_seconds(msg.header.stamp), msg.y, msg.z, msg.leg_angle)


# ---------------------------------------------------------------------- state estimator
def fill_body_state(msg: BodyState, estimate: Estimate) -> BodyState:
    to_stamp(estimate.stamp, msg.header.stamp)
    msg.header.frame_id = "ground"
    msg.sequence = estimate.sequence
    msg.mcu_time = estimate.mcu_time
    msg.y, msg.z, msg.y_dot, msg.z_dot = estimate.y, estimate.z, estimate.y_dot, estimate.z_dot
    msg.y_ddot, msg.z_ddot = estimate.y_ddot, estimate.z_ddot
    msg.leg_angle, msg.leg_angle_rate = estimate.leg_angle, estimate.leg_angle_rate
    msg.covariance_diagonal = list(estimate.variances)
    msg.measurement_used = estimate.measurement_used
    msg.outlier_rejected = estimate.outlier_rejected
    return msg


def estimate_from_msg(msg: BodyState) -> Estimate:
    """The estimate a BodyState carries; a state without its robot time (mcu_time 0) gets the stamp."""
    stamp = to_seconds(msg.header.stamp)
    return Estimate(msg.sequence, msg.mcu_time or stamp, stamp, msg.y, msg.z, msg.y_dot, msg.z_dot, msg.y_ddot, msg.z_ddot,
                    msg.leg_angle, msg.leg_angle_rate, tuple(msg.covariance_diagonal), msg.measurement_used,
                    msg.outlier_rejected)


# ---------------------------------------------------------------------- event detector
def gait_event_msg(event: DetectedEvent, detection_delay: float) -> GaitEvent:
    msg = GaitEvent()
    to_stamp(event.time, msg.header.stamp)
    msg.header.frame_id = "ground"
    msg.type = int(event.kind)
    msg.stride_index = event.stride_index
    msg.detection_delay = detection_delay
    fill_body_state(msg.state, event.state)
    return msg


def apex_state_msg(event: DetectedEvent) -> ApexState:
    msg = ApexState()
    to_stamp(event.time, msg.header.stamp)
    msg.header.frame_id = "ground"
    msg.stride_index = event.stride_index
    msg.apex_height = event.state.z
    msg.forward_speed = event.state.y_dot
    msg.y = event.state.y
    msg.leg_angle = event.state.leg_angle
    return msg


# ---------------------------------------------------------------------- diagnostics
class CounterDeltas:
    """Counter changes since the last report, for per-period rates and "new problem" levels."""

    def __init__(self) -> None:
        self._last: dict[str, int] = {}
        self._time: float | None = None

    def update(self, counters: Mapping[str, int], now: float) -> tuple[dict[str, int], float]:
        """(changes per counter, seconds since the last call; NaN the first time)."""
        deltas = {name: value - self._last.get(name, 0) for name, value in counters.items()}
        elapsed = now - self._time if self._time is not None else math.nan
        self._last, self._time = dict(counters), now
        return deltas, elapsed


def any_of(deltas: Mapping[str, int], names: Sequence[str]) -> bool:
    return any(deltas.get(name, 0) for name in names)
