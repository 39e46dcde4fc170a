"""Approximate analytical solution (AAS) of the extended TD-SLIP model and the apex return
map R = R_as o R_s o R_d, (2.3)-(2.7) with (2.17)-(2.37).

Stance approximation (Ankarali & Saranli's, as summarised in section 2.2.2): the angular
momentum is held at a constant p_hat, the centrifugal term is linearised about the rest
length, rho theta'^2 ~= omega^2 (4 rho_0 - 3 rho) with omega = p_hat / (m rho_0^2), and
cos(theta) ~= 1 in the radial gravity term. The radial equation becomes the damped
oscillator

    rho'' + (d/m) rho' + w0^2 rho = F,   w0^2 = k/m + 3 omega^2,   F = -g + rho_0 k/m + 4 rho_0 omega^2

and theta' ~= (p_hat / (m rho_0^2)) (3 - 2 rho/rho_0) integrates in closed form. Hip torque
and gravity enter through p_hat = p_td + dp_tau + dp_g (2.34).

Corrections to the seed, each used where marked below:

- Table 2.2: the natural frequency is w0 = sqrt(k/m + 3 omega^2); the seed squares k/m.
  The forcing term's "rho_0 omega_0^2" is rho_0 k/m (omega_0^2 = k/m, the unloaded leg) and
  "omega" is p_hat/(m rho_0^2), defined nowhere in the seed.
- (2.19) lacks the t in cos(w_d t + phi_1 - phi_2).
- (2.22), (2.23), (2.31) use arctan; the quadrant matters (A < 0 once rho_0 omega^2 > g,
  i.e. fast strides), so atan2 is used: phi_1 = atan2(-B, A), phi_2 = -arccos(zeta),
  phi_3 = atan2(d w0 sin phi_2, d w0 cos phi_2 - k), and the lift-off phase of (2.29) is
  reduced modulo 2 pi. With these, (2.29) is the seed's formula exactly.
- (2.37): r_lo is the leg length at lift-off, rho_lo. (2.35)-(2.37) are the stance averages
  of the accumulated torque and gravity impulses (the AAS needs the mean p over stance);
  (2.36) holds for t_f = t_lo, the general ramp is used when t_f differs.
- Sign: the applied torque is -tau_0 (1 - t/t_f) (package conventions), so dp_tau is
  -tau_0 t_lo/3 for t_f = t_lo.

Lift-off: (2.29) is one fixed-point step of (2.28) on the analytic rho(t) started from
t_lo = 2 t_b. Iterating it to the root of (2.28) changes t_lo by less than 1e-5 relative on
the thesis ranges, while both are ~2 % off the exact model (the AAS's rho(t) error
dominates), so the closed form is the default; `liftoff="root"` iterates to convergence.
"""

from __future__ import annotations

import operator

import numpy as np

from ._backend import ARRAY, SCALAR, select
from .flight import apex_time_xp, decay_integral, descent_time_xp, flight_state_xp
from .exact import FAILURE_TEXT, Failure
from .params import ModelParams

# the failure codes as plain ints: Enum attribute lookups cost a microsecond each on one stride
NONE, NO_FLIGHT, NO_LIFTOFF = int(Failure.NONE), int(Failure.NO_FLIGHT), int(Failure.NO_LIFTOFF)
NO_COMPRESSION, APEX_BELOW, NON_FINITE = int(Failure.NO_COMPRESSION), int(Failure.APEX_BELOW_TOUCHDOWN), int(Failure.NON_FINITE)

MOMENTUM_ITERATIONS = 3    # passes of the fixed point (2.34), Aitken-accelerated: within 2e-5
                           # (relative) of the converged map on the thesis ranges
ROOT_ITERATIONS = 4        # extra fixed-point steps of (2.28) for liftoff="root"


def mean_ramp_impulse(xp, stance_time, ramp_duration):
    """Mean over [0, t_lo] of the accumulated unit ramp impulse, int_0^t (1 - s/t_f)_+ ds.

    Equals t_lo/3 for t_f = t_lo, (2.35)-(2.36).
    """
    t_f = xp.maximum(ramp_duration, 1e-12)
    t_lo = xp.maximum(stance_time, 1e-12)
    return xp.where(t_lo <= t_f, t_lo / 2.0 - t_lo * t_lo / (6.0 * t_f), t_f / 2.0 - t_f * t_f / (6.0 * t_lo))


