"""Other robots' recordings into the table the tools read (`hopper import`, `--map` of diagnose/identify).

A mapping file (YAML, docs/bring_your_own_robot.md) says where each of the tools' channels is in a
recording of another robot, and how to turn it into SI:

    import:
      rate: 1000                  # [Hz] resample to this rate, or `recorded`: keep the recording's samples
      time: header                # bags: `header` (the messages' stamps) or `receive` (the bag's log times)
      channels:
        y:     {topic: /body/point, field: point.x, unit: mm}
        z:     {topic: /body/point, field: point.z, unit: mm, offset: -0.02}
        theta: {topic: /joint_states, field: "position[hip]", unit: deg, scale: -1}
        tau:   {topic: /joint_states, field: "effort[hip]", unit: N m}

A bag's channels name a topic and a field path into its messages (`point.x`, `pose.pose.position.z`,
`position[2]`; `position[hip]` indexes by the joint's entry in the message's `name` list, as
sensor_msgs/JointState pairs them); any message type the bag carries a definition for works
(`recording.msgdef`). A CSV's channels name a `column`, and `time: {column: NAME, unit: ms}` the time.
Each value becomes `value * scale` in `unit`, converted to SI, plus `offset` (in SI). y, z are the
body's forward position and height above the running surface [m], theta the leg angle from the
vertical [rad] (positive with the toe ahead of the body), tau the hip torque [N m] (positive when it
increases theta): recordings.py's t,y,z,theta,tau.

Topics at different instants are interpolated (linearly) onto the times of z's topic. A step longer
than three sample periods is a gap between runs; each run is resampled on its own (cubic for the
positions, linear for the torque), never across a gap. Every problem is one line naming the file and
the key: a missing topic, field or joint, time that does not increase, a unit of the wrong kind or
values no unit of that kind gives (a height of 400 m: the unit is mm).
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hopper_ros.recording.recordings import Recording, RecordingError
from hopper_ros.config.schema import ConfigError, Number, Section, Text, validate

CHANNELS = ("y", "z", "theta", "tau")
UNITS = {        # kind -> unit -> factor to SI
    "length": {"m": 1.0, "cm": 0.01, "mm": 1e-3, "um": 1e-6, "in": 0.0254, "ft": 0.3048},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3, "rev": 2.0 * math.pi},
    "torque": {"N m": 1.0, "Nm": 1.0, "N*m": 1.0, "mN m": 1e-3, "N mm": 1e-3, "Nmm": 1e-3, "kgf cm": 0.0980665},
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9},
}
KIND = {"y": "length", "z": "length", "theta": "angle", "tau": "torque", "t": "time"}
# what a hopping robot's channels can be, in SI: outside, the unit (or scale) is wrong
PLAUSIBLE = {"z": (-0.5, 3.0, "a body height above the ground lies within -0.5 to 3 m"),
             "theta": (-math.pi / 2, math.pi / 2, "a leg angle from the vertical lies within +-1.57 rad"),
             "tau": (-500.0, 500.0, "a hip torque lies within +-500 N m")}
MAX_FORWARD_SPEED = 30.0          # [m/s] a median |dy/dt| above it: y's unit is wrong
RATE_LIMITS = (20.0, 100000.0)    # [Hz] sample rates outside: the time unit is wrong
GAP_FACTOR = 3.0                  # a step longer than this many sample periods separates runs
RATE_TOLERANCE = 0.01             # a recorded rate this close to the target is used as it is
MAX_BAG_BYTES = 2 << 30

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


def field_value(message: dict, steps, type_name: str):
    """The value a field path points to; ValueError naming what is missing."""
    value = message
    for name, indexes in steps:
        if not isinstance(value, dict) or name not in value:
            known = ", ".join(value) if isinstance(value, dict) else "none"
            raise ValueError(f"{type_name} has no field {name!r} (fields there: {known})")
        parent, value = value, value[name]
        for index in indexes:
            if isinstance(index, str):
                names = parent.get("name")
                if not isinstance(names, list):
                    raise ValueError(f"{name}[{index}]: {type_name} has no `name` list to look {index!r} up in")
                if index not in names:
                    raise ValueError(f"{name}[{index}]: no entry {index!r} in name {names}")
                index = names.index(index)
            try:
                value = value[index]
            except (IndexError, TypeError, KeyError):
                length = len(value) if hasattr(value, "__len__") else 0
                raise ValueError(f"{name}[{index}]: {length} element(s) in this message") from None
    if isinstance(value, (dict, list, str)) or (isinstance(value, np.ndarray) and value.ndim):
        raise ValueError(f"{type_name}: the field path ends at a {type(value).__name__}, not a number")
    return float(value)


# ---------------------------------------------------------------------- reading


@dataclass
class Imported:
    """The recording in the tools' form and what was done to get it (one line each)."""

    recording: Recording
    notes: list[str] = field(default_factory=list)
    recorded_rate: float = 0.0


