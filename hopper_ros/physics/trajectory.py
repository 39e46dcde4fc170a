"""Predicted trajectory of one stride (as in Fig 4.6): closed-form flights around the
predictor's stance, sampled on a regular grid like `exact.simulate_stride`'s."""

from __future__ import annotations

import math

from numpy.polynomial import chebyshev

from .exact import EventState, Trajectory, sample_stride
from .params import ModelParams
from .predictors import DEFAULT_PREDICTOR, predict_stride


def predicted_trajectory(params: ModelParams, apex_height: float, forward_speed: float, touchdown_angle: float,
                         tau_0: float, ramp_duration: float | None = None, *, method: str = DEFAULT_PREDICTOR,
                         sample_period: float = 1e-3, y0: float = 0.0, t0: float = 0.0) -> Trajectory:
    """Sampled trajectory of the "aas" or "corrected" prediction of one stride."""
    if method not in ("aas", "corrected"):
        raise ValueError(f"trajectories come from 'aas' or 'corrected', not {method!r}")
    p = predict_stride(params, float(apex_height), float(forward_speed), float(touchdown_angle), float(tau_0),
                       ramp_duration, method=method)
    if not p.ok:
        raise ValueError(f"the {method} predictor finds no stride: {p.failure}")

    if p.correction is None:
        solution = p.stance.as_array()

        def stance_state(ts):
            return solution.leg_length(ts), solution.leg_angle(ts), solution.leg_rate(ts), solution.leg_angle_rate(ts)
    else:  # the corrected stance, interpolated through its Chebyshev nodes
        c = p.correction
        nodes = c.t[0]

        def stance_state(ts):
            scaled = 2.0 * ts / nodes[-1] - 1.0
            fit = lambda values: chebyshev.chebval(scaled, chebyshev.chebfit(2.0 * nodes / nodes[-1] - 1.0, values[0], nodes.size - 1))
            rho = fit(c.leg_length)
            return rho, fit(c.leg_angle), fit(c.leg_rate), fit(c.momentum) / (params.body_mass * rho * rho)

    r = params.collision_factor
    apex = EventState(t0, y0, float(apex_height), float(forward_speed), 0.0, params.rest_length, float(touchdown_angle))
    liftoff = EventState(t0 + p.descent_time + p.stance_time, y0 + p.liftoff_y, p.liftoff_z, r * p.liftoff_ydot,
                         r * p.liftoff_zdot, params.rest_length, p.liftoff_theta)
    toe_y = y0 + p.touchdown_y + params.rest_length * math.sin(touchdown_angle)
    return sample_stride(params, apex, t0 + p.descent_time, liftoff, toe_y, stance_state, float(tau_0),
                         p.ramp_duration, sample_period)
