"""Recordings as arrays of 1 kHz samples, from a bag of our recorder or from a CSV file.

CSV format (shared with the mismatch tool, issue 9): a header line, then one row per sample,

    t,y,z,theta,tau[,phase]

    t      time [s], increasing (a larger step marks a gap between separate runs)
    y      forward position of the body [m]
    z      body height above the ground (the running surface) [m]
    theta  leg angle from the vertical [rad], positive when the toe is ahead of the body
    tau    applied hip torque [N m], positive when it increases theta (what the controller commanded)
    phase  optional label: descent, compression, decompression or ascent (or 0-3, the
           `physics.exact.Phase` values); absent: the phases are detected from the data

From a bag: `body_measurement` gives t (header stamp), y, z, theta and tau (`hip_torque`, from
the measured motor current); `stride_command` the commanded inputs of each stride (tau_0,
theta_td, t_f), `sim/events` (true events, when present) the phase labels; `force_plate` and
`sim/truth` are kept when present. Topic names match under any namespace.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hopper_ros.physics.exact import Phase

CSV_COLUMNS = ("t", "y", "z", "theta", "tau")
PHASE_NAMES = {phase.name.lower(): int(phase) for phase in Phase}
TOPICS = {                       # our name -> the topic's relative name in the graph
    "body_measurement": "body_measurement",
    "force_plate": "force_plate",
    "truth": "sim/truth",
    "events": "sim/events",
    "stride_command": "stride_command",
}
UNLABELLED = -1
APEX_EVENT, TOUCHDOWN_EVENT, BOTTOM_EVENT, LIFTOFF_EVENT = 0, 2, 3, 4   # GaitEvent.type constants (msg/GaitEvent.msg)


class RecordingError(ValueError):
    """A recording that cannot be used; the message names the file, line or topic."""


@dataclass
class StrideCommandRecord:
    """One stride's commanded inputs (StrideCommand)."""

    t: float                     # [s] when it was issued
    tau_0: float                 # [N m]
    touchdown_angle: float       # [rad]
    ramp_duration: float         # [s] t_f
    profile: str = "ramp"


@dataclass
class Recording:
    """1 kHz samples of one recording (SI units); optional parts are None when absent."""

    t: np.ndarray
    y: np.ndarray
    z: np.ndarray
    theta: np.ndarray
    tau: np.ndarray
    phase: np.ndarray | None = None                    # Phase values, UNLABELLED where unknown
    source: str = ""
    force: dict | None = None                          # t, forward, vertical, contact arrays (force plate)
    truth: dict | None = None                          # t, y, z, ydot, zdot, theta (ground truth)
    events: list = field(default_factory=list)         # (t, GaitEvent type, stride_index, y, z, ydot, zdot, theta)
    commands: list = field(default_factory=list)       # StrideCommandRecord
    custom_data: dict = field(default_factory=dict)    # the bag's metadata custom_data

    def __post_init__(self) -> None:
        n = len(self.t)
        for name in ("y", "z", "theta", "tau"):
            if len(getattr(self, name)) != n:
                raise RecordingError(f"{self.source}: column {name} has {len(getattr(self, name))} samples, t has {n}")
        if n < 2:
            raise RecordingError(f"{self.source}: {n} sample(s) is not a recording")
        for name in CSV_COLUMNS:
            values = getattr(self, name)
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise RecordingError(f"{self.source}: column {name} is not finite at sample {bad[0]} (t index)")
        steps = np.diff(self.t)
        if np.any(steps <= 0.0):
            first = int(np.flatnonzero(steps <= 0.0)[0])
            raise RecordingError(f"{self.source}: time does not increase at sample {first + 1} "
                                 f"(t = {self.t[first]:.6f} then {self.t[first + 1]:.6f} s)")

    def __len__(self) -> int:
        return len(self.t)

    @property
    def period(self) -> float:
        """The sample period [s] (median step)."""
        return float(np.median(np.diff(self.t)))

    def segments(self, gap_factor: float = 3.0) -> list[slice]:
        """Runs of uninterrupted samples: a step longer than gap_factor periods starts a new one."""
        breaks = np.flatnonzero(np.diff(self.t) > gap_factor * self.period) + 1
        edges = [0, *breaks.tolist(), len(self.t)]
        return [slice(a, b) for a, b in zip(edges[:-1], edges[1:]) if b - a > 1]


