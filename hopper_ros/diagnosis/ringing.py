"""A position channel that rings after lift-off: a decaying oscillation the body does not have.

A structural mode excited by the lift-off collision (the boom bending, a loose encoder coupling) shows
in a position channel as

    x_meas = x + exp(-r s) (a sin(2 pi f s) + b cos(2 pi f s)),   s = time since lift-off >= 0.

After lift-off the body flies freely and its own path is close to a parabola, so each stride's
channel is fitted, from lift-off to the next apex, by a quadratic in s (its own per stride) plus the
oscillation. The frequency f (at least two periods per window: slower is a trend) and the decay
rate r (at most f: a faster decay is a transient, not ringing) are scanned, then refined about the
best; the amplitudes a, b are common to all
strides, fitted on training strides and judged on held-out ones (5 folds, paired over strides). The
oscillation is proposed only where held-out strides prefer it (one-sided t >= 3) and its amplitude is at least the channel's noise level; then, like any
discovered term set, it is refitted on the trajectories and must pass the engine's guards.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .sites import CHANNEL_SITE

FREQUENCIES = np.geomspace(4.0, 80.0, 64)      # [Hz] scanned (those with MIN_CYCLES in the median window)
DECAY_RATES = (2.0, 5.0, 10.0, 20.0, 40.0)     # [1/s] scanned, then both refined about the best
MIN_CYCLES = 2.0         # an oscillation slower than this many periods per window is a trend, not ringing
# ... and one that loses more than 1/e of its amplitude within a period (decay rate > frequency) a transient
GUARD = 0.002            # [s] skipped after the detected lift-off (its timing is uncertain)
FOLDS = 5
MIN_T = 3.0
MIN_AMPLITUDE = 1.0      # x the channel's noise level: a smaller oscillation cannot matter to the fit
CHANNEL_WORDS = {"z": "height", "y": "forward position"}
KEYS = ("sin", "cos", "hz", "decay")


def key(channel: str, part: str) -> str:
    """The sensor key (Variant.sensors) of one part of a channel's ringing."""
    return f"{channel}_ring_{part}"


def ringing(sensors: dict, channel: str, since_liftoff):
    """The oscillation added to `channel`'s measurement at times `since_liftoff` (zero before lift-off)."""
    a, b = sensors.get(key(channel, "sin"), 0.0), sensors.get(key(channel, "cos"), 0.0)
    s = np.asarray(since_liftoff, dtype=float)
    if not np.any(a) and not np.any(b):
        return np.zeros_like(s)
    w = 2 * math.pi * np.asarray(sensors[key(channel, "hz")])
    r = np.asarray(sensors[key(channel, "decay")])
    after = s >= 0.0
    sa = np.where(after, s, 0.0)
    return np.where(after, np.exp(-r * sa) * (a * np.sin(w * sa) + b * np.cos(w * sa)), 0.0)


def since_liftoff(t, liftoff_times):
    """Time since the latest lift-off (sorted `liftoff_times`) at each of `t`; -1 before the first."""
    t = np.asarray(t, dtype=float)
    k = np.searchsorted(liftoff_times, t, side="right") - 1
    return np.where(k >= 0, t - liftoff_times[np.maximum(k, 0)], -1.0)


@dataclass
class Ringing:
    site: str
    channel: str
    amplitudes: tuple        # (a, b) [m]
    frequency: float         # [Hz]
    decay: float             # [1/s]
    explained: float         # share of the detrended channel's variance explained on held-out strides
    t: float
    field: str = "ringing"
    measurement = True       # it changes what is measured, not the motion (judged like a sensor fault)

    @property
    def amplitude(self) -> float:
        return float(math.hypot(*self.amplitudes))

    def sensors(self, scale: float) -> dict:
        a, b = self.amplitudes
        return {key(self.channel, "sin"): scale * a, key(self.channel, "cos"): scale * b,
                key(self.channel, "hz"): self.frequency, key(self.channel, "decay"): self.decay}

    def terms(self) -> list[tuple[str, float, str, str]]:
        a, b = self.amplitudes
        what = f"a decaying oscillation at {self.frequency:.3g} Hz, decay rate {self.decay:.3g} 1/s"
        return [("exp(-r s) sin(2 pi f s)", a, what + " (sine part)", "m"),
                ("exp(-r s) cos(2 pi f s)", b, what + " (cosine part)", "m")]

    def words(self, scale: float = 1.0) -> str:
        return (f"after lift-off, the {CHANNEL_WORDS[self.channel]} channel rings: {scale * self.amplitude * 1e3:.3g} mm "
                f"at {self.frequency:.3g} Hz decaying at {self.decay:.3g} 1/s (time constant "
                f"{1e3 / self.decay:.3g} ms), which the body's flight does not have: a structural mode excited by "
                "the lift-off (the boom bending, a loose encoder coupling) seen by the sensor")


