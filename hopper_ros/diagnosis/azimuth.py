"""The residual's dependence on the boom's angle about its vertical axis (issue 28, point 1): the forward
position's reading wrong by an error periodic in it (an encoder's pulley or gear eccentric on its shaft, turning
with the boom once a lap or through a belt at a harmonic of it).

After the accepted effects, where they leave the recording not explained (the stage of `angle.find_angle_law`,
in its round): the forward position's trajectory residual of every stride (the model's re-simulation from the apex
read) is regressed on the error such a reading leaves there, for each period P of a frequency scan (`azimuth_scan`
periods, geometric, from one lap (`dependence.lap_length`) down to a lap over `azimuth_harmonics`):

    y_meas = y + a sin(2 pi y/P) + b cos(2 pi y/P) = y + e(y)

read from the apex, the model's y starting at the apex read, its speed read as v (1 + e'(y_0)), so a stride's
residual is e(y) - e(y_0) - e'(y_0) (y - y_0) (the linear part is what the apex speed's fit takes). The period whose
fit predicts held-out strides best is kept where it predicts them better than a smooth shape of the stride (a
quadratic and a cubic in y - y_0: a speed or a drag the model misses, the same at every place of the lap) by a
one-sided t over strides of at least `min_t`; the trajectories then choose among it and its neighbours in the
scan (`NEAR`). The law is a sensor fault (`simulate.periodic_y`: the lanes' y, the apex speed and the next apex as
read), one scale of the fitted (a, b) searched, and said with its amplitude and its period in laps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .candidates import Candidate
from .discover import FOLDS
from .periodic import scan_period
from .simulate import Y_PERIODIC, Variant, periodic_y, simulate_variants

NEAR = (-1.0, -0.5, 0.0, 0.5, 1.0)    # the periods tried by trajectory about the scan's best, in steps of the scan
NAME = "y_periodic"


@dataclass
class Eccentricity:
    """An error of the forward position's reading a sin(2 pi y/P) + b cos(2 pi y/P) [m] (at scale 1)."""
    period: float          # [m] of the forward position
    sin: float             # [m]
    cos: float
    t: float               # held-out t of the scan's fit over the smooth shape alone
    lap: float             # [m] one lap of the forward position

    @property
    def amplitude(self) -> float:
        return math.hypot(self.sin, self.cos)

    def laps(self) -> str:
        """The period as a share of the lap, and the harmonic of the lap it is where it is one (within 5 %)."""
        per_lap = self.lap / self.period
        harmonic = round(per_lap)
        if harmonic >= 1 and abs(per_lap / harmonic - 1.0) <= 0.05:
            return (f"{'once' if harmonic == 1 else f'{harmonic} times'} a lap of {self.lap:.2f} m: a pulley, gear or "
                    "shaft turning with the boom, eccentric")
        return f"{per_lap:.2f} times a lap of {self.lap:.2f} m: not a harmonic of the boom's turn"

    def words(self, scale: float = 1.0) -> str:
        return (f"the forward position's encoder reads wrong by an error periodic in the boom's angle, "
                f"+-{1e3 * scale * self.amplitude:.3g} mm every {self.period:.3g} m of track ({self.laps()}); "
                f"the forward speed read is wrong by up to "
                f"{100 * scale * self.amplitude * 2 * math.pi / self.period:.2g} %")

    def terms(self) -> list:
        symbol = f"2 pi y/{self.period:.4g}"
        return [(f"sin({symbol})", self.sin, "an error of the forward position's reading", "m"),
                (f"cos({symbol})", self.cos, "an error of the forward position's reading", "m")]


def periods(lap: float, settings) -> np.ndarray:
    """The frequency scan's periods [m]: geometric from one lap down to a lap over `azimuth_harmonics`."""
    if not lap > 0:
        return np.zeros(0)
    return np.geomspace(lap / settings.azimuth_harmonics, lap, settings.azimuth_scan)


def _strides(data, variant: Variant) -> list:
    """Per stride (y read, y_0 read, the y residual [m]) of the model `variant` re-simulated, finite samples."""
    series = simulate_variants(data, [variant], keep_series=True)["series"]
    s, rec = data.strides, data.rec
    out = []
    for i, r in enumerate(series):
        a, b = int(s.start[i]), int(s.stop[i])
        y, residual = np.asarray(rec.y[a:b], float), np.asarray(r["y"][0], float)
        ok = np.isfinite(y) & np.isfinite(residual) & (np.abs(residual) < 0.5)
        if ok.sum() >= 8:
            out.append((y[ok], float(s.apex_y[i]), residual[ok]))
    return out


def _design(y: np.ndarray, y0: float, period: float | None) -> np.ndarray:
    d = y - y0
    if period is None:                 # the smooth shape: the same at every place of the lap
        return np.column_stack([d * d, d * d * d])
    columns = []
    for a, b in ((1.0, 0.0), (0.0, 1.0)):
        e, _ = periodic_y(y, a, b, period)
        e0, slope0 = periodic_y(y0, a, b, period)
        columns.append(e - e0 - slope0 * d)
    return np.column_stack(columns)


def find_eccentricity(data, variant: Variant, settings, lap: float) -> list[Eccentricity]:
    """The period of the forward position's residual in the boom's angle that predicts held-out strides best (the
    vertex of the scan's held-out SSE about its least), where it beats the smooth shape (t >= `min_t`): the error at
    it and at the periods `NEAR` steps of the scan about it; none otherwise."""
    scan = periods(lap, settings)
    strides = _strides(data, variant) if len(scan) >= 3 else []
    if len(strides) < 2 * FOLDS:
        return []
    spread = np.ptp(np.mod([y0 for _, y0, _ in strides], lap))
    if spread < 0.5 * lap:             # the strides do not go round the lap: no period in it can be told
        return []
    fold = np.arange(len(strides)) % FOLDS
    residuals = [r for _, _, r in strides]
    found, t = scan_period(lambda period: [_design(y, y0, period) for y, y0, _ in strides], residuals, fold, scan,
                           NEAR, settings.min_t)
    return [Eccentricity(period, sine, cosine, t, lap) for period, sine, cosine in found]


def eccentricity_candidate(found: Eccentricity) -> Candidate:
    def build(variant: Variant, value: float, found=found) -> Variant:
        return variant.with_changes(sensors=dict(zip(Y_PERIODIC, (value * found.sin, value * found.cos,
                                                                  found.period))))

    return Candidate(NAME, "sensor", "sensor", "flight_horizontal", "m", found.words(), 0.0, 2.0, build,
                     lambda value, found=found: value * found.amplitude,
                     "a second forward-position reading (a tape along the track, or the boom's angle read at its "
                     "axis), or the boom turned slowly through a lap", plausible=(0.0, 0.05), discovery=found,
                     equation=f"y_meas = y + a sin(2 pi y/P) + b cos(2 pi y/P), P = {found.period:.4g} m")
