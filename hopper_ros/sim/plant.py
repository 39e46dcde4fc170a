"""The simulated robot's body and leg: the laws of `hopper_ros.physics.laws`, integrated event to event.

State (SI, model coordinates: y forward, z body height above the model's z = 0; the running
surface is at z = `ground_height`, 0 unless that effect is on): body (y, z, y', z'), leg angle
and rate (theta, theta'), toe depth into a compliant ground, the torque the hip applies (the
actuator's first-order lag state), the toe's slide since touchdown (a ground of finite friction).

Every force law, reset map and the actuator come from `laws`, parameterised by one
`laws.Coefficients` of floats (`SimConfig.coefficients()`: the physics plus the enabled
effects of `hopper_ros.physics.effects`), so the plant is the same model as the vectorised
`physics.lanes` and the exact model (tested):
- flight: the body by `laws.flight_acceleration`; the leg is a rigid rotor driven by the hip,
  J theta'' = tau - b theta' (the motor's inertia and friction, config/hardware.yaml);
- stance: `laws.stance_forces` about the toe (the massless leg follows the body; compliant
  ground, hip friction and every stance effect inside);
- the actuator: the commanded hip torque (the robot's `torque(t)`, delayed there by the
  actuation delay) -> `laws.actuator_torque` (gain, saturation, and in stance the offset) ->
  in stance the first-order lag `torque_lag` as a state (in flight the drive's own position
  loop holds the leg, which a lag of milliseconds would throw into oscillation; `physics.lanes`
  likewise starts the actuator at touchdown);
- touchdown when the toe at rest length meets the ground (`laws.touchdown_height`), velocity
  reset `laws.touchdown_velocity`; lift-off when the leg force vanishes (2.28) or the leg is
  fully extended, reset `laws.liftoff_velocity` (2.12).
Integration: RK4, every event located inside the step by regula falsi, so with no effect on this
reproduces `physics.exact` (tested to 1e-6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

from hopper_ros.physics import laws
from hopper_ros.physics.exact import COLLAPSE_FRACTION, MAX_LEG_ANGLE, Phase
from hopper_ros.physics.flight import flight_state

from .config import SimConfig

TorqueFunction = Callable[[float], float]   # the commanded hip torque [N m] at time t
EVENT_TIME_TOLERANCE = 1e-10  # [s]
_ROOT_ITERATIONS = 60

# state vector layout
Y, Z, YDOT, ZDOT, THETA, THETA_DOT, DEPTH, TORQUE, SLIP = range(9)


@dataclass(frozen=True)
class BodyMotion:
    """The true motion at one instant: the body's position and velocity, the leg angle."""

    t: float                 # [s]
    y: float                 # [m] forward
    z: float                 # [m] height above the running surface
    ydot: float              # [m/s]
    zdot: float              # [m/s]
    leg_angle: float         # [rad]


@dataclass(frozen=True)
class PlantEvent(BodyMotion):
    """An event of the true motion: kind is "apex", "touchdown", "bottom", "liftoff" or "fall"."""

    kind: str = field(kw_only=True)


