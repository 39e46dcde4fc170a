"""Section 4.1's single-stride experiment, run by the simulated robot itself (no CAN, no nodes).

For lockstep data generation and for checking the simulator against the exact model. Phases
as in Fig 4.1: the leg held at theta_td by the drive's position regulator (initialisation,
the robot thrown to an apex); the regulator off once the toe is `pre_touchdown_height` above
the ground; in stance the ramp tau = -tau_0 (1 - t/t_f) from the true touchdown (2.32),
applied in continuous time so it starts exactly at touchdown; after lift-off the regulator
holds the lift-off angle; after the next apex the experiment is done (the brake: hold).
"""

from __future__ import annotations

from enum import Enum

from hopper_ros.canbus.epos2_regulator import PositionRegulator
from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.physics import laws
from hopper_ros.physics.evaluation import sample_thesis_strides

from .plant import PlantEvent


class Stage(Enum):
    HOLD = "hold"
    PRE_TOUCHDOWN = "pre-touchdown"
    STANCE = "stance"
    ASCENT = "ascent"
    DONE = "done"


class StrideExperiment:
    def __init__(self, tau_0: float, touchdown_angle: float, ramp_duration: float, regulator,
                 pre_touchdown_height: float) -> None:
        """`regulator` is the drive's position regulator (`canbus.epos2_regulator.PositionRegulator`)."""
        if ramp_duration <= 0.0 and tau_0 != 0.0:
            raise ValueError(f"ramp duration must be positive, got {ramp_duration}")
        self.tau_0 = tau_0
        self.touchdown_angle = touchdown_angle
        self.ramp_duration = ramp_duration
        self.regulator = regulator
        self.pre_touchdown_height = pre_touchdown_height
        self.stage = Stage.HOLD
        self.hold_angle = touchdown_angle
        self.robot = None
        self.events: list[PlantEvent] = []

    def attach(self, robot) -> None:
        self.robot = robot
        self.regulator.reset()

    @property
    def done(self) -> bool:
        return self.stage is Stage.DONE

    def current_demand(self, t: float) -> float:
        """Motor current for the coming period [A]: the regulator's in flight, zero from pre-touchdown,
        the ramp's in stance."""
        plant = self.robot.plant
        if self.stage is Stage.HOLD and plant.toe_height < self.pre_touchdown_height:
            self.stage = Stage.PRE_TOUCHDOWN
        if self.stage is Stage.PRE_TOUCHDOWN:
            return 0.0
        if self.stage is Stage.STANCE:   # what the current sensor reads; the plant gets the ramp in continuous time
            ramp = laws.ramp_torque(t - plant.touchdown_time, self.tau_0, self.ramp_duration)     # (2.32)
            return self.robot.motor.current(ramp)
        motor = self.robot.motor
        return self.regulator.current(self.hold_angle, plant.leg_angle, plant.leg_rate, self.robot.period, motor)

    def torque_function(self, current_history, hip_torque, delay: float):
        """Commanded hip torque over the period: the regulator's current, or in stance the ramp (2.32) in
        continuous time, `delay` late (the actuation delay)."""
        plant, motor = self.robot.plant, self.robot.motor
        tau_0, t_f = self.tau_0, self.ramp_duration

        def torque(t: float) -> float:
            if plant.in_contact:
                return hip_torque(motor.current(laws.ramp_torque(t - delay - plant.touchdown_time, tau_0, t_f)))
            return hip_torque(current_history(t))

        return torque

    def on_events(self, events: list[PlantEvent]) -> None:
        for event in events:
            self.events.append(event)
            if event.kind == "touchdown":
                self.stage = Stage.STANCE
            elif event.kind == "liftoff":
                self.stage = Stage.ASCENT
                self.hold_angle = event.leg_angle
                self.regulator.reset()
            elif event.kind == "apex" and self.stage is Stage.ASCENT:
                self.stage = Stage.DONE
            elif event.kind == "fall":
                self.stage = Stage.DONE

    def event(self, kind: str) -> PlantEvent | None:
        """The first event of a kind in this experiment (None if it did not happen)."""
        return next((e for e in self.events if e.kind == kind), None)

    @property
    def next_apex(self) -> PlantEvent | None:
        apexes = [e for e in self.events if e.kind == "apex"]
        return apexes[-1] if self.stage is Stage.DONE and apexes else None

    @property
    def fell(self) -> bool:
        return any(e.kind == "fall" for e in self.events)



def drive_hold(hardware: HardwareConfig) -> PositionRegulator:
    """The drive's position regulator (Position Mode PID of section 4.1) for the experiment."""
    return PositionRegulator.from_hardware(hardware)


class ExperimentSeries:
    """Section 4.1's data collection: single-stride experiments one after another, each thrown
    anew with apex height, forward speed, tau_0 and theta_td drawn uniformly from the thesis's
    ranges and t_f the AAS's predicted lift-off (`physics.evaluation.sample_thesis_strides`)."""

    BATCH = 256

    def __init__(self, robot, seed: int = 0) -> None:
        self.robot = robot
        self.seed = seed
        self.started = 0
        self._draws: list[tuple[float, ...]] = []

    def start_next(self) -> StrideExperiment:
        if not self._draws:
            strides = sample_thesis_strides(self.robot.config.model_params(), self.BATCH,
                                            seed=self.seed + self.started)
            self._draws = [tuple(map(float, row)) for row in zip(*strides.columns())]
        apex_height, forward_speed, touchdown_angle, tau_0, ramp = self._draws.pop(0)
        robot = self.robot
        robot.throw(apex_height, forward_speed, touchdown_angle, y=robot.plant.state[0])
        experiment = StrideExperiment(tau_0, touchdown_angle, ramp, drive_hold(robot.hardware),
                                      robot.config.pre_touchdown_height)
        robot.run_experiment(experiment)
        self.started += 1
        return experiment
