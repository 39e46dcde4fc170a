"""The ground reaction force experiments of section 4.4 on the simulated robot: one
single-stride experiment per torque profile, recorded as a bag, then its stance forces both ways
(`hopper_ros.identification.grf`). Used by `hopper report` and test/test_grf.py."""

from __future__ import annotations

import math
from pathlib import Path

from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.identification.grf import PROFILE_TITLES, PROFILES, StanceForces, stance_forces
from hopper_ros.identification.strides import extract_strides
from hopper_ros.physics.aas import predict_aas
from hopper_ros.recording.recordings import load_bag

from .collect import CollectionSettings, collect


def simulate_profiles(folder, sim_config, hardware: HardwareConfig, grf_settings, params) -> dict[str, StanceForces]:
    """One single-stride experiment per torque profile on the simulated robot, recorded as a bag
    in `folder/<profile>` (body_measurement and force_plate), then its stance GRF both ways."""
    g = grf_settings
    theta = math.radians(g.touchdown_angle_deg)
    ramp = float(predict_aas(params, g.apex_height, g.forward_speed, theta, g.tau_0).stance_time)
    out = {}
    for profile in PROFILES:
        path = Path(folder) / profile
        collection = collect(path, sim_config, hardware, CollectionSettings(experiments=1, torque_profile=profile),
                             draws=[(g.apex_height, g.forward_speed, theta, g.tau_0, ramp)])
        if not collection.kept:
            raise ValueError(f"the {profile} GRF stride failed ({collection.discarded}); change identification.grf")
        recording = load_bag(path)
        strides = extract_strides(recording, params.rest_length)
        if len(strides) != 1:
            raise ValueError(f"the {profile} GRF recording holds {len(strides)} strides, expected 1 ({strides.rejected})")
        out[profile] = stance_forces(recording, strides, 0, params.body_mass, params.gravity, params.rest_length,
                                     PROFILE_TITLES[profile], g.position_noise, g.sigma_jerk, g.moving_average)
    return out
