"""Settings of the sensing nodes (config/sensing.yaml, section `sensing`). No ROS import.

Every key of the file is a field here; the file is checked by its schema
(hopper_ros/config/schemas.py SENSING: types, ranges with units, unknown and missing keys), so a
typo in the YAML never silently falls back to a default.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Mapping

from hopper_ros.config import load_yaml

DEFAULT_FILE = "sensing.yaml"
MEASUREMENT_NOISE_MODELS = ("quantization", "thesis")


@dataclass(frozen=True)
class BridgeSettings:
    receive_buffer_bytes: int
    clock_tolerance: float      # [s]
    reorder_window: int         # [packets]
    resync_after: int           # [packets]



@dataclass(frozen=True)
class EstimatorSettings:
    vertical_process_noise: float     # sigma_w of z [m s^-2.5]
    horizontal_process_noise: float   # sigma_w of y [m s^-2.5]
    measurement_noise: str            # "quantization" or "thesis"
    quantization_std_counts: float    # [counts]
    leg_process_noise: float          # [rad s^-1.5]
    initial_velocity_std: float       # [m/s]
    initial_acceleration_std: float   # [m/s^2]
    initial_leg_rate_std: float       # [rad/s]
    outlier_gate: float               # [1] Mahalanobis distance
    reinitialise_after: int           # [samples]
    max_prediction_gap: float         # [s]
    clock_drift_rate: float           # [s/s]
    clock_max_error: float            # [s]
    clock_max_lag: float              # [s]
    clock_reanchor_after: float       # [s] of host time



@dataclass(frozen=True)
class DetectorSettings:
    pre_touchdown_height: float   # [m]
    pre_touchdown_lead: float     # [s]
    flight_fit_settle: float      # [s]
    flight_fit_max_residual: float  # [m]
    bottom_hysteresis: float      # [m/s]
    touchdown_arming_clearance: float  # [m]
    acquire_velocity: float       # [m/s]
    acquire_clearance: float      # [m]
    acquire_window: float         # [s]
    acquire_velocity_std: float   # [m/s]
    track_velocity_std: float     # [m/s]
    max_state_spacing: float      # [s]
    sample_deadline: float        # [s]



@dataclass(frozen=True)
class SensingConfig:
    hardware_file: str
    model_file: str
    diagnostics_period: float
    queue_depth: int
    bridge: BridgeSettings
    estimator: EstimatorSettings
    detector: DetectorSettings

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "sensing config") -> "SensingConfig":
        """From the parsed file (with or without the `sensing:` level), validated by its schema
        (hopper_ros.config.schemas.SENSING): errors name the file and the key."""
        from hopper_ros.config.schemas import SENSING
        from hopper_ros.config.schema import validate

        if not (isinstance(data, Mapping) and "sensing" in data):
            data = {"sensing": data}
        s = validate(SENSING, data, source)["sensing"]
        return cls(s["hardware_file"], s["model_file"], s["diagnostics_period"], s["queue_depth"],
                   BridgeSettings(**s["bridge"]), EstimatorSettings(**s["estimator"]),
                   DetectorSettings(**s["detector"]))


def load_sensing_config(name: str | os.PathLike = DEFAULT_FILE) -> SensingConfig:
    from hopper_ros.config import config_path

    return SensingConfig.from_dict(load_yaml(name), source=str(config_path(name)))
