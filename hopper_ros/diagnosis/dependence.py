"""Dependence on the position along the track (issue 28, point 1): a floor whose height changes round the boom's
lap (a board on part of it, an undulating running surface, a tilted boom axis) while the model has one level floor.

A stride's track position is where its toe lands, x = y + rho_0 sin(theta_td) at the detected touchdown, taken
round the lap: u = (x mod L) / L, L one lap of the forward position (`track_lap`, or 2 pi (boom length + leg
offset) of hardware.yaml). After the accepted effects (and a drift) the ground height gets a value per stride,
h_i = h + a + f(u_i), fitted on the training folds and judged on the held-out strides by `perstride` against the
floor held level (h + a), in two forms:
- a wave, f = b sin(2 pi k u) + c cos(2 pi k u), k = 1 .. `track_harmonics` (the frequency scan: each fold picks
  its k);
- a board, f = H on [u_0, u_0 + w) of each lap, its edges on a grid of `track_bins` a lap (each fold picks them;
  w up to half a lap, H of either sign).
A form stands with a one-sided t over strides of at least `min_t` and `dependence_share` of the held-out
E_p + E_v + E_t taken off; the one that takes most off is said and modelled (the variant's `per_stride`). A wave
that stands is tried with gravity along the track in its period as well (`track_gravity`, a tilted boom axis:
the floor's slope), kept by the same rules against the wave alone. Where the forward position is not finite or
does not go round the lap (fewer than half the grid's bins reached), the stage does not apply.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import perstride
from .data import StrideData
from .perstride import Parameter
from .records import Errors
from .search import folds
from .simulate import Variant

FLOOR = Parameter("ground_height", "the floor", 0.001, relative=False)
SLOPE = Parameter("track_gravity", "gravity along the track", 0.01, relative=False)
PARAMETERS = (FLOOR, SLOPE)
REFINE = 2          # Gauss-Newton steps of a form's fit (the floor's effect on the next apex is not linear)
TIMES = {1: "once", 2: "twice"}


@dataclass
class Dependence:
    form: str                    # "wave", "board" or "tilt" (a wave with gravity along the track)
    magnitude: float             # the wave's amplitude or the board's height [m]
    level: float                 # the rest of the floor above the model's [m]
    where: tuple                 # wave: (periods a lap, position of the highest [m]); board: (start, end) [m] of a lap
    lap: float                   # [m]
    t: float                     # one-sided t over held-out strides against the simpler form
    before: Errors               # held-out next-apex errors with the floor level ...
    after: Errors                # ... and with it varying along the track
    per_stride: dict             # coefficient -> its value per stride
    slope: tuple = ()            # tilt: gravity along the track, (amplitude [m/s^2], where most forward [m])
    parameter: str = "ground_height"

    def sentence(self) -> str:
        mm = 1e3 * abs(self.magnitude)
        fit = f"held-out E_p {self.before.E_p:.3f} -> {self.after.E_p:.3f} %"
        if self.form == "board":
            start, end = self.where
            way = "higher" if self.magnitude > 0 else "lower"
            return (f"the floor is {mm:.1f} mm {way} over {(end - start) % self.lap:.1f} m of each {self.lap:.2f} m "
                    f"lap, at {start:.1f}-{end:.1f} m ({fit})")
        k, peak = self.where
        words = (f"the floor rises and falls {TIMES.get(k, f'{k} times')} a lap of {self.lap:.2f} m by +-{mm:.1f} mm "
                 f"(highest at {peak:.1f} m")
        if self.slope:
            words += (f"), and gravity pulls along the track by +-{self.slope[0]:.3f} m/s^2 (most forward at "
                      f"{self.slope[1]:.1f} m: a tilted boom axis")
        return f"{words}; {fit})"

    def as_dict(self) -> dict:
        slope = ({"amplitude": self.slope[0], "unit": "m/s^2", "most_forward_at_m": self.slope[1]} if self.slope
                 else None)
        return {"parameter": self.parameter, "variable": "track position", "form": self.form,
                "words": self.sentence(), "magnitude": self.magnitude, "unit": "m", "level": self.level,
                "where_m": list(self.where), "lap_m": self.lap, "track_gravity": slope, "t": self.t,
                "held_out_before": self.before.as_dict(), "held_out_after": self.after.as_dict()}


def lap_length(settings) -> float:
    """One lap of the forward position [m]: `track_lap`, or the boom's radius at the forward position."""
    if settings.track_lap > 0:
        return float(settings.track_lap)
    from hopper_ros.hardware.config import load_hardware
    boom = load_hardware().boom
    return 2.0 * math.pi * (boom.length + boom.leg_offset)


