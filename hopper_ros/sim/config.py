"""Configuration of the simulated robot (config/sim.yaml): physics, effects, sensors.

The true robot is `physics` (the extended TD-SLIP model's parameters, what config/model.yaml
holds) plus the enabled `effects`. An effect is an entry of the effect library
(`hopper_ros.physics.effects.LIBRARY`), named as there, with `enabled` and its parameter by the
library's name for it (`effects.get(name).primary.name`), in the parameter's physical unit:

    leg_friction: {enabled: true, F_c: 2.0}

`SimConfig.coefficients()` is the robot as `laws.Coefficients` (the plant integrates the laws of
`hopper_ros.physics.laws` with them). `SimConfig.with_effects` switches effects on or off or
changes a magnitude without touching the file, e.g.

    config.with_effects(leg_friction={"F_c": 3.0}, ground_compliance=True, actuation_delay=False)
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
from dataclasses import dataclass, fields
from typing import Any, Mapping

from hopper_ros.physics import effects as library
from hopper_ros.physics import laws
from hopper_ros.physics.params import ModelParams

DEFAULT_FILE = "sim.yaml"

# every physics entry of the effect library -> the name of its parameter
EFFECTS: dict[str, str] = {effect.name: effect.primary.name for effect in library.LIBRARY}
SENSORS: dict[str, tuple[str, ...]] = {
    "encoder_noise": ("counts",),
    "current_noise": ("current",),
    "force_plate_noise": ("force",),
}
PHYSICS = tuple(f.name for f in fields(ModelParams))


def _section(data: Mapping[str, Any], key: str, source: str) -> Mapping[str, Any]:
    value = data.get(key)
    if not isinstance(value, Mapping):
        raise ValueError(f"{source}: sim.{key} must be a mapping")
    return value


def _switches(data: Mapping[str, Any], known: Mapping[str, tuple[str, ...]], where: str) -> dict[str, dict]:
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ValueError(f"{where}: unknown name(s) {unknown}; known: {sorted(known)}")
    result = {}
    for name, keys in known.items():
        entry = data.get(name)
        if not isinstance(entry, Mapping) or not isinstance(entry.get("enabled"), bool):
            raise ValueError(f"{where}.{name}: needs `enabled: true|false` and {list(keys)}")
        values = {"enabled": entry["enabled"]}
        for key in keys:
            value = entry.get(key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
                raise ValueError(f"{where}.{name}.{key} must be a non-negative number, got {value!r}")
            values[key] = float(value)
        extra = sorted(set(entry) - set(keys) - {"enabled"})
        if extra:
            raise ValueError(f"{where}.{name}: unknown key(s) {extra}; known: {['enabled', *keys]}")
        result[name] = values
    return result


def _known_effect(name: str, where: str) -> library.Effect:
    if name not in EFFECTS:
        if name in library.EFFECTS:
            raise ValueError(f"{where}: {name!r} is a sensor fault of the effect library, not physics; the simulated "
                             f"robot's sensors are configured under sim.sensors")
        raise ValueError(f"{where}: unknown effect {name!r}; known (hopper_ros/physics/effects.py): "
                         f"{', '.join(EFFECTS)}")
    return library.get(name)


def _effect_entry(name: str, entry: Any, where: str) -> dict:
    """One `effects:` entry checked against the library: {enabled: bool, <parameter>: number}."""
    effect = _known_effect(name, where)
    parameter = effect.primary
    if not isinstance(entry, Mapping) or not isinstance(entry.get("enabled"), bool):
        raise ValueError(f"{where}.{name}: needs `enabled: true|false` and `{parameter.name}` [{parameter.unit}]")
    extra = sorted(set(entry) - {"enabled", parameter.name})
    if extra:
        raise ValueError(f"{where}.{name}: unknown key(s) {extra}; known: ['enabled', '{parameter.name}']")
    value = entry.get(parameter.name)
    key = f"{where}.{name}.{parameter.name}"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{key} must be a number [{parameter.unit}], got {value!r}")
    if (parameter.inverse or (parameter.relative and parameter.low > 0)) and value <= 0:
        raise ValueError(f"{key} must be a positive number [{parameter.unit}], got {value!r}")
    if parameter.low >= 0 and value < 0:
        raise ValueError(f"{key} must be a non-negative number [{parameter.unit}], got {value!r}")
    return {"enabled": entry["enabled"], parameter.name: float(value)}


def _effects(data: Mapping[str, Any], where: str) -> dict[str, dict]:
    return {name: _effect_entry(name, entry, where) for name, entry in data.items()}


def _physics(data: Mapping[str, Any], source: str) -> dict[str, float]:
    return ModelParams.from_dict(data, source=f"{source}: sim.physics").as_dict()


@dataclass(frozen=True)
class InitialApex:
    """sim.yaml `initial_apex`: the first throw."""

    apex_height: float       # [m]
    forward_speed: float     # [m/s]
    leg_angle: float         # [rad]


@dataclass(frozen=True)
class SimConfig:
    period: float
    substeps: int
    physics: dict[str, float]       # the extended TD-SLIP model's parameters (ModelParams' fields)
    effects: dict[str, dict]        # library name -> {enabled, <parameter>: value}
    sensors: dict[str, dict]
    contact_threshold: float
    pre_touchdown_height: float
    initial_apex: InitialApex
    seed: int

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "sim config") -> "SimConfig":
        if isinstance(data, Mapping) and "sim" in data:
            data = data["sim"]
        if not isinstance(data, Mapping):
            raise ValueError(f"{source}: expected a mapping under `sim:`")
        try:
            config = cls(
                period=float(data["period"]), substeps=int(data["substeps"]),
                physics=_physics(_section(data, "physics", source), source),
                effects=_effects(_section(data, "effects", source), f"{source}: sim.effects"),
                sensors=_switches(_section(data, "sensors", source), SENSORS, f"{source}: sim.sensors"),
                contact_threshold=float(_section(data, "force_plate", source)["contact_threshold"]),
                pre_touchdown_height=float(_section(data, "experiment", source)["pre_touchdown_height"]),
                initial_apex=InitialApex(**{k: float(v) for k, v in _section(data, "initial_apex", source).items()}),
                seed=int(data.get("seed", 0)),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"{source}: missing or invalid sim setting {exc}") from None
        if config.period <= 0 or config.substeps < 1:
            raise ValueError(f"{source}: sim.period must be positive and sim.substeps at least 1")
        return config

    # ------------------------------------------------------------------ effects
    def enabled(self, effect: str) -> bool:
        _known_effect(effect, "SimConfig.enabled")
        entry = self.effects.get(effect)
        return bool(entry and entry["enabled"])

    def value(self, effect: str, key: str | None = None) -> float:
        """An effect's magnitude (its library parameter `key`) if it is on, else 0."""
        parameter = _known_effect(effect, "SimConfig.value").primary.name
        if key is not None and key != parameter:
            raise ValueError(f"effect {effect!r} has the parameter {parameter!r}, not {key!r}")
        return self.effects[effect][parameter] if self.enabled(effect) else 0.0

    def enabled_effects(self) -> dict[str, float]:
        """{library name: physical magnitude} of the effects that are on (what `effects.apply` takes)."""
        return {name: entry[EFFECTS[name]] for name, entry in self.effects.items() if entry["enabled"]}

    def coefficients(self) -> laws.Coefficients:
        """The true robot for the laws: the physics' coefficients with the enabled effects applied."""
        base = laws.Coefficients.from_model(self.model_params())
        coefficients, _ = library.apply(base, self.enabled_effects())
        return coefficients

    def sensor(self, name: str, key: str) -> float:
        entry = self.sensors[name]
        return entry[key] if entry["enabled"] else 0.0

    @property
    def gravity(self) -> float:
        """The body's vertical acceleration in free fall: physics' g, or `effective_gravity`'s when on."""
        return float(self.coefficients().gravity)

    def with_effects(self, **changes: bool | Mapping[str, Any]) -> "SimConfig":
        """A copy with effects switched (True/False) or given new settings (a mapping: on unless it says
        `enabled: false`). An effect the file does not list needs its magnitude the first time."""
        table = copy.deepcopy(self.effects)
        where = "SimConfig.with_effects"
        for name, change in changes.items():
            parameter = _known_effect(name, where).primary
            if isinstance(change, bool):
                if name not in table:
                    if change:
                        raise ValueError(f"{where}: {name!r} has no magnitude in the sim config; give it, e.g. "
                                         f"{name}={{'{parameter.name}': value}} [{parameter.unit}]")
                    continue
                table[name]["enabled"] = change
            elif isinstance(change, Mapping):
                table[name] = _effect_entry(name, {**table.get(name, {}), "enabled": True, **dict(change)}, where)
            else:
                raise ValueError(f"{where}: {name} must be True/False or a mapping, got {change!r}")
        return dataclasses.replace(self, effects=table)

    def all_effects_off(self) -> "SimConfig":
        """The robot the extended TD-SLIP model describes: the physics alone."""
        return self.with_effects(**{name: False for name in self.effects})

    def with_physics(self, **changes: float) -> "SimConfig":
        """A copy with some of the physics' parameters (ModelParams' fields) changed."""
        physics = _physics({**self.physics, **changes}, "SimConfig.with_physics")
        return dataclasses.replace(self, physics=physics)

    def with_sensors(self, **changes: bool | Mapping[str, Any]) -> "SimConfig":
        table = copy.deepcopy(self.sensors)
        for name, change in changes.items():
            if name not in SENSORS:
                raise ValueError(f"unknown sensor {name!r}; known: {sorted(SENSORS)}")
            if isinstance(change, bool):
                table[name]["enabled"] = change
            else:
                merged = {**table[name], "enabled": True, **dict(change)}
                table[name] = _switches({name: merged}, {name: SENSORS[name]}, "sensors")[name]
        return dataclasses.replace(self, sensors=table)

    def model_params(self) -> ModelParams:
        """The extended TD-SLIP parameters of the physics (the robot exactly when no effect is on)."""
        return ModelParams(**self.physics)


def load_sim_config(name: str | os.PathLike = DEFAULT_FILE) -> SimConfig:
    """The file checked by its schema (hopper_ros.config.schemas.SIM: everything but sim.effects,
    which `from_dict` checks against the effect library), then built; either's errors are
    ConfigError, one line naming the file and the key."""
    from hopper_ros.config import config_path
    from hopper_ros.config.schemas import SIM
    from hopper_ros.config.schema import ConfigError, load_config

    data = load_config(name, SIM)
    try:
        return SimConfig.from_dict(data, source=str(config_path(name)))
    except ConfigError:
        raise
    except ValueError as exc:
        raise ConfigError(" ".join(str(exc).split())) from None
