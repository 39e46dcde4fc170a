"""Stride predictors behind one call: the next apex from an apex state and the stride's
inputs (tau_0, theta_td, t_f).

- "corrected"  the corrected AAS (`corrected`), the default: ~0.1 % from the exact model
- "aas"        the thesis's AAS (`aas`), (2.17)-(2.37): ~5 % E_p, ~15 % E_v
- "exact"      the exact hybrid model (`exact`), numerically integrated, one stride at a time

All take floats (one stride) or arrays (many) and return an `aas.StridePrediction`.
"""

from __future__ import annotations

import numpy as np

from .aas import StridePrediction, predict_aas
from .corrected import predict_corrected
from .exact import simulate_stride
from .params import ModelParams

DEFAULT_PREDICTOR = "corrected"
PREDICTORS = ("corrected", "aas", "exact")

_EXACT_FIELDS = ("next_apex_height", "next_forward_speed", "stride_length", "stride_time", "descent_time",
                 "stance_time", "ascent_time", "liftoff_rho", "liftoff_theta", "liftoff_rho_dot",
                 "liftoff_theta_dot", "liftoff_ydot", "liftoff_zdot")


def predict_exact(params: ModelParams, apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration=None) -> StridePrediction:
    """The exact model in the predictors' interface. t_f = None takes the corrected AAS's."""
    if ramp_duration is None:
        ramp_duration = predict_corrected(params, apex_height, forward_speed, touchdown_angle, tau_0).ramp_duration
    scalar = all(np.ndim(v) == 0 for v in (apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration))
    inputs = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float))
                                   for v in (apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration)))
    columns = {name: np.full(inputs[0].shape, np.nan) for name in _EXACT_FIELDS}
    codes = np.zeros(inputs[0].shape, dtype=int)
    for i, (h, v, theta, tau, t_f) in enumerate(zip(*(x.ravel() for x in inputs))):
        stride = simulate_stride(params, h, v, theta, tau, t_f)
        codes.flat[i] = stride.failure_code
        if not stride.ok:
            continue
        lo = stride.liftoff
        values = (stride.next_apex_height, stride.next_forward_speed, stride.stride_length, stride.stride_time,
                  stride.touchdown.t - stride.apex.t, stride.stance_time, stride.next_apex.t - lo.t,
                  lo.rho, lo.theta, lo.rho_dot, lo.theta_dot, lo.ydot, lo.zdot)
        for name, value in zip(_EXACT_FIELDS, values):
            columns[name].flat[i] = value
    out = StridePrediction()
    for name in StridePrediction.__slots__:
        setattr(out, name, None)
    out.correction = None
    for name, column in columns.items():
        setattr(out, name, column)
    out.ok, out.failure_code, out.ramp_duration = codes == 0, codes, inputs[4]
    return out.as_scalar() if scalar else out


def predict_stride(params: ModelParams, apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration=None,
                   method: str = DEFAULT_PREDICTOR) -> StridePrediction:
    """Next apex (height, forward speed, stride length and time) by the chosen predictor."""
    if method == "corrected":
        return predict_corrected(params, apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration)
    if method == "aas":
        return predict_aas(params, apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration)
    if method == "exact":
        return predict_exact(params, apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration)
    raise ValueError(f"unknown predictor {method!r}; choose one of {PREDICTORS}")
