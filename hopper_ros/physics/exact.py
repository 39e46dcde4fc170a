"""Exact extended TD-SLIP model: one apex-to-apex stride of the hybrid dynamics.

Descent and ascent use the closed-form flight (2.13)-(2.16); stance integrates (2.9) with the
ramp torque (2.32) numerically (scipy DOP853, rtol 1e-10); every event is located by root
finding, never by a fixed step:

- touchdown: the toe, at rest length and angle theta_td, reaches the ground,
  z - rho_0 cos(theta_td) = 0 (brentq on the closed-form descent);
- bottom: lowest body point in stance, z' = 0;
- lift-off: net leg force zero, k (rho_0 - rho) - d rho' = 0 (2.28), or full extension
  rho = rho_0, whichever comes first; then the lift-off collision (2.12);
- apex: z' = 0 in the ascent, closed form.

Stance dynamics in the package conventions (see `hopper_ros.physics`), with m = m_b:

    rho''   = rho theta'^2 - g cos(theta) - (k/m)(rho - rho_0) - (d/m) rho'
    theta'' = (g rho sin(theta) + tau/m - 2 rho rho' theta') / rho^2            (2.9)

Flight damping acts only in flight, as the thesis assumes; the toe mass only in (2.12).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from . import laws
from .flight import apex_time, flight_state
from .laws import ramp_torque  # noqa: F401  (the one ramp (2.32); imported from here by older code)
from .params import ModelParams

RTOL = 1e-10
ATOL = 1e-12
MAX_STANCE_TIME = 1.0          # [s] a stance longer than this is a failure
COLLAPSE_FRACTION = 0.3        # leg shorter than this fraction of rho_0: the leg collapsed
MAX_LEG_ANGLE = math.radians(80.0)  # the body tipped over


class Failure(IntEnum):
    """Why a stride fails; shared by the exact model and the predictors."""

    NONE = 0
    APEX_BELOW_TOUCHDOWN = 1
    NO_COMPRESSION = 2
    NO_LIFTOFF = 3
    NO_FLIGHT = 4
    NON_FINITE = 5
    LEG_COLLAPSED = 6
    TIPPED_OVER = 7
    ANGLE_OUT_OF_RANGE = 8


FAILURE_TEXT = {
    Failure.NONE: "",
    Failure.APEX_BELOW_TOUCHDOWN: "apex below the touchdown height: the toe is already on the ground",
    Failure.NO_COMPRESSION: "the body does not move toward the toe at touchdown",
    Failure.NO_LIFTOFF: "no lift-off: the leg force never returns to zero",
    Failure.NO_FLIGHT: "no flight: vertical velocity at lift-off is not upward",
    Failure.NON_FINITE: "non-finite result",
    Failure.LEG_COLLAPSED: "the leg collapsed in stance",
    Failure.TIPPED_OVER: "the body tipped over in stance",
    Failure.ANGLE_OUT_OF_RANGE: "touchdown angle beyond the leg's range",
}


class Phase(IntEnum):
    """Phases of a stride; compression and decompression split at the bottom event."""

    DESCENT = 0
    COMPRESSION = 1
    DECOMPRESSION = 2
    ASCENT = 3


@dataclass(frozen=True)
class EventState:
    """Body state at an event. In flight rho is the rest length and theta the held angle."""

    t: float
    y: float
    z: float
    ydot: float
    zdot: float
    rho: float
    theta: float
    rho_dot: float = 0.0
    theta_dot: float = 0.0


@dataclass
class Trajectory:
    """Sampled stride; every array has one entry per sample time."""

    t: np.ndarray
    y: np.ndarray
    z: np.ndarray
    ydot: np.ndarray
    zdot: np.ndarray
    rho: np.ndarray
    theta: np.ndarray
    torque: np.ndarray
    phase: np.ndarray


@dataclass
class StrideResult:
    """Outcome of one stride from an apex. `ok` is False with `failure` saying why."""

    ok: bool
    failure_code: Failure = Failure.NONE
    apex: EventState | None = None
    touchdown: EventState | None = None
    bottom: EventState | None = None
    liftoff: EventState | None = None              # before the collision
    liftoff_after_collision: EventState | None = None
    next_apex: EventState | None = None
    liftoff_reason: str = ""                       # "leg_force" (2.28) or "full_extension"
    trajectory: Trajectory | None = None
    stance_solutions: list = field(default_factory=list, repr=False)

    @property
    def failure(self) -> str:
        return FAILURE_TEXT[self.failure_code]

    @property
    def next_apex_height(self) -> float:
        return self.next_apex.z if self.next_apex else math.nan

    @property
    def next_forward_speed(self) -> float:
        return self.next_apex.ydot if self.next_apex else math.nan

    @property
    def stride_length(self) -> float:
        return self.next_apex.y - self.apex.y if self.next_apex else math.nan

    @property
    def stride_time(self) -> float:
        return self.next_apex.t - self.apex.t if self.next_apex else math.nan

    @property
    def stance_time(self) -> float:
        return self.liftoff.t - self.touchdown.t if self.liftoff else math.nan


def polar_to_cartesian_velocity(rho, theta, rho_dot, theta_dot):
    """Body velocity (y', z') from the stance polar coordinates about the toe."""
    s, c = np.sin(theta), np.cos(theta)
    return -rho_dot * s - rho * theta_dot * c, rho_dot * c - rho * theta_dot * s


def cartesian_to_polar_velocity(rho, theta, ydot, zdot):
    """(rho', theta') of a body moving with (y', z') at (rho, theta) from the toe."""
    s, c = np.sin(theta), np.cos(theta)
    return -ydot * s + zdot * c, (-ydot * c - zdot * s) / rho


def _stance_rhs(params: ModelParams, tau_0: float, ramp_duration: float, with_torque: bool):
    m = params.body_mass
    g = params.gravity
    law = laws.Coefficients.from_model(params)
    leg_force, ramp = laws.leg_force, laws.ramp_torque
    tau_0, ramp_duration = float(tau_0), float(ramp_duration)
    sin, cos = math.sin, math.cos

    def rhs(t, state):
        rho, theta, rho_dot, theta_dot = state
        torque = ramp(float(t), tau_0, ramp_duration) if with_torque else 0.0   # (2.32)
        rho_ddot = rho * theta_dot * theta_dot - g * cos(theta) + leg_force(law, rho, rho_dot) / m
        theta_ddot = (g * rho * sin(theta) + torque / m - 2.0 * rho * rho_dot * theta_dot) / (rho * rho)
        return [rho_dot, theta_dot, rho_ddot, theta_ddot]

    return rhs


def _stance_events(params: ModelParams):
    rho_0 = params.rest_length
    law = laws.Coefficients.from_model(params)

    def leg_force(t, s):  # (2.28): the leg would pull the toe off the ground
        return laws.leg_force(law, s[0], s[2])

    def full_extension(t, s):
        return s[0] - rho_0

    def bottom(t, s):  # z' = rho' cos(theta) - rho theta' sin(theta) crosses zero upwards
        return s[2] * math.cos(s[1]) - s[0] * s[3] * math.sin(s[1])

    def collapse(t, s):
        return s[0] - COLLAPSE_FRACTION * rho_0

    def tip_over(t, s):
        return MAX_LEG_ANGLE - abs(s[1])

    leg_force.terminal, leg_force.direction = True, -1
    full_extension.terminal, full_extension.direction = True, 1
    bottom.terminal, bottom.direction = False, 1
    collapse.terminal, collapse.direction = True, -1
    tip_over.terminal, tip_over.direction = True, -1
    return [leg_force, full_extension, bottom, collapse, tip_over]


_EVENT_NAMES = ("leg_force", "full_extension", "bottom", "collapse", "tip_over")


def simulate_stride(
    params: ModelParams,
    apex_height: float,
    forward_speed: float,
    touchdown_angle: float,
    tau_0: float,
    ramp_duration: float,
    *,
    y0: float = 0.0,
    t0: float = 0.0,
    sample_period: float | None = None,
) -> StrideResult:
    """Simulate one stride from an apex (zdot = 0) with the leg set to `touchdown_angle`.

    `tau_0` [N m] and `ramp_duration` t_f [s] define the stance torque ramp (2.32); the thesis
    sets t_f to the predicted lift-off time. With `sample_period` the full trajectory is
    sampled on t0 + n * sample_period.
    """
    from scipy.integrate import solve_ivp     # here, not at the top: the nodes that import this module for
    from scipy.optimize import brentq         # its types need neither (0.6 s of a process's start)
    p = params
    g, dh, dv, rho_0 = p.gravity, p.flight_damping_horizontal, p.flight_damping_vertical, p.rest_length
    apex = EventState(t0, y0, apex_height, forward_speed, 0.0, rho_0, touchdown_angle)
    result = StrideResult(ok=False, apex=apex)

    # Descent: the toe reaches the ground when z = rho_0 cos(theta_td).
    touchdown_height = rho_0 * math.cos(touchdown_angle)
    if abs(touchdown_angle) >= MAX_LEG_ANGLE:
        result.failure_code = Failure.ANGLE_OUT_OF_RANGE
        return result
    if apex_height <= touchdown_height:
        result.failure_code = Failure.APEX_BELOW_TOUCHDOWN
        return result

    def height_above_touchdown(t):
        return float(flight_state(t, 0.0, apex_height, 0.0, 0.0, g, dh, dv)[1]) - touchdown_height

    t_upper = math.sqrt(2.0 * (apex_height - touchdown_height) / g)
    while height_above_touchdown(t_upper) > 0.0:
        t_upper *= 1.5
    t_descent = brentq(height_above_touchdown, 0.0, t_upper, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    y_td, z_td, ydot_td, zdot_td = (
        float(v) for v in flight_state(t_descent, y0, apex_height, forward_speed, 0.0, g, dh, dv)
    )
    rho_dot_td, theta_dot_td = cartesian_to_polar_velocity(rho_0, touchdown_angle, ydot_td, zdot_td)
    t_td = t0 + t_descent
    result.touchdown = EventState(t_td, y_td, z_td, ydot_td, zdot_td, rho_0, touchdown_angle,
                                  float(rho_dot_td), float(theta_dot_td))
    if rho_dot_td >= 0.0:
        result.failure_code = Failure.NO_COMPRESSION
        return result
    toe_y = y_td + rho_0 * math.sin(touchdown_angle)

    # Stance: integrate (2.9) in up to two segments, split at the end of the torque ramp so
    # the integrator never steps across the kink of tau(t).
    events = _stance_events(p)
    state = np.array([rho_0, touchdown_angle, rho_dot_td, theta_dot_td])
    segments = []
    if ramp_duration > 0.0 and tau_0 != 0.0:
        segments.append((0.0, min(ramp_duration, MAX_STANCE_TIME), True))
    start = segments[-1][1] if segments else 0.0
    if start < MAX_STANCE_TIME:
        segments.append((start, MAX_STANCE_TIME, False))
    terminal_event = None
    terminal_time = None
    for t_start, t_end, with_torque in segments:
        sol = solve_ivp(
            _stance_rhs(p, tau_0, ramp_duration, with_torque), (t_start, t_end), state,
            method="DOP853", rtol=RTOL, atol=ATOL, events=events,
            dense_output=sample_period is not None,
        )
        result.stance_solutions.append(sol)
        if result.bottom is None and len(sol.t_events[2]):
            tb, sb = sol.t_events[2][0], sol.y_events[2][0]
            result.bottom = _stance_event_state(t_td + tb, toe_y, sb)
        for index in (0, 1, 3, 4):
            if len(sol.t_events[index]):
                t_hit = sol.t_events[index][0]
                if terminal_time is None or t_hit < terminal_time:
                    terminal_event, terminal_time, state = _EVENT_NAMES[index], t_hit, sol.y_events[index][0]
        if terminal_event is not None:
            break
        state = sol.y[:, -1]
    if terminal_event is None:
        result.failure_code = Failure.NO_LIFTOFF
        return result
    if terminal_event in ("collapse", "tip_over"):
        result.failure_code = Failure.LEG_COLLAPSED if terminal_event == "collapse" else Failure.TIPPED_OVER
        return result

    liftoff = _stance_event_state(t_td + terminal_time, toe_y, state)
    result.liftoff, result.liftoff_reason = liftoff, terminal_event
    factor = p.collision_factor                                                   # (2.12)
    after = EventState(liftoff.t, liftoff.y, liftoff.z, factor * liftoff.ydot, factor * liftoff.zdot,
                       rho_0, liftoff.theta)
    result.liftoff_after_collision = after
    if after.zdot <= 0.0:
        result.failure_code = Failure.NO_FLIGHT
        return result

    t_up = float(apex_time(after.zdot, g, dv))
    y1, z1, ydot1, zdot1 = (float(v) for v in flight_state(t_up, after.y, after.z, after.ydot, after.zdot, g, dh, dv))
    result.next_apex = EventState(after.t + t_up, y1, z1, ydot1, 0.0, rho_0, liftoff.theta)
    result.ok = True
    if sample_period is not None:
        result.trajectory = _sample(result, p, tau_0, ramp_duration, toe_y, sample_period)
    return result


def _stance_event_state(t: float, toe_y: float, s) -> EventState:
    rho, theta, rho_dot, theta_dot = (float(v) for v in s)
    ydot, zdot = polar_to_cartesian_velocity(rho, theta, rho_dot, theta_dot)
    return EventState(float(t), toe_y - rho * math.sin(theta), rho * math.cos(theta), float(ydot), float(zdot),
                      rho, theta, rho_dot, theta_dot)


def _sample(result: StrideResult, p: ModelParams, tau_0: float, ramp_duration: float,
            toe_y: float, period: float) -> Trajectory:
    """Sample a successful stride on a regular grid, the stance from the dense solutions."""

    def stance_state(ts):
        states = np.empty((4, ts.size))
        for sol in result.stance_solutions:
            mask = (ts >= sol.t[0]) & (ts <= sol.t[-1])
            if mask.any():
                states[:, mask] = sol.sol(ts[mask])
        return states

    return sample_stride(p, result.apex, result.touchdown.t, result.liftoff_after_collision, toe_y,
                         stance_state, tau_0, ramp_duration, period)


def sample_stride(params: ModelParams, apex: EventState, touchdown_time: float, liftoff: EventState,
                  toe_y: float, stance_state, tau_0: float, ramp_duration: float, period: float) -> Trajectory:
    """Sample one stride on t = apex.t + n * period up to the next apex, phase by phase.

    Flights in closed form from `apex` and from `liftoff` (the state after the collision,
    its theta the held leg angle); the stance from `stance_state(ts)` -> (rho, theta, rho',
    theta') at times ts from touchdown. Shared by the exact model and the predictors.
    """
    g, dh, dv, rho_0 = params.gravity, params.flight_damping_horizontal, params.flight_damping_vertical, params.rest_length
    t_up = float(apex_time(liftoff.zdot, g, dv))
    n = int(math.floor((liftoff.t + t_up - apex.t) / period + 1e-9)) + 1
    t = apex.t + period * np.arange(n)
    out = {name: np.empty(n) for name in ("y", "z", "ydot", "zdot", "rho", "theta", "torque")}
    phase = np.empty(n, dtype=np.int8)

    def fill(mask, y, z, ydot, zdot, rho, theta, torque):
        out["y"][mask], out["z"][mask], out["ydot"][mask], out["zdot"][mask] = y, z, ydot, zdot
        out["rho"][mask], out["theta"][mask], out["torque"][mask] = rho, theta, torque

    descent = t < touchdown_time
    fill(descent, *flight_state(t[descent] - apex.t, apex.y, apex.z, apex.ydot, 0.0, g, dh, dv), rho_0, apex.theta, 0.0)
    phase[descent] = Phase.DESCENT

    stance = (t >= touchdown_time) & (t < liftoff.t)
    ts = t[stance] - touchdown_time
    rho, theta, rho_dot, theta_dot = stance_state(ts)
    ydot, zdot = polar_to_cartesian_velocity(rho, theta, rho_dot, theta_dot)
    fill(stance, toe_y - rho * np.sin(theta), rho * np.cos(theta), ydot, zdot, rho, theta,
         ramp_torque(ts, tau_0, ramp_duration))
    phase[stance] = np.where(zdot < 0.0, Phase.COMPRESSION, Phase.DECOMPRESSION)   # split at the bottom, z' = 0

    ascent = t >= liftoff.t
    fill(ascent, *flight_state(t[ascent] - liftoff.t, liftoff.y, liftoff.z, liftoff.ydot, liftoff.zdot, g, dh, dv),
         rho_0, liftoff.theta, 0.0)
    phase[ascent] = Phase.ASCENT
    return Trajectory(t=t, phase=phase, **out)
