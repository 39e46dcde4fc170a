"""The deadbeat controller on the simulated robot in lockstep, without ROS: fast closed-loop runs
for tests and benchmarks (hundreds of strides in seconds).

Each stride: the controller decides at the true apex, the simulated robot runs the stride with
those inputs through section 4.1's experiment (`sim.experiment.StrideExperiment`: the drive's
position regulator holds theta_td, the ramp starts at the true touchdown), and the next true
apex is fed back. Sensing and the CAN/ROS path are left out here; the node graph exercises them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.sim.experiment import StrideExperiment, drive_hold
from hopper_ros.sim.robot import SimRobot

from hopper_ros.control.deadbeat import DeadbeatController


@dataclass(frozen=True)
class StrideRecord:
    stride_index: int
    target_height: float
    target_speed: float
    apex_height: float       # the apex that ends this stride [m]
    forward_speed: float     # [m/s]
    tau_0: float
    touchdown_angle: float
    feasible: bool
    decision_time: float     # [s] stage 1 (the fast decision within the 1 ms loop)
    refine_time: float       # [s] stage 2 (the refinement during the flight)


def run_closed_loop(controller: DeadbeatController, sim_config, hardware: HardwareConfig,
                    setpoints: Iterable[tuple[float, float]], start: tuple[float, float] | None = None) -> list[StrideRecord]:
    """One stride per setpoint (height [m], speed [m/s]); stops early if the robot falls."""
    setpoints = list(setpoints)
    robot = SimRobot(sim_config, hardware)
    apex_height, forward_speed = start or setpoints[0]
    robot.throw(apex_height, forward_speed, controller.neutral_angle(forward_speed))
    controller.prime(*setpoints[0])
    records = []
    for index, (target_height, target_speed) in enumerate(setpoints):
        decision = controller.decide(apex_height, forward_speed, target_height, target_speed, index)
        experiment = StrideExperiment(decision.tau_0, decision.touchdown_angle, decision.ramp_duration,
                                      drive_hold(hardware), sim_config.pre_touchdown_height)
        robot.run_experiment(experiment)
        robot.run_until(lambda sample: experiment.done, 5.0)
        apex = experiment.next_apex
        if experiment.fell or apex is None:
            records.append(StrideRecord(index, target_height, target_speed, math.nan, math.nan, decision.tau_0,
                                        decision.touchdown_angle, decision.feasible, *_times(decision)))
            break
        apex_height, forward_speed = apex.z, apex.ydot
        controller.observe(apex_height, forward_speed)
        records.append(StrideRecord(index, target_height, target_speed, apex_height, forward_speed, decision.tau_0,
                                    decision.touchdown_angle, decision.feasible, *_times(decision)))
    return records


def _times(decision) -> tuple[float, float]:
    if math.isnan(decision.first_compute_time):        # not refined: stage 1 only
        return decision.compute_time, 0.0
    return decision.first_compute_time, decision.compute_time


@dataclass(frozen=True)
class SegmentSummary:
    target_height: float
    target_speed: float
    strides: int
    strides_to_settle: int | None       # first stride within tolerance, counted from the step (1 = the first)
    height_error_pct: float             # steady state: mean of the last `window` strides, relative
    speed_error_pct: float


def summarise(records: list[StrideRecord], window: int = 10, height_tolerance: float = 0.01,
              speed_tolerance: float = 0.05) -> list[SegmentSummary]:
    """Per setpoint segment: strides to settle (within 1 cm and 0.05 m/s) and the steady error."""
    segments: list[list[StrideRecord]] = []
    for record in records:
        if segments and (segments[-1][0].target_height, segments[-1][0].target_speed) == (
                record.target_height, record.target_speed):
            segments[-1].append(record)
        else:
            segments.append([record])
    summaries = []
    for segment in segments:
        height, speed = segment[0].target_height, segment[0].target_speed
        settled = next((i + 1 for i, r in enumerate(segment)
                        if abs(r.apex_height - height) <= height_tolerance and abs(r.forward_speed - speed) <= speed_tolerance
                        and all(abs(q.apex_height - height) <= height_tolerance and abs(q.forward_speed - speed) <= speed_tolerance
                                for q in segment[i:])), None)
        tail = segment[-window:]
        summaries.append(SegmentSummary(
            height, speed, len(segment), settled,
            100.0 * abs(sum(r.apex_height for r in tail) / len(tail) - height) / height,
            100.0 * abs(sum(r.forward_speed for r in tail) / len(tail) - speed) / speed))
    return summaries
