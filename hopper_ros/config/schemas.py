"""One schema per configuration file (hopper_ros/config/schema.py: types, required keys, ranges with
units, unknown keys refused). No ROS import.

| file | schema | read by |
|---|---|---|
| hardware.yaml (and variants) | HARDWARE (built into `HardwareConfig` by hopper_ros.hardware.config.load_hardware) | sim_robot, motor_driver, encoder_bridge, state_estimator, collect, report |
| sim.yaml | SIM (`sim.physics`: the eight model parameters; `sim.effects` is checked by hopper_ros.sim.config against the effect library) | sim_robot, collect, report |
| sensing.yaml | SENSING | encoder_bridge, state_estimator, event_detector |
| model.yaml (and identified models) | MODEL (`model:`; an identified model's `effects:` is checked by hopper_ros.physics.params.load_model against the effect library) | deadbeat_controller, stride_predictor, event_detector, diagnose |
| control.yaml | CONTROL | deadbeat_controller |
| motor_driver.yaml (and variants) | MOTOR_DRIVER | motor_driver |
| identification.yaml | IDENTIFICATION (with `effects:`, library names checked against `fitted`, and `lanes:`) | identify, report |
| setpoints/*.yaml | SCHEDULE | setpoint_scheduler |

diagnosis.yaml (read by hopper_ros.diagnosis.settings.load_settings, which checks it itself) and the
launch files are not covered yet: `load_config(name, SCHEMA)` is the way to adopt them.
"""

from __future__ import annotations

import math

from hopper_ros.config.schema import Anything, Flag, Items, Number, Section, Text, ordered, within

PI_2 = math.pi / 2

# ------------------------------------------------------------------------------------ hardware.yaml


def _encoder(doc: str) -> Section:
    return Section({
        "lines": Number("lines", gt=0, integer=True),
        "quadrature": Number(choices=(1, 2, 4), integer=True),
        "transmission": Number("encoder turns per turn", gt=0),
        "direction": Number(choices=(-1, 1), integer=True),
        "offset_counts": Number("counts", integer=True),
    }, doc=doc)


def _continuous_within_limit(values: dict):
    if values["continuous_current"] > values["current_limit"]:
        return "continuous_current", (f"must not exceed current_limit ({values['current_limit']:g} A), "
                                      f"got {values['continuous_current']:g}")
    return None


HARDWARE = Section({
    "boom": Section({
        "length": Number("m", gt=0),
        "parallel_height": Number("m", ge=0),
        "leg_offset": Number("m"),
        "ground_height": Number("m", ge=0),
    }),
    "encoders": Section({"azimuth": _encoder("planarizer, forward"), "elevation": _encoder("planarizer, vertical"),
                         "motor": _encoder("hip motor")}),
    "motor": Section({
        "gear_ratio": Number(gt=0),
        "torque_constant": Number("N m/A", gt=0),
        "direction": Number(choices=(-1, 1), integer=True),
        "rotor_inertia": Number("kg m^2", gt=0),
        "leg_inertia": Number("kg m^2", gt=0),
        "viscous_friction": Number("N m s/rad", ge=0),
    }),
    "drive": Section({
        "node_id": Number(ge=1, le=127, integer=True),
        "current_limit": Number("A", gt=0),
        "continuous_current": Number("A", gt=0),
        "position_gains": Section({k: Number(ge=0, le=32767, integer=True) for k in ("p", "i", "d")}),
        "heartbeat_period": Number("s", gt=0, le=65.535),
    }, checks=(_continuous_within_limit,)),
    "microcontroller": Section({
        "host": Text(),
        "port": Number(ge=1, le=65535, integer=True),
        "sample_period": Number("s", gt=0, le=0.1),
    }),
    "can": Section({
        "interface": Text(),
        "channel": Text(default=None),
        "host": Text(default=None),
        "port": Number(ge=1, le=65535, integer=True, default=None),
        "bitrate": Number("bit/s", gt=0, integer=True, default=None),
        "connect_timeout": Number("s", gt=0, default=None),
    }),
})

