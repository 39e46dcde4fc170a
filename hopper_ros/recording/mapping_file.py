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

from hopper_ros.config.schema import ConfigError, Number, Section, Text

CHANNELS = ("y", "z", "theta", "tau")
UNITS = {        # kind -> unit -> factor to SI
    "length": {"m": 1.0, "cm": 0.01, "mm": 1e-3, "um": 1e-6, "in": 0.0254, "ft": 0.3048},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3, "rev": 2.0 * math.pi},
    "torque": {"N m": 1.0, "Nm": 1.0, "N*m": 1.0, "mN m": 1e-3, "N mm": 1e-3, "Nmm": 1e-3, "kgf cm": 0.0980665},
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9},
}
KIND = {"y": "length", "z": "length", "theta": "angle", "tau": "torque", "t": "time"}

_CHANNEL = Section({
    "topic": Text(default=None, doc="bag topic"),
    "field": Text(default=None, doc="field path in the topic's messages"),
    "column": Text(default=None, doc="CSV column"),
    "unit": Text(doc="unit of value * scale"),
    "scale": Number(default=1.0),
    "offset": Number(default=0.0, doc="added after the conversion to SI"),
})
_TIME = Section({"column": Text(), "unit": Text(default="s")})


def _rate(value, where: str):
    if value == "recorded":
        return None
    return Number("Hz", gt=0, le=100000).check(value, where)


class _Rate:
    default = 1000.0

    def check(self, value, where):
        return _rate(value, where)


class _TimeSpec:
    default = "header"

    def check(self, value, where):
        if isinstance(value, str):
            return Text(choices=("header", "receive")).check(value, where)
        return _TIME.check(value, where)


SCHEMA = Section({"import": Section({
    "rate": _Rate(),
    "time": _TimeSpec(),
    "channels": Section({name: _CHANNEL for name in CHANNELS}),
})})


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
