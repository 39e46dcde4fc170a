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

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hopper_ros.recording.recordings import Recording, RecordingError
from hopper_ros.recording.mapping_file import CHANNELS, Channel, ImportMapping, load_mapping
from hopper_ros.recording.mapped_read import bag_series, csv_series, field_value, parse_path

__all__ = ["CHANNELS", "Channel", "ImportMapping", "Imported", "field_value", "load_mapped", "load_mapping",
           "noise_level", "parse_path", "resample_with_noise"]

# what a hopping robot's channels can be, in SI: outside, the unit (or scale) is wrong
PLAUSIBLE = {"z": (-0.5, 3.0, "a body height above the ground lies within -0.5 to 3 m"),
             "theta": (-math.pi / 2, math.pi / 2, "a leg angle from the vertical lies within +-1.57 rad"),
             "tau": (-500.0, 500.0, "a hip torque lies within +-500 N m")}
MAX_FORWARD_SPEED = 30.0          # [m/s] a median |dy/dt| above it: y's unit is wrong
RATE_LIMITS = (20.0, 100000.0)    # [Hz] sample rates outside: the time unit is wrong
GAP_FACTOR = 3.0                  # a step longer than this many sample periods separates runs
RATE_TOLERANCE = 0.01             # a recorded rate this close to the target is used as it is


@dataclass
class Imported:
    """The recording in the tools' form and what was done to get it (one line each)."""

    recording: Recording
    notes: list[str] = field(default_factory=list)
    recorded_rate: float = 0.0


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
        series = csv_series(mapping, source)
    else:
        if not (source.is_dir() or source.suffix == ".mcap"):
            raise RecordingError(f"{mapping.path}: the channels name bag topics, {source} is not a bag "
                                 "(a folder or .mcap file)")
        series = bag_series(mapping, source)
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