# ------------------------------------------------------------------------------------ model.yaml

MODEL_FIELDS = {
    "body_mass": Number("kg", gt=0),
    "toe_mass": Number("kg", ge=0),
    "gravity": Number("m/s^2", gt=0),
    "stiffness": Number("N/m", gt=0),
    "damping": Number("N s/m", ge=0),
    "flight_damping_horizontal": Number("1/s", ge=0),
    "flight_damping_vertical": Number("1/s", ge=0),
    "rest_length": Number("m", gt=0),
}
MODEL = Section({
    "model": Section(MODEL_FIELDS),
    # an identified model's library effects {name: magnitude} (`hopper identify --effects`): names,
    # numbers and which may be infinite are checked by hopper_ros.physics.params.load_model
    "effects": Anything(default=None, doc="{effect library name: magnitude}, checked by physics.params.load_model"),
})

# ------------------------------------------------------------------------------------ sim.yaml


def _sensor(key: str, unit: str) -> Section:
    return Section({"enabled": Flag(), key: Number(unit, ge=0)})


SIM = Section({"sim": Section({
    "period": Number("s", gt=0, le=0.1),
    "substeps": Number(ge=1, le=1000, integer=True),
    "physics": Section(MODEL_FIELDS, doc="the extended TD-SLIP model's parameters (ModelParams' fields)"),
    "effects": Anything(doc="entries of the effect library, checked by hopper_ros.sim.config (library names, "
                        "each one's parameter)"),
    "sensors": Section({
        "encoder_noise": _sensor("counts", "counts"),
        "current_noise": _sensor("current", "A"),
        "force_plate_noise": _sensor("force", "N"),
    }),
    "force_plate": Section({"contact_threshold": Number("N", ge=0)}),
    "experiment": Section({"pre_touchdown_height": Number("m", ge=0)}),
    "initial_apex": Section({
        "apex_height": Number("m", gt=0),
        "forward_speed": Number("m/s"),
        "leg_angle": Number("rad", gt=-PI_2, lt=PI_2),
    }),
    "seed": Number(ge=0, integer=True, default=0),
})})

# ------------------------------------------------------------------------------------ sensing.yaml


def _acquire_below_track(values: dict):
    if values["acquire_velocity_std"] > values["track_velocity_std"]:
        return "acquire_velocity_std", (f"must not exceed track_velocity_std ({values['track_velocity_std']:g} m/s), "
                                        f"got {values['acquire_velocity_std']:g}")
    return None


SENSING = Section({"sensing": Section({
    "hardware_file": Text(),
    "model_file": Text(),
    "diagnostics_period": Number("s", gt=0),
    "queue_depth": Number("samples", ge=1, integer=True),
    "bridge": Section({
        "receive_buffer_bytes": Number("bytes", ge=0, integer=True),
        "clock_tolerance": Number("s", ge=0),
        "reorder_window": Number("packets", ge=0, integer=True),
        "resync_after": Number("packets", ge=2, integer=True),
    }),
    "estimator": Section({
        "vertical_process_noise": Number("m s^-2.5", gt=0),
        "horizontal_process_noise": Number("m s^-2.5", gt=0),
        "measurement_noise": Text(choices=("quantization", "thesis")),
        "quantization_std_counts": Number("counts", gt=0),
        "leg_process_noise": Number("rad s^-1.5", gt=0),
        "initial_velocity_std": Number("m/s", ge=0),
        "initial_acceleration_std": Number("m/s^2", ge=0),
        "initial_leg_rate_std": Number("rad/s", ge=0),
        "outlier_gate": Number("sigma", gt=0),
        "reinitialise_after": Number("samples", ge=1, integer=True),
        "max_prediction_gap": Number("s", gt=0),
        "clock_drift_rate": Number("s/s", ge=0),
        "clock_max_error": Number("s", ge=0),
        "clock_max_lag": Number("s", ge=0),
        "clock_reanchor_after": Number("s", ge=0),
    }),
    "detector": Section({
        "pre_touchdown_height": Number("m", ge=0),
        "pre_touchdown_lead": Number("s", ge=0),
        "flight_fit_settle": Number("s", ge=0),
        "flight_fit_max_residual": Number("m", ge=0),
        "bottom_hysteresis": Number("m/s", ge=0),
        "touchdown_arming_clearance": Number("m", ge=0),
        "acquire_velocity": Number("m/s", ge=0),
        "acquire_clearance": Number("m", ge=0),
        "acquire_window": Number("s", ge=0),
        "acquire_velocity_std": Number("m/s", gt=0),
        "track_velocity_std": Number("m/s", gt=0),
        "max_state_spacing": Number("s", ge=0),
        "sample_deadline": Number("s", ge=0),
    }, checks=(_acquire_below_track,)),
})})

