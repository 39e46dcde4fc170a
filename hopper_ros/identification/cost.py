"""Prediction errors of recorded strides and the identification cost C (4.4).

Every stride is predicted from its recorded apex state and inputs by one of the model
library's predictors (`physics.predictors.predict_stride`: "aas" and "corrected" take all
strides in one vectorised call, "exact" integrates them one by one) and scored with E_p, E_v,
E_t (4.1)-(4.3) (`physics.metrics`). A stride the predictor finds no solution for scores
`failed_error` percent on each metric, so the search cannot win by making strides fail.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hopper_ros.physics.metrics import identification_cost, position_error_pct, time_error_pct, velocity_error_pct
from hopper_ros.physics.params import ModelParams
from hopper_ros.physics.predictors import predict_stride

from .strides import Strides

OUTCOMES = ("next_apex_height", "stride_length", "next_forward_speed", "stride_time")


@dataclass
class StrideErrors:
    """E_p, E_v, E_t [%] per stride; `failed` marks strides without a prediction."""

    position: np.ndarray
    velocity: np.ndarray
    time: np.ndarray
    failed: np.ndarray

    def cost(self) -> float:
        """C (4.4)."""
        return identification_cost(self.position, self.velocity, self.time)

    def means(self) -> tuple[float, float, float]:
        return float(np.mean(self.position)), float(np.mean(self.velocity)), float(np.mean(self.time))

    def take(self, index) -> "StrideErrors":
        return StrideErrors(self.position[index], self.velocity[index], self.time[index], self.failed[index])


def predicted_outcomes(params: ModelParams, strides: Strides, method: str) -> dict[str, np.ndarray]:
    """Next apex height, stride length, next forward speed and stride time predicted for
    every stride (NaN where the predictor fails)."""
    prediction = predict_stride(params, *strides.inputs(), method=method)
    ok = np.asarray(prediction.ok, dtype=bool)
    return {name: np.where(ok, np.asarray(getattr(prediction, name), dtype=float), np.nan) for name in OUTCOMES}


def errors_of(strides: Strides, predicted: dict[str, np.ndarray], failed_error: float = 100.0) -> StrideErrors:
    """(4.1)-(4.3) of predictions against the recorded strides."""
    e_p = position_error_pct(strides.next_apex_height, strides.stride_length,
                             predicted["next_apex_height"], predicted["stride_length"])
    e_v = velocity_error_pct(strides.next_forward_speed, predicted["next_forward_speed"])
    e_t = time_error_pct(strides.stride_time, predicted["stride_time"])
    failed = ~(np.isfinite(e_p) & np.isfinite(e_v) & np.isfinite(e_t))
    return StrideErrors(np.where(failed, failed_error, e_p), np.where(failed, failed_error, e_v),
                        np.where(failed, failed_error, e_t), failed)


def stride_errors(params: ModelParams, strides: Strides, method: str, failed_error: float = 100.0) -> StrideErrors:
    return errors_of(strides, predicted_outcomes(params, strides, method), failed_error)
