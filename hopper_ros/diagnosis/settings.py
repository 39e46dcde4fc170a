"""The statistics that decide what the mismatch tool names (config/diagnosis.yaml, docs/diagnosis.md):
`Settings`, and DIAGNOSIS, the file's schema (a pydantic model made of Settings' fields and defaults
with the ranges of LIMITS), through which `load_settings` reads it."""

from __future__ import annotations

from dataclasses import dataclass, fields

from pydantic import create_model

from hopper_ros.config.schema import Section, load_config, unit


@dataclass
class Settings:
    folds: int = 5
    grid: int = 7
    min_strides: int = 6
    max_effects: int = 3
    min_reduction: float = 0.10      # held-out trajectory SSE must fall by at least this share ...
    min_total_reduction: float = 0.02  # ... and by this share of the model's own SSE (later rounds: not noise)
    min_t: float = 3.0               # ... with a one-sided t of the per-stride log ratio
    apex_tolerance: float = 0.01     # a held-out E_p/E_v/E_t may not grow by more than this share
    apex_improvement: float = 0.03   # ... and their sum must fall by at least this share
    sensor_alone: float = 0.5        # a sensor fault that leaves the next apex as it was must explain this share
    sensor_margin: float = 0.15      # a sensor effect must beat the best physics effect's reduction by this share
    discovery_margin: float = 0.15   # a discovered term set must beat the best library effect by this share
    margin_residual: float = 0.5     # ... or (a sensor) leave at most this share of what it leaves (paired t >= min_t)
    near_full: float = 0.95          # ... when it removes at least this share of the held-out residual
    tie_t: float = 2.5               # an effect fitting held-out strides not worse by this t is a look-alike ...
    tie_share: float = 0.02          # ... and so is one whose reduction is within this share of the best's
    locate_threshold: float = 2.5    # residual over noise for a site to stand out
    screen: int = 8                  # candidates the screening passes on to the full search
    screen_strides: int = 24         # strides the screening uses
    liftoff_window: float = 0.003
    exchange: int = 3                # runners-up tried as the partner of an exchanged effect
    polish: int = 3                  # passes of the joint refit of an accepted effect with the earlier ones
    restarts: int = 3                # first-round runners-up that start the rounds again ...
    restart_threshold: float = 5.0   # ... when the accepted set leaves a residual this far over the noise level
    trajectory_threshold: float = 10.0   # nothing located by force: a re-simulated phase this many noise levels off
    floor_factor: float = 2.0        # held-out next-apex errors within this many times their noise floor: explained
    drift_share: float = 0.5         # a main parameter's trend must remove this share of the held-out E_p+E_v+E_t
    explained_left_pct: float = 5.0  # ... or at most this share of the model's excess over the floor left [%]
    dependence_share: float = 0.5    # the floor varying along the track must remove this share of E_p+E_v+E_t too
    track_lap: float = 0.0           # [m] one lap of the forward position (0: the boom's, from hardware.yaml)
    track_harmonics: int = 3         # waves of 1 .. this many periods a lap tried
    track_bins: int = 24             # a board's edges on this grid a lap
    secondary_grid: int = 5          # values of an accepted entry's secondary parameter tried (geometric)
    angle_scan: int = 60             # periods of the frequency scan over the leg angle (geometric)
    motor_harmonics: int = 8         # ... the shortest: the motor's turn through the gear over this
    ripple_cycles: float = 1.5       # ... the longest: the angle's recorded range over this
    gear_ratio: float = 0.0          # motor turns per leg turn (0: hardware.yaml's motor.gear_ratio)
    backlash_max: float = 0.03       # [rad] the widest backlash of the leg angle's encoder searched
    azimuth_scan: int = 80           # periods of the frequency scan over the boom's angle (geometric) ...
    azimuth_harmonics: int = 24      # ... from a lap over this to one lap
    hysteresis_yields: int = 5       # yield deflections of the leg's hysteresis tried (geometric) ...
    hysteresis_yield_min: float = 0.0005   # [m] ... from this ...
    hysteresis_yield_max: float = 0.008    # [m] ... to this
    relaxation_times: int = 5        # relaxation times of a relaxing leg force tried (geometric) ...
    relaxation_time_min: float = 0.003     # [s] ... from this ...
    relaxation_time_max: float = 0.3       # [s] ... to this
    relaxation_lengths: int = 3      # air chamber lengths at rest of the relaxing force tried (geometric) ...
    relaxation_length_min: float = 0.05    # [m] ... from this ...
    relaxation_length_max: float = 0.2     # [m] ... to this
    relaxation_refinements: int = 4  # ... then steps of a pattern search over the time and the chamber from the best
    winding_resistances: int = 6     # winding resistances of the hip motor's voltage limit tried (geometric) ...
    winding_resistance_min: float = 0.1    # [ohm] ... from this ...
    winding_resistance_max: float = 2.0    # [ohm] ... to this
    servo_releases: int = 5          # the flight servo's release times after touchdown tried (geometric) ...
    servo_release_min: float = 0.005       # [s] ... from this ...
    servo_release_max: float = 0.08        # [s] ... to this
    unused_laws: int = 2             # laws of what the model does not use found one beside the other
    second_law_floor: float = 10.0   # ... the next only where a next-apex error stands this many times over its floor


