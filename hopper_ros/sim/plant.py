"""The simulated robot's body and leg: the extended TD-SLIP dynamics plus switchable effects.

State (SI, model coordinates: y forward, z body height above the running surface):
body (y, z, y', z'), leg angle and rate (theta, theta'), toe depth into a compliant ground.

Flight (2.8), with the leg a rigid rotor driven by the hip torque tau:

    y'' = -d_h y',   z'' = -g - d_v z',   J theta'' = tau - b theta'

Stance, in Cartesian form about the toe at (y_toe, -depth); with the rigid ground it is (2.9):

    e_rho = (-sin theta, cos theta),  e_theta = (-cos theta, -sin theta)
    F = k (rho_0 - rho) - d rho' - F_c tanh(rho' / v_c)           (leg force, Coulomb slide friction)
    m y'' = F e_rho,y + (tau / rho) e_theta,y
    m z'' = F e_rho,z + (tau / rho) e_theta,z - m g

The massless leg passes F e_rho + (tau/rho) e_theta to the ground, which is the ground reaction
force. A compliant ground holds the toe with k_g depth + d_g depth' = F_z (massless toe).
Touchdown: toe reaches the ground, z - depth - rho_0 cos theta = 0. Lift-off: F = 0 (2.28) or
full extension, then the collision (2.12). Every event is located inside the RK4 step by
regula falsi, so with the extra effects off this reproduces `physics.exact` (tested).
Equations of every effect: docs/sim.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from hopper_ros.physics.exact import COLLAPSE_FRACTION, MAX_LEG_ANGLE, Phase
from hopper_ros.physics.flight import flight_state

from .config import SimConfig

TorqueFunction = Callable[[float], float]
EVENT_TIME_TOLERANCE = 1e-10  # [s]
_ROOT_ITERATIONS = 60

# state vector layout
Y, Z, YDOT, ZDOT, THETA, THETA_DOT, DEPTH = range(7)


@dataclass(frozen=True)
class PlantEvent:
    """An event of the true motion: kind is "apex", "touchdown", "bottom", "liftoff" or "fall"."""

    kind: str
    t: float
    y: float
    z: float
    ydot: float
    zdot: float
    leg_angle: float


class Plant:
    """Integrates the true motion one period at a time; events located inside the step."""

    def __init__(self, config: SimConfig, leg_inertia: float, leg_friction: float) -> None:
        self.config = config
        physics = config.physics
        self.mass = physics["body_mass"]
        self.stiffness = physics["stiffness"]
        self.damping = physics["damping"]
        self.rest_length = physics["rest_length"]
        self.gravity = config.gravity
        self.damping_h = config.value("flight_damping", "horizontal")
        self.damping_v = config.value("flight_damping", "vertical")
        toe_mass = config.value("liftoff_collision", "toe_mass")
        self.collision_factor = self.mass / (self.mass + toe_mass)                      # (2.12)
        self.friction = config.value("leg_friction", "force")
        self.friction_speed = config.effects["leg_friction"]["smoothing_speed"] or 1e-3
        self.compliant = config.enabled("ground_compliance")
        self.ground_stiffness = config.value("ground_compliance", "stiffness")
        self.ground_damping = config.value("ground_compliance", "damping")
        self.impact_loss = config.value("touchdown_impact", "tangential_loss")
        self.leg_inertia = leg_inertia
        self.leg_friction = leg_friction
        self.h = config.period / config.substeps
        self.t = 0.0
        self.state = [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        self.in_contact = False
        self.fallen = False
        self.held = False            # held by hand at the throw's pose until released
        self.toe_y = math.nan
        self.touchdown_time = math.nan
        self.phase = Phase.DESCENT
        self.events: list[PlantEvent] = []
        self.torque_now = 0.0

    # ------------------------------------------------------------------ set-up
    def throw(self, apex_height: float, forward_speed: float, leg_angle: float, y: float = 0.0, t: float = 0.0,
              lead_time: float = 0.0, hold: bool = False) -> None:
        """Throw the robot so that it reaches this apex (section 4.1's throw), the leg at `leg_angle`.

        With `lead_time` the robot starts that long before the apex, still rising on the flight
        closed form (2.13)-(2.16) run backwards, so that the apex is a natural one the sensing
        sees; else it starts at the apex. With `hold` it is held there until `release()`.
        """
        if apex_height - self.rest_length * math.cos(leg_angle) <= 0.0:
            raise ValueError(f"apex height {apex_height} m puts the toe ({leg_angle} rad) into the ground")
        y0, z0, ydot0, zdot0 = (float(v) for v in flight_state(-lead_time, y, apex_height, forward_speed, 0.0,
                                                               self.gravity, self.damping_h, self.damping_v))
        if z0 - self.rest_length * math.cos(leg_angle) <= 0.0:
            raise ValueError(f"a lead time of {lead_time} s before apex {apex_height} m puts the toe into the ground")
        self.t = t
        self.state = [y0, z0, ydot0, zdot0, leg_angle, 0.0, 0.0]
        self.in_contact, self.fallen, self.held = False, False, hold
        self.toe_y, self.touchdown_time = math.nan, math.nan
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
    def _flight_rhs(self, t: float, s: list, torque: TorqueFunction) -> list:
        tau = torque(t)
        return [s[YDOT], s[ZDOT], -self.damping_h * s[YDOT], -self.gravity - self.damping_v * s[ZDOT],
                s[THETA_DOT], (tau - self.leg_friction * s[THETA_DOT]) / self.leg_inertia, 0.0]

    def _fallen_rhs(self, t: float, s: list, torque: TorqueFunction) -> list:
        tau = torque(t)
        return [0.0, 0.0, 0.0, 0.0, s[THETA_DOT], (tau - self.leg_friction * s[THETA_DOT]) / self.leg_inertia, 0.0]

    def _leg(self, t: float, s: list, torque: TorqueFunction):
        """Stance kinematics and forces: (sin, cos, rho, rho', F, tau, depth')."""
        dy = s[Y] - self.toe_y
        hz = s[Z] + s[DEPTH]
        rho = math.sqrt(dy * dy + hz * hz)
        sin, cos = -dy / rho, hz / rho
        tau = torque(t)
        approach = -sin * s[YDOT] + cos * s[ZDOT]               # rho' with the toe at rest
        friction = self.friction * math.tanh(approach / self.friction_speed) if self.friction else 0.0
        spring = self.stiffness * (self.rest_length - rho) - friction
        depth_rate = 0.0
        if self.compliant:  # massless toe: k_g depth + d_g depth' = F cos - (tau/rho) sin, depth' enters rho'
            push = (spring - self.damping * approach) * cos - tau / rho * sin
            depth_rate = (push - self.ground_stiffness * s[DEPTH]) / (self.ground_damping + self.damping * cos * cos)
        rho_dot = approach + cos * depth_rate
        force = spring - self.damping * rho_dot
        return sin, cos, rho, rho_dot, force, tau, depth_rate

    def _stance_rhs(self, t: float, s: list, torque: TorqueFunction) -> list:
        sin, cos, rho, _, force, tau, depth_rate = self._leg(t, s, torque)
        across = tau / rho
        m = self.mass
        return [s[YDOT], s[ZDOT], (-force * sin - across * cos) / m, (force * cos - across * sin) / m - self.gravity,
                0.0, 0.0, depth_rate]

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
        return s[Z] - self.rest_length * math.cos(s[THETA])

    def _zdot(self, t: float, s: list, torque) -> float:
        return s[ZDOT]

    def _leg_force(self, t: float, s: list, torque) -> float:
        return self._leg(t, s, torque)[4]

    def _extension(self, t: float, s: list, torque) -> float:
        dy, hz = s[Y] - self.toe_y, s[Z] + s[DEPTH]
        return self.rest_length - math.sqrt(dy * dy + hz * hz)

    def _collapse(self, t: float, s: list, torque) -> float:
        dy, hz = s[Y] - self.toe_y, s[Z] + s[DEPTH]
        rho = math.sqrt(dy * dy + hz * hz)
        return min(rho - COLLAPSE_FRACTION * self.rest_length, MAX_LEG_ANGLE - abs(math.atan2(-dy, hz)))

    # ------------------------------------------------------------------ stepping
    def advance(self, duration: float, torque: TorqueFunction) -> list[PlantEvent]:
        """Integrate `duration` seconds with hip torque `torque(t)` [N m]; returns the new events."""
        start = len(self.events)
        end = self.t + duration
        while self.t < end - 1e-12:
            self._substep(min(self.h, end - self.t), torque)
        self.torque_now = torque(self.t)
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
        dy, hz = s[Y] - self.toe_y, s[Z] + s[DEPTH]
        rho2 = dy * dy + hz * hz
        s[THETA] = math.atan2(-dy, hz)
        # theta' = ((y_toe - y)' hz - (-dy)(z + depth)') / rho^2 with the toe's depth rate ignored
        s[THETA_DOT] = (-s[YDOT] * hz + dy * s[ZDOT]) / rho2

    def _switch(self, kind: str, torque: TorqueFunction) -> None:
        s = self.state
        if kind == "touchdown":
            self.in_contact = True
            self.toe_y = s[Y] + self.rest_length * math.sin(s[THETA])
            self.touchdown_time = self.t
            s[DEPTH] = 0.0
            if self.impact_loss:  # the velocity across the leg loses a share (rotor and leg inertia)
                sin, cos = math.sin(s[THETA]), math.cos(s[THETA])
                across = -cos * s[YDOT] - sin * s[ZDOT]
                s[YDOT] += self.impact_loss * across * cos
                s[ZDOT] += self.impact_loss * across * sin
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
            s[YDOT] *= self.collision_factor                                            # (2.12)
            s[ZDOT] *= self.collision_factor
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
        return PlantEvent(kind, t, s[Y], s[Z], s[YDOT], s[ZDOT], s[THETA])

    # ------------------------------------------------------------------ outputs
    def ground_reaction_force(self) -> tuple[float, float]:
        """Force of the ground on the robot (forward, vertical) [N]; zero in flight."""
        if not self.in_contact:
            return 0.0, 0.0
        sin, cos, rho, _, force, tau, _ = self._leg(self.t, self.state, lambda t: self.torque_now)
        across = tau / rho
        return -force * sin - across * cos, force * cos - across * sin

    @property
    def leg_angle(self) -> float:
        return self.state[THETA]

    @property
    def leg_rate(self) -> float:
        return self.state[THETA_DOT]

    @property
    def toe_height(self) -> float:
        return self._toe_height(self.t, self.state, None)
