"""A recording made ready for diagnosis: strides, phases per sample, sensor noise levels."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from hopper_ros.recording.recordings import Recording
from hopper_ros.identification.strides import ExtractionSettings, extract_strides, ramp_from_torque
from hopper_ros.physics.exact import Phase
from hopper_ros.physics.params import ModelParams

PHASES = ("descent", "compression", "decompression", "liftoff", "ascent")
LEAD_RESOLVED = 1e-3   # [s] a median stance start this far from the model's touchdown is not timing noise


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


def held_touchdown_angles(rec: Recording, strides, sigma_theta: float, hold: int = 10, search: int = 40):
    """theta_td per stride as the angle the leg was held at when stance began, and how long before the
    model's touchdown (the toe at the model's rest length) that hold ended [s].

    The leg is held at the touchdown angle in late flight; in stance it turns with the body at several
    rad/s. The hold ends at the last sample (searched back from just after the model's touchdown) that
    stays within 4 noise levels of the median of the `hold` samples before it. The recorded angle just
    before the model's touchdown is already in stance when the ground is higher, or the leg longer, than
    the model has it; the held angle is not."""
    t, theta = rec.t, rec.theta
    angles, lead = strides.touchdown_angle.copy(), np.zeros(len(strides))
    limit = 4.0 * sigma_theta
    for i, td in enumerate(strides.touchdown_time):
        a = int(np.searchsorted(t, td))
        lowest = max(hold + 1, a - search)
        for j in range(min(a + 3, len(t) - 1), lowest, -1):
            ref = float(np.median(theta[j - hold:j]))
            if abs(theta[j] - ref) < limit and abs(theta[j - 1] - ref) < limit:
                angles[i] = float(np.median(theta[j - hold:j + 1]))
                lead[i] = td - _turn_start(t, theta, j, angles[i])
                break
    return angles, lead


def _turn_start(t, theta, j: int, angle: float) -> float:
    """Where the stance's turning leaves the held `angle`, j the last held sample: a line through the next 4."""
    after = slice(j + 1, min(j + 5, len(t)))
    if after.stop - after.start >= 2:
        slope, level = np.polyfit(t[after] - t[j], theta[after], 1)
        if abs(slope) > 0:
            return t[j] + float(np.clip((angle - level) / slope, 0.0, t[j + 1] - t[j]))
    return t[j]


def stance_begins(data: "StrideData", window: float = 0.04) -> np.ndarray:
    """[s] per stride where the held leg starts to turn, also when that is after the model's touchdown (where
    `held_touchdown_angles`, searching back from it, stops): searched forward from 3 ms before that start to
    `window` after the model's touchdown, the first of three samples 4 noise levels off the held angle on one
    side; the model's touchdown where none is."""
    rec, s = data.rec, data.strides
    limit = 4.0 * data.sigma["theta"]
    out = s.touchdown_time.copy()
    for i, (td, angle) in enumerate(zip(s.touchdown_time, s.touchdown_angle)):
        a, b = np.searchsorted(rec.t, [data.stance_start[i] - 0.003, td + window])
        off = rec.theta[a:b + 1] - angle
        side = np.where(off > limit, 1, np.where(off < -limit, -1, 0))
        turned = np.flatnonzero((side[1:-2] != 0) & (side[1:-2] == side[2:-1]) & (side[1:-2] == side[3:]))
        if turned.size:
            out[i] = _turn_start(rec.t, rec.theta, a + int(turned[0]), angle)
    return out


def _ramp_from_stance_start(strides, lead: float) -> None:
    """The (2.32) ramps read from the logged torque were timed from the model's touchdown; the drive
    started them when stance began, `lead` seconds earlier: the same line, t_f longer by `lead` and
    tau_0 the ramp's value at its real start (`earlier_ramps`)."""
    strides.tau_0, strides.ramp_duration = earlier_ramps(strides.tau_0, strides.ramp_duration, lead)


def ramps_retimed(data: "StrideData") -> bool:
    """Whether `prepare` re-timed the ramps from the start of stance (it began more than `LEAD_RESOLVED` before the
    model's touchdown), rather than from the model's touchdown."""
    return not data.rec.commands and data.touchdown_lead > LEAD_RESOLVED


def earlier_ramps(tau_0, ramp_duration, lead):
    """(tau_0, t_f) of (2.32)'s ramps started `lead` seconds earlier on the same line: t_f longer by `lead` and
    tau_0 the line's value there. Constant torques (t_f at its cap) are unchanged."""
    timed = (tau_0 != 0) & (ramp_duration > 0) & (ramp_duration < ExtractionSettings().max_ramp_duration)
    new_ramp = np.where(timed, ramp_duration + lead, ramp_duration)
    return np.where(timed, tau_0 * new_ramp / np.where(timed, ramp_duration, 1.0), tau_0), new_ramp


def own_ramps(data: "StrideData") -> "StrideData":
    """A copy whose ramps are read from the logged torque from each stride's own start of stance (where it is
    more than `LEAD_RESOLVED` from the model's touchdown), as a floor at another height per stride has them: a
    stance that begins late leaves the torque's first samples after the model's touchdown at zero, read as no
    ramp. Unchanged where the recording logs the commands."""
    s, rec = data.strides, data.rec
    if rec.commands:
        return data
    begins = stance_begins(data)
    lead = s.touchdown_time - begins
    if not np.any(np.abs(lead) > LEAD_RESOLVED):
        return data
    strides = s.subset(np.arange(len(s)))
    settings = ExtractionSettings()
    for i in np.flatnonzero(np.abs(lead) > LEAD_RESOLVED):
        start, end = begins[i], s.liftoff_time[i]
        a, b = np.searchsorted(rec.t, [start, end])
        strides.tau_0[i], strides.ramp_duration[i] = ramp_from_torque(rec.t[a:b] - start, rec.tau[a:b], end - start,
                                                                      settings)
    return replace(data, strides=strides)


@dataclass(repr=False)
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
    model_sse: float = 1.0       # the model's own trajectory SSE (before any effect)
    touchdown_lead: float = 0.0  # [s] median: stance began this long before the model's leg met the ground
    stance_start: np.ndarray = field(default_factory=lambda: np.zeros(0))   # [s] per stride: the held leg turns
    ringing: dict = field(default_factory=dict)   # channel -> its ringing after lift-off (`ringing`), found once
    # variant key -> (SSE, next apex) per stride, simulated once (`simulate.simulate_variants`); not passed on by
    # dataclasses.replace: a subset of the strides has its own
    simulated: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    located: dict = field(default_factory=dict, init=False, repr=False, compare=False)   # ... (locate.locate)
    swing: dict = field(default_factory=dict, init=False, repr=False, compare=False)     # ... (swing.geometry)
    # the strides' indices -> that subset of this data, made once so that its simulations are kept (`search.screen`)
    subsets: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return f"StrideData({self.rec.source}, {len(self.strides)} strides)"

    @property
    def liftoffs(self) -> np.ndarray:
        """[s] every stride's recorded lift-off, in order."""
        return np.sort(self.strides.liftoff_time)


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
    strides.touchdown_angle, touchdown_lead = held_touchdown_angles(rec, strides, sigma["theta"])
    q = {v: quantum(getattr(rec, v)) for v in ("y", "z", "theta")}
    duration = float(np.max(rec.t[strides.stop - 1] - strides.apex_time)) + 0.01
    data = StrideData(rec, strides, params, sigma, q, phase, duration)
    data.sample_count = int(sum(int(b - a) for a, b in zip(strides.start, strides.stop)))
    data.stance_start = strides.touchdown_time - touchdown_lead
    data.touchdown_lead = float(np.median(touchdown_lead))
    # only an early start is re-timed: a late one is as often the angle channel lagging as the ground lower
    if ramps_retimed(data):
        _ramp_from_stance_start(strides, data.touchdown_lead)
    return data