def full_ramp_impulse(xp, t, ramp_duration):
    """int_0^t (1 - s/t_f) ds, clipped at t_f: the unit ramp's impulse accumulated until t."""
    t_f = xp.maximum(ramp_duration, 1e-12)
    tc = xp.minimum(t, t_f)
    return tc - tc * tc / (2.0 * t_f)


class StanceSolution:
    """AAS of the stance for one constant angular momentum p_hat, (2.17)-(2.31).

    Time t is measured from touchdown. Works on floats or arrays (`xp`).
    """

    __slots__ = ("xp", "touchdown_angle", "angular_rate", "natural_frequency", "damping_ratio",
                 "damped_frequency", "decay_rate", "equilibrium_length", "amplitude", "phase_1",
                 "phase_2", "phase_3", "force_amplitude", "force_offset", "mean_angle_rate",
                 "angle_amplitude", "rest_length")

    def __init__(self, xp, params: ModelParams, angular_momentum, rho_dot_td, touchdown_angle,
                 radial_gravity=None):
        self.xp = xp
        self.solve(params, angular_momentum, rho_dot_td, touchdown_angle, radial_gravity)

    def solve(self, params: ModelParams, angular_momentum, rho_dot_td, touchdown_angle, radial_gravity=None) -> None:
        """This solution for another p_hat (and touchdown), in place: the passes of the fixed point
        (2.34) move one solution instead of building one each (an object costs ~0.1 us on floats)."""
        xp = self.xp
        m, k, d, rho_0 = params.body_mass, params.stiffness, params.damping, params.rest_length
        g = params.gravity if radial_gravity is None else radial_gravity
        self.touchdown_angle, self.rest_length = touchdown_angle, rho_0
        omega = angular_momentum / (m * rho_0 * rho_0)
        w0_sq = k / m + 3.0 * omega * omega                      # Table 2.2, corrected
        w0 = xp.sqrt(w0_sq)
        zeta = d / (2.0 * m * w0)                                # Table 2.2
        w_d = w0 * xp.sqrt(1.0 - zeta * zeta)
        a = zeta * w0
        forcing = -g + rho_0 * k / m + 4.0 * rho_0 * omega * omega  # Table 2.2, corrected
        rho_eq = forcing / w0_sq
        offset = rho_0 - rho_eq                                  # A (2.26)
        b = (rho_dot_td + a * offset) / w_d                      # B (2.27)
        phase_2 = -xp.arccos(zeta)                               # (2.23) in its quadrant
        sin_phase_2 = -w_d / w0                                  # -sqrt(1 - zeta^2)
        dw = d * w0
        self.angular_rate, self.natural_frequency, self.damping_ratio = omega, w0, zeta
        self.damped_frequency, self.decay_rate, self.equilibrium_length = w_d, a, rho_eq
        self.amplitude = xp.hypot(offset, b)                     # M (2.21)
        self.phase_1 = xp.arctan2(-b, offset)                    # (2.22) in its quadrant
        self.phase_2 = phase_2
        self.force_amplitude = xp.sqrt(k * k - 2.0 * k * dw * zeta + dw * dw)   # M_bar (2.30), cos(phi_2) = zeta
        self.phase_3 = xp.arctan2(dw * sin_phase_2, dw * zeta - k)              # (2.31) in its quadrant
        self.force_offset = k * offset                          # k (rho_0 - F/w0^2) of (2.29)
        self.mean_angle_rate = omega * (3.0 - 2.0 * rho_eq / rho_0)             # X (2.24)
        self.angle_amplitude = 2.0 * omega * self.amplitude / (rho_0 * w0)      # Y (2.25)

    def as_array(self) -> "StanceSolution":
        """The same solution on numpy arrays (1-D), e.g. to evaluate it on a grid of times."""
        copy = StanceSolution.__new__(StanceSolution)
        if self.xp is SCALAR:     # floats: one array, each field a view of length one (one allocation)
            values = np.array(_numeric_fields(self), dtype=float).reshape(-1, 1)
            copy.xp = ARRAY
            for name, view in zip(_NUMERIC_FIELDS, values):
                setattr(copy, name, view)
            return copy
        for name in self.__slots__:
            setattr(copy, name, np.atleast_1d(np.asarray(getattr(self, name), dtype=float)) if name != "xp" else ARRAY)
        return copy

    def leg_length(self, t):                                                    # (2.17)
        xp = self.xp
        return self.amplitude * xp.exp(-self.decay_rate * t) * xp.cos(self.damped_frequency * t + self.phase_1) + self.equilibrium_length

    def leg_rate(self, t):                                                      # (2.18)
        xp = self.xp
        return (-self.amplitude * self.natural_frequency * xp.exp(-self.decay_rate * t)
                * xp.cos(self.damped_frequency * t + self.phase_1 + self.phase_2))

    def leg_angle(self, t):                                                     # (2.19), with its missing t
        xp = self.xp
        shift = self.phase_1 - self.phase_2
        return (self.touchdown_angle + self.mean_angle_rate * t + self.angle_amplitude
                * (xp.exp(-self.decay_rate * t) * xp.cos(self.damped_frequency * t + shift) - xp.cos(shift)))

    def leg_angle_rate(self, t):                                                # (2.20)
        xp = self.xp
        return (self.mean_angle_rate - 2.0 * self.angular_rate * self.amplitude / self.rest_length
                * xp.exp(-self.decay_rate * t) * xp.cos(self.damped_frequency * t + self.phase_1))

    def leg_force(self, t):
        """Net leg force k (rho_0 - rho) - d rho' of (2.28), by (2.30)-(2.31)."""
        xp = self.xp
        return self.force_offset + self.amplitude * self.force_amplitude * xp.exp(-self.decay_rate * t) * xp.cos(
            self.damped_frequency * t + self.phase_1 + self.phase_3)

    def bottom_time(self):
        """Maximum compression, rho' = 0: w_d t_b + phi_1 + phi_2 = pi/2 (mod pi)."""
        xp = self.xp
        return xp.mod(0.5 * xp.pi - self.phase_1 - self.phase_2, xp.pi) / self.damped_frequency

    def liftoff_ratio(self, t):
        """-k A e^{a t} / (M M_bar): (2.28) holds where cos(w_d t + phi_1 + phi_3) equals it."""
        return -self.force_offset * self.xp.exp(self.decay_rate * t) / (self.amplitude * self.force_amplitude)

    def liftoff_time(self, guess=None, iterations: int = 1):
        """Lift-off time (2.29): the first decreasing zero of (2.28) after touchdown.

        One iteration from guess = 2 t_b is the seed's closed form; more iterate to the root.
        """
        xp = self.xp
        t = 2.0 * self.bottom_time() if guess is None else guess
        while iterations > 0:     # (not `for _ in range`: ~50 ns less, once a pass of (2.34))
            ratio = xp.clip(self.liftoff_ratio(t), -1.0, 1.0)
            t = xp.mod(xp.arccos(ratio) - self.phase_1 - self.phase_3, 2.0 * xp.pi) / self.damped_frequency
            iterations -= 1
        return t


