"""A recording made ready for diagnosis: strides, phases per sample, sensor noise levels."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hopper_ros.identification.recordings import Recording
from hopper_ros.identification.strides import extract_strides
from hopper_ros.physics.exact import Phase
from hopper_ros.physics.params import ModelParams

PHASES = ("descent", "compression", "decompression", "liftoff", "ascent")


class DiagnosisError(ValueError):
    """A recording the tool cannot diagnose (the message says why)."""


def check_recording(rec: Recording) -> None:
    period = rec.period
    if not 0.99e-3 <= period <= 1.01e-3:
        raise DiagnosisError(f"{rec.source}: the samples are {period * 1e3:.3f} ms apart; the tool needs a 1 kHz "
                             "time base (resample the recording first)")
    steps = np.diff(rec.t)
    bad = np.flatnonzero((steps > 1.5e-3) & (steps < 3 * period))
    if bad.size > 0.01 * len(steps):
        raise DiagnosisError(f"{rec.source}: irregular time base ({bad.size} steps between 1.5 and 3 ms)")


def quantum(x: np.ndarray) -> float:
    """The channel's quantisation step (0 when it looks continuous)."""
    q = np.diff(np.unique(np.round(x, 12)))
    q = q[q > 0]
    if q.size == 0:
        return 0.0
    step = float(np.median(q))
    return step if q.size > 10 and np.mean(np.abs(q / step - np.round(q / step)) < 0.05) > 0.9 else 0.0


def noise_level(x: np.ndarray, mask: np.ndarray) -> float:
    """Sensor noise std from the third differences over flight samples (robust, MAD), at least the
    quantisation's."""
    d3 = x[3:] - 3 * x[2:-1] + 3 * x[1:-2] - x[:-3]
    ok = mask[3:] & mask[:-3]
    d3 = d3[ok]
    if d3.size < 20:
        return float("nan")
    floor = quantum(x) / math.sqrt(12)
    return max(1.4826 * float(np.median(np.abs(d3 - np.median(d3)))) / math.sqrt(20.0), floor, 1e-7)


@dataclass
class StrideData:
    rec: Recording
    strides: object
    params: ModelParams
    sigma: dict
    quantum: dict
    phase: np.ndarray        # per sample: index into PHASES, -1 outside strides
    duration: float
    sample_count: int = 0
    corr_length: float = 1.0


def prepare(rec: Recording, params: ModelParams, min_strides: int, liftoff_window: float) -> StrideData:
    check_recording(rec)
    strides = extract_strides(rec, params.rest_length)
    if len(strides) < min_strides:
        raise DiagnosisError(f"{rec.source}: only {len(strides)} complete apex-to-apex strides found "
                             f"(at least {min_strides} needed; rejected: {strides.rejected[:3]})")
    labels = strides.phase
    phase = np.full(len(rec), -1)
    phase[labels == Phase.DESCENT] = 0
    phase[labels == Phase.COMPRESSION] = 1
    phase[labels == Phase.DECOMPRESSION] = 2
    phase[labels == Phase.ASCENT] = 4
    inside = np.zeros(len(rec), bool)
    for a, b in zip(strides.start, strides.stop):
        inside[a:b] = True
    for lo in strides.liftoff_time:
        phase[np.abs(rec.t - lo) <= liftoff_window] = 3
    phase[~inside] = -1
    flight = (labels == Phase.DESCENT) | (labels == Phase.ASCENT)
    sigma = {v: noise_level(getattr(rec, v), flight) for v in ("y", "z", "theta")}
    stance = (labels == Phase.COMPRESSION) | (labels == Phase.DECOMPRESSION)
    if not np.isfinite(sigma["theta"]):
        sigma["theta"] = noise_level(rec.theta, stance)
    for v in sigma:
        if not np.isfinite(sigma[v]):
            sigma[v] = 1e-4
    q = {v: quantum(getattr(rec, v)) for v in ("y", "z", "theta")}
    duration = float(np.max(rec.t[strides.stop - 1] - strides.apex_time)) + 0.01
    data = StrideData(rec, strides, params, sigma, q, phase, duration)
    data.sample_count = int(sum(int(b - a) for a, b in zip(strides.start, strides.stop)))
    return data
