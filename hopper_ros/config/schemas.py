"""One pydantic model per configuration file (hopper_ros/config/schema.py: `Section`, strict types,
units as field metadata, unknown keys refused, one-line errors). No ROS import.

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
| diagnosis.yaml | hopper_ros.diagnosis.settings.DIAGNOSIS (from its `Settings`) | diagnose |
| import mappings | hopper_ros.recording.mapping_file.SCHEMA | import, diagnose --map |

The launch files' entities are checked by the models of hopper_ros/launch/entities.py.
"""

import math
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field, model_validator

from hopper_ros.config.schema import DISTINCT, Problem, Section, at_most, choice, ordered, unit, within

PI_2 = math.pi / 2
Sign = choice(-1, 1)

# ------------------------------------------------------------------------------------ hardware.yaml


class Encoder(Section):
    lines: int = unit("lines", gt=0)
    quadrature: choice(1, 2, 4)
    transmission: float = unit("encoder turns per turn", gt=0)
    direction: Sign
    offset_counts: int = unit("counts")


class Encoders(Section):
    azimuth: Encoder = Field(description="planarizer, forward")
    elevation: Encoder = Field(description="planarizer, vertical")
    motor: Encoder = Field(description="hip motor")


class Boom(Section):
    length: float = unit("m", gt=0)
    parallel_height: float = unit("m", ge=0)
    leg_offset: float = unit("m")
    ground_height: float = unit("m", ge=0)


class Motor(Section):
    gear_ratio: float = Field(gt=0)
    torque_constant: float = unit("N m/A", gt=0)
    direction: Sign
    rotor_inertia: float = unit("kg m^2", gt=0)
    leg_inertia: float = unit("kg m^2", gt=0)
    viscous_friction: float = unit("N m s/rad", ge=0)


class PositionGains(Section):
    p: int = Field(ge=0, le=32767)
    i: int = Field(ge=0, le=32767)
    d: int = Field(ge=0, le=32767)


class Drive(Section):
    node_id: int = Field(ge=1, le=127)
    current_limit: float = unit("A", gt=0)
    continuous_current: float = unit("A", gt=0)
    position_gains: PositionGains
    heartbeat_period: float = unit("s", gt=0, le=65.535)

    @model_validator(mode="after")
    def _continuous_within_limit(self):
        at_most(self, "continuous_current", "current_limit", "A")
        return self


class Microcontroller(Section):
    host: str
    port: int = Field(ge=1, le=65535)
    sample_period: float = unit("s", gt=0, le=0.1)


class Can(Section):
    interface: str
    channel: str = None
    host: str = None
    port: int = Field(None, ge=1, le=65535)
    bitrate: int = unit("bit/s", None, gt=0)
    connect_timeout: float = unit("s", None, gt=0)


class HARDWARE(Section):
    boom: Boom
    encoders: Encoders
    motor: Motor
    drive: Drive
    microcontroller: Microcontroller
    can: Can

# ------------------------------------------------------------------------------------ model.yaml


class ModelParameters(Section):
    """The extended TD-SLIP model's parameters (ModelParams' fields)."""

    body_mass: float = unit("kg", gt=0)
    toe_mass: float = unit("kg", ge=0)
    gravity: float = unit("m/s^2", gt=0)
    stiffness: float = unit("N/m", gt=0)
    damping: float = unit("N s/m", ge=0)
    flight_damping_horizontal: float = unit("1/s", ge=0)
    flight_damping_vertical: float = unit("1/s", ge=0)
    rest_length: float = unit("m", gt=0)


MODEL_FIELDS = tuple(ModelParameters.model_fields)


class MODEL(Section):
    model: ModelParameters
    # an identified model's library effects {name: magnitude} (`hopper identify --effects`): names,
    # numbers and which may be infinite are checked by hopper_ros.physics.params.load_model
    effects: Any = Field(None, description="{effect library name: magnitude}, checked by physics.params.load_model")

# ------------------------------------------------------------------------------------ sim.yaml


class EncoderNoise(Section):
    enabled: bool
    counts: float = unit("counts", ge=0)


class CurrentNoise(Section):
    enabled: bool
    current: float = unit("A", ge=0)


class ForcePlateNoise(Section):
    enabled: bool
    force: float = unit("N", ge=0)