_NUMERIC_FIELDS = StanceSolution.__slots__[1:]          # all but xp (as_array)
_numeric_fields = operator.attrgetter(*_NUMERIC_FIELDS)


class StridePrediction:
    """A predicted stride from an apex; floats for one stride, arrays for many.

    Positions and times are relative to the opening apex (y = 0, t = 0). Lift-off values are
    before the collision (2.12). `failure_code` is an `exact.Failure` value (an int array for
    many strides); values are NaN where the prediction failed.
    """

    __slots__ = ("ok", "failure_code", "next_apex_height", "next_forward_speed", "stride_length",
                 "stride_time", "descent_time", "stance_time", "ascent_time", "ramp_duration",
                 "touchdown_y", "touchdown_ydot", "touchdown_zdot", "touchdown_rho_dot",
                 "touchdown_theta_dot", "liftoff_y", "liftoff_z", "liftoff_ydot", "liftoff_zdot",
                 "liftoff_rho", "liftoff_theta", "liftoff_rho_dot", "liftoff_theta_dot", "stance",
                 "correction")

    def __init__(self):
        self.correction = None

    @property
    def failure(self):
        """Why the stride failed, in words ("" on success); a list for arrays."""
        if isinstance(self.failure_code, int):
            return FAILURE_TEXT[self.failure_code]
        return [FAILURE_TEXT[int(code)] for code in self.failure_code]

    def take(self, index) -> "StridePrediction":
        """The predictions of the strides `index` selects (arrays only)."""
        out = StridePrediction()
        for name in self.__slots__:
            value = getattr(self, name)
            setattr(out, name, value[index] if isinstance(value, np.ndarray) else value)
        return out

    def as_scalar(self) -> "StridePrediction":
        """This prediction of a single stride with plain floats (arrays of length 1 in)."""
        for name in self.__slots__:
            value = getattr(self, name)
            if isinstance(value, np.ndarray):
                setattr(self, name, value.reshape(-1)[0].item())
        return self


