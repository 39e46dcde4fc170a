"""Drift over a recording (issue 28, point 2): a main parameter of the model that changes with time (a spring that
heats, a joint that wears, a bolt that loosens) while the model holds it constant.

After the accepted effects each main parameter p (k, d, g, rho_0) is given a linear trend over the recording, p_i =
p (1 + a + b s_i), s_i the stride's time from the recording's middle over its length, and the ground's height under
the toe one in its own unit, h_i = h + a + b s_i (the floor as the height reading gives it: where the reading's zero
drifts, an encoder's coupling slipping at the touchdowns' shocks, the ground seems to move by as much the other way,
the flight's law being the same at any height; its ramps read from each stride's own start of stance,
`data.own_ramps`, as a floor at another height per stride has them), fitted and judged on held-out strides by
`perstride` against the same parameter held constant. A trend stands when its one-sided t over strides is at least
`min_t` and it lowers the held-out E_p + E_v + E_t by `drift_share` (a trend that removes less leaves a larger
mismatch it may stand in for); it is then said with its size and rate and modelled (the variant's `per_stride`
values).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import perstride
from .data import StrideData, own_ramps
from .perstride import Parameter
from .records import Errors
from .search import folds
from .simulate import Variant

PARAMETERS = (Parameter("stiffness", "the leg stiffness k", 0.01), Parameter("damping", "the leg damping d", 0.05),
              Parameter("gravity", "the effective gravity g", 0.005),
              Parameter("rest_length", "the leg's rest length rho_0", 0.005),
              Parameter("ground_height", "the ground's height under the toe, as the height reading gives it (the "
                                         "reading's zero drifting, an encoder's coupling that slips; or the floor "
                                         "itself)", 0.0005, relative=False, moves_stance=True))


@dataclass
class Drift:
    parameter: str
    words: str
    change_pct: float            # from the first stride to the last [%] (nan for the ground's height: from 0) ...
    rate_pct_per_s: float
    t: float                     # one-sided t over held-out strides against the parameter held constant
    before: Errors               # held-out next-apex errors without the drift ...
    after: Errors                # ... and with it
    per_stride: np.ndarray       # the parameter's value per stride
    change: float = float("nan")  # ... and in the parameter's unit [m] where it is not a share
    rate_per_s: float = float("nan")

    def sentence(self) -> str:
        relative = np.isfinite(self.change_pct)
        change = self.change_pct if relative else self.change
        way = "rises" if change > 0 else "falls"
        size = (f"{abs(self.change_pct):.1f} % over the recording ({self.rate_pct_per_s:+.3g} %/s" if relative else
                f"{1e3 * abs(self.change):.3g} mm over the recording ({1e3 * self.rate_per_s:+.3g} mm/s")
        return f"{self.words} {way} {size}; held-out E_p {self.before.E_p:.3f} -> {self.after.E_p:.3f} %)"

    def as_dict(self) -> dict:
        return {"parameter": self.parameter, "words": self.sentence(), "change_pct": self.change_pct,
                "rate_pct_per_s": self.rate_pct_per_s, "change": self.change, "rate_per_s": self.rate_per_s,
                "t": self.t, "held_out_before": self.before.as_dict(), "held_out_after": self.after.as_dict()}


def drift_data(recording: StrideData, parameter: str) -> StrideData:
    """The strides a drift of `parameter` (a name of PARAMETERS) is fitted and judged on: with the ramps read from
    each stride's own start of stance (`data.own_ramps`) where it moves the stance's start, the recording's
    otherwise."""
    moves = next(p.moves_stance for p in PARAMETERS if p.name == parameter)
    return own_ramps(recording) if moves else recording


def with_drift(variant: Variant, drifts: list) -> Variant:
    """`variant` with the first drift's values per stride."""
    if not drifts:
        return variant
    drift = drifts[0]
    return Variant(variant.coefficients, variant.sensors, {**variant.per_stride, drift.parameter: drift.per_stride})


def find_drift(recording: StrideData, variant: Variant, settings) -> list[Drift]:
    """The main parameters whose trend over the recording stands on held-out strides, strongest first."""
    s = recording.strides
    n = len(s)
    if n < 4 * settings.folds:
        return []
    span = float(s.apex_time[-1] - s.apex_time[0])
    if span <= 0.0:
        return []
    when = (s.apex_time - 0.5 * (s.apex_time[0] + s.apex_time[-1])) / span      # -1/2 .. 1/2
    fold = folds(n, settings.folds)
    ones, trend = np.ones((n, 1)), when[:, None]
    forms = {"constant": [(ones,)], "trend": [(ones, trend)]}
    found = []
    for p in PARAMETERS:
        data = drift_data(recording, p.name)
        residual, slope, ok = perstride.sensitivity(data, variant, [p])
        if ok.sum() < 4 * settings.folds:
            continue
        held = {form: perstride.held_out(slope, residual, ok, fold, settings.folds, bases)
                for form, bases in forms.items()}
        # judged by re-simulation: every held-out stride with the value its training folds gave it
        sse, errors = perstride.judge(data, variant, [p], held)
        t, gain = perstride.stands(sse, errors, "constant", "trend", 4 * settings.folds)
        if not (t >= settings.min_t and gain >= settings.drift_share):
            continue
        _, (a, b), _ = perstride.fit(slope, residual, ok, forms["trend"])
        value = float(getattr(variant.coefficients, p.name))
        per_stride = p.values(value, a + b * when)
        first, last = p.values(value, a - 0.5 * b), p.values(value, a + 0.5 * b)
        change = 100.0 * (last - first) / first if p.relative else float("nan")
        found.append(Drift(p.name, p.words, change, change / span, t, errors["constant"], errors["trend"], per_stride,
                           float("nan") if p.relative else last - first,
                           float("nan") if p.relative else (last - first) / span))
    return sorted(found, key=lambda d: -d.t)
