"""The simulated robot, one 1 ms period at a time: plant, hip motor, drive, sensors, force plate.

Per period (`SimRobot.step`):
1. the hip command for the period: from the emulated EPOS2 (`drive`, commanded over CAN by the
   motor driver: poll its frames, run its control cycle -> current demand), or from the built-in
   single-stride experiment (`experiment`, section 4.1, no CAN), or none (motor off);
2. the plant integrates the period with that hip torque: the commanded torque reaches the
   plant `torque_delay` late (the actuation delay, through the motor current's history here),
   and the plant's actuator (`laws.actuator_torque`, the lag) turns it into the applied torque;
3. the sensors sample the end of the period: the three encoder counts (quantised, optional noise)
   and the motor current go into one microcontroller packet; the force plate samples the ground
   reaction force.

The microcontroller clock is the simulation clock (plus a start offset), so lockstep runs
produce the same packets as real-time runs, only faster.
"""

from __future__ import annotations

import random
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

from hopper_ros.canbus.epos2_objects import OperationMode
from hopper_ros.canbus.epos2_regulator import POSITION_LOOP_PERIOD
from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.hardware.encoders import BoomKinematics, to_register
from hopper_ros.hardware.motor import HipMotor
from hopper_ros.hardware.packet import EncoderPacket
from hopper_ros.physics.exact import Phase

from .config import SimConfig
from .plant import BodyMotion, Plant, PlantEvent

MCU_CLOCK_START_US = 1_000_000  # the microcontroller has been up for a second when the sim starts


@dataclass(frozen=True)
class GroundForce:
    """One force plate sample: force of the ground on the robot [N], centre of pressure [m]."""

    t: float
    forward: float
    vertical: float
    center_of_pressure: float
    contact: bool


@dataclass(frozen=True)
class TrueState(BodyMotion):
    """Ground truth at the end of a period, for tests and for the mismatch tool's proofs."""

    leg_rate: float
    phase: Phase
    in_contact: bool
    hip_torque: float
    fallen: bool


@dataclass
class SimSample:
    packet: EncoderPacket
    force: GroundForce
    truth: TrueState
    events: list[PlantEvent] = field(default_factory=list)


class CommandHistory:
    """The motor current, one value per period: a commanded current (current mode) reaches the
    motor `delay` seconds late (the actuation delay effect, `laws.Coefficients.torque_delay`); the
    drive's own position regulator acts at once (it runs inside the drive, after the delay)."""

    def __init__(self, delay: float) -> None:
        self.delay = delay
        self._entries: deque[tuple[float, float, bool]] = deque(maxlen=max(4, int(delay / 1e-4) + 4))

    def push(self, t_start: float, value: float, delayed: bool = True) -> None:
        self._entries.append((t_start, value, delayed))

    def __call__(self, t: float) -> float:
        if self._entries and not self._entries[-1][2]:
            return self._entries[-1][1]
        when = t - self.delay
        for t_start, value, _ in reversed(self._entries):
            if t_start <= when + 1e-12:
                return value
        return 0.0