def descend(xp, params: ModelParams, apex_height, forward_speed, touchdown_angle):
    """Descent map R_d (2.3): apex -> touchdown, closed form.

    Returns (ok, t_descent, y_td, ydot_td, zdot_td, rho_dot_td, theta_dot_td).
    """
    g, dh, dv, rho_0 = params.gravity, params.flight_damping_horizontal, params.flight_damping_vertical, params.rest_length
    c = xp.cos(touchdown_angle)
    drop = apex_height - rho_0 * c
    t_d = descent_time_xp(xp, drop, g, dv)
    # (2.13), (2.15), (2.16) from rest at the apex; z is the touchdown height by construction
    y_td = forward_speed * decay_integral(xp, dh, t_d)
    ydot = forward_speed * xp.exp(-dh * t_d)
    zdot = -g * decay_integral(xp, dv, t_d)
    s = xp.sin(touchdown_angle)
    rho_dot = -ydot * s + zdot * c
    theta_dot = (-ydot * c - zdot * s) / rho_0
    return drop > 0.0, t_d, y_td, ydot, zdot, rho_dot, theta_dot


def ascend(xp, params: ModelParams, liftoff_y, liftoff_z, liftoff_ydot, liftoff_zdot):
    """Lift-off collision (2.12) and ascent map R_as (2.5): lift-off -> next apex.

    Returns (ok, t_ascent, apex_y, apex_height, apex_speed).
    """
    g, dh, dv = params.gravity, params.flight_damping_horizontal, params.flight_damping_vertical
    factor = params.collision_factor                                    # (2.12)
    ydot, zdot = factor * liftoff_ydot, factor * liftoff_zdot
    t_a = apex_time_xp(xp, xp.maximum(zdot, 0.0), g, dv)
    y, z, speed, _ = flight_state_xp(xp, t_a, liftoff_y, liftoff_z, ydot, zdot, g, dh, dv)
    return zdot > 0.0, t_a, y, z, speed


def predict_aas(params: ModelParams, apex_height, forward_speed, touchdown_angle, tau_0,
                ramp_duration=None, *, liftoff: str = "closed_form",
                momentum_iterations: int = MOMENTUM_ITERATIONS) -> StridePrediction:
    """The thesis's AAS return map (2.7) for one stride (floats) or many (arrays).

    `ramp_duration` t_f of the torque ramp; None uses the predicted lift-off time, as the
    thesis does (section 4.1). `liftoff` is "closed_form" (2.29) or "root" of (2.28).
    """
    xp = select(apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration)
    if liftoff not in ("closed_form", "root"):
        raise ValueError(f"liftoff must be 'closed_form' or 'root', got {liftoff!r}")
    apex_height, forward_speed = xp.asarray(apex_height), xp.asarray(forward_speed)
    touchdown_angle, tau_0 = xp.asarray(touchdown_angle), xp.asarray(tau_0)
    m, g, rho_0 = params.body_mass, params.gravity, params.rest_length
    m_g = m * g

    ok_td, t_d, y_td, ydot_td, zdot_td, rho_dot_td, theta_dot_td = descend(xp, params, apex_height, forward_speed, touchdown_angle)
    momentum_td = m * rho_0 * rho_0 * theta_dot_td
    sin_td = xp.sin(touchdown_angle)
    gravity_arm_td = 2.0 * rho_0 * sin_td
    iterations = 1 + ROOT_ITERATIONS if liftoff == "root" else 1

    # Fixed point p_hat = G(p_hat) of (2.34) from a physical guess (half-period stance, symmetric
    # sweep: rho_lo ~ rho_0, theta_lo ~ -theta_td), accelerated by Aitken's delta-squared: p1 = G(p0);
    # (momentum_iterations - 2) times p2 = G(p1) and Aitken's step; the last pass G(p1) gives the stance.
    half_period = xp.pi / xp.sqrt(params.stiffness / m + 3.0 * theta_dot_td * theta_dot_td)  # omega = theta_dot_td
    t_f = half_period if ramp_duration is None else ramp_duration
    p0 = momentum_td - tau_0 * mean_ramp_impulse(xp, half_period, t_f) + m_g * half_period / 6.0 * rho_0 * sin_td
    passes = momentum_iterations if momentum_iterations > 2 else 2   # (builtin max: ~70 ns)
    momentum = p1 = p0
    stance = StanceSolution(xp, params, momentum, rho_dot_td, touchdown_angle)
    for index in range(passes):
        if index:
            stance.solve(params, momentum, rho_dot_td, touchdown_angle)              # one pass: stance for p_hat
        t_lo = stance.liftoff_time(None, iterations)                                 # -> lift-off (2.29)
        rho_lo, theta_lo = stance.leg_length(t_lo), stance.leg_angle(t_lo)
        t_f = t_lo if ramp_duration is None else ramp_duration
        if index == passes - 1:
            break
        updated = (momentum_td - tau_0 * mean_ramp_impulse(xp, t_lo, t_f)            # -> (2.34)-(2.36)
                   + m_g * t_lo / 6.0 * (gravity_arm_td + rho_lo * xp.sin(theta_lo)))   # (2.37)
        if index == 0:
            p1 = updated
        else:
            curvature = updated - 2.0 * p1 + p0
            usable = xp.abs(curvature) > 1e-15
            p0, p1 = p1, xp.where(usable, updated - (updated - p1) ** 2 / xp.where(usable, curvature, 1.0), updated)
        momentum = p1
    ok_lo = xp.abs(stance.liftoff_ratio(t_lo)) < 1.0
    return finish_stride(xp, params, stance, ok_td, ok_lo, rho_dot_td, t_d, y_td, ydot_td, zdot_td, theta_dot_td,
                   t_lo, t_f, rho_lo, stance.leg_rate(t_lo), theta_lo, stance.leg_angle_rate(t_lo))


