"""Ground reaction forces (section 4.4) from the kinematics and from the force plate, for no,
ramp and constant hip torque, on the simulated robot with its sensor noise."""

from __future__ import annotations

import numpy as np

from hopper_ros.harness.grf import simulate_profiles
from hopper_ros.identification.grf import PROFILES, kalman_smooth


def test_the_smoother_recovers_the_acceleration_of_quantised_positions():
    t = np.arange(0.0, 0.3, 1e-3)
    z = 0.4 + 1.0 * t - 0.5 * 11.42 * t ** 2
    quantised = np.floor(z / 2.2e-4) * 2.2e-4 + np.random.default_rng(0).normal(0.0, 2.2e-4, t.size)
    position, velocity, acceleration = kalman_smooth(t, quantised, 2.5e-4, 60.0)
    inner = slice(20, -20)
    error = acceleration[inner] + 11.42
    assert np.sqrt(np.mean(error ** 2)) < 1.2 and np.max(np.abs(error)) < 3.0   # raw double differences: ~500 m/s^2
    raw = np.diff(quantised, 2) / 1e-6
    assert np.std(raw) > 100 * np.sqrt(np.mean(error ** 2))
    assert np.max(np.abs(velocity[inner] - (1.0 - 11.42 * t[inner]))) < 0.02
    assert np.max(np.abs(position - z)) < 5e-4


def test_virtual_footfalls_sit_on_the_toe_without_torque_and_behind_it_with_torque(tmp_path):
    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.identification.settings import load_settings
    from hopper_ros.sim.config import SENSORS, load_sim_config

    config = load_sim_config().with_sensors(**{name: True for name in SENSORS})
    forces = simulate_profiles(tmp_path, config, load_hardware(), load_settings().grf, config.model_params())
    assert list(forces) == list(PROFILES)
    for profile, f in forces.items():
        assert f.plate is not None and len(f.t) > 40
        # both measurements of the same force agree: directions within a few degrees, peaks within 5 %
        assert f.direction_difference_deg() < 3.0, profile
        assert abs(np.max(f.kinematic[:, 1]) / np.max(f.plate[:, 1]) - 1.0) < 0.05, profile
        # the vertical force carries the body's weight on average plus its vertical momentum change
        assert np.max(f.plate[:, 1]) > 3 * 2.2 * 11.42
    none, ramp, constant = (forces[p].footfall_offsets("plate") for p in PROFILES)
    assert max(abs(v) for v in none) < 0.005                 # the force runs along the leg: through the toe
    assert ramp[0] < -0.02 and constant[0] < -0.02           # the torque's tau/rho across the leg: behind the toe
    assert constant[2] < -0.05 and constant[2] < ramp[2] - 0.03   # constant torque keeps its backward bias to lift-off
    assert abs(ramp[2]) < abs(ramp[0])                        # the ramp fades: its footfalls come back toward the toe
    kinematic = forces["constant"].footfall_offsets("kinematic")
    assert kinematic[2] < -0.04                               # the kinematics show the same, less sharply