class Sensors(Section):
    encoder_noise: EncoderNoise
    current_noise: CurrentNoise
    force_plate_noise: ForcePlateNoise


class ForcePlate(Section):
    contact_threshold: float = unit("N", ge=0)


class Experiment(Section):
    pre_touchdown_height: float = unit("m", ge=0)


class InitialApex(Section):
    apex_height: float = unit("m", gt=0)
    forward_speed: float = unit("m/s")
    leg_angle: float = unit("rad", gt=-PI_2, lt=PI_2)


class Sim(Section):
    period: float = unit("s", gt=0, le=0.1)
    substeps: int = Field(ge=1, le=1000)
    physics: ModelParameters
    effects: Any = Field(description="entries of the effect library, checked by hopper_ros.sim.config (library "
                         "names, each one's parameter)")
    sensors: Sensors
    force_plate: ForcePlate
    experiment: Experiment
    initial_apex: InitialApex
    seed: int = Field(0, ge=0)


class SIM(Section):
    sim: Sim

# ------------------------------------------------------------------------------------ sensing.yaml


class Bridge(Section):
    receive_buffer_bytes: int = unit("bytes", ge=0)
    clock_tolerance: float = unit("s", ge=0)
    reorder_window: int = unit("packets", ge=0)
    resync_after: int = unit("packets", ge=2)


class Estimator(Section):
    vertical_process_noise: float = unit("m s^-2.5", gt=0)
    horizontal_process_noise: float = unit("m s^-2.5", gt=0)
    measurement_noise: Literal["quantization", "thesis"]
    quantization_std_counts: float = unit("counts", gt=0)
    leg_process_noise: float = unit("rad s^-1.5", gt=0)
    initial_velocity_std: float = unit("m/s", ge=0)
    initial_acceleration_std: float = unit("m/s^2", ge=0)
    initial_leg_rate_std: float = unit("rad/s", ge=0)
    outlier_gate: float = unit("sigma", gt=0)
    reinitialise_after: int = unit("samples", ge=1)
    max_prediction_gap: float = unit("s", gt=0)
    clock_drift_rate: float = unit("s/s", ge=0)
    clock_max_error: float = unit("s", ge=0)
    clock_max_lag: float = unit("s", ge=0)
    clock_reanchor_after: float = unit("s", ge=0)


class Detector(Section):
    pre_touchdown_height: float = unit("m", ge=0)
    pre_touchdown_lead: float = unit("s", ge=0)
    flight_fit_settle: float = unit("s", ge=0)
    flight_fit_max_residual: float = unit("m", ge=0)
    bottom_hysteresis: float = unit("m/s", ge=0)
    touchdown_arming_clearance: float = unit("m", ge=0)
    acquire_velocity: float = unit("m/s", ge=0)
    acquire_clearance: float = unit("m", ge=0)
    acquire_window: float = unit("s", ge=0)
    acquire_velocity_std: float = unit("m/s", gt=0)
    track_velocity_std: float = unit("m/s", gt=0)
    max_state_spacing: float = unit("s", ge=0)
    sample_deadline: float = unit("s", ge=0)

    @model_validator(mode="after")
    def _acquire_below_track(self):
        at_most(self, "acquire_velocity_std", "track_velocity_std", "m/s")
        return self


class Sensing(Section):
    hardware_file: str
    model_file: str
    diagnostics_period: float = unit("s", gt=0)
    queue_depth: int = unit("samples", ge=1)
    bridge: Bridge
    estimator: Estimator
    detector: Detector


class SENSING(Section):
    sensing: Sensing

# ------------------------------------------------------------------------------------ control.yaml


PREDICTORS = ("aas", "corrected", "exact")
# identification's: the model library's predictors and "lanes" (the laws with library effects)
IDENTIFICATION_PREDICTORS = PREDICTORS + ("lanes",)