def track_position(data: StrideData, variant: Variant, lap: float) -> np.ndarray | None:
    """Each stride's landing place as a share of the lap (0 .. 1); None where the recording cannot give it."""
    s, rec = data.strides, data.rec
    i = np.clip(np.searchsorted(rec.t, s.touchdown_time), 0, len(rec.t) - 1)
    x = rec.y[i] + float(variant.coefficients.rest_length) * np.sin(s.touchdown_angle)
    if not (lap > 0 and np.all(np.isfinite(x))):
        return None
    return np.mod(x, lap) / lap


def _floor(column):
    return np.column_stack([column, np.zeros_like(column)])


def _slope(column):
    return np.column_stack([np.zeros_like(column), column])


def forms(u: np.ndarray, harmonics: int, bins: int):
    """The candidate bases of each form (tuples of (strides, parameters) columns), the level first; each
    board's (start, width) in bins."""
    level = _floor(np.ones(len(u)))
    waves = [(np.sin(2 * np.pi * k * u), np.cos(2 * np.pi * k * u)) for k in range(1, harmonics + 1)]
    cell = np.minimum((u * bins).astype(int), bins - 1)
    boards, edges, seen = [], [], set()
    for start in range(bins):
        for width in range(1, bins // 2 + 1):
            on = ((cell - start) % bins) < width
            if 2 <= on.sum() <= len(u) - 2 and on.tobytes() not in seen:
                seen.add(on.tobytes())
                boards.append((level, _floor(on.astype(float))))
                edges.append((start, width))
    return {"level": [(level,)], "wave": [(level, _floor(a), _floor(b)) for a, b in waves], "board": boards,
            "tilt": [(level, _floor(a), _floor(b), _slope(a), _slope(b)) for a, b in waves]}, edges


def _crest(b: float, c: float, k: int, lap: float) -> tuple:
    """(amplitude, where the highest) of b sin(2 pi k u) + c cos(2 pi k u) over a lap."""
    phase = math.atan2(c, b)
    return math.hypot(b, c), lap * (((math.pi / 2 - phase) / (2 * math.pi * k)) % (1.0 / k))


def find_dependence(data: StrideData, variant: Variant, settings, lap: float) -> list[Dependence]:
    """The floor's dependence on the track position where it stands on held-out strides (at most one form)."""
    n = len(data.strides)
    u = track_position(data, variant, lap)
    bins = settings.track_bins
    if n < 4 * settings.folds or u is None or len(np.unique(np.minimum((u * bins).astype(int), bins - 1))) < bins / 2:
        return []
    bases, edges = forms(u, settings.track_harmonics, bins)
    if not bases["board"]:
        return []
    residual, slopes, ok = perstride.sensitivity(data, variant, PARAMETERS)
    if ok.sum() < 4 * settings.folds:
        return []

    def refine(change):
        return perstride.sensitivity(data, variant, PARAMETERS, change)[:2]

    fold = folds(n, settings.folds)
    held = {form: perstride.held_out(slopes, residual, ok, fold, settings.folds, candidates, refine, REFINE)
            for form, candidates in bases.items()}
    sse, errors = perstride.judge(data, variant, PARAMETERS, held)

    def stands(simple, form):
        t, share = perstride.stands(sse, errors, simple, form, 4 * settings.folds)
        return (share, t, form) if t >= settings.min_t and share >= settings.dependence_share else None

    standing = [found for found in (stands("level", "wave"), stands("level", "board")) if found]
    if not standing:
        return []
    _, t, form = max(standing)
    tilt = stands("wave", "tilt") if form == "wave" else None
    form, t = ("tilt", tilt[1]) if tilt else (form, t)
    best, coef, change = perstride.fit(slopes, residual, ok, bases[form], refine, REFINE)
    slope = ()
    if form == "board":
        start, width = edges[best]
        amplitude, where = float(coef[1]), (lap * start / bins, lap * ((start + width - 1) % bins + 1) / bins)
    else:
        amplitude, crest = _crest(coef[1], coef[2], best + 1, lap)
        where = (best + 1, crest)
        slope = _crest(coef[3], coef[4], best + 1, lap) if form == "tilt" else ()
    values = {p.name: p.values(float(getattr(variant.coefficients, p.name)), change[:, k])
              for k, p in enumerate(PARAMETERS) if np.any(change[:, k] != 0.0)}
    return [Dependence(form, amplitude, float(coef[0]), where, lap, t, errors["level"], errors[form], values, slope)]