class SimRobot:
    """The robot: `throw` it to an apex, then `step` once per period."""

    def __init__(self, config: SimConfig, hardware: HardwareConfig, *, drive=None) -> None:
        self.config = config
        self.hardware = hardware
        self.kinematics = BoomKinematics.from_config(hardware)
        self.motor = HipMotor.from_config(hardware)
        self.plant = Plant(config, self.motor.leg_inertia_total, self.motor.leg_friction)
        self.drive = drive
        self.experiment = None
        self.period = config.period
        # the drive's regulator runs at its own 1 ms loop whatever the packet period (a 2 ms sample
        # period must not halve the EPOS2's position loop): `step` advances in this many parts
        self._substeps = max(1, round(self.period / POSITION_LOOP_PERIOD)) if drive is not None else 1
        self.sequence = 0
        self.delay = float(self.plant.coefficients.torque_delay)   # [s] command -> hip torque
        self._current = CommandHistory(self.delay)   # actual motor current: the demand, `delay` late
        self._rng = random.Random(config.seed)
        self._count_noise = config.sensor("encoder_noise", "counts")
        self._current_noise = config.sensor("current_noise", "current")
        self._force_noise = config.sensor("force_plate_noise", "force")

    # ------------------------------------------------------------------ set-up
    def throw(self, apex_height: float, forward_speed: float, leg_angle: float, y: float = 0.0,
              lead_time: float = 0.0, hold: bool = False) -> None:
        """Throw the robot to an apex with the leg at `leg_angle`, as the thesis does (see Plant.throw)."""
        self.plant.throw(apex_height, forward_speed, leg_angle, y=y, t=self.plant.t, lead_time=lead_time, hold=hold)

    def run_experiment(self, experiment) -> None:
        """Let the built-in single-stride experiment command the hip (instead of the drive)."""
        self.experiment = experiment
        experiment.attach(self)

    @property
    def t(self) -> float:
        return self.plant.t

    @property
    def current_mode(self) -> bool:
        """The hip is commanded a current (the stance ramp), not a position, or has no drive."""
        return self.drive is None or self.drive.operation_mode == OperationMode.CURRENT

    # ------------------------------------------------------------------ one period
    def hip_torque(self, current: float) -> float:
        """The hip torque a motor current commands; the plant's actuator (`laws.actuator_torque`: gain,
        offset, saturation, and the lag) makes the torque that reaches the leg of it."""
        return self.motor.torque(current)

    def step(self, catching_up: bool = False, at_substep: Callable[[float], None] | None = None) -> SimSample:
        """One sample period: the drive's loop periods within it, then the packet of its end.

        `catching_up`: the period runs late, behind a stall of the process (sim/runner.py): the drive
        takes the frames of one SYNC period only, as it would have on time. `at_substep(offset)`, called
        before each loop period after the first with its offset into the period [s] (not catching up):
        the real-time runner waits for that instant, so that the drive takes the frames that came by then
        at its own loop period, not all at the period's start."""
        events: list[PlantEvent] = []
        for substep in range(self._substeps):
            poll = "one_sync" if catching_up and substep == 0 else "none" if catching_up else "all"
            if at_substep is not None and substep and not catching_up:
                at_substep(substep * self.period / self._substeps)
            events += self._advance(self.period / self._substeps, poll)
        if self.experiment is not None:
            self.experiment.on_events(events)
        return self._sample(events)

    def _advance(self, dt: float, poll: str = "all") -> list[PlantEvent]:
        plant = self.plant
        t0 = plant.t
        demand, commanded = 0.0, True
        if self.drive is not None:
            counts = self.kinematics.motor.count(plant.leg_angle)
            if poll != "none":
                self.drive.poll(t0, one_sync=poll == "one_sync")
            demand = self.drive.control(t0, counts, self.motor.motor_speed_rpm(plant.leg_rate), self._current(t0))
            commanded = self.drive.operation_mode == OperationMode.CURRENT
        elif self.experiment is not None:
            demand = self.experiment.current_demand(t0)
            commanded = False       # the experiment's stance ramp is delayed in its torque function
        demand = max(-self.motor.current_limit, min(self.motor.current_limit, demand))
        self._current.push(t0, demand, delayed=commanded)
        if self.experiment is not None and self.drive is None:
            torque = self.experiment.torque_function(self._current, self.hip_torque, self.delay)
        else:
            current = self._current
            torque = lambda t: self.hip_torque(current(t))  # noqa: E731 - per-period closure
        return plant.advance(dt, torque)

    def _sample(self, events: list[PlantEvent]) -> SimSample:
        plant, k = self.plant, self.kinematics
        s = plant.state
        azimuth, elevation, motor = k.counts(s[0], s[1], s[4])
        if self._count_noise:
            gauss, noise = self._rng.gauss, self._count_noise
            azimuth += round(gauss(0.0, noise))
            elevation += round(gauss(0.0, noise))
            motor += round(gauss(0.0, noise))
        current = self._current(plant.t)
        if self._current_noise:
            current += self._rng.gauss(0.0, self._current_noise)
        self.sequence = (self.sequence + 1) & 0xFFFFFFFF
        packet = EncoderPacket(
            sequence=self.sequence,
            mcu_time_us=MCU_CLOCK_START_US + round(plant.t * 1e6),
            azimuth_counts=to_register(azimuth), elevation_counts=to_register(elevation),
            motor_counts=to_register(motor), motor_current_ma=round(current * 1000.0),
        )
        forward, vertical = plant.ground_reaction_force()
        if self._force_noise:
            forward += self._rng.gauss(0.0, self._force_noise)
            vertical += self._rng.gauss(0.0, self._force_noise)
        contact = vertical > self.config.contact_threshold
        force = GroundForce(plant.t, forward, vertical, plant.toe_position, contact)
        truth = TrueState(plant.t, s[0], s[1], s[2], s[3], s[4], s[5], plant.phase, plant.in_contact,
                          plant.torque_now, plant.fallen)
        return SimSample(packet, force, truth, events)

    def run_until(self, condition: Callable[[SimSample], bool], max_time: float) -> list[SimSample]:
        """Step until `condition(sample)` holds or `max_time` seconds pass; returns the samples."""
        samples = []
        end = self.plant.t + max_time
        while self.plant.t < end - 1e-12:
            sample = self.step()
            samples.append(sample)
            if condition(sample):
                break
        return samples