def failure_code(xp, ok_touchdown, compressing, ok_liftoff, ok_flight, result_sum):
    """The first failure of a stride (an `exact.Failure` value; an int array for many)."""
    return xp.to_int(xp.where(ok_touchdown, xp.where(compressing, xp.where(ok_liftoff, xp.where(
        ok_flight, xp.where(xp.isfinite(result_sum), NONE, NON_FINITE), NO_FLIGHT), NO_LIFTOFF), NO_COMPRESSION),
        APEX_BELOW))


def finish_stride(xp, params, stance, ok_td, ok_lo, rho_dot_td, t_d, y_td, ydot_td, zdot_td, theta_dot_td,
            t_lo, t_f, rho_lo, rho_dot_lo, theta_lo, theta_dot_lo) -> StridePrediction:
    """Lift-off state -> collision -> ascent, and the prediction record (shared by predictors)."""
    rho_0 = params.rest_length
    s, c = xp.sin(theta_lo), xp.cos(theta_lo)
    ydot_lo = -rho_dot_lo * s - rho_lo * theta_dot_lo * c
    zdot_lo = rho_dot_lo * c - rho_lo * theta_dot_lo * s
    y_lo = y_td + rho_0 * xp.sin(stance.touchdown_angle) - rho_lo * s
    z_lo = rho_lo * c
    ok_up, t_a, y1, z1, speed1 = ascend(xp, params, y_lo, z_lo, ydot_lo, zdot_lo)
    code = failure_code(xp, ok_td, rho_dot_td < 0.0, ok_lo, ok_up, z1 + speed1 + y1)
    ok = code == NONE
    nan = xp.nan
    out = StridePrediction()
    out.ok, out.failure_code = ok, code
    out.next_apex_height, out.next_forward_speed = xp.where(ok, z1, nan), xp.where(ok, speed1, nan)
    out.stride_length, out.stride_time = xp.where(ok, y1, nan), xp.where(ok, t_d + t_lo + t_a, nan)
    out.descent_time, out.stance_time, out.ascent_time, out.ramp_duration = t_d, t_lo, t_a, t_f
    out.touchdown_y, out.touchdown_ydot, out.touchdown_zdot = y_td, ydot_td, zdot_td
    out.touchdown_rho_dot, out.touchdown_theta_dot = rho_dot_td, theta_dot_td
    out.liftoff_y, out.liftoff_z, out.liftoff_ydot, out.liftoff_zdot = y_lo, z_lo, ydot_lo, zdot_lo
    out.liftoff_rho, out.liftoff_theta, out.liftoff_rho_dot, out.liftoff_theta_dot = rho_lo, theta_lo, rho_dot_lo, theta_dot_lo
    out.stance = stance
    return out
