"""Settings of the sensing nodes (config/sensing.yaml, section `sensing`). No ROS import.

Every key of the file is a field here; unknown or missing keys are errors naming the key, so a
typo in the YAML never silently falls back to a default.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from typing import Any, Mapping

from hopper_ros.config import load_yaml

DEFAULT_FILE = "sensing.yaml"
MEASUREMENT_NOISE_MODELS = ("quantization", "thesis")


def _numbers(cls, values: Mapping[str, Any], where: str) -> dict[str, Any]:
    if not isinstance(values, Mapping):
        raise ValueError(f"{where}: expected a mapping")
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(values) - set(names))
    missing = [name for name in names if name not in values]
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; known: {names}")
    if missing:
        raise ValueError(f"{where}: missing key(s) {missing}")
    result = {}
    for f in fields(cls):
        value = values[f.name]
        if f.type == "str":
            if not isinstance(value, str):
                raise ValueError(f"{where}.{f.name} must be a string, got {value!r}")
        elif isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise ValueError(f"{where}.{f.name} must be a finite number >= 0, got {value!r}")
        elif f.type == "int":
            if int(value) != value:
                raise ValueError(f"{where}.{f.name} must be an integer, got {value!r}")
            value = int(value)
        else:
            value = float(value)
        result[f.name] = value
    return result


@dataclass(frozen=True)
class BridgeSettings:
    receive_buffer_bytes: int
    clock_tolerance: float      # [s]
    reorder_window: int         # [packets]
    resync_after: int           # [packets]

    def __post_init__(self) -> None:
        if self.resync_after < 2:
            raise ValueError("sensing.bridge.resync_after must be at least 2")


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
    clock_reanchor_after: float       # [s] of microcontroller time

    def __post_init__(self) -> None:
        if self.measurement_noise not in MEASUREMENT_NOISE_MODELS:
            raise ValueError(f"sensing.estimator.measurement_noise must be one of {MEASUREMENT_NOISE_MODELS}, "
                             f"got {self.measurement_noise!r}")
        for name in ("vertical_process_noise", "horizontal_process_noise", "quantization_std_counts",
                     "leg_process_noise", "outlier_gate", "max_prediction_gap"):
            if getattr(self, name) <= 0:
                raise ValueError(f"sensing.estimator.{name} must be positive")
        if self.reinitialise_after < 1:
            raise ValueError("sensing.estimator.reinitialise_after must be at least 1")


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

    def __post_init__(self) -> None:
        if not 0 < self.acquire_velocity_std <= self.track_velocity_std:
            raise ValueError("sensing.detector: need 0 < acquire_velocity_std <= track_velocity_std")


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
        if isinstance(data, Mapping) and "sensing" in data:
            data = data["sensing"]
        if not isinstance(data, Mapping):
            raise ValueError(f"{source}: expected a mapping under `sensing:`")
        sections = {"bridge": BridgeSettings, "estimator": EstimatorSettings, "detector": DetectorSettings}
        top = ("hardware_file", "model_file", "diagnostics_period", "queue_depth")
        unknown = sorted(set(data) - set(sections) - set(top))
        if unknown:
            raise ValueError(f"{source}: unknown key(s) sensing.{unknown}")
        try:
            period = data["diagnostics_period"]
            if isinstance(period, bool) or not isinstance(period, (int, float)) or not period > 0:
                raise ValueError(f"{source}: sensing.diagnostics_period must be a positive number, got {period!r}")
            depth = data["queue_depth"]
            if isinstance(depth, bool) or not isinstance(depth, int) or depth < 1:
                raise ValueError(f"{source}: sensing.queue_depth must be a positive integer, got {depth!r}")
            built = {name: kind(**_numbers(kind, data[name], f"{source}: sensing.{name}"))
                     for name, kind in sections.items()}
            return cls(str(data["hardware_file"]), str(data["model_file"]), float(period), depth, **built)
        except KeyError as exc:
            raise ValueError(f"{source}: sensing lacks {exc.args[0]!r}") from None
        except ValueError as exc:
            message = str(exc)
            raise ValueError(message if message.startswith(source) else f"{source}: {message}") from None


def load_sensing_config(name: str | os.PathLike = DEFAULT_FILE) -> SensingConfig:
    return SensingConfig.from_dict(load_yaml(name), source=str(name))
