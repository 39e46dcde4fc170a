"""Flight phase with flight damping in closed form, (2.8) and (2.13)-(2.16).

    y'' = -d_h y',   z'' = -g - d_v z'                                         (2.8)

The public functions take floats (math) or arrays (numpy, broadcasting); the `*_xp`
versions take the backend explicitly (see `_backend`). The damping coefficients are scalar
parameters; below `NEGLIGIBLE_DAMPING` the ballistic limit is used (over a 0.5 s flight it
differs by less than 2e-6 m/s and 1e-6 m), so nothing divides by zero.
"""

from __future__ import annotations

from ._backend import select

NEGLIGIBLE_DAMPING = 1e-6  # [1/s]


def decay_integral(xp, rate, t):
    """(1 - e^{-rate t}) / rate = integral of e^{-rate s} over [0, t]."""
    if rate < NEGLIGIBLE_DAMPING:
        return t
    return -xp.expm1(-rate * t) / rate


def ramp_integral(xp, rate, t):
    """(1 - e^{-rate t} - rate t) / rate^2, which is -t^2/2 without damping."""
    if rate < NEGLIGIBLE_DAMPING:
        return -0.5 * t * t
    x = rate * t
    return (-xp.expm1(-x) - x) / (rate * rate)


def flight_state_xp(xp, t, y0, z0, ydot0, zdot0, gravity, damping_h, damping_v):
    decay_v = decay_integral(xp, damping_v, t)
    y = y0 + ydot0 * decay_integral(xp, damping_h, t)                       # (2.13)
    z = z0 + gravity * ramp_integral(xp, damping_v, t) + zdot0 * decay_v     # (2.14)
    ydot = ydot0 * xp.exp(-damping_h * t)                                   # (2.15)
    zdot = zdot0 * xp.exp(-damping_v * t) - gravity * decay_v               # (2.16)
    return y, z, ydot, zdot


def flight_state(t, y0, z0, ydot0, zdot0, gravity, damping_h, damping_v):
    """State (y, z, y', z') after flying for time t from (y0, z0, y0', z0'), (2.13)-(2.16)."""
    xp = select(t, y0, z0, ydot0, zdot0)
    return flight_state_xp(xp, xp.asarray(t), y0, z0, ydot0, zdot0, gravity, damping_h, damping_v)


def apex_time_xp(xp, zdot0, gravity, damping_v):
    if damping_v < NEGLIGIBLE_DAMPING:
        return zdot0 / gravity
    return xp.log1p(damping_v * zdot0 / gravity) / damping_v


def apex_time(zdot0, gravity, damping_v):
    """Time until z' = 0 from an upward velocity zdot0 >= 0: ln(1 + d_v zdot0 / g) / d_v.

    Solves (2.16) = 0. (The thesis defines the apex time by y' = 0 below (4.3); z' = 0 is
    meant.)
    """
    return apex_time_xp(select(zdot0), zdot0, gravity, damping_v)


def descent_time_xp(xp, drop, gravity, damping_v, iterations: int = 2):
    drop = xp.maximum(drop, 0.0)
    t = xp.sqrt(2.0 * drop / gravity)
    if damping_v < NEGLIGIBLE_DAMPING:
        return t
    t = t * (1.0 + damping_v * t / 6.0)   # first-order damping correction of the ballistic time
    while iterations > 0:
        decay = -xp.expm1(-damping_v * t) / damping_v          # (1 - e^{-d t}) / d
        fallen = gravity * (t - decay) / damping_v             # drop of (2.14) from rest
        t = t - (fallen - drop) / xp.maximum(gravity * decay, 1e-300)
        iterations -= 1
    return t


def descent_time(drop, gravity, damping_v, iterations: int = 2):
    """Time to fall `drop` >= 0 metres from rest (an apex) under (2.14).

    Newton's method on the closed-form fall, started from the ballistic time with its
    first-order damping correction; two steps reach 1e-15 s for |d_v t| < 0.1.
    """
    return descent_time_xp(select(drop), drop, gravity, damping_v, iterations)


def touchdown_time(z0, zdot0, leg_angle, leg_rate, rest_length, gravity, damping_v, max_steps=20):
    """Time until the toe reaches the ground in flight: z(t) = rho_0 cos(theta + theta' t), with z(t)
    of (2.14) and the leg swinging at a constant rate (scalars; Newton from the linearised fall).

    Used to schedule the stance ramp ahead of the touchdown event (the controller learns of a
    touchdown only after the sensing chain's latency). NaN if the toe does not come down (the
    gap between toe and ground is not closing) or Newton does not converge.
    """
    import math

    def gap(t):
        z = z0 + gravity * ramp_integral(math, damping_v, t) + zdot0 * decay_integral(math, damping_v, t)
        return z - rest_length * math.cos(leg_angle + leg_rate * t)

    def gap_rate(t):
        zdot = zdot0 * math.exp(-damping_v * t) - gravity * decay_integral(math, damping_v, t)
        return zdot + rest_length * math.sin(leg_angle + leg_rate * t) * leg_rate

    t = 0.0
    if zdot0 > 0.0:      # rising: start on the descending branch, a free fall from the apex
        t = apex_time(zdot0, gravity, damping_v)
        t += math.sqrt(2.0 * max(0.0, gap(t)) / gravity)
    for _ in range(max_steps):
        slope = gap_rate(t)
        if slope >= 0.0:
            return math.nan
        step = gap(t) / slope
        t -= step
        if abs(step) < 1e-7:
            return t
    return t if abs(gap(t)) < 1e-6 else math.nan
