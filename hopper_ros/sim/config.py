"""Configuration of the simulated robot (config/sim.yaml): physics, effects, sensors.

Every effect is a mapping with `enabled` and its magnitudes. `SimConfig.with_effects` switches
effects on or off or changes a magnitude without touching the file, e.g.

    config.with_effects(leg_friction={"enabled": True, "force": 3.0}, flight_damping=False)
"""

from __future__ import annotations

import copy
import dataclasses
import os
from dataclasses import dataclass
from typing import Any, Mapping

from hopper_ros.physics.params import ModelParams

DEFAULT_FILE = "sim.yaml"

# effect name -> its magnitudes (the keys besides `enabled`), in the order docs/sim.md lists them
EFFECTS: dict[str, tuple[str, ...]] = {
    "flight_damping": ("horizontal", "vertical"),
    "liftoff_collision": ("toe_mass",),
    "boom_gravity": ("effective_gravity",),
    "leg_friction": ("force", "smoothing_speed"),
    "ground_compliance": ("stiffness", "damping"),
    "touchdown_impact": ("tangential_loss",),
    "torque_saturation": ("max_torque",),
    "actuation_delay": ("delay",),
}
MODEL_EFFECTS = ("flight_damping", "liftoff_collision", "boom_gravity")  # the extended TD-SLIP has these
SENSORS: dict[str, tuple[str, ...]] = {
    "encoder_noise": ("counts",),
    "current_noise": ("current",),
    "force_plate_noise": ("force",),
}
PHYSICS = ("body_mass", "stiffness", "damping", "rest_length", "gravity")


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


@dataclass(frozen=True)
class SimConfig:
    period: float
    substeps: int
    physics: dict[str, float]
    effects: dict[str, dict]
    sensors: dict[str, dict]
    contact_threshold: float
    pre_touchdown_height: float
    initial_apex: dict[str, float]
    seed: int

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "sim config") -> "SimConfig":
        if isinstance(data, Mapping) and "sim" in data:
            data = data["sim"]
        if not isinstance(data, Mapping):
            raise ValueError(f"{source}: expected a mapping under `sim:`")
        physics = _section(data, "physics", source)
        missing = [name for name in PHYSICS if not isinstance(physics.get(name), (int, float))]
        if missing:
            raise ValueError(f"{source}: sim.physics lacks number(s) {missing}")
        try:
            config = cls(
                period=float(data["period"]), substeps=int(data["substeps"]),
                physics={name: float(physics[name]) for name in PHYSICS},
                effects=_switches(_section(data, "effects", source), EFFECTS, f"{source}: sim.effects"),
                sensors=_switches(_section(data, "sensors", source), SENSORS, f"{source}: sim.sensors"),
                contact_threshold=float(_section(data, "force_plate", source)["contact_threshold"]),
                pre_touchdown_height=float(_section(data, "experiment", source)["pre_touchdown_height"]),
                initial_apex={k: float(v) for k, v in _section(data, "initial_apex", source).items()},
                seed=int(data.get("seed", 0)),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"{source}: missing or invalid sim setting {exc}") from None
        if config.period <= 0 or config.substeps < 1:
            raise ValueError(f"{source}: sim.period must be positive and sim.substeps at least 1")
        if config.effects["ground_compliance"]["enabled"] and config.effects["ground_compliance"]["damping"] <= 0:
            raise ValueError(f"{source}: ground_compliance needs a positive damping (the toe is massless)")
        return config

    def enabled(self, effect: str) -> bool:
        return self.effects[effect]["enabled"]

    def value(self, effect: str, key: str) -> float:
        """An effect's magnitude if it is on, else 0."""
        entry = self.effects[effect]
        return entry[key] if entry["enabled"] else 0.0

    def sensor(self, name: str, key: str) -> float:
        entry = self.sensors[name]
        return entry[key] if entry["enabled"] else 0.0

    @property
    def gravity(self) -> float:
        """The body's vertical acceleration in free fall: g_0, or the boom's effective value."""
        return self.value("boom_gravity", "effective_gravity") or self.physics["gravity"]

    def with_effects(self, **changes: bool | Mapping[str, Any]) -> "SimConfig":
        """A copy with effects switched (True/False) or given new settings (a mapping)."""
        return self._with("effects", EFFECTS, changes)

    def with_sensors(self, **changes: bool | Mapping[str, Any]) -> "SimConfig":
        return self._with("sensors", SENSORS, changes)

    def only_model_effects(self) -> "SimConfig":
        """The robot the extended TD-SLIP model describes: its three effects as configured, the rest off."""
        return self.with_effects(**{name: False for name in EFFECTS if name not in MODEL_EFFECTS})

    def all_effects_off(self) -> "SimConfig":
        return self.with_effects(**{name: False for name in EFFECTS})

    def _with(self, field: str, known: Mapping[str, tuple], changes: Mapping[str, Any]) -> "SimConfig":
        table = copy.deepcopy(getattr(self, field))
        for name, change in changes.items():
            if name not in known:
                raise ValueError(f"unknown {field[:-1]} {name!r}; known: {sorted(known)}")
            if isinstance(change, bool):
                table[name]["enabled"] = change
            else:
                merged = {**table[name], "enabled": True, **dict(change)}
                table[name] = _switches({name: merged}, {name: known[name]}, field)[name]
        return dataclasses.replace(self, **{field: table})

    def model_params(self) -> ModelParams:
        """The extended TD-SLIP parameters of this robot (exact when only the model's effects are on)."""
        return ModelParams(
            body_mass=self.physics["body_mass"],
            toe_mass=self.value("liftoff_collision", "toe_mass"),
            gravity=self.gravity,
            stiffness=self.physics["stiffness"],
            damping=self.physics["damping"],
            flight_damping_horizontal=self.value("flight_damping", "horizontal"),
            flight_damping_vertical=self.value("flight_damping", "vertical"),
            rest_length=self.physics["rest_length"],
        )


def load_sim_config(name: str | os.PathLike = DEFAULT_FILE) -> SimConfig:
    """The file checked by its schema (hopper_ros.config_schemas.SIM: everything but sim.effects,
    which `from_dict` checks), then built."""
    from hopper_ros.config import config_path
    from hopper_ros.config_schemas import SIM
    from hopper_ros.schema import load_config

    return SimConfig.from_dict(load_config(name, SIM), source=str(config_path(name)))
