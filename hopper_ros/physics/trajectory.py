"""Predicted trajectory of one stride (as in Fig 4.6): closed-form flights around the
predictor's stance, sampled on a regular grid like `exact.simulate_stride`'s."""

from __future__ import annotations

import math

import numpy as np
from numpy.polynomial import chebyshev

from .exact import Phase, Trajectory, polar_to_cartesian_velocity, ramp_torque
from .flight import flight_state
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
    g, dh, dv, rho_0 = params.gravity, params.flight_damping_horizontal, params.flight_damping_vertical, params.rest_length
    t_td, t_lo = p.descent_time, p.descent_time + p.stance_time
    n = int(math.floor(p.stride_time / sample_period + 1e-9)) + 1
    t = sample_period * np.arange(n)
    out = {name: np.empty(n) for name in ("y", "z", "ydot", "zdot", "rho", "theta", "torque")}
    phase = np.empty(n, dtype=np.int8)

    descent = t < t_td
    y, z, yd, zd = flight_state(t[descent], 0.0, apex_height, forward_speed, 0.0, g, dh, dv)
    _fill(out, descent, y, z, yd, zd, rho_0, touchdown_angle, 0.0)
    phase[descent] = Phase.DESCENT

    stance = (t >= t_td) & (t < t_lo)
    ts = t[stance] - t_td
    if p.correction is None:
        solution = p.stance.as_array()
        rho, rho_dot, theta, theta_dot = (solution.leg_length(ts), solution.leg_rate(ts), solution.leg_angle(ts),
                                          solution.leg_angle_rate(ts))
    else:  # interpolate the corrected stance through its Chebyshev nodes
        c = p.correction
        nodes = c.t[0]
        scaled = 2.0 * ts / nodes[-1] - 1.0
        fit = lambda values: chebyshev.chebval(scaled, chebyshev.chebfit(2.0 * nodes / nodes[-1] - 1.0, values[0], nodes.size - 1))
        rho, rho_dot, theta = fit(c.leg_length), fit(c.leg_rate), fit(c.leg_angle)
        theta_dot = fit(c.momentum) / (params.body_mass * rho * rho)
    yd, zd = polar_to_cartesian_velocity(rho, theta, rho_dot, theta_dot)
    toe_y = p.touchdown_y + rho_0 * math.sin(touchdown_angle)
    _fill(out, stance, toe_y - rho * np.sin(theta), rho * np.cos(theta), yd, zd, rho, theta,
          ramp_torque(ts, tau_0, p.ramp_duration))
    phase[stance] = np.where(zd < 0.0, Phase.COMPRESSION, Phase.DECOMPRESSION)

    ascent = t >= t_lo
    r = params.collision_factor
    y, z, yd, zd = flight_state(t[ascent] - t_lo, p.liftoff_y, p.liftoff_z, r * p.liftoff_ydot, r * p.liftoff_zdot, g, dh, dv)
    _fill(out, ascent, y, z, yd, zd, rho_0, p.liftoff_theta, 0.0)
    phase[ascent] = Phase.ASCENT
    out["y"] += y0
    return Trajectory(t=t + t0, phase=phase, **out)


def _fill(out, mask, y, z, ydot, zdot, rho, theta, torque):
    out["y"][mask], out["z"][mask], out["ydot"][mask], out["zdot"][mask] = y, z, ydot, zdot
    out["rho"][mask], out["theta"][mask], out["torque"][mask] = rho, theta, torque
