"""Corrected AAS, the default stride predictor: the thesis's AAS plus a perturbation
correction of its stance, computed on a few Chebyshev nodes.

The thesis blames its ~5 % prediction error on folding the hip torque into a constant
angular momentum (section 4.3.2). Measured against the exact model on the thesis ranges,
the AAS's error has three sources: the lift-off velocity uses the stance-average momentum
p_hat instead of the momentum at lift-off; theta' = p/(m rho^2) is linearised in rho (the leg
compresses by up to 25 %); and the radial equation drops the momentum's change, the rest of
the centrifugal term and cos(theta) in gravity. This predictor keeps the AAS as the seed and
corrects all three on N Chebyshev-Lobatto nodes t_j over the seed's stance [0, T]:

1. p(t) = p_td + int_0^t tau + int_0^t m g rho sin(theta), the torque impulse exactly and the
   gravity impulse by spectral cumulative quadrature, (2.33) without averaging;
2. theta(t) = theta_td + int_0^t p / (m rho^2), exact in rho;
3. rho = rho_AAS + delta, where delta solves the AAS's own oscillator (2.17) driven by the
   residual r(t) = rho theta'^2 - g cos(theta) - (omega^2 (4 rho_0 - 3 rho) - g) that the AAS
   leaves out, from delta(0) = delta'(0) = 0 (Duhamel's integral, again by quadrature).

Steps 1-3 are repeated `sweeps` times (a Picard iteration; the residual's slope is
3 omega^2 ((rho_0/rho)^4 - 1), small against w0^2, so it converges fast), then one Newton
step of (2.28) moves the lift-off from T to where the corrected leg force vanishes.
Everything is a fixed number of vectorised numpy operations: no adaptive stepping. With the
defaults (8 nodes, 2 sweeps) the mean E_p and E_v against the exact model fall from ~5 % and
~15 % (plain AAS) to ~0.1 % (docs/predictors/predictors.md has the figures and costs).
"""

from __future__ import annotations

from functools import lru_cache

import math

import numpy as np
from numpy.polynomial import chebyshev

from ._backend import ARRAY as xp
from ._backend import SCALAR, select
from .aas import (_APEX_BELOW, _NO_FLIGHT, _NONE, StanceSolution, _finish, _finish_scalar, full_ramp_impulse,
                  predict_aas)
from .exact import ramp_torque
from .params import ModelParams

NODES = 8
SWEEPS = 2
SEED_ITERATIONS = 3


@lru_cache(maxsize=8)
def chebyshev_nodes(count: int):
    """Chebyshev-Lobatto nodes on [0, 1] and the matrix S with (S f)_i ~= int_0^{x_i} f."""
    x = -np.cos(np.pi * np.arange(count) / (count - 1))
    vandermonde = chebyshev.chebvander(x, count - 1)
    integrated = np.empty((count, count))
    for j in range(count):
        coefficients = np.zeros(count)
        coefficients[j] = 1.0
        integrated[:, j] = chebyshev.chebval(x, chebyshev.chebint(coefficients, lbnd=-1))
    cumulative = integrated @ np.linalg.inv(vandermonde) / 2.0
    nodes = (x + 1.0) / 2.0
    nodes.setflags(write=False)
    cumulative.setflags(write=False)
    return nodes, cumulative


class StanceCorrection:
    """Corrected stance on the nodes: times, leg length and rate, angle, momentum, (n, N)."""

    __slots__ = ("t", "leg_length", "leg_rate", "leg_angle", "momentum")

    def __init__(self, t, leg_length, leg_rate, leg_angle, momentum):
        self.t, self.leg_length, self.leg_rate, self.leg_angle, self.momentum = t, leg_length, leg_rate, leg_angle, momentum