# ---------------------------------------------------------------------- CSV


def write_csv(path: str | os.PathLike, recording: Recording, with_phase: bool = False) -> Path:
    """Write `t,y,z,theta,tau[,phase]` (SI units, one row per sample) into a new file."""
    path = Path(path)
    if path.exists():
        raise RecordingError(f"{path} exists already; a recording is never written over")
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = [recording.t, recording.y, recording.z, recording.theta, recording.tau]
    header = list(CSV_COLUMNS)
    names = {int(p): p.name.lower() for p in Phase}
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        if with_phase:
            if recording.phase is None:
                raise RecordingError(f"{recording.source}: no phase labels to write")
            header.append("phase")
        writer.writerow(header)
        for i in range(len(recording)):
            row = [f"{columns[0][i]:.6f}", *(f"{c[i]:.9g}" for c in columns[1:])]
            if with_phase:
                row.append(names.get(int(recording.phase[i]), ""))
            writer.writerow(row)
    return path


MAX_CSV_BYTES = 256 << 20        # [bytes] larger CSV files are refused before reading (about 70 min at 1 kHz)
MAX_BAG_BYTES = 2 << 30          # [bytes] larger bags are refused before loading their messages


def _check_size(path: Path, limit: int, what: str) -> None:
    size = path.stat().st_size
    if size > limit:
        raise RecordingError(f"{path}: {size / 2**20:.1f} MiB is more than this tool loads ({limit >> 20} MiB of "
                             f"{what}); cut the recording into shorter runs")


def load_csv(path: str | os.PathLike) -> Recording:
    """Read a `t,y,z,theta,tau[,phase]` CSV; errors name the file, line and column.

    Bounded memory: the size is checked before reading (MAX_CSV_BYTES), rows are parsed one at a
    time into compact arrays (8 bytes a value), and a line longer than any row is refused."""
    import array

    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"no such file: {path}")
    _check_size(path, MAX_CSV_BYTES, "CSV")
    columns = [array.array("d") for _ in CSV_COLUMNS]
    phases = array.array("b")
    line_number = 1
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            reader = csv.reader(_bounded_lines(handle, path))
            try:
                header = [h.strip().lower() for h in next(reader)]
            except StopIteration:
                raise RecordingError(f"{path}: empty file") from None
            missing = [c for c in CSV_COLUMNS if c not in header]
            if missing:
                raise RecordingError(f"{path}: header lacks column(s) {missing}; expected {','.join(CSV_COLUMNS)}[,phase]")
            index = [header.index(name) for name in CSV_COLUMNS]
            phase_index = header.index("phase") if "phase" in header else None
            for line_number, row in enumerate(reader, start=2):
                if not row or all(not cell.strip() for cell in row):
                    continue
                try:
                    values = [float(row[i]) for i in index]
                except (ValueError, IndexError):
                    short = f" ({len(row)} of {len(header)} columns: the file looks cut short)" if len(row) < len(header) else ""
                    raise RecordingError(f"{path}:{line_number}: expected numbers in {','.join(CSV_COLUMNS)}, "
                                         f"got {','.join(row)[:80]!r}{short}") from None
                for column, value in zip(columns, values):
                    column.append(value)
                if phase_index is not None:
                    phases.append(_phase_value(row[phase_index] if phase_index < len(row) else "", path, line_number))
    except UnicodeDecodeError as exc:
        raise RecordingError(f"{path}: not a text CSV file (byte 0x{exc.object[exc.start]:02x} near line "
                             f"{line_number + 1} is not UTF-8)") from None
    except csv.Error as exc:
        raise RecordingError(f"{path}:{line_number + 1}: not a CSV row ({exc})") from None
    if not columns[0]:
        raise RecordingError(f"{path}: no samples")
    data = [np.frombuffer(column, dtype=float) for column in columns]
    phase = np.asarray(phases, dtype=int) if phase_index is not None else None
    return Recording(*data, phase=phase, source=str(path))