class Plant:
    """Integrates the true motion one period at a time; events located inside the step."""

    def __init__(self, config: SimConfig, leg_inertia: float, leg_friction: float,
                 coefficients: laws.Coefficients | None = None) -> None:
        self.config = config
        self.coefficients = config.coefficients() if coefficients is None else coefficients
        c = self.coefficients
        self._stance_c = c
        self._flight_c = c.replace(torque_offset=0.0)     # the offset acts in stance (effects.py)
        self.rest_length = float(c.rest_length)
        self.ground_height = float(c.ground_height)
        self.compliant = float(c.ground_stiffness) > 0.0
        self.lag = float(c.torque_lag)
        self.leg_inertia = leg_inertia
        self.leg_friction = leg_friction
        self._actuator_key, self._actuator_target = None, 0.0
        self.h = config.period / config.substeps
        self.t = 0.0
        self.state = [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        self.in_contact = False
        self.fallen = False
        self.held = False            # held by hand at the throw's pose until released
        self.toe_y = math.nan
        self.touchdown_time = math.nan
        self.touchdown_angle = math.nan
        self.phase = Phase.DESCENT
        self.events: list[PlantEvent] = []
        self.torque_now = 0.0        # [N m] the torque the hip applies (after the actuator)
        self.command_now = 0.0       # [N m] the commanded hip torque (after the actuation delay)

    @property
    def gravity(self) -> float:
        return float(self.coefficients.gravity)

    # ------------------------------------------------------------------ set-up
    def throw(self, apex_height: float, forward_speed: float, leg_angle: float, y: float = 0.0, t: float = 0.0,
              lead_time: float = 0.0, hold: bool = False) -> None:
        """Throw the robot so that it reaches this apex (section 4.1's throw), the leg at `leg_angle`.

        With `lead_time` the robot starts that long before the apex, still rising on the flight
        closed form (2.13)-(2.16) run backwards, so that the apex is a natural one the sensing
        sees; else it starts at the apex. With `hold` it is held there until `release()`.
        """
        c = self.coefficients
        if apex_height - laws.touchdown_height(c, leg_angle) <= 0.0:
            raise ValueError(f"apex height {apex_height} m puts the toe ({leg_angle} rad) into the ground")
        y0, z0, ydot0, zdot0 = (float(v) for v in flight_state(-lead_time, y, apex_height, forward_speed, 0.0,
                                                               float(c.gravity), float(c.flight_damping_y),
                                                               float(c.flight_damping_z)))
        if z0 - laws.touchdown_height(c, leg_angle) <= 0.0:
            raise ValueError(f"a lead time of {lead_time} s before apex {apex_height} m puts the toe into the ground")
        self.t = t
        self.state = [y0, z0, ydot0, zdot0, leg_angle, 0.0, 0.0, 0.0, 0.0]
        self.in_contact, self.fallen, self.held = False, False, hold
        self.toe_y, self.touchdown_time, self.touchdown_angle = math.nan, math.nan, math.nan
        if lead_time > 0.0:
            self.phase = Phase.ASCENT
            self.events = []
        else:
            self.phase = Phase.DESCENT
            self.events = [self._event("apex", t, self.state)]

    def release(self) -> None:
        """Let go of a robot held by `throw(..., hold=True)`."""
        self.held = False

    # ------------------------------------------------------------------ dynamics
    def _actuator(self, c: laws.Coefficients, command: float, s: list, lagged: bool) -> tuple[float, float]:
        """(torque the hip applies, the lag state's rate) for a commanded torque: `laws.actuator_torque`,
        through the first-order lag when `lagged` (the applied torque is then the state)."""
        key = (c is self._stance_c, command)
        if key != self._actuator_key:       # the command holds over a period in flight: evaluate it once
            self._actuator_key, self._actuator_target = key, float(laws.actuator_torque(c, command))
        target = self._actuator_target
        return (s[TORQUE], (target - s[TORQUE]) / self.lag) if lagged else (target, 0.0)

    def _rotor_rhs(self, t: float, s: list, torque: TorqueFunction, body: list) -> list:
        """The leg in flight (or held, or fallen): a rotor the hip drives, J theta'' = tau - b theta'. The
        actuator acts here without its stance-only parts (offset, lag) that the drive's position loop sees
        through (as `physics.lanes`: the actuator's torque starts at touchdown)."""
        tau, _ = self._actuator(self._flight_c, torque(t), s, False)
        theta_ddot = (tau - self.leg_friction * s[THETA_DOT]) / self.leg_inertia
        return body + [s[THETA_DOT], theta_ddot, 0.0, 0.0, 0.0]

    def _flight_rhs(self, t: float, s: list, torque: TorqueFunction) -> list:
        ydd, zdd = laws.flight_acceleration(self._flight_c, s[Y], s[Z], s[YDOT], s[ZDOT])
        return self._rotor_rhs(t, s, torque, [s[YDOT], s[ZDOT], float(ydd), float(zdd)])

    def _fallen_rhs(self, t: float, s: list, torque: TorqueFunction) -> list:
        return self._rotor_rhs(t, s, torque, [0.0, 0.0, 0.0, 0.0])

    def _stance(self, t: float, s: list, torque: TorqueFunction) -> tuple[laws.StanceForces, float]:
        """`laws.stance_forces` at this state, and the actuator lag's rate."""
        command = torque(t)
        tau, lag_rate = self._actuator(self._stance_c, command, s, self.lag > 0.0)
        forces = laws.stance_forces(self._stance_c, s[Y], s[Z], s[YDOT], s[ZDOT], s[DEPTH], self.toe_y + s[SLIP], tau,
                                    command=command, theta_td=self.touchdown_angle,
                                    since_touchdown=t - self.touchdown_time, compliant=self.compliant)
        return forces, lag_rate

    def _stance_rhs(self, t: float, s: list, torque: TorqueFunction) -> list:
        f, lag_rate = self._stance(t, s, torque)
        return [s[YDOT], s[ZDOT], float(f.ydd), float(f.zdd), 0.0, 0.0, float(f.depth_rate), lag_rate,
                float(f.toe_rate)]

    def _rk4(self, t: float, s: list, h: float, rhs, torque: TorqueFunction) -> list:
        k1 = rhs(t, s, torque)
        s2 = [a + 0.5 * h * b for a, b in zip(s, k1)]
        k2 = rhs(t + 0.5 * h, s2, torque)
        s3 = [a + 0.5 * h * b for a, b in zip(s, k2)]
        k3 = rhs(t + 0.5 * h, s3, torque)
        s4 = [a + h * b for a, b in zip(s, k3)]
        k4 = rhs(t + h, s4, torque)
        return [a + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4)]

    # ------------------------------------------------------------------ guards
    def _toe_height(self, t: float, s: list, torque) -> float:
        """Height of the toe (at rest length) above the ground: touchdown at 0."""
        return s[Z] - float(laws.touchdown_height(self._stance_c, s[THETA]))

    def _zdot(self, t: float, s: list, torque) -> float:
        return s[ZDOT]

    def _leg_force(self, t: float, s: list, torque) -> float:
        return float(self._stance(t, s, torque)[0].force)

    def _leg_vector(self, s: list) -> tuple[float, float]:
        """From the toe to the body: (y - y_toe, height above the toe)."""
        return s[Y] - self.toe_y - s[SLIP], s[Z] - self.ground_height + s[DEPTH]

    def _extension(self, t: float, s: list, torque) -> float:
        dy, hz = self._leg_vector(s)
        return self.rest_length - math.sqrt(dy * dy + hz * hz)

    def _collapse(self, t: float, s: list, torque) -> float:
        dy, hz = self._leg_vector(s)
        rho = math.sqrt(dy * dy + hz * hz)
        return min(rho - COLLAPSE_FRACTION * self.rest_length, MAX_LEG_ANGLE - abs(math.atan2(-dy, hz)))

    # ------------------------------------------------------------------ stepping
    def advance(self, duration: float, torque: TorqueFunction) -> list[PlantEvent]:
        """Integrate `duration` seconds with hip torque `torque(t)` [N m]; returns the new events."""
        start = len(self.events)
        end = self.t + duration
        while self.t < end - 1e-12:
            self._substep(min(self.h, end - self.t), torque)
        self.command_now = torque(self.t)
        self.torque_now = self.applied_torque(torque)
        return self.events[start:]

    def _substep(self, h: float, torque: TorqueFunction) -> None:
        t0, s0 = self.t, self.state
        if self.fallen or self.held:  # the body lies on the boom's stop or is held; the leg still swings
            self.t, self.state = t0 + h, self._rk4(t0, s0, h, self._fallen_rhs, torque)
            return
        if self.in_contact:
            rhs = self._stance_rhs
            guards = [(self._leg_force, "liftoff"), (self._extension, "liftoff"), (self._collapse, "fall")]
            if self.phase == Phase.COMPRESSION:
                guards.append((lambda t, s, f: -s[ZDOT], "bottom"))
        else:
            rhs = self._flight_rhs
            guards = [(self._toe_height, "touchdown")]
            if self.phase == Phase.ASCENT:
                guards.append((self._zdot, "apex"))
        s1 = self._rk4(t0, s0, h, rhs, torque)
        first = None
        for guard, kind in guards:
            if guard(t0 + h, s1, torque) <= 0.0 < guard(t0, s0, torque):
                dt = self._locate(guard, t0, s0, h, rhs, torque)
                if first is None or dt < first[0]:
                    first = (dt, kind)
        if first is None:
            self.t, self.state = t0 + h, s1
            if self.in_contact:
                self._stance_angles()
            return
        dt, kind = first
        self.t, self.state = t0 + dt, self._rk4(t0, s0, dt, rhs, torque) if dt > 0.0 else list(s0)
        if self.in_contact:
            self._stance_angles()
        self._switch(kind, torque)
        if h - dt > 1e-12:
            self._substep(h - dt, torque)

    def _locate(self, guard, t0: float, s0: list, h: float, rhs, torque) -> float:
        """Time into the step where `guard` reaches zero (Illinois regula falsi on the RK4 step)."""
        a, b = 0.0, h
        fa, fb = guard(t0, s0, torque), guard(t0 + h, self._rk4(t0, s0, h, rhs, torque), torque)
        side = 0
        for _ in range(_ROOT_ITERATIONS):
            c = (a * fb - b * fa) / (fb - fa) if fb != fa else 0.5 * (a + b)
            fc = guard(t0 + c, self._rk4(t0, s0, c, rhs, torque), torque)
            if fc > 0.0:
                a, fa = c, fc
                if side == -1:
                    fb *= 0.5
                side = -1
            else:
                b, fb = c, fc
                if side == 1:
                    fa *= 0.5
                side = 1
            if b - a < EVENT_TIME_TOLERANCE:
                break
        return b

    def _stance_angles(self) -> None:
        s = self.state
        dy, hz = self._leg_vector(s)
        rho2 = dy * dy + hz * hz
        s[THETA] = math.atan2(-dy, hz)
        # theta' = ((y_toe - y)' hz - (-dy)(z + depth)') / rho^2 with the toe's depth rate ignored
        s[THETA_DOT] = (-s[YDOT] * hz + dy * s[ZDOT]) / rho2

    def _switch(self, kind: str, torque: TorqueFunction) -> None:
        s = self.state
        c = self._stance_c
        if kind == "touchdown":
            s[TORQUE] = self._actuator(self._flight_c, torque(self.t), s, False)[0]   # the lag starts from here
            self.in_contact = True
            self.toe_y = s[Y] + self.rest_length * math.sin(s[THETA])
            self.touchdown_time = self.t
            self.touchdown_angle = s[THETA]
            s[DEPTH] = s[SLIP] = 0.0
            ydot, zdot = laws.touchdown_velocity(c, s[THETA], s[YDOT], s[ZDOT])
            s[YDOT], s[ZDOT] = float(ydot), float(zdot)
            self.events.append(self._event("touchdown", self.t, s))
            self.phase = Phase.COMPRESSION
            self._stance_angles()
            if self._leg_force(self.t, s, torque) <= 0.0:   # landing with the leg extending: the toe scuffs off
                self._switch("liftoff", torque)
        elif kind == "bottom":
            self.events.append(self._event("bottom", self.t, s))
            self.phase = Phase.DECOMPRESSION
        elif kind == "liftoff":
            self.events.append(self._event("liftoff", self.t, s))
            self.in_contact = False
            s[DEPTH] = 0.0
            ydot, zdot = laws.liftoff_velocity(c, s[THETA], s[YDOT], s[ZDOT])           # (2.12)
            s[YDOT], s[ZDOT] = float(ydot), float(zdot)
            self.phase = Phase.ASCENT
            if s[ZDOT] <= 0.0:
                self._fall()
        elif kind == "apex":
            self.events.append(self._event("apex", self.t, s))
            self.phase = Phase.DESCENT
        elif kind == "fall":
            self._fall()

    def _fall(self) -> None:
        """The stride failed: the robot drops onto the boom's stop and stays there."""
        self.fallen = True
        s = self.state
        s[YDOT] = s[ZDOT] = s[THETA_DOT] = 0.0
        self.in_contact = False
        self.events.append(self._event("fall", self.t, s))

    def _event(self, kind: str, t: float, s: list) -> PlantEvent:
        return PlantEvent(t, s[Y], s[Z], s[YDOT], s[ZDOT], s[THETA], kind=kind)

    # ------------------------------------------------------------------ outputs
    def applied_torque(self, torque: TorqueFunction) -> float:
        """The torque the hip applies now for the commanded `torque(t)` (the actuator's output)."""
        if self.in_contact:
            return self._actuator(self._stance_c, torque(self.t), self.state, self.lag > 0.0)[0]
        return self._actuator(self._flight_c, torque(self.t), self.state, False)[0]

    def ground_reaction_force(self) -> tuple[float, float]:
        """Force of the ground on the robot (forward, vertical) [N]; zero in flight."""
        if not self.in_contact:
            return 0.0, 0.0
        s, applied = self.state, self.torque_now
        f = laws.stance_forces(self._stance_c, s[Y], s[Z], s[YDOT], s[ZDOT], s[DEPTH], self.toe_y + s[SLIP], applied,
                               command=self.command_now, theta_td=self.touchdown_angle,
                               since_touchdown=self.t - self.touchdown_time, compliant=self.compliant)
        force, across = float(f.force), float(f.torque / f.rho)
        sin, cos = float(f.sin), float(f.cos)
        return -force * sin - across * cos, force * cos - across * sin

    @property
    def toe_position(self) -> float:
        """Forward position of the toe [m] (where it touched down, plus its slide); nan in flight."""
        return self.toe_y + self.state[SLIP] if self.in_contact else math.nan

    @property
    def leg_angle(self) -> float:
        return self.state[THETA]

    @property
    def leg_rate(self) -> float:
        return self.state[THETA_DOT]

    @property
    def toe_height(self) -> float:
        return self._toe_height(self.t, self.state, None)