# ------------------------------------------------------------------------------------ control.yaml

PREDICTORS = ("aas", "corrected", "exact")
# identification's: the model library's predictors and "lanes" (the laws with library effects)
IDENTIFICATION_PREDICTORS = PREDICTORS + ("lanes",)

CONTROL = Section({
    "deadbeat": Section({
        "predictor": Text(choices=PREDICTORS),
        "angle_span": Number("rad", gt=0, lt=PI_2),
        "angle_points": Number(ge=3, le=1000, integer=True),
        "torque_step": Number("N m", gt=0),
        "min_torque": Number("N m", ge=0),
        "max_torque": Number("N m", gt=0),
        "min_angle": Number("rad", ge=0, lt=PI_2),
        "max_angle": Number("rad", gt=0, lt=PI_2),
        "initial_torque": Number("N m", ge=0),
        "adaptation": Flag(),
        "adaptation_gain": Number(ge=0, le=1),
        "max_bias_height": Number("m", ge=0),
        "max_bias_speed": Number("m/s", ge=0),
    }, checks=(ordered("min_torque", "max_torque"), ordered("min_angle", "max_angle"),
               within("initial_torque", "min_torque", "max_torque"))),
    "stride": Section({
        "ramp_ahead": Flag(default=False),
        "touchdown_grace": Number("s", gt=0, default=0.02),
        "keep_alive": Number("s", gt=0, le=0.1, default=0.003),
        "executor_timeout": Number("s", gt=0, default=0.02),
        "sensing_timeout": Number("s", gt=0, default=0.5),
        "keep_alive_priority_boost": Number(ge=0, le=49, integer=True, default=10),
    }, default={"ramp_ahead": False, "touchdown_grace": 0.02, "keep_alive": 0.003, "executor_timeout": 0.02,
                "sensing_timeout": 0.5, "keep_alive_priority_boost": 10}),
})

# ------------------------------------------------------------------------------------ motor_driver.yaml


def _timeout_above_sync(values: dict):
    if "command_timeout" in values and "sync_period" in values and values["command_timeout"] <= values["sync_period"]:
        return "command_timeout", (f"must be longer than sync_period ({values['sync_period']:g} s), "
                                   f"got {values['command_timeout']:g}")
    return None


def _heartbeat_below_consumer(values: dict):
    consumer, period = values.get("drive_consumer_time", 0.0), values.get("master_heartbeat_period", 0.0)
    if consumer and not 0 < period < consumer:
        return "master_heartbeat_period", (f"must be positive and below drive_consumer_time ({consumer:g} s), "
                                           f"got {period:g}")
    return None


