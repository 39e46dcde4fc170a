"""A mapped recording's channels read from a bag (topics, field paths into its messages) or a CSV
(columns), each as (t, values in SI), for recording/mapping.py."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from hopper_ros.recording.recordings import RecordingError
from hopper_ros.recording.mapping_file import ImportMapping, parse_path

MAX_BAG_BYTES = 2 << 30

# ---------------------------------------------------------------------- field paths

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

def bag_series(mapping: ImportMapping, source: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
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
        check_time(t, f"{source}: {topic} ({mapping.time} stamps)")
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


def csv_series(mapping: ImportMapping, source: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
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
    check_time(t, f"{source}: column {mapping.time.column}")
    return {c.name: (t, c.to_si(values)) for c, values in zip(wanted[1:], columns[1:])}


def check_time(t: np.ndarray, where: str) -> None:
    steps = np.diff(t)
    bad = np.flatnonzero(~(steps > 0))
    if bad.size:
        i = int(bad[0])
        scale = 1e-9 if t.dtype.kind == "i" else 1.0
        raise RecordingError(f"{where}: time does not increase at sample {i + 1} ({t[i] * scale:.9f} then "
                             f"{t[i + 1] * scale:.9f} s; {bad.size} such step(s))")
