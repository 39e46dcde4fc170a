"""The mapping file of `hopper import` (recording/mapping.py has the format): its schema, the units of
each kind of channel, the field paths into a bag's messages, and `load_mapping` into an `ImportMapping` of
`Channel`s."""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pydantic import Field, create_model, field_validator

from hopper_ros.config.schema import ConfigError, Problem, Section, unit

CHANNELS = ("y", "z", "theta", "tau")
UNITS = {        # kind -> unit -> factor to SI
    "length": {"m": 1.0, "cm": 0.01, "mm": 1e-3, "um": 1e-6, "in": 0.0254, "ft": 0.3048},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3, "rev": 2.0 * math.pi},
    "torque": {"N m": 1.0, "Nm": 1.0, "N*m": 1.0, "mN m": 1e-3, "N mm": 1e-3, "Nmm": 1e-3, "kgf cm": 0.0980665},
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9},
}
KIND = {"y": "length", "z": "length", "theta": "angle", "tau": "torque", "t": "time"}

BAG_TIMES = ("header", "receive")


class _Channel(Section):
    topic: str = Field(None, description="bag topic")
    field: str = Field(None, description="field path in the topic's messages")
    column: str = Field(None, description="CSV column")
    unit: str = Field(description="unit of value * scale")
    scale: float = 1.0
    offset: float = Field(0.0, description="added after the conversion to SI")


class _TimeColumn(Section):
    column: str
    unit: str = "s"


class _Import(Section):
    rate: float = unit("Hz", 1000.0, gt=0, le=100000, description="target rate; `recorded`: as recorded (None)")
    time: _TimeColumn = Field("header", description="a bag's header or receive stamps, or a CSV's time column")
    channels: create_model("Channels", __base__=Section, **{name: (_Channel, ...) for name in CHANNELS})

    @field_validator("rate", mode="wrap")
    @classmethod
    def _as_recorded(cls, value, handler):
        return None if value == "recorded" else handler(value)

    @field_validator("time", mode="wrap")
    @classmethod
    def _bag_time(cls, value, handler):
        if not isinstance(value, str):
            return handler(value)
        if value not in BAG_TIMES:
            raise Problem(None, f"must be one of {list(BAG_TIMES)}, got {value!r}")
        return value


SCHEMA = create_model("SCHEMA", __base__=Section, **{"import": (_Import, ...)})


@dataclass(frozen=True)
class Channel:
    name: str
    unit: str
    scale: float = 1.0
    offset: float = 0.0
    topic: str | None = None
    field: str | None = None
    column: str | None = None
    where: str = ""                # `FILE: import.channels.NAME` for the error lines

    @property
    def factor(self) -> float:
        return self.scale * UNITS[KIND[self.name]][self.unit]

    def to_si(self, values: np.ndarray) -> np.ndarray:
        return np.asarray(values, dtype=float) * self.factor + self.offset


@dataclass(frozen=True)
class ImportMapping:
    path: Path
    rate: float | None                    # [Hz] target rate, None: as recorded
    time: str | Channel                   # "header" / "receive" (bags) or the CSV's time column
    channels: dict[str, Channel]

    @property
    def kind(self) -> str:
        return "csv" if any(c.column for c in self.channels.values()) else "bag"


def load_mapping(path: str | os.PathLike) -> ImportMapping:
    """The mapping file checked: ConfigError with one line `FILE: key: what is wrong` otherwise."""
    from hopper_ros.config.schema import load_config

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such mapping file")
    values = load_config(path, SCHEMA)["import"]
    source = f"{path}: import"
    channels = {}
    for name, entry in values["channels"].items():
        where = f"{source}.channels.{name}"
        kind = KIND[name]
        if entry["unit"] not in UNITS[kind]:
            other = next((k for k, units in UNITS.items() if entry["unit"] in units), None)
            what = f"{entry['unit']!r} is a unit of {other}" if other else f"{entry['unit']!r} is not a known unit"
            raise ConfigError(f"{where}.unit: {what}; {name} is a {kind}: one of {', '.join(UNITS[kind])}")
        if entry["scale"] == 0:
            raise ConfigError(f"{where}.scale: must not be 0")
        entry = {key: entry.get(key) for key in ("topic", "field", "column", "unit", "scale", "offset")}
        if entry["column"] is not None and (entry["topic"] or entry["field"]):
            raise ConfigError(f"{where}: give either column (CSV) or topic and field (bag), not both")
        if entry["column"] is None and not (entry["topic"] and entry["field"]):
            missing = "field" if entry["topic"] else "topic"
            raise ConfigError(f"{where}.{missing}: missing (a bag channel needs topic and field; a CSV's, column)")
        if entry["field"] is not None:
            try:
                parse_path(entry["field"])
            except ValueError as exc:
                raise ConfigError(f"{where}.field: {exc}") from None
        channels[name] = Channel(name, entry["unit"], entry["scale"], entry["offset"], entry["topic"], entry["field"],
                                 entry["column"], where)
    kinds = {"csv" if c.column else "bag" for c in channels.values()}
    if len(kinds) > 1:
        raise ConfigError(f"{source}.channels: some channels name CSV columns, others bag topics; one recording "
                          "is either")
    time = values["time"]
    if isinstance(time, dict):
        if kinds != {"csv"}:
            raise ConfigError(f"{source}.time: a column is for CSV recordings; a bag's time is header or receive")
        if time["unit"] not in UNITS["time"]:
            raise ConfigError(f"{source}.time.unit: {time['unit']!r} is not a unit of time: one of "
                              f"{', '.join(UNITS['time'])}")
        time = Channel("t", time["unit"], column=time["column"], where=f"{source}.time")
    elif kinds == {"csv"}:
        raise ConfigError(f"{source}.time: a CSV needs its time column: time: {{column: NAME, unit: s}}")
    return ImportMapping(path, values["rate"], time, channels)


# ---------------------------------------------------------------------- field paths

_STEP = re.compile(r"^([A-Za-z_]\w*)((?:\[[^\[\]]+\])*)$")


def parse_path(text: str) -> list[tuple[str, list]]:
    """`pose.pose.position.z` / `position[hip]` / `data[3]` as [(field, [index, ...]), ...]."""
    steps = []
    for part in text.split("."):
        match = _STEP.match(part.strip())
        if match is None:
            raise ValueError(f"{text!r} is not a field path (e.g. point.x, pose.position.z, position[hip], data[2])")
        indexes = [int(i) if re.fullmatch(r"-?\d+", i) else i for i in re.findall(r"\[([^\[\]]+)\]", match.group(2))]
        steps.append((match.group(1), indexes))
    return steps
