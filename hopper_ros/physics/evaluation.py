"""Predictors against the exact model on strides drawn from the thesis's ranges
(section 4.2): forward speed 0.8631-2.4868 m/s, apex height 0.2601-0.4255 m, tau_0 3-8 N m,
theta_td 10-45 deg. As on the robot, the torque ramp ends at the plain AAS's predicted
lift-off (2.29), and only strides that succeed are kept: the robot keeps running forward,
next apex speed 0.6-3.2 m/s and height 0.2-0.5 m.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .aas import predict_aas
from .corrected import predict_corrected
from .exact import simulate_stride
from .metrics import position_error_pct, time_error_pct, velocity_error_pct
from .params import ModelParams
from .predictors import predict_exact, predict_stride

THESIS_RANGES = {
    "apex_height": (0.2601, 0.4255),         # [m]
    "forward_speed": (0.8631, 2.4868),       # [m/s]
    "tau_0": (3.0, 8.0),                     # [N m]
    "touchdown_angle": (math.radians(10.0), math.radians(45.0)),  # [rad]
}
SUCCESS_RANGES = {"next_forward_speed": (0.6, 3.2), "next_apex_height": (0.2, 0.5)}


@dataclass
class StrideSet:
    """Inputs of many strides, one entry each."""

    apex_height: np.ndarray
    forward_speed: np.ndarray
    touchdown_angle: np.ndarray
    tau_0: np.ndarray
    ramp_duration: np.ndarray

    def __len__(self) -> int:
        return len(self.apex_height)

    def subset(self, mask) -> "StrideSet":
        return StrideSet(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))

    def columns(self) -> tuple[np.ndarray, ...]:
        """(apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration), a predictor's inputs."""
        return tuple(getattr(self, f) for f in self.__dataclass_fields__)


def sample_thesis_strides(params: ModelParams, count: int, seed: int = 0) -> StrideSet:
    """Uniform draws from the thesis ranges; t_f is the plain AAS's lift-off time (2.29)."""
    rng = np.random.default_rng(seed)
    draws = {name: rng.uniform(low, high, count) for name, (low, high) in THESIS_RANGES.items()}
    seed_prediction = predict_aas(params, draws["apex_height"], draws["forward_speed"],
                                  draws["touchdown_angle"], draws["tau_0"])
    ramp = np.where(seed_prediction.ok | np.isfinite(seed_prediction.stance_time), seed_prediction.stance_time, 0.0)
    return StrideSet(ramp_duration=np.nan_to_num(ramp), **draws)


def successful(prediction) -> np.ndarray:
    """Strides that run on: ok and the next apex inside `SUCCESS_RANGES`."""
    ok = np.asarray(prediction.ok, dtype=bool).copy()
    for name, (low, high) in SUCCESS_RANGES.items():
        value = np.asarray(getattr(prediction, name))
        with np.errstate(invalid="ignore"):
            ok &= (value >= low) & (value <= high)
    return ok


@dataclass
class PredictionErrors:
    """E_p, E_v, E_t (4.1)-(4.3) per stride [%] of one predictor against a reference."""

    method: str
    position: np.ndarray
    velocity: np.ndarray
    time: np.ndarray

    def summary(self) -> dict[str, float]:
        out = {}
        for name in ("position", "velocity", "time"):
            values = getattr(self, name)
            out[f"{name}_mean"] = float(np.mean(values))
            out[f"{name}_std"] = float(np.std(values))
            out[f"{name}_median"] = float(np.median(values))
            out[f"{name}_p95"] = float(np.percentile(values, 95))
            out[f"{name}_max"] = float(np.max(values))
        return out


def prediction_errors(method: str, reference, prediction) -> PredictionErrors:
    return PredictionErrors(
        method,
        position_error_pct(reference.next_apex_height, reference.stride_length,
                           prediction.next_apex_height, prediction.stride_length),
        velocity_error_pct(reference.next_forward_speed, prediction.next_forward_speed),
        time_error_pct(reference.stride_time, prediction.stride_time),
    )


@dataclass
class Comparison:
    """The predictors' errors on the successful strides of a set."""

    strides: StrideSet          # successful strides only
    drawn: int                  # strides drawn before the success filter
    exact: object               # exact-model StridePrediction on `strides`
    errors: dict                # method -> PredictionErrors


def compare_predictors(params: ModelParams, count: int, seed: int = 0,
                       methods: tuple[str, ...] = ("aas", "corrected"), keep: int | None = None) -> Comparison:
    """Draw `count` strides, keep those the exact model runs successfully (the first `keep`
    of them, if given), score the predictors on them."""
    strides = sample_thesis_strides(params, count, seed)
    exact = predict_exact(params, *strides.columns())
    index = np.flatnonzero(successful(exact))[:keep]
    kept, exact_kept = strides.subset(index), exact.take(index)
    errors = {method: prediction_errors(method, exact_kept, predict_stride(params, *kept.columns(), method=method))
              for method in methods}
    return Comparison(kept, count, exact_kept, errors)


def time_predictors(params: ModelParams, strides: StrideSet, repeats: int = 3) -> dict[str, tuple[float, float]]:
    """Cost of each model on the same strides, one run: method -> (microseconds per single
    stride, batched strides per second; NaN for the exact model, which has no batch)."""
    columns = strides.columns()
    rows = [tuple(float(c[i]) for c in columns) for i in range(len(strides))]
    models = {"exact": simulate_stride, "aas": predict_aas, "corrected": predict_corrected}
    out = {}
    for name, model in models.items():
        start = time.perf_counter()
        for row in rows:
            model(params, *row)
        single = (time.perf_counter() - start) / len(rows) * 1e6
        batch = math.nan
        if name != "exact":
            best = math.inf
            for _ in range(repeats):
                start = time.perf_counter()
                model(params, *columns)
                best = min(best, time.perf_counter() - start)
            batch = len(rows) / best
        out[name] = (single, batch)
    return out


def breakdown(comparison: Comparison, variable: str, edges) -> list[dict]:
    """Mean errors of each predictor in bins of one input variable (where each breaks down)."""
    values = getattr(comparison.strides, variable)
    rows = []
    for low, high in zip(edges[:-1], edges[1:]):
        inside = (values >= low) & (values < high) if high != edges[-1] else (values >= low) & (values <= high)
        row = {"low": float(low), "high": float(high), "count": int(inside.sum())}
        for method, err in comparison.errors.items():
            for name in ("position", "velocity", "time"):
                row[f"{method}_{name}"] = float(np.mean(getattr(err, name)[inside])) if inside.any() else math.nan
        rows.append(row)
    return rows
