"""Single-stride experiments (section 4.1, Fig 4.1) as the recordings need them, built on the
simulated robot's `StrideExperiment` without changing it:

- the stance torque profile: "ramp" -tau_0 (1 - t/t_f) (2.32), "constant" -tau_0 over the whole
  stance (Fig 4.9), or "none" (the lossy SLIP of Fig 4.8a); t from touchdown;
- the drive's current demand follows the stance torque too, so the measured motor current
  shows it (the base class lets the torque bypass the current in stance);
- `commanded_torque(t)`: the hip torque the controller asked for at t, before any actuation
  delay or saturation (the `tau` of the CSV export);
- `throw_before_apex`: the robot is thrown upward and passes through its apex `lead` seconds
  later, as the thesis's researcher throws it ("to detect a natural apex state"), so the
  recording holds the opening apex with data on both sides.
"""

from __future__ import annotations

from hopper_ros.canbus.epos2_regulator import PositionRegulator
from hopper_ros.physics import laws
from hopper_ros.physics.exact import Phase
from hopper_ros.physics.flight import flight_state
from hopper_ros.sim.experiment import Stage, StrideExperiment

TORQUE_PROFILES = ("ramp", "constant", "none")


class ProfiledStrideExperiment(StrideExperiment):
    """`StrideExperiment` with a chosen stance torque profile and the commanded torque exposed."""

    def __init__(self, tau_0: float, touchdown_angle: float, ramp_duration: float, regulator,
                 pre_touchdown_height: float, profile: str = "ramp") -> None:
        if profile not in TORQUE_PROFILES:
            raise ValueError(f"torque profile must be one of {TORQUE_PROFILES}, got {profile!r}")
        if profile == "none":
            tau_0 = 0.0
        if profile == "constant" and ramp_duration <= 0.0:
            ramp_duration = 1.0            # unused by the constant profile
        super().__init__(tau_0, touchdown_angle, ramp_duration, regulator, pre_touchdown_height)
        self.profile = profile
        self.last_demand = 0.0             # [A] the drive's demand of the last period

    def stance_torque(self, since_touchdown: float) -> float:
        """Commanded hip torque [N m] at `since_touchdown` seconds into the stance."""
        if since_touchdown < 0.0 or self.tau_0 == 0.0:
            return 0.0
        if self.profile == "constant":
            return -self.tau_0
        return laws.ramp_torque(since_touchdown, self.tau_0, self.ramp_duration)         # (2.32)

    def current_demand(self, t: float) -> float:
        demand = super().current_demand(t)
        if self.stage is Stage.STANCE:
            demand = self.robot.motor.current(self.stance_torque(t - self.robot.plant.touchdown_time))
        self.last_demand = demand
        return demand

    def torque_function(self, current_history, hip_torque, delay: float):
        plant, motor = self.robot.plant, self.robot.motor

        def torque(t: float) -> float:
            if plant.in_contact:
                return hip_torque(motor.current(self.stance_torque(t - delay - plant.touchdown_time)))
            return hip_torque(current_history(t))

        return torque

    def commanded_torque(self, t: float) -> float:
        """Hip torque the controller commands at time t [N m] (no delay, no saturation)."""
        plant = self.robot.plant
        if plant.in_contact:
            return self.stance_torque(t - plant.touchdown_time)
        return self.robot.motor.torque(self.last_demand)


def throw_before_apex(robot, apex_height: float, forward_speed: float, leg_angle: float, lead: float,
                      y_apex: float = 0.0) -> None:
    """Throw the robot so that it passes its apex (apex_height, forward_speed) `lead` seconds
    later, the leg held at `leg_angle`: the state `lead` before the apex on the flight (2.13)-(2.16)."""
    robot.throw(apex_height, forward_speed, leg_angle, y=y_apex)
    if lead <= 0.0:
        return
    plant = robot.plant
    c = plant.coefficients
    y, z, ydot, zdot = flight_state(-lead, y_apex, apex_height, forward_speed, 0.0, float(c.gravity),
                                    float(c.flight_damping_y), float(c.flight_damping_z))
    plant.state[0], plant.state[1], plant.state[2], plant.state[3] = y, z, ydot, zdot
    plant.phase = Phase.ASCENT          # the plant locates the apex itself
    plant.events.clear()


def start_experiment(robot, tau_0: float, touchdown_angle: float, ramp_duration: float,
                     profile: str = "ramp") -> ProfiledStrideExperiment:
    """Attach a new experiment to `robot` (already thrown) and return it."""
    experiment = ProfiledStrideExperiment(tau_0, touchdown_angle, ramp_duration,
                                          PositionRegulator.from_hardware(robot.hardware),
                                          robot.config.pre_touchdown_height, profile)
    robot.run_experiment(experiment)
    return experiment
