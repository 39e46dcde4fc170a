"""The event detector as plain Python: gait events from the state estimate (no ROS).

`EventDetector.update(estimate)` returns the events the estimate reveals, each with its own time
interpolated between samples (or solved on the flight fit) and the state there. A phase machine
(descent -> compression -> decompression -> ascent -> descent) admits each event once per
stride, so noise can never produce a second touchdown or a second apex:

- pre-touchdown (descent): the toe 2 cm (`pre_touchdown_height`) above the ground. The touchdown
  height is z_td = rho_0 cos(theta) with the current leg angle; the time the ballistic flight
  prediction reaches z_td + 2 cm is solved on the flight fit (below). The event is published on
  the first sample for which that time is at most `pre_touchdown_lead` ahead (the controller
  learns it before it happens, and acts at its time: negative detection lag).
- touchdown (flight; usually in descent, in ascent when the leg swings down faster than the body
  rises): the toe reaches the ground, h = z - rho_0 cos(theta) <= 0; the time is where h, linear
  between the two samples, is zero. The toe stays at y_toe = y + rho_0 sin(theta).
- bottom (compression): z' = 0. A crossing is confirmed once z' >= `bottom_hysteresis`; the
  event's time is the last zero crossing before that (interpolated), so a noise blip that falls
  back below zero never counts.
- lift-off (compression or decompression): the model's (2.28), the leg force
  F = k (rho_0 - rho) - d rho' crosses zero, or the leg reaches full extension rho >= rho_0,
  with rho = |body - toe| and rho' = (body - toe) . v / rho from the estimate and the toe where
  it touched down; the guard min(F, k (rho_0 - rho)) interpolated to zero. (The kinematic toe
  height alone, z - rho_0 cos(theta) > 0, sees the lift-off some milliseconds late: at F = 0 the
  leg is still d rho' / k ~ 3 mm short of rho_0.)
- apex (ascent): z' = 0, timed on the flight fit.

Flight fit: from lift-off (after `flight_fit_settle`, the filter's transient) to touchdown the
body follows (2.8), y'' = -d_h y', z'' = -g - d_v z', whose solution is linear in the initial
position and velocity:

    z(tau) = z_0 + v_z phi_v(tau) + (g / d_v) (phi_v(tau) - tau),   phi(tau) = (1 - e^{-d tau}) / d
    y(tau) = y_0 + v_y phi_h(tau)

so the detector keeps a running least-squares fit of (z_0, v_z) and (y_0, v_y) to the estimated
positions of the flight (g, d_v, d_h from model.yaml). The estimate's own velocity carries the
noise of the thesis's process noise (sigma_w = 500 m s^-2.5: ~0.03 m/s in flight, i.e. ~3 ms on
an apex found from its zero crossing); the fit's velocity is good to ~1e-3 m/s after 20 ms of
flight. Apex: z'(tau) = 0 at tau_a = ln(1 + d_v v_z / g) / d_v; apex height and forward speed
come from the fit too.

Trust: the detector follows the robot only while the estimate is trusted (z' and y' standard
deviations below `track_velocity_std`). A restart of the filter (the robot moved by hand or
thrown by the simulator, a long gap) makes it untrusted: the phase becomes unknown and no
event is published until the robot is seen in flight again with a settled estimate (standard
deviations below `acquire_velocity_std`), clear of the ground by `acquire_clearance`, and moved
vertically by at least `acquire_velocity` x `acquire_window` within `acquire_window`, in the
direction of its z' (a robot held still never qualifies, and an apex is never guessed from a
robot that may already be past it). A flight fit that misses the estimated heights by more than
`flight_fit_max_residual` (RMS) is no ballistic flight: the track is lost.

Time: every guard and fit runs on the states' host stamps, which keep the microcontroller's
spacing (the estimator's clock mapping). Two states closer than zero or further apart than
`max_state_spacing` mean the stamps jumped. When their sequence numbers say the second is the
state one sample period after the first (the estimator publishes one per period), the mapping
stepped (the estimator re-anchored it: the simulated robot skipped time, the host clock stepped)
and the robot did not: the detector carries on in its own time (stamps minus the steps so far,
`stamp_steps` counts them) and publishes events on the present mapping. Otherwise samples are
missing as well and the track is lost rather than a flight being timed across the jump.

Hysteresis: a flight counts (touchdown and apex armed) once the toe has risen
`touchdown_arming_clearance` above the ground since the lift-off, a stance (lift-off armed) once
the lift-off guard has been positive; a flight or contact that never gets there loses the track
instead of producing events (a toe scuffing the ground, a touch of no duration).
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from enum import Enum

from hopper_ros.physics.params import ModelParams

from .config import DetectorSettings
from .samples import DetectedEvent, Estimate, EventType

COUNTER_NAMES = ("samples", "untrusted_samples", "track_lost", "track_acquired", "strides",
                 "apex", "pre_touchdown", "touchdown", "bottom", "liftoff", "stamp_steps")
FLIGHT_FIT_MIN_SAMPLES = 10   # with flight_fit_settle: no apex is timed within 15 ms of a lift-off
STEP_TOLERANCE = 1e-4         # [s] consecutive states whose spacing differs more from the last regular one: a step
_NEWTON_STEPS = 8


class Phase(Enum):
    UNKNOWN = "unknown"
    DESCENT = "descent"
    COMPRESSION = "compression"
    DECOMPRESSION = "decompression"
    ASCENT = "ascent"


def _phi(damping: float, tau: float) -> float:
    """(1 - e^{-d tau}) / d, tau as d -> 0."""
    if damping * tau < 1e-9:
        return tau
    return -math.expm1(-damping * tau) / damping


class FlightFit:
    """Running least-squares fit of the flight solution of (2.8) to positions y(t), z(t)."""

    def __init__(self, gravity: float, damping_vertical: float, damping_horizontal: float) -> None:
        self.gravity = gravity
        self.d_v = damping_vertical
        self.d_h = damping_horizontal
        self.reset(0.0)

    def reset(self, t_ref: float) -> None:
        self.t_ref = t_ref
        self.n = 0
        # sums for z: phi_v, phi_v^2, w, phi_v w; for y: phi_h, phi_h^2, y, phi_h y
        self._z = [0.0, 0.0, 0.0, 0.0]
        self._y = [0.0, 0.0, 0.0, 0.0]
        self._w_squares = 0.0          # sum of w^2, for the residual
        self._w_origin = math.nan      # w is taken relative to its first value (no cancellation)
        self.z0 = self.v_z = self.y0 = self.v_y = math.nan

    def _z_known(self, tau: float, phi: float) -> float:
        """The gravity part of z(tau): (g / d_v)(phi - tau), or -g tau^2 / 2 without damping."""
        if self.d_v * tau < 1e-9:
            return -0.5 * self.gravity * tau * tau
        return self.gravity / self.d_v * (phi - tau)

    def add(self, t: float, y: float, z: float) -> None:
        tau = t - self.t_ref
        phi_v, phi_h = _phi(self.d_v, tau), _phi(self.d_h, tau)
        w = z - self._z_known(tau, phi_v)
        if self.n == 0:
            self._w_origin = w
        w -= self._w_origin
        self._w_squares += w * w
        sz, sy = self._z, self._y
        sz[0] += phi_v
        sz[1] += phi_v * phi_v
        sz[2] += w
        sz[3] += phi_v * w
        sy[0] += phi_h
        sy[1] += phi_h * phi_h
        sy[2] += y
        sy[3] += phi_h * y
        self.n += 1
        if self.n >= 2:
            self.z0, self.v_z = self._solve(sz)
            self.z0 += self._w_origin
            self.y0, self.v_y = self._solve(sy)

    def _solve(self, sums: list[float]) -> tuple[float, float]:
        n = self.n
        s_x, s_xx, s_w, s_xw = sums
        determinant = n * s_xx - s_x * s_x
        if determinant <= 0.0:
            return math.nan, math.nan
        slope = (n * s_xw - s_x * s_w) / determinant
        return (s_w - slope * s_x) / n, slope

    @property
    def ready(self) -> bool:
        return self.n >= FLIGHT_FIT_MIN_SAMPLES and math.isfinite(self.v_z)

    @property
    def residual(self) -> float:
        """RMS distance of the fitted heights from the flight solution [m]: a real flight fits to
        the estimate's noise (~0.1 mm), a robot carried by hand does not."""
        if self.n < 3:
            return math.inf
        s_x, _, s_w, s_xw = self._z
        a = (s_w - self.v_z * s_x) / self.n
        squares = self._w_squares - a * s_w - self.v_z * s_xw
        return math.sqrt(max(squares, 0.0) / self.n)

    def z(self, t: float) -> float:
        tau = t - self.t_ref
        phi = _phi(self.d_v, tau)
        return self.z0 + self.v_z * phi + self._z_known(tau, phi)

    def z_dot(self, t: float) -> float:
        tau = t - self.t_ref
        if self.d_v * tau < 1e-9:
            return self.v_z - self.gravity * tau
        return (self.v_z + self.gravity / self.d_v) * math.exp(-self.d_v * tau) - self.gravity / self.d_v

    def y(self, t: float) -> float:
        return self.y0 + self.v_y * _phi(self.d_h, t - self.t_ref)

    def y_dot(self, t: float) -> float:
        return self.v_y * math.exp(-self.d_h * (t - self.t_ref))

    def apex_time(self) -> float:
        """z' = 0: tau = ln(1 + d_v v_z / g) / d_v (v_z / g without damping)."""
        if self.d_v == 0.0:
            return self.t_ref + self.v_z / self.gravity
        return self.t_ref + math.log1p(self.d_v * self.v_z / self.gravity) / self.d_v

    def time_at_height(self, height: float, t_after: float) -> float:
        """When the descending branch reaches `height`, given z(t_after) <= height (Newton from the right).

        z is concave (z'' = -g - d_v z' < 0 for z' > -g / d_v), so Newton iterates from a point past
        the crossing stay past it and converge monotonically; the result is never before the apex.
        """
        t, apex = t_after, self.apex_time()
        for _ in range(_NEWTON_STEPS):
            slope = self.z_dot(t)
            if slope >= 0.0:
                return apex
            step = (self.z(t) - height) / slope
            t -= step
            if abs(step) < 1e-7:
                break
        return max(t, apex)


