"""Model parameters of the extended TD-SLIP model (Table 4.1), YAML load/save, validation.

A model file holds the parameters, bare or under `model:`; an identified model with library
effects (`hopper identify --effects`) adds `effects: {name: physical magnitude}` (names of
`physics.effects`, magnitudes in their primary parameter's unit). `load_params` returns the
parameters of either (the controller and the estimator use the model alone); `load_model`
returns the parameters and the effects.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Mapping

import yaml

from hopper_ros.config import load_yaml

DEFAULT_FILE = "model.yaml"


@dataclass(frozen=True)
class ModelParams:
    """Physical parameters; defaults are the thesis's identified means (Table 4.1).

    The flight damping coefficients act per unit mass, (2.8): y'' = -d_h^f y'. Their unit is
    therefore 1/s, not the N s/m printed in Table 4.1.
    """

    body_mass: float = 2.20                  # m_b [kg]
    toe_mass: float = 0.03                   # m_t [kg], only in the lift-off collision (2.12)
    gravity: float = 11.42                   # g [m/s^2], boom-corrected gravity (section 4.3.1.1)
    stiffness: float = 4696.0                # k [N/m]
    damping: float = 9.87                    # d [N s/m]
    flight_damping_horizontal: float = 0.01  # d_h^f [1/s]
    flight_damping_vertical: float = 0.23    # d_v^f [1/s]
    rest_length: float = 0.205               # rho_0 [m]

    def __post_init__(self) -> None:
        validate(self)

    @property
    def damping_ratio(self) -> float:
        """Leg damping ratio d / (2 sqrt(k m_b)); the AAS needs it below 1."""
        return self.damping / (2.0 * math.sqrt(self.stiffness * self.body_mass))

    @property
    def collision_factor(self) -> float:
        """Velocity ratio of the lift-off collision, m_b / (m_b + m_t), (2.12)."""
        return self.body_mass / (self.body_mass + self.toe_mass)

    def replace(self, **changes: float) -> "ModelParams":
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict[str, float]:
        return {f.name: float(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls, values: Mapping[str, Any], source: str = "parameters") -> "ModelParams":
        """Build from a mapping holding every field; unknown or missing keys are errors."""
        if not isinstance(values, Mapping):
            raise ValueError(f"{source}: expected a mapping of parameter names to numbers")
        names = [f.name for f in fields(cls)]
        unknown = sorted(set(values) - set(names))
        missing = [n for n in names if n not in values]
        if unknown:
            raise ValueError(f"{source}: unknown parameter(s) {unknown}; known: {names}")
        if missing:
            raise ValueError(f"{source}: missing parameter(s) {missing}")
        converted = {}
        for name in names:
            value = values[name]
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{source}: {name} must be a number, got {value!r}")
            converted[name] = float(value)
        try:
            return cls(**converted)
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None


def validate(p: ModelParams) -> None:
    """Reject non-physical values with an error naming the parameter."""
    for f in fields(p):
        value = getattr(p, f.name)
        if not math.isfinite(value):
            raise ValueError(f"{f.name} must be finite, got {value}")
    positive = ("body_mass", "gravity", "stiffness", "rest_length")
    non_negative = ("toe_mass", "damping", "flight_damping_horizontal", "flight_damping_vertical")
    for name in positive:
        if getattr(p, name) <= 0.0:
            raise ValueError(f"{name} must be positive, got {getattr(p, name)}")
    for name in non_negative:
        if getattr(p, name) < 0.0:
            raise ValueError(f"{name} must not be negative, got {getattr(p, name)}")
    if p.damping_ratio >= 1.0:
        raise ValueError(
            f"damping ratio d/(2 sqrt(k m_b)) = {p.damping_ratio:.3f} must be below 1 "
            f"(damping={p.damping}, stiffness={p.stiffness}, body_mass={p.body_mass})"
        )


def load_params(name: str | os.PathLike = DEFAULT_FILE) -> ModelParams:
    """Load a complete parameter set from `config/<name>` or a path.

    A file with `effects:` (an identified model with library effects) gives its model parameters
    here; `load_model` gives the effects too."""
    data = load_yaml(name)
    if isinstance(data, Mapping) and "model" in data:
        data = data["model"]
    return ModelParams.from_dict(data, source=str(name))


def load_model(name: str | os.PathLike = DEFAULT_FILE) -> tuple[ModelParams, dict[str, float]]:
    """(parameters, effects {name: physical magnitude}) of a model file; effects {} when it has none.

    Effect names are checked against the library (`physics.effects.get`), magnitudes must be
    numbers (not NaN; infinite only for an effect whose "off" is infinity, e.g. torque_saturation);
    errors name the file and the key."""
    from hopper_ros.physics import effects as library

    source = str(name)
    data = load_yaml(name)
    if not isinstance(data, Mapping):
        raise ValueError(f"{source}: expected a mapping of parameter names to numbers (or `model:` and `effects:`)")
    if "model" not in data:
        if "effects" in data:
            raise ValueError(f"{source}: a model file with `effects:` must hold its parameters under `model:`")
        return ModelParams.from_dict(data, source=source), {}
    unknown = sorted(set(data) - {"model", "effects"})
    if unknown:
        raise ValueError(f"{source}: unknown top-level key(s) {unknown}; a model file has `model:` and `effects:`")
    params = ModelParams.from_dict(data["model"], source=f"{source}: model")
    raw = data.get("effects") or {}
    if not isinstance(raw, Mapping):
        raise ValueError(f"{source}: effects must be a mapping of effect names to magnitudes, got {raw!r}")
    effects: dict[str, float] = {}
    for key, value in raw.items():
        try:
            effect = library.get(str(key))
        except ValueError as exc:
            raise ValueError(f"{source}: effects.{key}: {exc}") from None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
            raise ValueError(f"{source}: effects.{key} must be a number ({effect.primary.name} "
                             f"[{effect.primary.unit or '1'}]), got {value!r}")
        if math.isinf(value) and not effect.primary.inverse:
            raise ValueError(f"{source}: effects.{key} must be finite, got {value!r}")
        effects[str(key)] = float(value)
    return params, effects


def save_params(params: ModelParams, path: str | os.PathLike, comment: str = "",
                effects: Mapping[str, float] | None = None) -> Path:
    """Write a parameter set as YAML (the format `load_params` reads); with `effects` ({name: physical
    magnitude}) as `model:` plus `effects:` (the format `load_model` reads)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = "".join(f"# {line}\n" for line in comment.splitlines())
    document: dict[str, Any] = {"model": params.as_dict()}
    if effects:
        document["effects"] = {str(name): float(value) for name, value in effects.items()}
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(header)
        yaml.safe_dump(document, handle, sort_keys=False)
    return path