def _windows(data, channel: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per stride (time since lift-off, the channel with its best quadratic in s removed, and that projector)."""
    rec, s = data.rec, data.strides
    x = getattr(rec, channel)
    out = []
    for i in range(len(s)):
        lo = float(s.liftoff_time[i])
        a = int(np.searchsorted(rec.t, lo + GUARD))
        b = int(s.stop[i])
        if b - a < 20:
            continue
        since = rec.t[a:b] - lo
        basis = np.column_stack([np.ones_like(since), since, since ** 2])
        q = np.linalg.qr(basis)[0]
        out.append((since, q, x[a:b] - q @ (q.T @ x[a:b])))
    return out


def _design(windows, frequency: float, decay: float) -> list[np.ndarray]:
    out = []
    w = 2 * math.pi * frequency
    for since, q, _ in windows:
        e = np.exp(-decay * since)
        m = np.column_stack([e * np.sin(w * since), e * np.cos(w * since)])
        out.append(m - q @ (q.T @ m))
    return out


def _amplitudes(designs, residuals, rows) -> np.ndarray:
    gram = sum(designs[i].T @ designs[i] for i in rows)
    rhs = sum(designs[i].T @ residuals[i] for i in rows)
    return np.linalg.lstsq(gram, rhs, rcond=None)[0]


def discover_ringing(data, channel: str) -> Ringing | None:
    """The oscillation in `channel` after lift-off that held-out strides prefer, or None."""
    windows = _windows(data, channel)
    n = len(windows)
    if n < 2 * FOLDS:
        return None
    residuals = [w[2] for w in windows]
    zero = np.array([r @ r for r in residuals])
    everyone = range(n)
    lowest = MIN_CYCLES / float(np.median([w[0][-1] for w in windows]))

    def scan(frequencies, decays, best=None):
        for frequency in frequencies:
            for decay in decays:
                if decay > frequency:
                    continue
                designs = _design(windows, frequency, decay)
                amp = _amplitudes(designs, residuals, everyone)
                sse = sum(float(np.sum((residuals[i] - designs[i] @ amp) ** 2)) for i in everyone)
                if best is None or sse < best[0]:
                    best = (sse, frequency, decay, designs, amp)
        return best

    coarse = scan([f for f in FREQUENCIES if f >= lowest], DECAY_RATES)
    if coarse is None:
        return None
    _, frequency, decay, designs, amp = scan(coarse[1] * np.geomspace(0.96, 1.04, 9),
                                              coarse[2] * np.geomspace(0.4, 2.5, 11), coarse)
    fold = np.arange(n) % FOLDS
    held = np.zeros(n)
    for f in range(FOLDS):
        fit = _amplitudes(designs, residuals, np.flatnonzero(fold != f))
        for i in np.flatnonzero(fold == f):
            held[i] = np.sum((residuals[i] - designs[i] @ fit) ** 2)
    d = zero - held
    t = float(d.mean() / (d.std(ddof=1) / math.sqrt(n))) if d.std(ddof=1) > 0 else 0.0
    explained = float(1.0 - held.sum() / zero.sum()) if zero.sum() > 0 else 0.0
    if t < MIN_T or explained <= 0 or math.hypot(*amp) < MIN_AMPLITUDE * data.sigma[channel]:
        return None
    return Ringing(CHANNEL_SITE[channel], channel, (float(amp[0]), float(amp[1])), float(frequency), float(decay),
                   explained, t)