_SHARE = {"ge": 0, "le": 1}
_COUNT = {"ge": 1}
#: the range of each key of diagnosis.yaml (and its unit)
LIMITS = {
    "folds": {"ge": 2}, "grid": {"ge": 2}, "min_strides": {"ge": 2}, "max_effects": _COUNT,
    "min_reduction": _SHARE, "min_total_reduction": _SHARE, "min_t": {"ge": 0}, "apex_tolerance": _SHARE,
    "apex_improvement": _SHARE, "sensor_alone": _SHARE, "sensor_margin": _SHARE, "discovery_margin": _SHARE,
    "margin_residual": _SHARE, "near_full": _SHARE, "tie_t": {"ge": 0}, "tie_share": _SHARE,
    "locate_threshold": {"gt": 0}, "screen": _COUNT, "screen_strides": _COUNT, "liftoff_window": {"gt": 0, "unit": "s"},
    "exchange": {"ge": 0}, "polish": {"ge": 0}, "restarts": {"ge": 0}, "restart_threshold": {"gt": 0},
    "trajectory_threshold": {"gt": 0}, "floor_factor": {"gt": 0}, "drift_share": _SHARE,
    "dependence_share": _SHARE, "track_lap": {"ge": 0, "unit": "m"}, "track_harmonics": _COUNT, "track_bins": {"ge": 4},
    "explained_left_pct": {"ge": 0, "le": 100, "unit": "%"}, "secondary_grid": _COUNT,
    "angle_scan": {"ge": 2}, "motor_harmonics": _COUNT, "ripple_cycles": {"gt": 0}, "gear_ratio": {"ge": 0},
    "backlash_max": {"gt": 0, "le": 0.5, "unit": "rad"},
    "azimuth_scan": {"ge": 3}, "azimuth_harmonics": {"ge": 1}, "hysteresis_yields": _COUNT,
    "hysteresis_yield_min": {"gt": 0, "le": 0.1, "unit": "m"},
    "hysteresis_yield_max": {"gt": 0, "le": 0.1, "unit": "m"},
    "relaxation_times": {"ge": 2}, "relaxation_time_min": {"gt": 0, "unit": "s"},
    "relaxation_time_max": {"gt": 0, "unit": "s"},
    "relaxation_lengths": _COUNT, "relaxation_length_min": {"gt": 0, "unit": "m"},
    "relaxation_length_max": {"gt": 0, "unit": "m"}, "relaxation_refinements": {"ge": 0},
    "winding_resistances": _COUNT, "winding_resistance_min": {"gt": 0, "unit": "ohm"},
    "winding_resistance_max": {"gt": 0, "unit": "ohm"}, "servo_releases": _COUNT,
    "servo_release_min": {"gt": 0, "unit": "s"}, "servo_release_max": {"gt": 0, "unit": "s"},
    "unused_laws": _COUNT, "second_law_floor": {"gt": 0},
}


def _key(name: str, default):
    limits = dict(LIMITS[name])
    return type(default), unit(limits.pop("unit", ""), default, **limits)


DIAGNOSIS = create_model("DIAGNOSIS", __base__=Section, diagnosis=(
    create_model("Diagnosis", __base__=Section, **{f.name: _key(f.name, f.default) for f in fields(Settings)}), ...))


def load_settings(path="diagnosis.yaml") -> Settings:
    """diagnosis.yaml (a config/ name or a path), checked by DIAGNOSIS: a ConfigError line naming the
    file and the key otherwise."""
    return Settings(**load_config(path, DIAGNOSIS)["diagnosis"])