class Deadbeat(Section):
    predictor: Literal[PREDICTORS]
    angle_span: float = unit("rad", gt=0, lt=PI_2)
    angle_points: int = Field(ge=3, le=1000)
    torque_step: float = unit("N m", gt=0)
    min_torque: float = unit("N m", ge=0)
    max_torque: float = unit("N m", gt=0)
    min_angle: float = unit("rad", ge=0, lt=PI_2)
    max_angle: float = unit("rad", gt=0, lt=PI_2)
    min_apex_height: float = unit("m", gt=0)
    initial_torque: float = unit("N m", ge=0)
    adaptation: bool
    adaptation_gain: float = Field(ge=0, le=1)
    max_bias_height: float = unit("m", ge=0)
    max_bias_speed: float = unit("m/s", ge=0)
    adaptation_outlier: float = Field(ge=0)
    adaptation_floor_height: float = unit("m", ge=0)
    adaptation_floor_speed: float = unit("m/s", ge=0)

    @model_validator(mode="after")
    def _ranges(self):
        ordered(self, "min_torque", "max_torque")
        ordered(self, "min_angle", "max_angle")
        within(self, "initial_torque", "min_torque", "max_torque")
        return self


class Stride(Section):
    ramp_ahead: bool = False
    touchdown_grace: float = unit("s", 0.02, gt=0)
    stand_still_step: float = unit("s", 0.01, gt=0)
    keep_alive: float = unit("s", 0.003, gt=0, le=0.1)
    executor_timeout: float = unit("s", 0.02, gt=0)
    sensing_timeout: float = unit("s", 0.5, gt=0)
    keep_alive_priority_boost: int = Field(10, ge=0, le=49)
    fault_acknowledge: float = unit("s", 0.02, gt=0, le=1.0)
    settled_angle: float = unit("rad", 0.05, gt=0)
    settled_rate: float = unit("rad/s", 5.0, gt=0)
    release_lead: float = unit("s", 0.003, ge=0)


class CONTROL(Section):
    deadbeat: Deadbeat
    stride: Stride = Field(default_factory=Stride)

# ------------------------------------------------------------------------------------ motor_driver.yaml


class MOTOR_DRIVER_SECTION(Section):
    hardware_file: str = None
    sync_period: float = unit("s", None, gt=0, le=0.1)
    max_ramp_age: float = unit("s", None, ge=0)
    rpdo_refresh: float = unit("s", None, ge=0)
    command_timeout: float = unit("s", None, gt=0, le=10)
    quick_stop_time: float = unit("s", None, ge=0)
    heartbeat_timeout: float = unit("s", None, gt=0)
    master_node_id: int = Field(None, ge=1, le=127)
    master_heartbeat_period: float = unit("s", None, ge=0)
    drive_consumer_time: float = unit("s", None, ge=0, le=65.535)
    sdo_timeout: float = unit("s", None, gt=0)
    startup_retry: float = unit("s", None, ge=0)
    bus_error_holdoff: float = unit("s", None, ge=0)
    fault_reset_attempts: int = Field(None, ge=1)
    fault_reset_interval: float = unit("s", None, ge=0)
    shutdown_timeout: float = unit("s", None, gt=0)
    status_period: float = unit("s", None, gt=0)
    status_decimation: int = Field(None, ge=1)
    diagnostics_period: float = unit("s", None, gt=0)

    @model_validator(mode="after")
    def _timing(self):
        if None not in (self.command_timeout, self.sync_period) and self.command_timeout <= self.sync_period:
            raise Problem("command_timeout", f"must be longer than sync_period ({self.sync_period:g} s), "
                                             f"got {self.command_timeout:g}")
        consumer, period = self.drive_consumer_time or 0.0, self.master_heartbeat_period or 0.0
        if consumer and not 0 < period < consumer:
            raise Problem("master_heartbeat_period", f"must be positive and below drive_consumer_time ({consumer:g} "
                                                     f"s), got {period:g}")
        return self


class MOTOR_DRIVER(Section):
    motor_driver: MOTOR_DRIVER_SECTION

# ------------------------------------------------------------------------------------ identification.yaml


FITTABLE = tuple(name for name in MODEL_FIELDS if name != "rest_length")

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


def _bounds_ordered(bounds: dict) -> dict:
    for name, (low, high) in bounds.items():
        if not low < high:
            raise Problem(name, f"must be [low, high] with low < high, got [{low:g}, {high:g}]")
    return bounds


Fittable = Literal[FITTABLE]
Positive = Annotated[float, Field(gt=0)]