_MAX_LINE = 4096                 # [characters] no row of t,y,z,theta,tau[,phase] comes near it


def _bounded_lines(handle, path: Path):
    """The file's lines, refusing one longer than _MAX_LINE (garbage, or a binary file)."""
    for number, line in enumerate(iter(lambda: handle.readline(_MAX_LINE + 1), ""), start=1):
        if len(line) > _MAX_LINE:
            raise RecordingError(f"{path}:{number}: line longer than {_MAX_LINE} characters: not a "
                                 f"t,y,z,theta,tau CSV")
        yield line


def _phase_value(cell: str, path, line_number: int) -> int:
    text = cell.strip().lower()
    if text == "":
        return UNLABELLED
    if text in PHASE_NAMES:
        return PHASE_NAMES[text]
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value not in PHASE_NAMES.values():
        raise RecordingError(f"{path}:{line_number}: phase {cell!r} is not one of {sorted(PHASE_NAMES)} or 0-3")
    return value


# ---------------------------------------------------------------------- bags


def _find_topic(available, relative: str, source: str, required: bool) -> str | None:
    matches = [name for name in available if name == "/" + relative or name.endswith("/" + relative)]
    if len(matches) > 1:
        raise RecordingError(f"{source}: several topics match {relative!r}: {sorted(matches)}")
    if not matches and required:
        raise RecordingError(f"{source}: no {relative!r} topic in the bag (topics: {sorted(available)})")
    return matches[0] if matches else None


