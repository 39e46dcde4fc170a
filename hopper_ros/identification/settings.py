"""Identification settings (config/identification.yaml), validated with errors naming the key."""

from __future__ import annotations

import os
from dataclasses import dataclass, fields, replace
from typing import Any, Mapping

from hopper_ros.config import load_yaml
from hopper_ros.physics.params import ModelParams
from hopper_ros.physics.predictors import PREDICTORS

from .strides import ExtractionSettings

DEFAULT_FILE = "identification.yaml"
PARAMETERS = tuple(f.name for f in fields(ModelParams))
FITTABLE = tuple(name for name in PARAMETERS if name != "rest_length")
# the model library's predictors, and "lanes": the laws with library effects (physics.lanes, `lanesfit`)
IDENTIFICATION_PREDICTORS = PREDICTORS + ("lanes",)


@dataclass(frozen=True)
class NelderMeadSettings:
    initial_step: float = 0.15
    xatol: float = 1e-5
    fatol: float = 1e-7
    max_evaluations: int = 6000
    restarts: int = 2


@dataclass(frozen=True)
class ExactSettings:
    defect_iterations: int = 3
    defect_step: float = 0.02
    defect_tolerance: float = 1e-3
    polish_evaluations: int = 0
    polish_step: float = 0.005


@dataclass(frozen=True)
class LanesSettings:
    """The "lanes" predictor's fit (identification with effects, `lanesfit`)."""

    step: float = 5e-4              # [s] RK4 step of physics.lanes
    duration_factor: float = 1.5    # simulated time: this times the longest recorded stride
    fd_step: float = 1e-2           # forward-difference step (ln(parameter); share of an effect's search range)
    max_iterations: int = 30        # least squares: evaluations (each one lanes call with its Jacobian)
    initial_radius: float = 0.5     # first trust radius of the least squares (in ln(parameter))
    xtol: float = 1e-3
    ftol: float = 1e-3
    polish_iterations: int = 0      # then L-BFGS-B iterations on C (4.4); 0: least squares only
    batch_lanes: int = 8000         # the folds' lanes calls are batched up to this many lanes per call


@dataclass(frozen=True)
class GrfSettings:
    sigma_jerk: float = 60.0
    position_noise: float = 1.3e-4
    moving_average: int = 5
    apex_height: float = 0.36
    forward_speed: float = 2.0
    touchdown_angle_deg: float = 17.0
    tau_0: float = 5.0


@dataclass(frozen=True)
class IdentificationSettings:
    predictor: str
    folds: int
    seed: int
    fitted: tuple[str, ...]
    initial: ModelParams
    bounds: dict[str, tuple[float, float]]
    nelder_mead: NelderMeadSettings
    exact: ExactSettings
    failed_stride_error_pct: float
    extraction: ExtractionSettings
    grf: GrfSettings = GrfSettings()
    lanes: LanesSettings = LanesSettings()
    effects: tuple[str, ...] = ()      # library effects fitted with the model (the "lanes" predictor only)

    def with_changes(self, **changes) -> "IdentificationSettings":
        out = replace(self, **changes)
        _validate(out, "settings")
        return out


def settings_from_dict(data: Mapping[str, Any], source: str = "identification settings") -> IdentificationSettings:
    """From the parsed file (with or without the `identification:` level), checked by its schema
    (hopper_ros.config.schemas.IDENTIFICATION: types, ranges with units, unknown and missing keys),
    then across keys (`_validate`: bounds, the initial point inside them)."""
    from hopper_ros.config.schemas import IDENTIFICATION
    from hopper_ros.config.schema import validate

    if not (isinstance(data, Mapping) and "identification" in data):
        data = {"identification": data}
    d = validate(IDENTIFICATION, data, source)["identification"]
    settings = IdentificationSettings(
        predictor=d["predictor"],
        folds=d["folds"],
        seed=d["seed"],
        fitted=tuple(d["fitted"]),
        initial=ModelParams.from_dict(d["initial"], source=f"{source}: identification.initial"),
        bounds={name: (pair[0], pair[1]) for name, pair in d["bounds"].items()},
        nelder_mead=NelderMeadSettings(**d["nelder_mead"]),
        exact=ExactSettings(**d["exact"]),
        failed_stride_error_pct=d["failed_stride_error_pct"],
        extraction=ExtractionSettings.from_dict(d["extraction"], f"{source}: identification.extraction"),
        grf=GrfSettings(**d["grf"]),
        lanes=LanesSettings(**d["lanes"]),
        effects=tuple(d["effects"]),
    )
    _validate(settings, source)
    return settings


def _validate(s: IdentificationSettings, source: str) -> None:
    if s.predictor not in IDENTIFICATION_PREDICTORS:
        raise ValueError(f"{source}: identification.predictor: {s.predictor!r} is not one of {IDENTIFICATION_PREDICTORS}")
    if s.folds < 2:
        raise ValueError(f"{source}: identification.folds: must be at least 2, got {s.folds}")
    unknown = [name for name in s.fitted if name not in FITTABLE]
    if unknown or not s.fitted:
        raise ValueError(f"{source}: fitted must name some of {list(FITTABLE)}, got {list(s.fitted)}")
    if len(set(s.fitted)) != len(s.fitted):
        raise ValueError(f"{source}: fitted names a parameter twice: {list(s.fitted)}")
    for name in s.fitted:
        if name not in s.bounds:
            raise ValueError(f"{source}: identification.bounds.{name}: missing (fitted parameters need bounds)")
        low, high = s.bounds[name]
        if not 0.0 < low < high:
            raise ValueError(f"{source}: bounds of {name} must be 0 < low < high, got [{low}, {high}]")
        value = getattr(s.initial, name)
        if not low <= value <= high:
            raise ValueError(f"{source}: identification.initial.{name}: {value:g} is outside its bounds [{low:g}, {high:g}]")
    if s.nelder_mead.max_evaluations < 10 or s.nelder_mead.initial_step <= 0:
        raise ValueError(f"{source}: nelder_mead needs max_evaluations >= 10 and a positive initial_step")
    lanes = s.lanes
    if not (0 < lanes.step <= 2e-3 and lanes.duration_factor >= 1.0 and 0 < lanes.fd_step < 0.1
            and lanes.max_iterations >= 1 and lanes.polish_iterations >= 0 and lanes.initial_radius > 0
            and lanes.batch_lanes >= 1):
        raise ValueError(f"{source}: lanes needs 0 < step <= 0.002, duration_factor >= 1, 0 < fd_step < 0.1, "
                         f"max_iterations >= 1, polish_iterations >= 0, initial_radius > 0, batch_lanes >= 1; got {lanes}")
    if s.effects:
        from hopper_ros.config.schemas import check_effects

        try:
            check_effects(s.effects, s.fitted)
        except ValueError as exc:
            text = str(exc)
            raise ValueError(f"{source}: identification.{text}" if text.startswith("effects:")
                             else f"{source}: identification.effects: {text}") from None


def load_settings(name: str | os.PathLike = DEFAULT_FILE) -> IdentificationSettings:
    from hopper_ros.config import config_path

    return settings_from_dict(load_yaml(name), source=str(config_path(name)))