class NelderMead(Section):
    initial_step: float = unit("log units", None, gt=0)
    xatol: float = unit("log units", None, gt=0)
    fatol: float = unit("%", None, gt=0)
    max_evaluations: int = Field(None, ge=10)
    restarts: int = Field(None, ge=0)


class Exact(Section):
    defect_iterations: int = Field(None, ge=0)
    defect_step: float = unit("log units", None, gt=0)
    defect_tolerance: float = unit("log units", None, gt=0)
    polish_evaluations: int = Field(None, ge=0)
    polish_step: float = unit("log units", None, gt=0)


class Lanes(Section):
    step: float = unit("s", None, gt=0, le=0.002)
    duration_factor: float = Field(None, ge=1)
    fd_step: float = unit("log units or share of the search range", None, gt=0, lt=0.1)
    max_iterations: int = Field(None, ge=1)
    initial_radius: float = unit("log units", None, gt=0)
    xtol: float = Field(None, gt=0)
    ftol: float = Field(None, gt=0)
    polish_iterations: int = Field(None, ge=0)
    batch_lanes: int = unit("lanes", None, ge=1)


class Extraction(Section):
    apex_window: float = unit("s", None, gt=0)
    speed_window: float = unit("s", None, gt=0)
    min_apex_points: int = Field(None, ge=3)
    edge_guard: float = unit("s", None, ge=0)
    min_phase: float = unit("s", None, ge=0)
    touchdown_samples: int = Field(None, ge=1)
    zero_torque: float = unit("N m", None, ge=0)
    torque_skip: float = unit("s", None, ge=0)
    late_torque: float = unit("s", None, ge=0)
    max_ramp_duration: float = unit("s", None, gt=0)
    max_stance_time: float = unit("s", None, gt=0)
    min_forward_speed: float = unit("m/s", None, ge=0)


class Grf(Section):
    sigma_jerk: float = unit("m/s^3", None, gt=0)
    position_noise: float = unit("m", None, gt=0)
    moving_average: int = unit("samples", None, ge=1)
    apex_height: float = unit("m", None, gt=0)
    forward_speed: float = unit("m/s", None)
    touchdown_angle_deg: float = unit("deg", None, gt=-90, lt=90)
    tau_0: float = unit("N m", None)


class Identification(Section):
    predictor: Literal[IDENTIFICATION_PREDICTORS] = "aas"
    folds: int = Field(ge=2)
    seed: int = Field(0, ge=0)
    fitted: Annotated[list[Fittable], DISTINCT] = Field(min_length=1)
    initial: ModelParameters
    bounds: Annotated[dict[Fittable, Annotated[list[Positive], Field(min_length=2, max_length=2)]],
                      AfterValidator(_bounds_ordered)]
    nelder_mead: NelderMead = Field(default_factory=NelderMead)
    exact: Exact = Field(default_factory=Exact)
    effects: Annotated[list[str], DISTINCT] = Field(
        [], description="library effects (hopper_ros/physics/effects.py) fitted with the model by the lanes predictor")
    lanes: Lanes = Field(default_factory=Lanes)
    failed_stride_error_pct: float = unit("%", 100.0, ge=0)
    extraction: Extraction = Field(default_factory=Extraction)
    grf: Grf = Field(default_factory=Grf)

    @model_validator(mode="after")
    def _effects_identifiable(self):
        """The effects are library physics entries, named once, none setting a parameter `fitted` fits."""
        if self.effects:
            try:
                check_effects(self.effects, self.fitted)
            except ValueError as exc:
                raise Problem("effects", str(exc).removeprefix("effects: ")) from None
        return self


class IDENTIFICATION(Section):
    identification: Identification

# ------------------------------------------------------------------------------------ setpoint schedules


class Segment(Section):
    apex_height: float = unit("m", gt=0)
    forward_speed: float = unit("m/s")
    strides: int = Field(None, ge=1)
    seconds: float = unit("s", None, gt=0)

    @model_validator(mode="after")
    def _strides_or_seconds(self):
        if self.strides is not None and self.seconds is not None:
            raise Problem("seconds", "give either strides or seconds, not both")
        return self


class SCHEDULE(Section):
    segments: list[Segment] = Field(min_length=1)
    repeat: bool = False


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
