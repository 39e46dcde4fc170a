"""Apex-to-apex strides from 1 kHz kinematics (section 4.1's post-processing).

For every run of samples (a gap in t separates runs):

1. Phases. Given labels (a bag's true events, a CSV's phase column) are used as they are.
   Without them the stance is where the toe is on the ground, z - rho_0 cos(theta) <= 0: the
   leg is held at rest length in flight, so its toe height is known from the body height and
   the leg angle; touchdown and lift-off are the crossings of zero, interpolated between
   samples. (The leg force vanishes before the leg is back at rest length, at
   rho_0 - rho_lo = (d/k) rho' (2.28), 2-4 mm, so a detected lift-off is late by the time the
   toe takes to rise that far, 1-4 ms; kinematics alone cannot place it better, as the thesis
   notes in section 4.4.) Stances and flights
   shorter than `min_phase` are noise and merged away; the bottom is the lowest point of the
   stance (z' = 0, from a quadratic fit).
2. Apexes. In each flight the apex is the vertex of a quadratic fitted to z(t) over
   +-`apex_window` around the highest sample (inside the flight, away from its ends): its
   time and height; a quadratic fit of y(t) over the wider +-`speed_window` (the slope's noise
   falls as the window^-3/2; the quadratic term takes the flight damping) gives the forward
   position and speed there. A flight whose top is not inside the data has no apex. No model
   parameter enters (g is being identified).
3. Strides: an apex, the next stance, the next apex. Inputs: theta_td is the leg angle held
   before touchdown (median of the last `touchdown_samples`); tau_0 and t_f come from the
   stride's StrideCommand when the recording has one, else from a least-squares line through
   the stance torque, tau = -tau_0 (1 - t/t_f) (2.32), t from touchdown (|tau_0| below
   `zero_torque` counts as no torque).

Strides that fail a check are listed in `rejected` with the reason (the thesis eliminated its
outliers too).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from hopper_ros.physics.exact import Phase

from hopper_ros.recording.recordings import LIFTOFF_EVENT, TOUCHDOWN_EVENT, UNLABELLED, Recording


@dataclass(frozen=True)
class ExtractionSettings:
    apex_window: float = 0.04         # [s] half width of the apex fit of z(t)
    speed_window: float = 0.1         # [s] half width of the fit of y(t) for the apex speed
    min_apex_points: int = 15         # samples the apex fit needs
    edge_guard: float = 0.003         # [s] samples this close to touchdown/lift-off stay out of the apex fit
    min_phase: float = 0.015          # [s] shorter stances or flights are noise
    touchdown_samples: int = 5        # leg angle samples before touchdown for theta_td
    zero_torque: float = 0.05         # [N m] |tau_0| below this is no torque
    torque_skip: float = 0.002        # [s] stance torque samples skipped after touchdown (drive lag)
    late_torque: float = 0.01         # [s] a stance torque zero at touchdown starting within this: begun late
    max_ramp_duration: float = 10.0   # [s] a flat (constant) torque gets this t_f
    max_stance_time: float = 0.5      # [s]
    min_forward_speed: float = 0.05   # [m/s] the robot must run forward

    @classmethod
    def from_dict(cls, values, source: str = "extraction settings") -> "ExtractionSettings":
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values or {}) - known)
        if unknown:
            raise ValueError(f"{source}: unknown setting(s) {unknown}; known: {sorted(known)}")
        return cls(**{k: type(getattr(cls, k))(v) for k, v in (values or {}).items()})


APEX_FIT_FIELDS = ("apex_height", "apex_time", "apex_y", "forward_speed")   # Strides.apex_errors' columns
_STRIDE_FIELDS = ("apex_height", "forward_speed", "touchdown_angle", "tau_0", "ramp_duration",
                  "next_apex_height", "next_forward_speed", "stride_length", "stride_time",
                  "apex_time", "apex_y", "touchdown_time", "bottom_time", "liftoff_time", "next_apex_time",
                  "start", "stop")


@dataclass
class Strides:
    """Apex-to-apex strides, one entry per stride (SI; times on the recording's clock).

    `start`/`stop` index the recording's samples from the opening to the closing apex.
    """

    apex_height: np.ndarray
    forward_speed: np.ndarray
    touchdown_angle: np.ndarray
    tau_0: np.ndarray
    ramp_duration: np.ndarray
    next_apex_height: np.ndarray
    next_forward_speed: np.ndarray
    stride_length: np.ndarray
    stride_time: np.ndarray
    apex_time: np.ndarray
    apex_y: np.ndarray
    touchdown_time: np.ndarray
    bottom_time: np.ndarray
    liftoff_time: np.ndarray
    next_apex_time: np.ndarray
    start: np.ndarray
    stop: np.ndarray
    rejected: list = field(default_factory=list)    # (time [s], reason)
    phase: np.ndarray | None = None                 # phase label of every sample of the recording
    labelled: bool = False                          # phases from labels (True) or detected
    # per stride, the standard errors of the opening apex's fits (APEX_FIT_FIELDS columns), from their own residuals
    apex_errors: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.apex_height)

    def inputs(self) -> tuple[np.ndarray, ...]:
        """(apex height, forward speed, theta_td, tau_0, t_f): a predictor's arguments."""
        return self.apex_height, self.forward_speed, self.touchdown_angle, self.tau_0, self.ramp_duration

    def subset(self, index) -> "Strides":
        errors = None if self.apex_errors is None else self.apex_errors[index]
        return Strides(*(getattr(self, name)[index] for name in _STRIDE_FIELDS), rejected=[], phase=self.phase,
                       labelled=self.labelled, apex_errors=errors)

    @classmethod
    def empty(cls) -> "Strides":
        return cls(*(np.empty(0) for _ in _STRIDE_FIELDS))


# ---------------------------------------------------------------------- fits


def _quadratic_vertex(t: np.ndarray, values: np.ndarray):
    """Least-squares quadratic through (t, values): (vertex time, value there, curvature 2a)."""
    t0 = t.mean()
    a, b, c = np.polyfit(t - t0, values, 2)
    if a == 0.0:
        return math.nan, math.nan, 0.0
    vertex = -b / (2.0 * a)
    return t0 + vertex, c - b * b / (4.0 * a), 2.0 * a


def _quadratic_errors(t: np.ndarray, values: np.ndarray, orders) -> tuple[float, ...]:
    """Standard errors of the coefficients of t^order (for each of `orders`) of the least-squares quadratic
    through (t, values), the noise level taken from its own residual."""
    basis = np.vander(t, 3, increasing=True)
    coefficients, *_ = np.linalg.lstsq(basis, values, rcond=None)
    residual = values - basis @ coefficients
    variance = float(residual @ residual) / max(len(t) - 3, 1)
    inverse = np.linalg.pinv(basis.T @ basis)
    return tuple(math.sqrt(max(variance * inverse[k, k], 0.0)) for k in orders)


def _crossing(t: np.ndarray, values: np.ndarray, index: int) -> float:
    """Time where `values` crosses zero between samples index-1 and index (linear)."""
    v0, v1 = values[index - 1], values[index]
    if v1 == v0:
        return float(t[index])
    return float(t[index - 1] + (t[index] - t[index - 1]) * v0 / (v0 - v1))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the True runs of a boolean array."""
    padded = np.concatenate(([False], mask, [False]))
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def _clean_stance(mask: np.ndarray, min_samples: int) -> np.ndarray:
    """Drop stance blips and fill flight blips shorter than `min_samples`."""
    mask = mask.copy()
    for a, b in _runs(~mask):
        if 0 < a and b < len(mask) and b - a < min_samples:
            mask[a:b] = True
    for a, b in _runs(mask):
        if b - a < min_samples:
            mask[a:b] = False
    return mask


# ---------------------------------------------------------------------- extraction


def extract_strides(recording: Recording, rest_length: float, settings: ExtractionSettings | None = None) -> Strides:
    """Every apex-to-apex stride of a recording (see the module docstring)."""
    settings = settings or ExtractionSettings()
    period = recording.period
    labelled = recording.phase is not None and np.any(recording.phase != UNLABELLED)
    phase_out = np.full(len(recording), UNLABELLED, dtype=int)
    rows: list[tuple] = []
    errors: list[tuple] = []
    rejected: list[tuple[float, str]] = []
    for segment in recording.segments():
        _segment_strides(recording, segment, rest_length, settings, period, labelled, phase_out, rows, errors,
                         rejected)
    if not rows:
        out = Strides.empty()
    else:
        columns = list(zip(*rows))
        out = Strides(*(np.asarray(c, dtype=float) for c in columns[:-2]),
                      np.asarray(columns[-2], dtype=int), np.asarray(columns[-1], dtype=int))
    out.rejected, out.phase, out.labelled = rejected, phase_out, bool(labelled)
    out.apex_errors = np.asarray(errors, dtype=float).reshape(len(rows), len(APEX_FIT_FIELDS))
    return out


def _segment_strides(rec: Recording, segment: slice, rho_0: float, s: ExtractionSettings, period: float,
                     labelled: bool, phase_out: np.ndarray, rows: list, errors: list, rejected: list) -> None:
    t, y, z, theta, tau = (getattr(rec, n)[segment] for n in ("t", "y", "z", "theta", "tau"))
    offset = segment.start
    min_samples = max(2, int(round(s.min_phase / period)))
    if labelled:
        labels = rec.phase[segment]
        stance = (labels == Phase.COMPRESSION) | (labels == Phase.DECOMPRESSION)
    else:
        clearance = z - rho_0 * np.cos(theta)
        stance = _clean_stance(clearance <= 0.0, min_samples)
    stance_runs = _runs(stance)
    # event times: interpolated crossings (detected) or the label edges
    stances = []
    for a, b in stance_runs:
        if a == 0 or b == len(t):
            continue                              # a stance cut by the segment's ends
        if labelled:
            td = _event_time(rec, TOUCHDOWN_EVENT, t[a - 1], t[a])
            lo = _event_time(rec, LIFTOFF_EVENT, t[b - 1], t[b])
        else:
            td, lo = _crossing(t, clearance, a), _crossing(t, clearance, b)
        stances.append((a, b, td, lo))
    flights = []
    edges = [0] + [x for a, b, *_ in stances for x in (a, b)] + [len(t)]
    for k in range(0, len(edges), 2):
        flights.append((edges[k], edges[k + 1]))
    apexes = [_apex(t, y, z, a, b, s, period) for a, b in flights]
    # phase labels of the segment's samples
    if labelled:
        phase_out[segment] = rec.phase[segment]
    else:
        for (a, b), apex in zip(flights, apexes):
            top = apex[0] if apex else (t[a] if a > 0 else t[b - 1])
            phase_out[offset + a:offset + b] = np.where(t[a:b] < top, int(Phase.ASCENT), int(Phase.DESCENT))
    bottoms = []
    for a, b, td, lo in stances:
        low = a + int(np.argmin(z[a:b]))
        window = slice(max(a, low - 10), min(b, low + 11))
        bottom = _quadratic_vertex(t[window], z[window])[0] if window.stop - window.start >= 5 else t[low]
        if not t[a] <= bottom <= t[b - 1]:
            bottom = float(t[low])
        bottoms.append(bottom)
        if not labelled:
            phase_out[offset + a:offset + b] = np.where(t[a:b] < bottom, int(Phase.COMPRESSION), int(Phase.DECOMPRESSION))
    # strides: flight k's apex, stance k, flight k+1's apex
    for k, (a, b, td, lo) in enumerate(stances):
        opening, closing = apexes[k], apexes[k + 1]
        when = float(t[a])
        if opening is None or closing is None:
            rejected.append((when, "no apex " + ("before" if opening is None else "after") + " the stance in the data"))
            continue
        if not lo - td <= s.max_stance_time:
            rejected.append((when, f"stance of {lo - td:.3f} s is longer than {s.max_stance_time} s"))
            continue
        if opening[3] < s.min_forward_speed:
            rejected.append((when, f"forward speed {opening[3]:.3f} m/s at the apex: not running forward"))
            continue
        before = theta[max(0, a - s.touchdown_samples):a]
        touchdown_angle = float(np.median(before)) if before.size else float(theta[a])
        command = _command_for(rec, t[flights[k][0]], td)
        if command is not None:
            tau_0, ramp = command.tau_0, command.ramp_duration
            if command.profile == "constant":
                ramp = s.max_ramp_duration
        else:
            tau_0, ramp = ramp_from_torque(t[a:b] - td, tau[a:b], lo - td, s)
        start = offset + int(np.searchsorted(t, opening[0]))
        stop = offset + int(np.searchsorted(t, closing[0], side="right"))
        rows.append((opening[1], opening[3], touchdown_angle, tau_0, ramp, closing[1], closing[3], closing[2] - opening[2],
                     closing[0] - opening[0], opening[0], opening[2], td, bottoms[k], lo, closing[0], start, stop))
        errors.append(opening[4])


def _event_time(rec: Recording, kind: int, before: float, after: float) -> float:
    """The recorded event of `kind` between two samples, else their midpoint."""
    for event in rec.events:
        if event[1] == kind and before - 1e-9 <= event[0] <= after + 1e-9:
            return float(event[0])
    return 0.5 * (before + after)


def _apex(t, y, z, a: int, b: int, s: ExtractionSettings, period: float):
    """(time, height, y, forward speed, their standard errors in APEX_FIT_FIELDS order) of the apex of flight
    [a, b), or None."""
    guard = int(math.ceil(s.edge_guard / period))
    lo = a + (guard if a > 0 else 0)
    hi = b - (guard if b < len(t) else 0)
    if hi - lo < s.min_apex_points:
        return None
    top = lo + int(np.argmax(z[lo:hi]))
    half = int(round(s.apex_window / period))
    window = slice(max(lo, top - half), min(hi, top + half + 1))
    if window.stop - window.start < s.min_apex_points:
        return None
    tt = t[window]
    vertex, height, curvature = _quadratic_vertex(tt, z[window])
    z_errors = _quadratic_errors(tt - vertex, z[window], (0, 1))
    if not (curvature < 0.0 and tt[0] - 2 * period <= vertex <= tt[-1] + 2 * period):
        return None
    if (vertex < tt[0] + 0.2 * (tt[-1] - tt[0]) and window.start == lo and lo > 0) or \
            (vertex > tt[-1] - 0.2 * (tt[-1] - tt[0]) and window.stop == hi and hi < len(t)):
        return None                       # the top is at the flight's end: no apex inside this flight
    wide = int(round(s.speed_window / period))
    window = slice(max(lo, top - wide), min(hi, top + wide + 1))
    cy = np.polyfit(t[window] - vertex, y[window], 2)
    y_errors = _quadratic_errors(t[window] - vertex, y[window], (0, 1))
    # the vertex time's error: the slope's at the vertex over the curvature (the height's is first order zero)
    errors = (z_errors[0], z_errors[1] / max(abs(curvature), 1e-9), y_errors[0], y_errors[1])
    return float(vertex), float(height), float(cy[2]), float(cy[1]), errors


def _command_for(rec: Recording, flight_start: float, touchdown: float):
    """The StrideCommand issued during the flight that ends at `touchdown`."""
    chosen = None
    for command in rec.commands:
        if flight_start - 1.0 <= command.t <= touchdown:
            chosen = command
    return chosen


def torque_start(since: np.ndarray, tau: np.ndarray, s: ExtractionSettings) -> float | None:
    """[s] after the touchdown `since` counts from, where the stance torque's ramp starts: 0 where the torque is on
    at the first sample from touchdown, else between its last zero and first nonzero sample; None where it never
    starts, or starts later than `late_torque` (no ramp)."""
    on = (np.abs(tau) > s.zero_torque) & (since >= 0.0)
    if not np.any(on):
        return None
    first = int(np.argmax(on))
    if first == 0 or since[first - 1] < 0.0:
        return 0.0
    start = 0.5 * (since[first - 1] + since[first])      # zero at the touchdown: from between its last zero and first
    return start if start <= s.late_torque else None


def ramp_from_torque(since: np.ndarray, tau: np.ndarray, stance_time: float, s: ExtractionSettings):
    """(tau_0, t_f) of the ramp -tau_0 (1 - t/t_f) (2.32) through the stance torque samples, `since` the
    touchdown as the recording's leg length gives it. A torque still zero there that starts within
    `late_torque` began late (the ground lower than the model's, the height read low): its ramp is read from
    its own start, as the leg met it (read from that touchdown it was no ramp at all once it started after
    the skipped samples, and a larger one before)."""
    start = torque_start(since, tau, s)
    if start is None:
        return 0.0, stance_time
    # away from both ends: the drive lags at the ramp's start, and the detected lift-off is late, so
    # the last stance samples may already hold the flight's leg regulator torque
    use = (since >= start + s.torque_skip) & (since <= stance_time - s.edge_guard)
    if use.sum() < 3:
        return 0.0, stance_time
    t_use, tau_use = since[use] - start, tau[use]
    active = np.abs(tau_use) > s.zero_torque
    if active.sum() < 3 or not active[0]:
        return 0.0, stance_time
    # the ramp is the active run from its start on; once it ends the torque stays zero
    inactive = np.flatnonzero(~active)
    end = int(inactive[0]) if inactive.size else len(active)
    if end < 3:
        return 0.0, stance_time
    slope, intercept = np.polyfit(t_use[:end], tau_use[:end], 1)
    tau_0 = -float(intercept)
    if abs(tau_0) < s.zero_torque:
        return 0.0, stance_time
    if slope == 0.0 or tau_0 / slope <= 0.0:
        return tau_0, s.max_ramp_duration      # flat: a constant torque
    return tau_0, float(min(tau_0 / slope, s.max_ramp_duration))
