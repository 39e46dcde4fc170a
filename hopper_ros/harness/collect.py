"""Section 4.1's data collection on the simulated robot, in lockstep and in-process (no ROS
graph), recorded as a bag holding what a live recording of the robot holds:

    per 1 kHz sample   body_measurement (BodyMeasurement: the microcontroller's encoder packet
                       converted through the boom kinematics of appendix A, so quantised, and
                       noisy when the sensor noise is on), force_plate (GroundReactionForce),
                       sim/truth (BodyState, the true state)
    per stride         stride_command (StrideCommand: tau_0, touchdown_angle, the ramp's end
                       t_f as predicted_liftoff_time) and the true events sim/events (GaitEvent)

Each experiment: the robot is thrown upward and passes the apex drawn from the thesis's
ranges (`physics.evaluation.sample_thesis_strides`, as `sim.ExperimentSeries`), the leg held
at theta_td; the stance torque profile is applied from the touchdown; the experiment ends a
little after the next apex. Failed strides are discarded as the thesis did (the robot fell,
no next apex, or the next apex outside `physics.evaluation.SUCCESS_RANGES`): nothing of them is
written. Separate experiments are `gap` seconds apart on the recording's clock.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Iterable

import numpy as np
import yaml

from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.hardware.encoders import BoomKinematics, CounterUnwrapper
from hopper_ros.hardware.motor import HipMotor
from hopper_ros.physics.aas import predict_aas
from hopper_ros.physics.evaluation import SUCCESS_RANGES, sample_thesis_strides
from hopper_ros.sim.config import EFFECTS, SimConfig
from hopper_ros.sim.robot import SimRobot

from hopper_ros.recording.bag import BagWriter
from .experiments import TORQUE_PROFILES, start_experiment, throw_before_apex

TOE_CLEARANCE_AT_THROW = 0.025   # [m] the toe stays this far above the ground when thrown
TAIL_TOE_CLEARANCE = 0.005       # [m] the recording of an experiment stops before the toe lands again
DRAW_BATCH = 256
PROFILE_REASON = {"ramp": "ramp torque", "constant": "constant torque", "none": "no torque"}


@dataclass(frozen=True)
class CollectionSettings:
    """How many experiments, how they are drawn and framed. Times in seconds."""

    experiments: int | None = None    # run this many experiments (failed ones are discarded) ...
    strides: int | None = None        # ... or run until this many strides are kept
    seed: int = 0
    torque_profile: str = "ramp"
    lead: float = 0.06                # throw this long before the opening apex
    tail: float = 0.06                # keep recording this long after the closing apex
    gap: float = 0.5                  # between experiments on the recording's clock
    max_experiment_time: float = 3.0
    max_attempts_per_stride: int = 20  # with `strides`: give up after strides * this experiments

    def __post_init__(self) -> None:
        if (self.experiments is None) == (self.strides is None):
            raise ValueError("give either the number of experiments or the number of strides to keep")
        count = self.experiments if self.experiments is not None else self.strides
        if count < 1:
            raise ValueError(f"the number of experiments or strides must be at least 1, got {count}")
        if self.torque_profile not in TORQUE_PROFILES:
            raise ValueError(f"torque profile must be one of {TORQUE_PROFILES}, got {self.torque_profile!r}")
        for name in ("lead", "tail", "gap"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must not be negative")


@dataclass
class KeptStride:
    """One recorded stride: drawn inputs and what the robot did."""

    index: int
    apex_height: float
    forward_speed: float
    touchdown_angle: float
    tau_0: float
    ramp_duration: float
    next_apex_height: float
    next_forward_speed: float
    stride_time: float


@dataclass
class Collection:
    """What `collect` did."""

    bag: Path
    csv: Path | None
    experiments: int
    kept: list[KeptStride]
    discarded: dict[str, int]
    messages: int
    wall_time: float
    true_params: dict
    recording: object = field(default=None, repr=False)   # recording.recordings.Recording of the kept samples


class PacketConverter:
    """Encoder packets -> BodyMeasurement fields through the kinematics of appendix A."""

    def __init__(self, hardware: HardwareConfig) -> None:
        self.kinematics = BoomKinematics.from_config(hardware)
        self.motor = HipMotor.from_config(hardware)
        self.unwrap = (CounterUnwrapper(), CounterUnwrapper(), CounterUnwrapper())

    def fill(self, msg, packet) -> None:
        a, e, m = self.unwrap
        position = self.kinematics.position(a.update(packet.azimuth_counts), e.update(packet.elevation_counts),
                                            m.update(packet.motor_counts))
        msg.sequence = packet.sequence
        msg.boom_azimuth, msg.boom_elevation = position.boom_azimuth, position.boom_elevation
        msg.y, msg.z, msg.leg_angle = position.y, position.z, position.leg_angle
        msg.motor_current = packet.motor_current
        msg.hip_torque = self.motor.torque(packet.motor_current)


def _draws(params, seed: int) -> Iterable[tuple[float, ...]]:
    batch = 0
    while True:
        strides = sample_thesis_strides(params, DRAW_BATCH, seed=seed + batch * DRAW_BATCH)
        yield from (tuple(map(float, row)) for row in zip(*strides.columns()))
        batch += 1


def _failure(experiment) -> str:
    if experiment.fell:
        return "fell"
    apex = experiment.next_apex
    if apex is None:
        return "no next apex"
    for name, value in (("next_apex_height", apex.z), ("next_forward_speed", apex.ydot)):
        low, high = SUCCESS_RANGES[name]
        if not low <= value <= high:
            return f"{name.replace('_', ' ')} out of {low}-{high}"
    return ""


def collect(output: str | os.PathLike, sim_config: SimConfig, hardware: HardwareConfig, settings: CollectionSettings, *,
            csv_path: str | os.PathLike | None = None, csv_phase: bool = False,
            draws: Iterable[tuple[float, float, float, float, float]] | None = None,
            progress: Callable[[int, int], None] | None = None, origin_ns: int | None = None) -> Collection:
    """Run single-stride experiments on the simulated robot and record the successful ones.

    `draws` (apex height, forward speed, theta_td, tau_0, t_f) replaces the thesis-range draws.
    """

    from hopper_ros.msg import BodyMeasurement, BodyState, GaitEvent, GroundReactionForce, StrideCommand
    from hopper_ros.nodes.stamps import stamp_of_ns
    from hopper_ros.recording.recordings import Recording, write_csv

    if csv_path is not None and Path(csv_path).exists():
        raise ValueError(f"{csv_path} exists already; a recording is never written over")
    started = time.perf_counter()
    gait_event_types = {"apex": GaitEvent.APEX, "touchdown": GaitEvent.TOUCHDOWN, "bottom": GaitEvent.BOTTOM,
                        "liftoff": GaitEvent.LIFTOFF}
    params = sim_config.model_params()
    origin_ns = time.time_ns() if origin_ns is None else origin_ns
    custom = {
        "hopper_ros.source": "lockstep simulated robot, single-stride experiments (section 4.1)",
        "hopper_ros.true_model": yaml.safe_dump(params.as_dict(), sort_keys=False),
        "hopper_ros.effects": ",".join(f"{name} {EFFECTS[name]}={value:g}"
                                       for name, value in sim_config.enabled_effects().items()),
        "hopper_ros.sensors": ",".join(n for n in sim_config.sensors if sim_config.sensors[n]["enabled"]) or "none",
        "hopper_ros.collection": yaml.safe_dump(asdict(settings), sort_keys=False),
    }
    bag = BagWriter(output, custom_data=custom, chunk_interval=0.0)
    topics = {"body": bag.add_topic("/body_measurement", "hopper_ros/msg/BodyMeasurement"),
              "force": bag.add_topic("/force_plate", "hopper_ros/msg/GroundReactionForce"),
              "truth": bag.add_topic("/sim/truth", "hopper_ros/msg/BodyState"),
              "command": bag.add_topic("/stride_command", "hopper_ros/msg/StrideCommand"),
              "events": bag.add_topic("/sim/events", "hopper_ros/msg/GaitEvent")}
    robot = SimRobot(sim_config, hardware)
    converter = PacketConverter(hardware)
    body, force, truth = BodyMeasurement(), GroundReactionForce(), BodyState(measurement_used=True)
    body.header.frame_id, force.header.frame_id, truth.header.frame_id = "ground", "force_plate", "ground"
    columns = {name: [] for name in ("t", "y", "z", "theta", "tau", "phase")}

    def stamp(t: float, message_stamp=None):
        ns = origin_ns + int(round(t * 1e9))
        return stamp_of_ns(ns, message_stamp), ns

    limit = settings.experiments if settings.experiments is not None else settings.strides * settings.max_attempts_per_stride
    source = iter(draws) if draws is not None else _draws(params, settings.seed)
    kept: list[KeptStride] = []
    discarded: dict[str, int] = {}
    experiments = 0
    offset = 0.0                       # the recording's clock minus the simulation's
    rho_0, g = params.rest_length, params.gravity
    for apex_height, forward_speed, touchdown_angle, tau_0, ramp in source:
        if experiments >= limit or (settings.strides is not None and len(kept) >= settings.strides):
            break
        experiments += 1
        clearance = apex_height - rho_0 * math.cos(touchdown_angle) - TOE_CLEARANCE_AT_THROW
        lead = min(settings.lead, math.sqrt(2.0 * max(clearance, 0.0) / g))
        y_start = robot.plant.state[0]
        throw_before_apex(robot, apex_height, forward_speed, touchdown_angle, lead, y_apex=y_start + forward_speed * lead)
        experiment = start_experiment(robot, tau_0, touchdown_angle, ramp, settings.torque_profile)
        t_throw = robot.t
        buffer = []
        while not experiment.done and robot.t - t_throw < settings.max_experiment_time:
            sample = robot.step()
            buffer.append((sample, experiment.commanded_torque(sample.truth.t)))
        reason = _failure(experiment) if experiment.done else "no next apex"
        if not reason:
            apex_t = experiment.next_apex.t
            while (robot.t - apex_t < settings.tail - 1e-9 and robot.plant.toe_height > TAIL_TOE_CLEARANCE
                   and not robot.plant.fallen):
                sample = robot.step()
                buffer.append((sample, experiment.commanded_torque(sample.truth.t)))
        if progress is not None:
            progress(len(kept) + (not reason), experiments)
        if reason:
            discarded[reason] = discarded.get(reason, 0) + 1
            offset += settings.gap
            continue
        index = len(kept) + 1
        opening = experiment.event("apex")
        closing = experiment.next_apex
        kept.append(KeptStride(index, apex_height, forward_speed, touchdown_angle, tau_0, ramp, closing.z, closing.ydot,
                               closing.t - opening.t))
        # the inputs, issued at the throw (the ramp's end t_f as the predicted lift-off time)
        prediction = predict_aas(params, apex_height, forward_speed, touchdown_angle, tau_0, ramp)
        command = StrideCommand(stride_index=index, feasible=True, reason=f"{PROFILE_REASON[settings.torque_profile]}, "
                                "single-stride experiment (section 4.1)", tau_0=experiment.tau_0,
                                touchdown_angle=touchdown_angle, predicted_liftoff_time=ramp,
                                predicted_apex_height=float(prediction.next_apex_height),
                                predicted_forward_speed=float(prediction.next_forward_speed),
                                predicted_stride_time=float(prediction.stride_time),
                                target_apex_height=math.nan, target_forward_speed=math.nan)
        command.header.stamp, ns = stamp(t_throw + offset)
        bag.write_message(topics["command"], command, ns)
        phase_now = 3                  # rising toward the opening apex: ascent
        for sample, commanded in buffer:
            t = sample.truth.t + offset
            _, ns = stamp(t, body.header.stamp)
            converter.fill(body, sample.packet)
            body.mcu_time = sample.packet.mcu_time_us * 1e-6 + offset
            bag.write_message(topics["body"], body, ns)
            stamp(t, force.header.stamp)
            f = sample.force
            force.force_forward, force.force_vertical, force.contact = f.forward, f.vertical, f.contact
            force.center_of_pressure = f.center_of_pressure
            bag.write_message(topics["force"], force, ns)
            s = sample.truth
            stamp(t, truth.header.stamp)
            truth.sequence = sample.packet.sequence
            truth.y, truth.z, truth.y_dot, truth.z_dot = s.y, s.z, s.ydot, s.zdot
            truth.leg_angle, truth.leg_angle_rate = s.leg_angle, s.leg_rate
            bag.write_message(topics["truth"], truth, ns)
            for event in sample.events:
                if event.kind not in gait_event_types:
                    continue
                msg = GaitEvent(type=gait_event_types[event.kind], stride_index=index)
                msg.header.stamp, event_ns = stamp(event.t + offset)
                msg.header.frame_id = "ground"
                msg.state.header.stamp = msg.header.stamp
                msg.state.y, msg.state.z, msg.state.y_dot, msg.state.z_dot = event.y, event.z, event.ydot, event.zdot
                msg.state.leg_angle = event.leg_angle
                bag.write_message(topics["events"], msg, event_ns)
            phase_now = int(s.phase) if not s.fallen else phase_now
            for name, value in (("t", t), ("y", body.y), ("z", body.z), ("theta", body.leg_angle), ("tau", commanded),
                                ("phase", phase_now)):
                columns[name].append(value)
        offset += settings.gap
    bag.close()
    recording = None
    if columns["t"]:
        t, y, z, theta, tau = (np.asarray(columns[n], dtype=float) for n in ("t", "y", "z", "theta", "tau"))
        recording = Recording(t - t[0], y, z, theta, tau, phase=np.asarray(columns["phase"], dtype=int),
                              source=str(output))       # time from the first sample, as `load_bag` gives it
    csv_written = None
    if csv_path is not None and recording is not None:
        csv_written = write_csv(csv_path, recording, with_phase=csv_phase)
    return Collection(Path(output), csv_written, experiments, kept, discarded, bag.message_count,
                      time.perf_counter() - started, params.as_dict(), recording)