MOTOR_DRIVER_FIELDS = {
    "hardware_file": Text(default=None),
    "sync_period": Number("s", gt=0, le=0.1, default=None),
    "max_ramp_age": Number("s", ge=0, default=None),
    "rpdo_refresh": Number("s", ge=0, default=None),
    "command_timeout": Number("s", gt=0, le=10, default=None),
    "quick_stop_time": Number("s", ge=0, default=None),
    "heartbeat_timeout": Number("s", gt=0, default=None),
    "master_node_id": Number(ge=1, le=127, integer=True, default=None),
    "master_heartbeat_period": Number("s", ge=0, default=None),
    "drive_consumer_time": Number("s", ge=0, le=65.535, default=None),
    "sdo_timeout": Number("s", gt=0, default=None),
    "startup_retry": Number("s", ge=0, default=None),
    "bus_error_holdoff": Number("s", ge=0, default=None),
    "fault_reset_attempts": Number(ge=1, integer=True, default=None),
    "fault_reset_interval": Number("s", ge=0, default=None),
    "shutdown_timeout": Number("s", gt=0, default=None),
    "status_period": Number("s", gt=0, default=None),
    "status_decimation": Number(ge=1, integer=True, default=None),
    "diagnostics_period": Number("s", gt=0, default=None),
}
MOTOR_DRIVER_SECTION = Section(MOTOR_DRIVER_FIELDS, checks=(_timeout_above_sync, _heartbeat_below_consumer))
MOTOR_DRIVER = Section({"motor_driver": MOTOR_DRIVER_SECTION})

# ------------------------------------------------------------------------------------ identification.yaml

FITTABLE = tuple(name for name in MODEL_FIELDS if name != "rest_length")


def _bounds_ordered(values: dict):
    for name, (low, high) in values.items():
        if not low < high:
            return name, f"must be [low, high] with low < high, got [{low:g}, {high:g}]"
    return None


# ModelParams field -> the laws.Coefficients field it sets (toe_mass through the collision factor)
MODEL_COEFFICIENT = {"body_mass": "mass", "toe_mass": "collision_factor", "gravity": "gravity",
                     "stiffness": "stiffness", "damping": "damping", "flight_damping_horizontal": "flight_damping_y",
                     "flight_damping_vertical": "flight_damping_z", "rest_length": "rest_length"}


def check_effects(names, fitted) -> tuple[str, ...]:
    """Validated effect names for an identification that fits the model parameters `fitted`."""
    from hopper_ros.physics import effects as effect_library

    names = tuple(names)
    if len(set(names)) != len(names):
        raise ValueError(f"effects: an effect is named twice: {list(names)}")
    fitted_coefficients = {MODEL_COEFFICIENT[n]: n for n in fitted}
    for name in names:
        effect = effect_library.get(name)
        if effect.kind != "physics":
            raise ValueError(f"effects: {name} is a sensor fault; identify fits physics effects only "
                             "(hopper diagnose estimates sensor faults)")
        coefficient = "collision_factor" if effect.primary.coefficient == "toe_mass" else effect.primary.coefficient
        if coefficient in fitted_coefficients:
            raise ValueError(f"effects: {name} sets {effect.primary.coefficient}, which the fit already fits as the "
                             f"model parameter {fitted_coefficients[coefficient]}; drop one of them (--fit or --effects)")
    return names


def _effects_identifiable(values: dict):
    """The effects are library physics entries, named once, none setting a parameter `fitted` fits."""
    if not values.get("effects"):
        return None
    try:
        check_effects(values["effects"], values.get("fitted", ()))
    except ValueError as exc:
        text = str(exc)
        return "effects", text[len("effects: "):] if text.startswith("effects: ") else text
    return None


