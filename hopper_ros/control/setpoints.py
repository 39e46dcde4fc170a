"""Apex setpoint schedules: parsing, validation and advancing. No ROS import.

A schedule file is YAML:

    segments:                 # in order; the first is active from the start
      - apex_height: 0.39     # desired apex height [m], > 0
        forward_speed: 2.0    # desired forward speed at apex [m/s], finite
        strides: 10           # hold for this many apexes, then advance (integer >= 1)
      - apex_height: 0.42
        forward_speed: 2.0
        seconds: 5.0          # ... or hold for this long [s] (> 0), counted from activation
      - apex_height: 0.38
        forward_speed: 2.5    # the last segment may omit strides/seconds: held for good
    repeat: false             # optional: after the last segment, start over at the first

Each segment has exactly one of `strides` and `seconds` (only the last may have neither).
When the last segment ends without `repeat`, its setpoint stays in force (`finished` is set).
Errors name the file and the segment (1-based) at fault.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

from hopper_ros.config import load_yaml

_SEGMENT_KEYS = {"apex_height", "forward_speed", "strides", "seconds"}
_TOP_KEYS = {"segments", "repeat"}


from hopper_ros.config.schema import ConfigError  # noqa: E402 - no ROS, no heavy import


class ScheduleError(ConfigError):
    """A schedule file that cannot be used, with the file and entry named."""


@dataclass(frozen=True)
class Segment:
    apex_height: float  # [m]
    forward_speed: float  # [m/s]
    strides: int | None = None  # advance after this many apexes
    seconds: float | None = None  # advance after this long [s]

    def describe(self) -> str:
        if self.strides is not None:
            hold = f"for {self.strides} strides"
        elif self.seconds is not None:
            hold = f"for {self.seconds:g} s"
        else:
            hold = "until stopped"
        return f"apex height {self.apex_height:g} m, forward speed {self.forward_speed:g} m/s, {hold}"


@dataclass(frozen=True)
class Schedule:
    segments: tuple[Segment, ...]
    repeat: bool = False
    source: str = "<schedule>"


def _number(value: Any, where: str, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScheduleError(f"{where}: {key!r} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ScheduleError(f"{where}: {key!r} must be finite, got {value!r}")
    return value


def parse_schedule(data: Any, source: str = "<schedule>") -> Schedule:
    """Validate the parsed YAML of a schedule file and build the `Schedule`."""
    if not isinstance(data, dict):
        raise ScheduleError(f"{source}: expected a mapping with a 'segments' list, got {type(data).__name__}")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise ScheduleError(f"{source}: unknown key(s) {', '.join(map(repr, unknown))} (known: segments, repeat)")
    entries = data.get("segments")
    if not isinstance(entries, list) or not entries:
        raise ScheduleError(f"{source}: 'segments' must be a non-empty list")
    repeat = data.get("repeat", False)
    if not isinstance(repeat, bool):
        raise ScheduleError(f"{source}: 'repeat' must be true or false, got {repeat!r}")

    segments = []
    for index, entry in enumerate(entries):
        where = f"{source}: segment {index + 1}"
        if not isinstance(entry, dict):
            raise ScheduleError(f"{where}: expected a mapping, got {entry!r}")
        unknown = sorted(set(entry) - _SEGMENT_KEYS)
        if unknown:
            raise ScheduleError(
                f"{where}: unknown key(s) {', '.join(map(repr, unknown))} (known: {', '.join(sorted(_SEGMENT_KEYS))})"
            )
        for key in ("apex_height", "forward_speed"):
            if key not in entry:
                raise ScheduleError(f"{where}: missing {key!r}")
        height = _number(entry["apex_height"], where, "apex_height")
        if height <= 0.0:
            raise ScheduleError(f"{where}: 'apex_height' must be positive [m], got {height:g}")
        speed = _number(entry["forward_speed"], where, "forward_speed")

        strides = entry.get("strides")
        seconds = entry.get("seconds")
        if strides is not None and seconds is not None:
            raise ScheduleError(f"{where}: give either 'strides' or 'seconds', not both")
        if strides is not None and (isinstance(strides, bool) or not isinstance(strides, int) or strides < 1):
            raise ScheduleError(f"{where}: 'strides' must be an integer >= 1, got {strides!r}")
        if seconds is not None:
            seconds = _number(seconds, where, "seconds")
            if seconds <= 0.0:
                raise ScheduleError(f"{where}: 'seconds' must be positive, got {seconds:g}")
        last = index == len(entries) - 1
        if strides is None and seconds is None and (not last or repeat):
            raise ScheduleError(
                f"{where}: missing 'strides' or 'seconds' (only the last segment of a schedule "
                "without repeat may be held for good)"
            )
        segments.append(Segment(height, speed, strides, seconds))
    return Schedule(tuple(segments), repeat, source)


def load_schedule(name: str | os.PathLike) -> Schedule:
    """Read and validate a schedule file (a path, or relative to the config directory): its schema
    (hopper_ros.config.schemas.SCHEDULE) first, then the rules across segments."""
    from hopper_ros.config import config_path
    from hopper_ros.config.schemas import SCHEDULE
    from hopper_ros.config.schema import ConfigError, load_config

    try:
        load_config(name, SCHEDULE)
    except ConfigError as exc:
        raise ScheduleError(str(exc)) from None
    return parse_schedule(load_yaml(name), source=str(config_path(name)))


class ScheduleRunner:
    """Where a schedule stands: the active segment, advanced by apexes and by time.

    Times are plain floats in seconds on any monotonic clock the caller chooses.
    """

    def __init__(self, schedule: Schedule, start_time: float):
        self.schedule = schedule
        self.index = 0
        self.finished = False
        self._apexes = 0
        self._since = start_time

    @property
    def segment(self) -> Segment:
        return self.schedule.segments[self.index]

    def deadline(self) -> float | None:
        """When the active segment ends by time, or None."""
        if self.finished or self.segment.seconds is None:
            return None
        return self._since + self.segment.seconds

    def on_apex(self, time: float) -> bool:
        """Count one apex; True when this made the active segment change."""
        if self.finished or self.segment.strides is None:
            return False
        self._apexes += 1
        if self._apexes >= self.segment.strides:
            return self._advance(time)
        return False

    def on_time(self, time: float) -> bool:
        """Advance past every segment whose time is up at `time`; True when the segment changed."""
        changed = False
        while True:
            deadline = self.deadline()
            if deadline is None or time < deadline:
                return changed
            changed = self._advance(deadline) or changed

    def _advance(self, time: float) -> bool:
        if self.index + 1 < len(self.schedule.segments):
            self.index += 1
        elif self.schedule.repeat:
            self.index = 0
        else:
            self.finished = True
            return False
        self._apexes = 0
        self._since = time
        return True