def load_bag(path: str | os.PathLike) -> Recording:
    """The recording a bag of our recorder holds (finished or interrupted)."""
    from rclpy.serialization import deserialize_message

    from hopper_ros.runtime.messages import message_class
    from hopper_ros.recording.bag import BagReader
    from hopper_ros.recording.cdr import decode_columns

    reader = BagReader(path)
    source = str(path)
    size = sum(f.stat().st_size for f in reader.files)
    if size > MAX_BAG_BYTES:
        raise RecordingError(f"{source}: {size / 2**20:.1f} MiB of MCAP is more than this tool loads "
                             f"({MAX_BAG_BYTES >> 20} MiB); cut the recording into shorter runs")
    payloads = reader.payloads()
    if not payloads:
        raise RecordingError(f"{source}: the bag holds no messages")
    names = {key: _find_topic(payloads, relative, source, key == "body_measurement")
             for key, relative in TOPICS.items()}

    def columns(key: str, fields: tuple[str, ...]):
        """Time [s, relative to `origin`] and the fields of one topic, sorted by time."""
        type_name, _, data = payloads[names[key]]
        cls = message_class(type_name)
        decoded = decode_columns(cls, data)
        if decoded is not None:
            sec, nanosec = decoded["stamp_sec"], decoded["stamp_nanosec"]
            values = [decoded[f] for f in fields]
        else:  # message by message
            messages = [deserialize_message(d, cls) for d in data]
            sec = np.array([m.header.stamp.sec for m in messages], dtype=np.int64)
            nanosec = np.array([m.header.stamp.nanosec for m in messages], dtype=np.int64)
            values = [np.array([getattr(m, f) for m in messages]) for f in fields]
        t = (sec - origin) + nanosec * 1e-9
        order = np.argsort(t, kind="stable")
        return t[order], [np.asarray(v)[order] for v in values]

    origin = 0
    type_name, _, data = payloads[names["body_measurement"]]
    if len(data) < 2:
        raise RecordingError(f"{source}: {len(data)} body_measurement message(s): nothing to analyse")
    first = deserialize_message(data[0], message_class(type_name))
    origin = int(first.header.stamp.sec)
    t, (y, z, theta, tau) = columns("body_measurement", ("y", "z", "leg_angle", "hip_torque"))
    t0 = float(t[0])
    recording = Recording(t - t0, y, z, theta, tau, source=source, custom_data=reader.custom_data)
    if names["force_plate"]:
        ft, (forward, vertical, contact) = columns("force_plate", ("force_forward", "force_vertical", "contact"))
        recording.force = {"t": ft - t0, "forward": forward.astype(float), "vertical": vertical.astype(float),
                           "contact": contact.astype(bool)}
    if names["truth"]:
        gt, (gy, gz, gydot, gzdot, gtheta) = columns("truth", ("y", "z", "y_dot", "z_dot", "leg_angle"))
        recording.truth = {"t": gt - t0, "y": gy, "z": gz, "ydot": gydot, "zdot": gzdot, "theta": gtheta}
    if names["events"]:
        type_name, _, data = payloads[names["events"]]
        cls = message_class(type_name)
        for raw in data:
            msg = deserialize_message(raw, cls)
            s = msg.state
            recording.events.append(((msg.header.stamp.sec - origin) + msg.header.stamp.nanosec * 1e-9 - t0, int(msg.type),
                                     int(msg.stride_index), s.y, s.z, s.y_dot, s.z_dot, s.leg_angle))
        recording.events.sort()
    if names["stride_command"]:
        type_name, _, data = payloads[names["stride_command"]]
        cls = message_class(type_name)
        for raw in data:
            msg = deserialize_message(raw, cls)
            if not msg.feasible:
                continue
            profile = "constant" if msg.reason.startswith("constant") else "none" if msg.reason.startswith("no torque") else "ramp"
            recording.commands.append(StrideCommandRecord(
                (msg.header.stamp.sec - origin) + msg.header.stamp.nanosec * 1e-9 - t0, msg.tau_0, msg.touchdown_angle,
                msg.predicted_liftoff_time, profile))
        recording.commands.sort(key=lambda c: c.t)
    if recording.events:
        recording.phase = phases_from_events(recording.t, recording.events, recording.segments())
    return recording


def phases_from_events(t: np.ndarray, events: list, segments: list[slice] | None = None) -> np.ndarray:
    """Phase labels from true events: descent after an apex, compression after touchdown,
    decompression after the bottom, ascent after lift-off, and ascent before a run's first
    event when that is an apex; each run of samples (`segments`) on its own."""
    from hopper_ros.msg import GaitEvent

    following = {GaitEvent.APEX: Phase.DESCENT, GaitEvent.TOUCHDOWN: Phase.COMPRESSION,
                 GaitEvent.BOTTOM: Phase.DECOMPRESSION, GaitEvent.LIFTOFF: Phase.ASCENT}
    phase = np.full(len(t), UNLABELLED, dtype=int)
    ordered = sorted((e for e in events if e[1] in following), key=lambda e: e[0])
    for segment in segments or [slice(0, len(t))]:
        times = t[segment]
        inside = [e for e in ordered if times[0] <= e[0] <= times[-1]]
        labels = phase[segment]
        for k, event in enumerate(inside):
            start = np.searchsorted(times, event[0], side="right")
            end = np.searchsorted(times, inside[k + 1][0], side="right") if k + 1 < len(inside) else len(times)
            labels[start:end] = int(following[event[1]])
        if inside and inside[0][1] == GaitEvent.APEX:
            labels[:np.searchsorted(times, inside[0][0], side="right")] = int(Phase.ASCENT)
    return phase


def load_recording(path: str | os.PathLike) -> Recording:
    """A bag (folder, or .mcap file) or a CSV file."""
    path = Path(path)
    if path.is_dir() or path.suffix == ".mcap":
        return load_bag(path)
    if path.suffix.lower() == ".csv":
        return load_csv(path)
    raise RecordingError(f"{path}: expected a bag folder, an .mcap file or a .csv file")