IDENTIFICATION = Section({"identification": Section({
    "predictor": Text(choices=IDENTIFICATION_PREDICTORS, default="aas"),
    "folds": Number(ge=2, integer=True),
    "seed": Number(ge=0, integer=True, default=0),
    "fitted": Items(Text(choices=FITTABLE), min_items=1, unique=True),
    "initial": Section(MODEL_FIELDS),
    "bounds": Section(values=Items(Number(gt=0), min_items=2, max_items=2), keys=FITTABLE, checks=(_bounds_ordered,)),
    "nelder_mead": Section({
        "initial_step": Number("log units", gt=0, default=None),
        "xatol": Number("log units", gt=0, default=None),
        "fatol": Number("%", gt=0, default=None),
        "max_evaluations": Number(ge=10, integer=True, default=None),
        "restarts": Number(ge=0, integer=True, default=None),
    }, default={}),
    "exact": Section({
        "defect_iterations": Number(ge=0, integer=True, default=None),
        "defect_step": Number("log units", gt=0, default=None),
        "defect_tolerance": Number("log units", gt=0, default=None),
        "polish_evaluations": Number(ge=0, integer=True, default=None),
        "polish_step": Number("log units", gt=0, default=None),
    }, default={}),
    "effects": Items(Text(), unique=True, default=[],
                     doc="library effects (hopper_ros/physics/effects.py) fitted with the model by the lanes predictor"),
    "lanes": Section({
        "step": Number("s", gt=0, le=0.002, default=None),
        "duration_factor": Number(ge=1, default=None),
        "fd_step": Number("log units or share of the search range", gt=0, lt=0.1, default=None),
        "max_iterations": Number(ge=1, integer=True, default=None),
        "initial_radius": Number("log units", gt=0, default=None),
        "xtol": Number(gt=0, default=None),
        "ftol": Number(gt=0, default=None),
        "polish_iterations": Number(ge=0, integer=True, default=None),
        "batch_lanes": Number("lanes", ge=1, integer=True, default=None),
    }, default={}),
    "failed_stride_error_pct": Number("%", ge=0, default=100.0),
    "extraction": Section({
        "apex_window": Number("s", gt=0, default=None),
        "speed_window": Number("s", gt=0, default=None),
        "min_apex_points": Number(ge=3, integer=True, default=None),
        "edge_guard": Number("s", ge=0, default=None),
        "min_phase": Number("s", ge=0, default=None),
        "touchdown_samples": Number(ge=1, integer=True, default=None),
        "zero_torque": Number("N m", ge=0, default=None),
        "torque_skip": Number("s", ge=0, default=None),
        "max_ramp_duration": Number("s", gt=0, default=None),
        "max_stance_time": Number("s", gt=0, default=None),
        "min_forward_speed": Number("m/s", ge=0, default=None),
    }, default={}),
    "grf": Section({
        "sigma_jerk": Number("m/s^3", gt=0, default=None),
        "position_noise": Number("m", gt=0, default=None),
        "moving_average": Number("samples", ge=1, integer=True, default=None),
        "apex_height": Number("m", gt=0, default=None),
        "forward_speed": Number("m/s", default=None),
        "touchdown_angle_deg": Number("deg", gt=-90, lt=90, default=None),
        "tau_0": Number("N m", default=None),
    }, default={}),
}, checks=(_effects_identifiable,))})

# ------------------------------------------------------------------------------------ setpoint schedules


def _strides_or_seconds(values: dict):
    if values.get("strides") is not None and values.get("seconds") is not None:
        return "seconds", "give either strides or seconds, not both"
    return None


SCHEDULE = Section({
    "segments": Items(Section({
        "apex_height": Number("m", gt=0),
        "forward_speed": Number("m/s"),
        "strides": Number(ge=1, integer=True, default=None),
        "seconds": Number("s", gt=0, default=None),
    }, checks=(_strides_or_seconds,)), min_items=1),
    "repeat": Flag(default=False),
})


# ------------------------------------------------------------------------------------ loaders


def load_model(name="model.yaml"):
    """A model parameter file, validated, as ModelParams (hopper_ros.physics.params). An identified
    model's `effects:` are validated too (hopper_ros.physics.params.load_model, which returns them)
    and left out here: the controller, the predictor and the detector use the model alone."""
    from hopper_ros.config.files import config_path
    from hopper_ros.physics.params import load_model as load_params_and_effects
    from hopper_ros.config.schema import ConfigError, load_config

    load_config(name, MODEL)
    try:
        return load_params_and_effects(config_path(name))[0]
    except ValueError as exc:           # physical checks across parameters (damping ratio)
        text = str(exc)
        raise ConfigError(text if str(config_path(name)) in text else f"{config_path(name)}: model: {text}") from None