def _lerp(a: float, b: float, fraction: float) -> float:
    return a + (b - a) * fraction


def _crossing(before: float, after: float) -> float:
    """Fraction of the way from `before` (> 0) to `after` (<= 0) where a linear guard is zero."""
    span = before - after
    return before / span if span > 0.0 else 1.0


class EventDetector:
    def __init__(self, params: ModelParams, settings: DetectorSettings) -> None:
        self.params = params
        self.settings = settings
        self.rest_length = params.rest_length
        self.stiffness = params.stiffness
        self.damping = params.damping
        self.fit = FlightFit(params.gravity, params.flight_damping_vertical, params.flight_damping_horizontal)
        self.counters = dict.fromkeys(COUNTER_NAMES, 0)
        self.phase = Phase.UNKNOWN
        self.stride_index = 0
        self.last_problem = ""
        self._previous: Estimate | None = None
        self._pre_touchdown_done = False
        self._toe_cleared = False       # flight: the toe has risen above touchdown_arming_clearance
        self._liftoff_armed = False     # stance: the lift-off guard has been positive
        self._flight_start = 0.0
        self._toe_y = math.nan
        self._bottom_candidate: tuple[float, Estimate] | None = None
        self._acquisition: deque[tuple[float, float]] = deque()   # (stamp, z) while unknown
        self._shift = 0.0               # [s] the stamps' mapping steps so far: internal time = stamp - shift
        self._spacing: float | None = None   # [s] the last regular spacing of two states (one sample period)
        self._run = 0                   # states since the sequence number last changed (predictions)
        self._last: tuple[int, float] | None = None   # (sequence, internal stamp) of the last state

    # ------------------------------------------------------------------ guards
    def toe_height(self, e: Estimate) -> float:
        """z - rho_0 cos(theta): the toe's height above the ground in flight."""
        return e.z - self.rest_length * math.cos(e.leg_angle)

    def leg_length(self, e: Estimate) -> tuple[float, float]:
        """rho and rho' with the toe where it touched down (stance)."""
        dy = e.y - self._toe_y
        rho = math.hypot(dy, e.z)
        return rho, (dy * e.y_dot + e.z * e.z_dot) / rho

    def liftoff_guard(self, e: Estimate) -> float:
        """min(F, k (rho_0 - rho)), F = k (rho_0 - rho) - d rho' (2.28): <= 0 at lift-off [N]."""
        rho, rho_dot = self.leg_length(e)
        spring = self.stiffness * (self.rest_length - rho)
        return min(spring - self.damping * rho_dot, spring)

    @staticmethod
    def _velocity_std_below(e: Estimate, limit: float) -> bool:
        return e.variances[3] <= limit * limit and e.variances[2] <= limit * limit

    def trusted(self, e: Estimate) -> bool:
        """Good enough to keep following the robot (y' and z' std below `track_velocity_std`)."""
        return self._velocity_std_below(e, self.settings.track_velocity_std)

    # ------------------------------------------------------------------ samples
    def update(self, e: Estimate) -> list[DetectedEvent]:
        """The events revealed by one estimate (usually none)."""
        self.counters["samples"] += 1
        if not self.trusted(e):
            self.counters["untrusted_samples"] += 1
            self._lose_track(f"estimate not trusted at sample {e.sequence}")
            self._previous = self._last = None
            return []
        last = self._last
        if last is not None:
            sequence, stamp = last
            step = (e.sequence - sequence) & 0xFFFFFFFF
            # one sample period after the last state: the estimator publishes one per period, a
            # prediction with the last sequence number used, a measurement with its own
            follows = step == 0 or step == self._run + 1
            self._run = self._run + 1 if step == 0 else 0
            spacing = e.stamp - self._shift - stamp
            regular = self._spacing is not None and abs(spacing - self._spacing) <= STEP_TOLERANCE
            if 0.0 < spacing <= self.settings.max_state_spacing and (regular or not follows or self._spacing is None):
                self._spacing = spacing
            elif follows and self._spacing is not None:
                # the stamps' mapping stepped (the estimator re-anchored it, the host clock stepped),
                # the robot did not: carry on in internal time
                self._shift += spacing - self._spacing
                self.counters["stamp_steps"] += 1
            else:
                self._lose_track(f"sample {e.sequence} is {spacing * 1e3:.3f} ms after the last one "
                                 f"(stamps jumped and samples are missing)")
                self._previous = None
        self._last = (e.sequence, e.stamp - self._shift)
        if self._shift:
            e = dataclasses.replace(e, stamp=e.stamp - self._shift)
        events = self._update(e)
        return [self._external(event) for event in events] if self._shift else events

    def _external(self, event: DetectedEvent) -> DetectedEvent:
        """An event of internal time on the stamps' present mapping."""
        shift = self._shift
        return dataclasses.replace(event, time=event.time + shift, detected_at=event.detected_at + shift,
                                   state=dataclasses.replace(event.state, stamp=event.state.stamp + shift))

    def _update(self, e: Estimate) -> list[DetectedEvent]:
        events: list[DetectedEvent] = []
        if e.outlier_rejected:
            # A measurement failed the gate: no guard is evaluated on it. Only an apex that the
            # flight fit (built from good samples) places before this sample is reported.
            if self.phase is Phase.ASCENT and self._previous is not None:
                self._apex(self._previous, e, events)
            return events
        previous = self._previous
        if self.phase is Phase.UNKNOWN or previous is None:
            if self.phase is not Phase.UNKNOWN:
                self._set_phase(Phase.UNKNOWN)
            self._acquire(e)
        elif self.phase is Phase.DESCENT:
            self._flight(previous, e, events)
        elif self.phase is Phase.ASCENT:
            self._flight(previous, e, events)
            if self.phase is Phase.ASCENT:
                self._apex(previous, e, events)
        else:
            self._stance(previous, e, events)
        self._previous = e
        return events

    def _set_phase(self, phase: Phase) -> None:
        self.phase = phase
        self._bottom_candidate = None
        self._acquisition.clear()

    def _lose_track(self, why: str) -> None:
        if self.phase is not Phase.UNKNOWN:
            self.counters["track_lost"] += 1
            self.last_problem = f"{why}: phase unknown until the robot is seen in flight"
            self._set_phase(Phase.UNKNOWN)

    def _acquire(self, e: Estimate) -> None:
        """Follow the robot again once it is clearly flying: settled estimate, toe clear of the
        ground, and moved vertically by at least acquire_velocity x acquire_window in the last
        acquire_window (the estimate's z' alone is too noisy: a robot held still would pass)."""
        s = self.settings
        window = self._acquisition
        clearance = self.toe_height(e)
        if clearance <= s.acquire_clearance or not self._velocity_std_below(e, s.acquire_velocity_std):
            window.clear()
            return
        window.append((e.stamp, e.z))
        while len(window) > 1 and window[1][0] <= e.stamp - s.acquire_window:
            window.popleft()
        start_time, start_z = window[0]
        rise = e.z - start_z
        if (e.stamp - start_time < s.acquire_window - 1e-9 or abs(rise) < s.acquire_velocity * s.acquire_window
                or abs(e.z_dot) <= s.acquire_velocity or (rise > 0.0) != (e.z_dot > 0.0)):
            return
        window.clear()
        self.counters["track_acquired"] += 1
        self._start_flight(e.stamp)
        self._toe_cleared = True
        if e.z_dot > 0.0:
            self._set_phase(Phase.ASCENT)
        else:
            self._set_phase(Phase.DESCENT)
            self._pre_touchdown_done = clearance <= s.pre_touchdown_height
        self._fit(e)

    def _start_flight(self, t: float) -> None:
        self._flight_start = t
        self._toe_cleared = False
        self._pre_touchdown_done = False
        self.fit.reset(t)

    def _fit(self, e: Estimate) -> None:
        if e.measurement_used and e.stamp - self._flight_start >= self.settings.flight_fit_settle:
            self.fit.add(e.stamp, e.y, e.z)

    # ------------------------------------------------------------------ phases
    def _flight(self, previous: Estimate, e: Estimate, events: list) -> None:
        """Ascent and descent: the flight fit, pre-touchdown (descent only) and touchdown."""
        self._fit(e)
        s = self.settings
        if self.fit.n >= 2 * FLIGHT_FIT_MIN_SAMPLES and self.fit.residual > s.flight_fit_max_residual:
            self._lose_track(f"not a ballistic flight at sample {e.sequence} (fit residual "
                             f"{self.fit.residual * 1e3:.2f} mm)")
            return
        clearance, clearance_before = self.toe_height(e), self.toe_height(previous)
        if clearance > s.touchdown_arming_clearance:
            self._toe_cleared = True
        if self.phase is Phase.DESCENT and not self._pre_touchdown_done:
            self._pre_touchdown(previous, e, clearance, clearance_before, events)
        if clearance > 0.0:
            return
        if not self._toe_cleared:
            if self.phase is Phase.DESCENT:   # the toe never cleared the ground: no flight to time
                self._lose_track(f"flight too low at sample {e.sequence} (toe below "
                                 f"{s.touchdown_arming_clearance * 1e3:.1f} mm)")
            return
        fraction = _crossing(clearance_before, clearance) if clearance_before > 0.0 else 1.0
        event = self._event(EventType.TOUCHDOWN, _lerp(previous.stamp, e.stamp, fraction), previous, e)
        self._toe_y = event.state.y + self.rest_length * math.sin(event.state.leg_angle)
        events.append(event)
        self._set_phase(Phase.COMPRESSION)
        self._liftoff_armed = False

    def _pre_touchdown(self, previous: Estimate, e: Estimate, clearance: float, clearance_before: float,
                       events: list) -> None:
        s, fit = self.settings, self.fit
        event_time = None
        if fit.ready:   # ballistic prediction: the crossing at most `pre_touchdown_lead` ahead
            target = s.pre_touchdown_height + self.rest_length * math.cos(e.leg_angle)
            horizon = e.stamp + s.pre_touchdown_lead
            if fit.z(horizon) <= target:
                event_time = fit.time_at_height(target, horizon)
        elif clearance <= s.pre_touchdown_height:   # no flight fit yet: between the samples
            fraction = _crossing(clearance_before - s.pre_touchdown_height, clearance - s.pre_touchdown_height)
            event_time = _lerp(previous.stamp, e.stamp, fraction)
        if event_time is not None:
            self._pre_touchdown_done = True
            events.append(self._event(EventType.PRE_TOUCHDOWN, event_time, previous, e, use_fit=fit.ready))

    def _stance(self, previous: Estimate, e: Estimate, events: list) -> None:
        if self.phase is Phase.COMPRESSION:
            if previous.z_dot < 0.0 <= e.z_dot:
                fraction = _crossing(-previous.z_dot, -e.z_dot)
                self._bottom_candidate = (_lerp(previous.stamp, e.stamp, fraction), previous)
            elif e.z_dot < 0.0:
                self._bottom_candidate = None
            candidate = self._bottom_candidate
            if candidate is not None and e.z_dot >= self.settings.bottom_hysteresis:
                event_time, before = candidate
                events.append(self._event(EventType.BOTTOM, event_time, before, e))
                self._set_phase(Phase.DECOMPRESSION)
        guard = self.liftoff_guard(e)
        if guard > 0.0:
            self._liftoff_armed = True
            return
        if not self._liftoff_armed:
            if self.toe_height(e) > self.settings.touchdown_arming_clearance:   # a touch too short to time
                self._lose_track(f"contact too short at sample {e.sequence}")
            return
        guard_before = self.liftoff_guard(previous)
        fraction = _crossing(guard_before, guard) if guard_before > 0.0 else 1.0
        event_time = _lerp(previous.stamp, e.stamp, fraction)
        events.append(self._event(EventType.LIFTOFF, event_time, previous, e))
        self._set_phase(Phase.ASCENT)
        self._start_flight(event_time)

    def _apex(self, previous: Estimate, e: Estimate, events: list) -> None:
        """z' = 0 on the flight fit, once the toe has cleared the ground (a flight, not a scuff)."""
        fit = self.fit
        if fit.ready and self._toe_cleared and fit.z_dot(e.stamp) <= 0.0:
            self.stride_index += 1
            self.counters["strides"] += 1
            events.append(self._event(EventType.APEX, fit.apex_time(), previous, e, use_fit=True))
            self._set_phase(Phase.DESCENT)
        elif e.z_dot < -self.settings.acquire_velocity and not (fit.ready and self._toe_cleared):
            self._lose_track(f"apex not timed (flight too short or too low) before sample {e.sequence}")

    # ------------------------------------------------------------------ events
    def _event(self, kind: EventType, event_time: float, previous: Estimate, e: Estimate,
               use_fit: bool = False) -> DetectedEvent:
        """The event with the state at its time: linear between the samples, flight fit for y, z, y', z'."""
        span = e.stamp - previous.stamp
        fraction = min(1.0, max(0.0, (event_time - previous.stamp) / span)) if span > 0.0 else 1.0
        values = {name: _lerp(getattr(previous, name), getattr(e, name), fraction)
                  for name in ("y", "z", "y_dot", "z_dot", "y_ddot", "z_ddot", "leg_angle", "leg_angle_rate")}
        if use_fit:
            fit = self.fit
            values.update(y=fit.y(event_time), z=fit.z(event_time), y_dot=fit.y_dot(event_time),
                          z_dot=fit.z_dot(event_time))
        state = dataclasses.replace(e, stamp=event_time, mcu_time=e.mcu_time + (event_time - e.stamp), **values)
        self.counters[kind.name.lower()] += 1
        return DetectedEvent(kind, event_time, self.stride_index, state, e.stamp)