def predict_corrected(params: ModelParams, apex_height, forward_speed, touchdown_angle, tau_0,
                      ramp_duration=None, *, nodes: int = NODES, sweeps: int = SWEEPS):
    """Return map of the corrected AAS for one stride (floats) or many (arrays).

    `ramp_duration` t_f; None uses the seed AAS's lift-off time, which is what a controller
    commands before the stride. Returns an `aas.StridePrediction` whose `stance` is the AAS
    seed and whose `correction` holds the corrected stance on the nodes.
    """
    if select(apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration) is SCALAR:
        try:
            return _predict_corrected_scalar(params, apex_height, forward_speed, touchdown_angle, tau_0,
                                             ramp_duration, nodes, sweeps)
        except (ArithmeticError, ValueError):   # a degenerate stride on floats (math raises where numpy
            pass                                #   gives inf or NaN): the array path, as before
    scalar = all(np.ndim(value) == 0 for value in (apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration)
                 if value is not None)
    seed = predict_aas(params, apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration,
                       momentum_iterations=SEED_ITERATIONS)     # floats stay on the fast scalar path
    stance: StanceSolution = seed.stance.as_array()
    m, g, k, d, rho_0 = params.body_mass, params.gravity, params.stiffness, params.damping, params.rest_length
    (theta_td, tau_0, t_f, failure, stance_time, t_d, y_td, ydot_td, zdot_td, rho_dot_td, theta_dot_td) = np.broadcast_arrays(
        *(np.atleast_1d(value) for value in (
            stance.touchdown_angle, tau_0, seed.ramp_duration, seed.failure_code, seed.stance_time, seed.descent_time,
            seed.touchdown_y, seed.touchdown_ydot, seed.touchdown_zdot, seed.touchdown_rho_dot, seed.touchdown_theta_dot)))
    momentum_td = m * rho_0 * rho_0 * theta_dot_td
    x, cumulative = chebyshev_nodes(nodes)
    span = np.where(np.isfinite(stance_time), stance_time, 0.0)[:, None]   # T
    t = span * x                                                                       # (n, N)
    integrate = lambda f: span * (f @ cumulative.T)                                   # int_0^{t_j} f

    a = stance.decay_rate[:, None]
    w_d = stance.damped_frequency[:, None]
    omega = stance.angular_rate[:, None]
    decay = np.exp(-a * t)
    cos_wt, sin_wt = np.cos(w_d * t), np.sin(w_d * t)
    rho_aas = stance.leg_length(t.T).T            # (2.17)-(2.19) broadcast over (N, n)
    rho_dot_aas = stance.leg_rate(t.T).T
    theta = stance.leg_angle(t.T).T
    torque_impulse = -tau_0[:, None] * full_ramp_impulse(xp, t, t_f[:, None])
    delta = np.zeros_like(t)
    delta_rate = np.zeros_like(t)
    for _ in range(sweeps):
        rho = rho_aas + delta
        momentum = momentum_td[:, None] + torque_impulse + m * g * integrate(rho * np.sin(theta))   # 1.
        theta_dot = momentum / (m * rho * rho)
        theta = theta_td[:, None] + integrate(theta_dot)                                            # 2.
        residual = rho * theta_dot * theta_dot - g * np.cos(theta) - (omega * omega * (4.0 * rho_0 - 3.0 * rho) - g)
        growth = residual / decay                                                                    # 3. Duhamel
        in_phase, quadrature = integrate(growth * cos_wt), integrate(growth * sin_wt)
        delta = decay / w_d * (sin_wt * in_phase - cos_wt * quadrature)
        delta_rate = -a * delta + decay * (cos_wt * in_phase + sin_wt * quadrature)
    rho = rho_aas + delta
    rho_dot = rho_dot_aas + delta_rate
    momentum = momentum_td[:, None] + torque_impulse + m * g * integrate(rho * np.sin(theta))
    correction = StanceCorrection(t, rho, rho_dot, theta, momentum)

    # Lift-off: one Newton step of (2.28) from the seed's T on the corrected leg force.
    end = (slice(None), -1)
    rho_T, rate_T, theta_T, p_T = rho[end], rho_dot[end], theta[end], momentum[end]
    theta_rate_T = p_T / (m * rho_T * rho_T)
    span_T = span[:, 0]
    accel_T = (rho_T * theta_rate_T ** 2 - g * np.cos(theta_T) - k / m * (rho_T - rho_0) - d / m * rate_T)
    force_T = k * (rho_0 - rho_T) - d * rate_T
    force_rate_T = -k * rate_T - d * accel_T
    step = -force_T / np.where(force_rate_T != 0.0, force_rate_T, -1.0)
    torque_T = ramp_torque(span_T, tau_0, t_f)
    t_lo = span_T + step
    rho_lo = rho_T + rate_T * step + 0.5 * accel_T * step * step
    rho_dot_lo = rate_T + accel_T * step
    theta_lo = theta_T + theta_rate_T * step
    p_lo = p_T + (m * g * rho_T * np.sin(theta_T) + torque_T) * step
    theta_dot_lo = p_lo / (m * rho_lo * rho_lo)
    ok_td = failure != _APEX_BELOW
    ok_lo = (failure == _NONE) | (failure == _NO_FLIGHT)   # the seed found a lift-off
    prediction = _finish(xp, params, stance, ok_td, ok_lo, rho_dot_td, t_d, y_td, ydot_td, zdot_td, theta_dot_td,
                         t_lo, t_f, rho_lo, rho_dot_lo, theta_lo, theta_dot_lo)
    prediction.correction = correction
    return prediction.as_scalar() if scalar else prediction