def _bag_series(mapping: ImportMapping, source: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{channel: (t [s since epoch], values in SI)} of a bag."""
    from hopper_ros.recording.bag import BagReader
    from hopper_ros.recording.msgdef import MessageDecoder, MessageDefinitionError

    reader = BagReader(source)
    size = sum(f.stat().st_size for f in reader.files)
    if size > MAX_BAG_BYTES:
        raise RecordingError(f"{source}: {size / 2**20:.1f} MiB of MCAP is more than this tool loads")
    wanted = {}
    for channel in mapping.channels.values():
        wanted.setdefault(channel.topic if channel.topic.startswith("/") else "/" + channel.topic, []).append(channel)
    raw: dict[str, list] = {topic: [] for topic in wanted}
    types: dict[str, str] = {}
    for message in reader.raw_messages():
        types.setdefault(message.topic, message.type)
        if message.topic in raw:
            raw[message.topic].append(message)
    schemas = {}
    for scan in reader.scans:
        for channel in scan.channels.values():
            types.setdefault(channel.topic, "")
            schema = scan.schemas.get(channel.schema_id)
            if schema is not None:
                schemas[schema.name] = schema
    out = {}
    for topic, channels in wanted.items():
        if topic not in types:
            raise RecordingError(f"{channels[0].where}.topic: no topic {channels[0].topic} in {source} "
                                 f"(topics: {', '.join(sorted(types)) or 'none'})")
        messages = raw[topic]
        if len(messages) < 2:
            raise RecordingError(f"{source}: {len(messages)} message(s) on {topic}: nothing to import")
        type_name = types[topic]
        schema = schemas.get(type_name)
        if schema is None or schema.encoding != "ros2msg" or not schema.data:
            raise RecordingError(f"{source}: {topic} ({type_name}) has no ros2msg definition in the bag to decode it by")
        try:
            decoder = MessageDecoder(type_name, schema.data.decode("utf-8"))
        except (MessageDefinitionError, UnicodeDecodeError) as exc:
            raise RecordingError(f"{source}: {topic}: {exc}") from None
        steps = {c.name: parse_path(c.field) for c in channels}
        has_header = any(f.name == "header" for f in decoder.fields())
        if mapping.time == "header" and not has_header:
            raise RecordingError(f"{mapping.path}: import.time: {topic} ({type_name}) has no header stamp; "
                                 "use time: receive (the bag's log times)")
        t = np.empty(len(messages), dtype=np.int64)          # [ns]: epoch seconds in float64 would lose 0.2 us
        values = {c.name: np.empty(len(messages)) for c in channels}
        for i, message in enumerate(messages):
            try:
                decoded = decoder.decode(message.data)
            except MessageDefinitionError as exc:
                raise RecordingError(f"{source}: {topic} message {i}: {exc}") from None
            if mapping.time == "header":
                stamp = decoded["header"]["stamp"]
                t[i] = int(stamp["sec"]) * 1_000_000_000 + int(stamp["nanosec"])
            else:
                t[i] = message.log_time
            for c in channels:
                try:
                    values[c.name][i] = field_value(decoded, steps[c.name], type_name)
                except ValueError as exc:
                    raise RecordingError(f"{c.where}.field: {topic} message {i}: {exc}") from None
        _check_time(t, f"{source}: {topic} ({mapping.time} stamps)")
        for c in channels:
            out[c.name] = (t, c.to_si(values[c.name]))
    origin = min(int(t[0]) for t, _ in out.values())
    seconds = {}
    for name, (t, v) in out.items():
        key = id(t)
        if key not in seconds:
            seconds[key] = (t - origin) * 1e-9
        out[name] = (seconds[key], v)
    return out


def _csv_series(mapping: ImportMapping, source: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    from hopper_ros.recording.recordings import MAX_CSV_BYTES

    if source.stat().st_size > MAX_CSV_BYTES:
        raise RecordingError(f"{source}: {source.stat().st_size / 2**20:.1f} MiB is more than this tool loads")
    wanted = [mapping.time, *mapping.channels.values()]
    columns: list[list[float]] = [[] for _ in wanted]
    try:
        with open(source, newline="", encoding="utf-8") as handle:
            reader = csv.reader(handle)
            try:
                header = [h.strip() for h in next(reader)]
            except StopIteration:
                raise RecordingError(f"{source}: empty file") from None
            index = []
            for c in wanted:
                if c.column not in header:
                    raise RecordingError(f"{c.where}.column: no column {c.column!r} in {source} "
                                         f"(columns: {', '.join(header)})")
                index.append(header.index(c.column))
            for number, row in enumerate(reader, start=2):
                if not row or all(not cell.strip() for cell in row):
                    continue
                for k, (c, i) in enumerate(zip(wanted, index)):
                    try:
                        columns[k].append(float(row[i]))
                    except (ValueError, IndexError):
                        cell = row[i] if i < len(row) else "nothing"
                        raise RecordingError(f"{source}:{number}: column {c.column} is not a number: {cell!r}"[:300]) from None
    except UnicodeDecodeError:
        raise RecordingError(f"{source}: not a text CSV file") from None
    if len(columns[0]) < 2:
        raise RecordingError(f"{source}: {len(columns[0])} row(s): nothing to import")
    t = mapping.time.to_si(columns[0])
    _check_time(t, f"{source}: column {mapping.time.column}")
    return {c.name: (t, c.to_si(values)) for c, values in zip(wanted[1:], columns[1:])}


def _check_time(t: np.ndarray, where: str) -> None:
    steps = np.diff(t)
    bad = np.flatnonzero(~(steps > 0))
    if bad.size:
        i = int(bad[0])
        scale = 1e-9 if t.dtype.kind == "i" else 1.0
        raise RecordingError(f"{where}: time does not increase at sample {i + 1} ({t[i] * scale:.9f} then "
                             f"{t[i + 1] * scale:.9f} s; {bad.size} such step(s))")


def _check_plausible(mapping: ImportMapping, series: dict) -> None:
    for name, (t, values) in series.items():
        c = mapping.channels[name]
        if not np.all(np.isfinite(values)):
            i = int(np.flatnonzero(~np.isfinite(values))[0])
            raise RecordingError(f"{c.where}: value {i} is not finite")
        if name in PLAUSIBLE:
            low, high, what = PLAUSIBLE[name]
            lo, hi = float(np.percentile(values, 1)), float(np.percentile(values, 99))
            if lo < low or hi > high:
                raise RecordingError(f"{c.where}: values from {lo:.4g} to {hi:.4g} in SI after the unit {c.unit!r}, "
                                     f"scale {c.scale:g} and offset {c.offset:g}; {what}: check unit, scale and offset")
        if name == "y":
            speed = float(np.median(np.abs(np.diff(values) / np.diff(t))))
            if speed > MAX_FORWARD_SPEED:
                raise RecordingError(f"{c.where}: the body moves forward at {speed:.4g} m/s (median) after the unit "
                                     f"{c.unit!r} and scale {c.scale:g}; a hopping robot runs below "
                                     f"{MAX_FORWARD_SPEED:g} m/s: check unit and scale")


def load_mapped(source: str | os.PathLike, mapping: ImportMapping | str | os.PathLike) -> Imported:
    """The recording `source` (bag or CSV) read through `mapping`, at the mapping's rate."""
    if not isinstance(mapping, ImportMapping):
        mapping = load_mapping(mapping)
    source = Path(source)
    if not source.exists():
        raise RecordingError(f"no such recording: {source}")
    if mapping.kind == "csv":
        if source.is_dir() or source.suffix == ".mcap":
            raise RecordingError(f"{mapping.path}: the channels name CSV columns, {source} is a bag")
        series = _csv_series(mapping, source)
    else:
        if not (source.is_dir() or source.suffix == ".mcap"):
            raise RecordingError(f"{mapping.path}: the channels name bag topics, {source} is not a bag "
                                 "(a folder or .mcap file)")
        series = _bag_series(mapping, source)
    _check_plausible(mapping, series)
    return _assemble(mapping, series, str(source))


def _runs(t: np.ndarray, period: float) -> tuple[list[slice], int]:
    """Runs of samples between gaps (more than 3 samples each), and how many samples shorter runs held."""
    breaks = np.flatnonzero(np.diff(t) > GAP_FACTOR * period) + 1
    edges = [0, *breaks.tolist(), len(t)]
    runs = [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]
    kept = [r for r in runs if r.stop - r.start > 3]
    return kept, sum(r.stop - r.start for r in runs if r.stop - r.start <= 3)


def noise_level(x: np.ndarray) -> float:
    """The channel's white noise std from its third differences (MAD; a smooth motion's third differences
    are far below a sensor's noise at 100 Hz and more)."""
    d3 = x[3:] - 3 * x[2:-1] + 3 * x[1:-2] - x[:-3]
    if d3.size < 10:
        return 0.0
    return 1.4826 * float(np.median(np.abs(d3 - np.median(d3)))) / math.sqrt(20.0)


HIGH_FREQUENCY_GAIN = 924.0 / 400.0   # the third-difference estimate's variance of unit high-frequency noise


def resample_with_noise(t: np.ndarray, x: np.ndarray, grid: np.ndarray, sigma: float, rng) -> np.ndarray:
    """x on `grid`, more samples than recorded: cubic interpolation between the recorded samples (kept where
    the grid meets them), plus noise near the new Nyquist frequency of the size that makes the channel's
    noise estimate right.

    A sensor sampled at f_r with noise sigma has sigma^2 f_target / f_r of 1 kHz white noise's density in the
    band below f_r / 2, where the motion is; the tools estimate the noise level from third differences (the
    band near the Nyquist frequency) and judge residuals against white noise of that level. Interpolated
    samples alone would make that estimate too small by the ratio of the rates and the noise in the motion's
    band look like physics. The added noise is the third difference of white noise: nearly all of it lies
    above f_r / 2, so it raises the estimate to sigma^2 f_target / f_r without adding to the motion's band."""
    from scipy.interpolate import CubicSpline

    def interpolate(values):
        out = CubicSpline(t, values)(grid)
        out[recorded] = values[nearest[recorded]]
        return out

    index = np.clip(np.searchsorted(t, grid), 0, len(t) - 1)
    previous = np.clip(index - 1, 0, len(t) - 1)
    nearest = np.where(np.abs(t[index] - grid) < np.abs(t[previous] - grid), index, previous)
    recorded = np.abs(t[nearest] - grid) < 1e-3 * np.median(np.diff(t))
    out = interpolate(x)
    ratio = float(np.median(np.diff(t)) / np.median(np.diff(grid)))
    if sigma > 0 and ratio > 1.0 + RATE_TOLERANCE and len(grid) > 10:
        unit = interpolate(np.random.default_rng(1).standard_normal(len(t)))
        kept = noise_level(unit) ** 2                        # what the estimate sees of interpolated unit noise
        share = max(0.0, ratio - kept) / HIGH_FREQUENCY_GAIN
        white = rng.standard_normal(len(grid) + 3)
        high = (white[3:] - 3 * white[2:-1] + 3 * white[1:-2] - white[:-3]) / math.sqrt(20.0)
        out += sigma * math.sqrt(share) * high
    return out


def _assemble(mapping: ImportMapping, series: dict, source: str) -> Imported:
    notes = []
    base_t = series["z"][0]
    period = float(np.median(np.diff(base_t)))
    rate = 1.0 / period
    if not RATE_LIMITS[0] <= rate <= RATE_LIMITS[1]:
        where = mapping.time.where if isinstance(mapping.time, Channel) else f"{mapping.path}: import.time"
        raise RecordingError(f"{where}: samples {period:.6g} s apart ({rate:.4g} Hz) after the conversion to s; "
                             f"a recording is sampled at {RATE_LIMITS[0]:g} Hz to {RATE_LIMITS[1] / 1000:g} kHz: "
                             "check the time unit")
    # channels of other topics (other instants) onto z's times, where every topic has samples
    first = max(t[0] for t, _ in series.values())
    last = min(t[-1] for t, _ in series.values())
    inside = (base_t >= first) & (base_t <= last)
    if inside.sum() < 2:
        raise RecordingError(f"{source}: the topics' samples do not overlap in time")
    if not inside.all():
        notes.append(f"{int((~inside).sum())} of z's samples outside the other topics' times left out")
    base_t = base_t[inside]
    values = {}
    interpolated = {}
    for name, (t, v) in series.items():
        if len(t) == len(series["z"][0]) and np.allclose(t, series["z"][0], rtol=0, atol=period * 1e-3):
            values[name] = v[inside]
            continue
        values[name] = np.interp(base_t, t, v)
        interpolated.setdefault(mapping.channels[name].topic, []).append(name)
    for topic, names in interpolated.items():
        notes.append(f"{', '.join(names)}: {topic} sampled at other instants than z's {mapping.channels['z'].topic}: "
                     "interpolated linearly onto them")
    runs, dropped = _runs(base_t, period)
    if not runs:
        raise RecordingError(f"{source}: no run of more than 3 samples between gaps")
    if dropped:
        notes.append(f"{dropped} sample(s) in runs of 3 or fewer between gaps left out")
    gaps = len(runs) - 1
    if gaps:
        lengths = [base_t[b.start] - base_t[a.stop - 1] for a, b in zip(runs[:-1], runs[1:])]
        notes.append(f"{gaps} gap(s) of {min(lengths):.3g} to {max(lengths):.3g} s (longer than {GAP_FACTOR:g} "
                     f"samples): {len(runs)} runs, never interpolated across")
    origin = base_t[runs[0].start]
    target = mapping.rate
    if target is None or abs(rate - target) <= RATE_TOLERANCE * target:
        why = "as the mapping asks (rate: recorded)" if target is None else f"(within {RATE_TOLERANCE:.0%} of {target:g} Hz)"
        notes.append(f"{rate:.4g} Hz recorded: samples used as they are {why}")
        pieces = [(base_t[r] - origin, {k: v[r] for k, v in values.items()}) for r in runs]
    else:
        notes.append(f"{rate:.4g} Hz recorded: resampled to {target:g} Hz within each run (recorded samples kept; "
                     "between them cubic for y, z, theta with the channel's own noise level, linear for tau)")
        step = 1.0 / target
        noise = {k: noise_level(values[k]) for k in ("y", "z", "theta")}
        rng = np.random.default_rng(0)
        pieces = []
        for r in runs:
            t = base_t[r]
            grid = t[0] + step * np.arange(int(math.floor((t[-1] - t[0]) / step + 1e-9)) + 1)
            out = {"tau": np.interp(grid, t, values["tau"][r])}
            for k in noise:
                out[k] = resample_with_noise(t, values[k][r], grid, noise[k], rng)
            pieces.append((grid - origin, out))
    t = np.concatenate([p[0] for p in pieces])
    columns = {k: np.concatenate([p[1][k] for p in pieces]) for k in CHANNELS}
    recording = Recording(t, columns["y"], columns["z"], columns["theta"], columns["tau"], source=source)
    return Imported(recording, notes, rate)
