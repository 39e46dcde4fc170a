"""Drift over a recording (issue 28, point 2): a main parameter of the model that changes with time (a spring that
heats, a joint that wears, a bolt that loosens) while the model holds it constant.

After the accepted effects each main parameter p (k, d, g, rho_0) is given a linear trend over the recording,
p_i = p (1 + a + b s_i), s_i the stride's time from the recording's middle over its length. The next apexes'
change with p comes from one moved re-simulation per stride; (a, b) are fitted to the next-apex residuals
(normalised as E_p, E_v, E_t) on the training folds and judged by re-simulating the held-out strides with their
own p_i. A trend stands when it fits held-out strides better than the same parameter held constant (its one-sided
t over strides at least `min_t`) and lowers the held-out E_p + E_v + E_t by `drift_share` (a trend
that removes less leaves a larger mismatch it may stand in for); it is then said with
its size and rate and modelled (the variant's `per_stride` values).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .acceptance import paired_t
from .data import StrideData
from .records import Errors
from .search import folds
from .simulate import Variant, simulate_variants

# coefficient -> (words, relative step of the sensitivity's re-simulation)
PARAMETERS = {"stiffness": ("the leg stiffness k", 0.01), "damping": ("the leg damping d", 0.05),
              "gravity": ("the effective gravity g", 0.005), "rest_length": ("the leg's rest length rho_0", 0.005)}
OUTPUTS = ("height", "length", "speed", "time")


@dataclass
class Drift:
    parameter: str
    words: str
    change_pct: float            # from the first stride to the last [%]
    rate_pct_per_s: float
    t: float                     # one-sided t over held-out strides against the parameter held constant
    before: Errors               # held-out next-apex errors without the drift ...
    after: Errors                # ... and with it
    per_stride: np.ndarray       # the parameter's value per stride

    def sentence(self) -> str:
        way = "rises" if self.change_pct > 0 else "falls"
        return (f"{self.words} {way} {abs(self.change_pct):.1f} % over the recording "
                f"({self.rate_pct_per_s:+.3g} %/s; held-out E_p {self.before.E_p:.3f} -> {self.after.E_p:.3f} %)")

    def as_dict(self) -> dict:
        return {"parameter": self.parameter, "words": self.sentence(), "change_pct": self.change_pct,
                "rate_pct_per_s": self.rate_pct_per_s, "t": self.t, "held_out_before": self.before.as_dict(),
                "held_out_after": self.after.as_dict()}


def _normalised(data: StrideData, pred: dict) -> np.ndarray:
    """(strides, 4) next-apex residuals, recorded - predicted, in the units of E_p, E_v, E_t [%]."""
    s = data.strides
    scale = np.hypot(s.next_apex_height, s.stride_length)
    recorded = {"height": s.next_apex_height, "length": s.stride_length, "speed": s.next_forward_speed,
                "time": s.stride_time}
    units = {"height": scale, "length": scale, "speed": np.abs(s.next_forward_speed), "time": s.stride_time}
    return np.column_stack([100.0 * (recorded[k] - pred[k]) / units[k] for k in OUTPUTS])


def find_drift(data: StrideData, variant: Variant, settings) -> list[Drift]:
    """The main parameters whose trend over the recording stands on held-out strides, strongest first."""
    s = data.strides
    n = len(s)
    if n < 4 * settings.folds:
        return []
    span = float(s.apex_time[-1] - s.apex_time[0])
    if span <= 0.0:
        return []
    when = (s.apex_time - 0.5 * (s.apex_time[0] + s.apex_time[-1])) / span      # -1/2 .. 1/2
    fold = folds(n, settings.folds)
    sim = simulate_variants(data, [variant])
    base = {k: v[0] for k, v in sim["pred"].items()}
    residual = _normalised(data, base)
    found = []
    for name, (words, step) in PARAMETERS.items():
        value = float(getattr(variant.coefficients, name))
        moved = simulate_variants(data, [variant.with_changes({name: value * (1.0 + step)})])["pred"]
        slope = (_normalised(data, base) - _normalised(data, {k: v[0] for k, v in moved.items()})) / step
        ok = np.all(np.isfinite(slope), axis=1) & np.all(np.isfinite(residual), axis=1)
        if ok.sum() < 4 * settings.folds:
            continue
        held = {"constant": np.zeros(n), "trend": np.zeros(n)}
        for k in range(settings.folds):
            train, test = ok & (fold != k), fold == k
            for form, columns in (("constant", (np.ones(n),)), ("trend", (np.ones(n), when))):
                design = np.stack([(slope[train] * c[train, None]).ravel() for c in columns], axis=1)
                coef, *_ = np.linalg.lstsq(design, residual[train].ravel(), rcond=None)
                change = sum(cf * c for cf, c in zip(coef, columns))
                held[form][test] = change[test]
        # judged by re-simulation: every held-out stride with the value its training folds gave it
        sse = {}
        errors = {}
        for form, relative in held.items():
            trial = Variant(variant.coefficients, variant.sensors,
                            {**variant.per_stride, name: value * (1.0 + relative)})
            pred = {k: v[0] for k, v in simulate_variants(data, [trial])["pred"].items()}
            r = _normalised(data, pred)
            sse[form] = np.where(np.all(np.isfinite(r), axis=1), np.sum(r * r, axis=1), np.inf)
            errors[form] = Errors.of(data, pred)
        both = np.isfinite(sse["constant"]) & np.isfinite(sse["trend"])
        t = paired_t(sse["constant"][both], sse["trend"][both]) if both.sum() >= 4 * settings.folds else 0.0
        gain = 1.0 - errors["trend"].total / max(errors["constant"].total, 1e-12)
        if not (t >= settings.min_t and gain >= settings.drift_share):
            continue
        design = np.stack([slope[ok].ravel(), (slope[ok] * when[ok, None]).ravel()], axis=1)
        (a, b), *_ = np.linalg.lstsq(design, residual[ok].ravel(), rcond=None)
        per_stride = value * (1.0 + a + b * when)
        first, last = value * (1.0 + a - 0.5 * b), value * (1.0 + a + 0.5 * b)
        change = 100.0 * (last - first) / first
        found.append(Drift(name, words, change, change / span, t, errors["constant"], errors["trend"], per_stride))
    return sorted(found, key=lambda d: -d.t)