def _predict_corrected_scalar(params: ModelParams, apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration,
                              nodes: int, sweeps: int):
    """`predict_corrected` for one stride: the same steps on 1-D arrays of the N nodes with the
    stride's values as floats (no arrays of length one), in fewer numpy calls. Equal to the generic
    path to rounding (~1e-14 relative):

    - the AAS stance by complex exponentials, E = e^{(-a + i w_d) t}: rho_AAS = Re(M e^{i phi_1} E)
      + rho_eq, rho'_AAS = Re(-M w0 e^{i(phi_1 + phi_2)} E), theta_AAS likewise (2.17)-(2.19);
    - the two Duhamel integrals as one complex one, Z = int_0^t r e^{a s} e^{i w_d s} ds; then
      delta = -Im(conj(E) Z) / w_d and delta' = Re(conj(E) Z) - a delta;
    - T, m g and 1/m folded into the quadrature matrix; delta' only after the last sweep (no sweep
      uses it); the lift-off step and the ascent on floats."""
    seed = predict_aas(params, apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration,
                       momentum_iterations=SEED_ITERATIONS)
    stance: StanceSolution = seed.stance
    m, g, k, d, rho_0 = params.body_mass, params.gravity, params.stiffness, params.damping, params.rest_length
    theta_td, tau_0, t_f = stance.touchdown_angle, float(tau_0), float(seed.ramp_duration)
    failure, stance_time = seed.failure_code, seed.stance_time
    momentum_td = m * rho_0 * rho_0 * seed.touchdown_theta_dot
    x, cumulative = chebyshev_nodes(nodes)
    span = stance_time if math.isfinite(stance_time) else 0.0                          # T
    dot, cos, sin = np.dot, np.cos, np.sin

    a, w_d, omega = stance.decay_rate, stance.damped_frequency, stance.angular_rate
    phase_1, phase_2, amplitude = stance.phase_1, stance.phase_2, stance.amplitude
    shift = phase_1 - phase_2
    t = span * x
    growth = np.exp(complex(-a, w_d) * t)                                   # E = e^{-a t} e^{i w_d t}
    rho_aas = (amplitude * complex(math.cos(phase_1), math.sin(phase_1)) * growth).real + stance.equilibrium_length
    rho_dot_aas = (-amplitude * stance.natural_frequency
                   * complex(math.cos(phase_1 + phase_2), math.sin(phase_1 + phase_2)) * growth).real
    y_amplitude = stance.angle_amplitude
    theta = ((y_amplitude * complex(math.cos(shift), math.sin(shift)) * growth).real
             + (stance.mean_angle_rate * t + (theta_td - y_amplitude * math.cos(shift))))
    ramp = max(t_f, 1e-12)
    clipped = t if span <= ramp else np.minimum(t, ramp)
    base = momentum_td - tau_0 * (clipped - clipped * clipped * (0.5 / ramp))          # p_td + int_0^t tau
    integral = span * cumulative.T                                      # int_0^{t_j} f = (f @ integral)_j
    momentum_integral, angle_integral = (m * g) * integral, integral / m
    duhamel_integral = integral.astype(complex)
    back = growth.conjugate()                                           # e^{-a t} e^{-i w_d t}
    undo = 1.0 / back                                                   # e^{a t} e^{i w_d t}
    radial = 3.0 * omega * omega
    offset = g - 4.0 * rho_0 * omega * omega
    rho, delta, swept = rho_aas, 0.0, None
    for sweep in range(sweeps):
        if sweep:
            rho = rho_aas + delta
        momentum = base + dot(rho * sin(theta), momentum_integral)                    # 1.
        scaled_rate = momentum / (rho * rho)                                            # m theta'
        theta = theta_td + dot(scaled_rate, angle_integral)                            # 2.
        theta_dot = scaled_rate / m
        residual = rho * (theta_dot * theta_dot + radial) - g * cos(theta) + offset
        swept = back * dot(residual * undo, duhamel_integral)                         # 3. Duhamel
        delta = swept.imag / -w_d
    rho = rho_aas + delta
    rho_dot = rho_dot_aas if swept is None else rho_dot_aas + (swept.real - a * delta)
    momentum = base + dot(rho * sin(theta), momentum_integral)
    correction = StanceCorrection(t[None], rho[None], rho_dot[None], theta[None], momentum[None])

    # Lift-off: one Newton step of (2.28) from the seed's T on the corrected leg force.
    rho_T, rate_T, theta_T, p_T = float(rho[-1]), float(rho_dot[-1]), float(theta[-1]), float(momentum[-1])
    theta_rate_T = p_T / (m * rho_T * rho_T)
    accel_T = (rho_T * theta_rate_T ** 2 - g * math.cos(theta_T) - k / m * (rho_T - rho_0) - d / m * rate_T)
    force_T = k * (rho_0 - rho_T) - d * rate_T
    force_rate_T = -k * rate_T - d * accel_T
    step = -force_T / (force_rate_T if force_rate_T != 0.0 else -1.0)
    torque_T = -tau_0 * (1.0 - span / t_f) if 0.0 <= span < t_f else 0.0                 # ramp_torque (2.32)
    t_lo = span + step
    rho_lo = rho_T + rate_T * step + 0.5 * accel_T * step * step
    rho_dot_lo = rate_T + accel_T * step
    theta_lo = theta_T + theta_rate_T * step
    p_lo = p_T + (m * g * rho_T * math.sin(theta_T) + torque_T) * step
    theta_dot_lo = p_lo / (m * rho_lo * rho_lo)
    ok_td = failure != _APEX_BELOW
    ok_lo = failure == _NONE or failure == _NO_FLIGHT   # the seed found a lift-off
    prediction = _finish_scalar(params, params.collision_factor, math.sin(theta_td), ok_td, ok_lo,
                                seed.touchdown_rho_dot, seed.descent_time, seed.touchdown_y, seed.touchdown_ydot,
                                seed.touchdown_zdot, seed.touchdown_theta_dot, t_lo, t_f, rho_lo, rho_dot_lo, theta_lo,
                                theta_dot_lo, stance.as_array())
    prediction.correction = correction
    return prediction
