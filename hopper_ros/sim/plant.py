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
reproduces `physics.exact` (tested to 1e-6). A step's arithmetic (the rates, the RK4 step, the guards,
the force plate's force) is one kernel written like the laws, for floats: numba compiles it with the
laws (`kernel`, cached on disk), and where numba is missing it runs in Python; the two give the same
strides to rounding (tested). The hip's command, a Python callable, is read at each step's stage times.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np

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


# ---------------------------------------------------------------------------- the step's kernel
# A step's arithmetic, written once, like the laws, for Python floats and for numba (`Kernel`): the state is a
# tuple of the 9 floats above; `cs` holds the coefficients of flight (cs[FLIGHT], the torque offset off) and of
# stance (cs[STANCE]): `laws.Coefficients`, or numba records (`physics.compiled.records`); `p` the leg's and the
# stance's constants (indices below); the hip's commanded torque [N m] is given at a step's stage times.

FLIGHT, STANCE, ROTOR = 0, 1, 2                       # kernel modes; ROTOR: the leg alone (fallen, or held)
INERTIA, FRICTION, TOE_Y, THETA_TD, T_TD = range(5)   # p: [kg m^2], [N m s/rad], [m], [rad], [s]


def leg_vector(c, s, p):
    """From the toe to the body: (y - y_toe, height above the toe) [m]."""
    return s[Y] - p[TOE_Y] - s[SLIP], s[Z] - c.ground_height + s[DEPTH]


def stance_angles(c, s, p):
    """The state with the leg angle and rate of the toe-to-body vector (the massless leg follows the body;
    theta' = ((y_toe - y)' hz - (-dy)(z + depth)') / rho^2 with the toe's depth rate ignored)."""
    dy, hz = leg_vector(c, s, p)
    rho2 = dy * dy + hz * hz
    return (s[Y], s[Z], s[YDOT], s[ZDOT], math.atan2(-dy, hz), (-s[YDOT] * hz + dy * s[ZDOT]) / rho2, s[DEPTH],
            s[TORQUE], s[SLIP])


def stance(c, t, s, command, p):
    """`laws.stance_forces` at this state and the actuator lag's rate: the commanded torque through
    `laws.actuator_torque` (gain, offset, saturation), through the first-order lag `torque_lag` when it is on (the
    applied torque then is the state's)."""
    target = laws.actuator_torque(c, command)
    lagged = c.torque_lag > 0.0
    applied = s[TORQUE] if lagged else target
    lag_rate = (target - s[TORQUE]) / c.torque_lag if lagged else 0.0
    forces = laws.stance_forces(c, s[Y], s[Z], s[YDOT], s[ZDOT], s[DEPTH], p[TOE_Y] + s[SLIP], applied, command,
                                p[THETA_TD], t - p[T_TD], c.ground_stiffness > 0.0)
    return forces, lag_rate


def rates(cs, mode, t, s, command, p):
    """The state's rate. In flight (or fallen, or held) the leg is a rotor the hip drives, J theta'' = tau - b
    theta', with the actuator's torque without its stance-only parts (offset, lag) that the drive's position loop
    sees through (as `physics.lanes`: the actuator's torque starts at touchdown); in stance theta follows the
    body (`stance_angles`)."""
    if mode == STANCE:
        f, lag_rate = stance(cs[STANCE], t, s, command, p)
        return (s[YDOT], s[ZDOT], f.ydd, f.zdd, 0.0, 0.0, f.depth_rate, lag_rate, f.toe_rate)
    c = cs[FLIGHT]
    theta_ddot = (laws.actuator_torque(c, command) - p[FRICTION] * s[THETA_DOT]) / p[INERTIA]
    if mode == FLIGHT:
        ydd, zdd = laws.flight_acceleration(c, s[Y], s[Z], s[YDOT], s[ZDOT])
        return (s[YDOT], s[ZDOT], ydd, zdd, s[THETA_DOT], theta_ddot, 0.0, 0.0, 0.0)
    return (0.0, 0.0, 0.0, 0.0, s[THETA_DOT], theta_ddot, 0.0, 0.0, 0.0)


def axpy(s, a, k):
    """s + a k."""
    return (s[0] + a * k[0], s[1] + a * k[1], s[2] + a * k[2], s[3] + a * k[3], s[4] + a * k[4], s[5] + a * k[5],
            s[6] + a * k[6], s[7] + a * k[7], s[8] + a * k[8])


def rk4(cs, mode, t, h, s, commands, p):
    """One RK4 step of h from (t, s), the hip commanded `commands` at t, t + h/2 and t + h."""
    k1 = rates(cs, mode, t, s, commands[0], p)
    k2 = rates(cs, mode, t + 0.5 * h, axpy(s, 0.5 * h, k1), commands[1], p)
    k3 = rates(cs, mode, t + 0.5 * h, axpy(s, 0.5 * h, k2), commands[1], p)
    k4 = rates(cs, mode, t + h, axpy(s, h, k3), commands[2], p)
    w = h / 6.0
    return (s[0] + w * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
            s[1] + w * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
            s[2] + w * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]),
            s[3] + w * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3]),
            s[4] + w * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4]),
            s[5] + w * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5]),
            s[6] + w * (k1[6] + 2.0 * k2[6] + 2.0 * k3[6] + k4[6]),
            s[7] + w * (k1[7] + 2.0 * k2[7] + 2.0 * k3[7] + k4[7]),
            s[8] + w * (k1[8] + 2.0 * k2[8] + 2.0 * k3[8] + k4[8]))


def guards(cs, mode, t, s, command, p):
    """The mode's guards, positive before their event and <= 0 at it. Stance: the leg force (lift-off, 2.28), the
    leg's extension short of its rest length (lift-off), the collapse and tipping margin (a fall), -z' (bottom);
    flight: the toe's height above the ground at rest length (touchdown), z' (apex); none for the rotor (inf)."""
    if mode == STANCE:
        c = cs[STANCE]
        f, _ = stance(c, t, s, command, p)
        dy, hz = leg_vector(c, s, p)
        rho = math.sqrt(dy * dy + hz * hz)
        return (f.force, c.rest_length - rho,
                min(rho - COLLAPSE_FRACTION * c.rest_length, MAX_LEG_ANGLE - abs(math.atan2(-dy, hz))), -s[ZDOT])
    if mode == FLIGHT:
        return s[Z] - laws.touchdown_height(cs[FLIGHT], s[THETA]), s[ZDOT], math.inf, math.inf
    return math.inf, math.inf, math.inf, math.inf


def step(cs, mode, t, h, s, commands, p):
    """One RK4 step of h (`rk4`): (the state at t + h, in stance with the leg's angles (`stance_angles`); the
    guards there (`guards`))."""
    s1 = rk4(cs, mode, t, h, s, commands, p)
    g = guards(cs, mode, t + h, s1, commands[2], p)
    if mode == STANCE:
        s1 = stance_angles(cs[STANCE], s1, p)
    return s1, g


def ground_reaction(cs, t, s, command, p):
    """Force of the ground on the robot in stance (forward, vertical) [N]: the leg's force and its torque over its
    length, from the toe."""
    f, _ = stance(cs[STANCE], t, s, command, p)
    across = f.torque / f.rho
    return -f.force * f.sin - across * f.cos, f.force * f.cos - across * f.sin


class Kernel(NamedTuple):
    """The kernel's entry points (`step`, `guards`, `ground_reaction`), in Python or compiled, and `coefficients`:
    (flight, stance) `laws.Coefficients` -> their `cs`."""

    step: Callable
    guards: Callable
    ground_reaction: Callable
    coefficients: Callable
    compiled: bool


def _python_step(cs, mode, t, h, s, commands, p):
    s1, g = step(cs, mode, t, h, s, commands, p)
    return tuple(float(v) for v in s1), tuple(float(v) for v in g)


def _python_guards(cs, mode, t, s, command, p):
    return tuple(float(v) for v in guards(cs, mode, t, s, command, p))


def _python_ground_reaction(cs, t, s, command, p):
    forward, vertical = ground_reaction(cs, t, s, command, p)
    return float(forward), float(vertical)


PYTHON_KERNEL = Kernel(_python_step, _python_guards, _python_ground_reaction,
                       lambda flight, stance_c: (flight, stance_c), False)
_COMPILED_KERNEL: Kernel | None = None


def kernel(compiled: bool | None = None) -> Kernel:
    """The kernel compiled by numba (`physics.compiled.compile_kernels`, with the laws compiled from `laws` itself;
    the first call of a process loads it from the disk cache, or compiles it), or in Python where numba is missing
    (`physics.lanes.compiled_backend`, said once) or `compiled` is False (True requires the compiled one)."""
    global _COMPILED_KERNEL
    from hopper_ros.physics.lanes import compiled_backend

    backend = compiled_backend() if compiled is not False else None
    if compiled and backend is None:
        raise RuntimeError("the compiled plant is not available (numba missing or HOPPER_LANES=numpy)")
    if backend is None:
        return PYTHON_KERNEL
    if _COMPILED_KERNEL is None:
        jitted = backend.compile_kernels((step, guards, ground_reaction),
                                         (leg_vector, stance_angles, stance, rates, axpy, rk4, guards))

        def records(flight, stance_c):
            return np.concatenate([backend.records(flight, 1), backend.records(stance_c, 1)])

        built = Kernel(*jitted, records, True)
        cs, s, p = records(laws.Coefficients(), laws.Coefficients()), (0.0, 1.0) + (0.0,) * 7, (1.0,) + (0.0,) * 4
        built.step(cs, FLIGHT, 0.0, 1e-3, s, (0.0, 0.0, 0.0), p)     # loaded (or compiled) now, not in a period
        built.guards(cs, STANCE, 0.0, s, 0.0, p)
        built.ground_reaction(cs, 0.0, s, 0.0, p)
        _COMPILED_KERNEL = built
    return _COMPILED_KERNEL


class Plant:
    """Integrates the true motion one period at a time; events located inside the step. `compiled`: the step's
    kernel compiled by numba (None: where it is available, `kernel`), or in Python (False)."""

    def __init__(self, config: SimConfig, leg_inertia: float, leg_friction: float,
                 coefficients: laws.Coefficients | None = None, compiled: bool | None = None) -> None:
        self.config = config
        self.coefficients = config.coefficients() if coefficients is None else coefficients
        c = self.coefficients
        self._stance_c = c
        self._flight_c = c.replace(torque_offset=0.0)     # the offset acts in stance (effects.py)
        self.rest_length = float(c.rest_length)
        self.ground_height = float(c.ground_height)
        self.lag = float(c.torque_lag)
        self.leg_inertia = float(leg_inertia)
        self.leg_friction = float(leg_friction)
        self.kernel = kernel(compiled)
        self._cs = self.kernel.coefficients(self._flight_c, self._stance_c)
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
        self.t = float(t)
        self.state = [y0, z0, ydot0, zdot0, float(leg_angle), 0.0, 0.0, 0.0, 0.0]
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

    # ------------------------------------------------------------------ the kernel's inputs
    def _mode(self) -> int:
        if self.fallen or self.held:  # the body lies on the boom's stop or is held; the leg still swings
            return ROTOR
        return STANCE if self.in_contact else FLIGHT

    def _params(self) -> tuple:
        return self.leg_inertia, self.leg_friction, self.toe_y, self.touchdown_angle, self.touchdown_time

    def _watched(self, mode: int) -> tuple:
        """(index into `guards`, the event's kind) of the events that may end this step."""
        if mode == STANCE:
            if self.phase == Phase.COMPRESSION:
                return (0, "liftoff"), (1, "liftoff"), (2, "fall"), (3, "bottom")
            return (0, "liftoff"), (1, "liftoff"), (2, "fall")
        if mode == FLIGHT:
            return ((0, "touchdown"), (1, "apex")) if self.phase == Phase.ASCENT else ((0, "touchdown"),)
        return ()

    def _step(self, mode: int, t: float, s: tuple, h: float, torque: TorqueFunction, p: tuple) -> tuple:
        """The kernel's `step` of h from (t, s), the hip's command read at the step's stage times."""
        commands = (float(torque(t)), float(torque(t + 0.5 * h)), float(torque(t + h)))
        return self.kernel.step(self._cs, mode, t, h, s, commands, p)

    # ------------------------------------------------------------------ stepping
    def advance(self, duration: float, torque: TorqueFunction) -> list[PlantEvent]:
        """Integrate `duration` seconds with hip torque `torque(t)` [N m]; returns the new events."""
        start = len(self.events)
        end = self.t + duration
        while self.t < end - 1e-12:
            self._substep(min(self.h, end - self.t), torque)
        self.command_now = float(torque(self.t))
        self.torque_now = self._applied(self.command_now)
        return self.events[start:]

    def _substep(self, h: float, torque: TorqueFunction) -> None:
        t0, s0 = self.t, tuple(self.state)
        mode, p = self._mode(), self._params()
        s1, g1 = self._step(mode, t0, s0, h, torque, p)
        first, g0 = None, None
        for i, kind in self._watched(mode):
            if g1[i] <= 0.0:
                if g0 is None:
                    g0 = self.kernel.guards(self._cs, mode, t0, s0, float(torque(t0)), p)
                if 0.0 < g0[i]:
                    dt = self._locate(i, g0[i], g1[i], mode, t0, s0, h, torque, p)
                    if first is None or dt < first[0]:
                        first = (dt, kind)
        if first is None:
            self.t, self.state = t0 + h, list(s1)
            return
        dt, kind = first
        if dt > 0.0:
            self.state = list(self._step(mode, t0, s0, dt, torque, p)[0])
        else:
            self.state = list(stance_angles(self._stance_c, s0, p) if mode == STANCE else s0)
        self.t = t0 + dt
        self._switch(kind, torque)
        if h - dt > 1e-12:
            self._substep(h - dt, torque)

    def _locate(self, i: int, fa: float, fb: float, mode: int, t0: float, s0: tuple, h: float, torque, p) -> float:
        """Time into the step where guard `i` reaches zero (Illinois regula falsi on the RK4 step), from its values
        at the step's start (fa) and end (fb)."""
        a, b = 0.0, h
        side = 0
        for _ in range(_ROOT_ITERATIONS):
            c = (a * fb - b * fa) / (fb - fa) if fb != fa else 0.5 * (a + b)
            fc = self._step(mode, t0, s0, c, torque, p)[1][i]
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

    def _switch(self, kind: str, torque: TorqueFunction) -> None:
        s = self.state
        c = self._stance_c
        if kind == "touchdown":
            s[TORQUE] = float(laws.actuator_torque(self._flight_c, torque(self.t)))   # the lag starts from here
            self.in_contact = True
            self.toe_y = s[Y] + self.rest_length * math.sin(s[THETA])
            self.touchdown_time = self.t
            self.touchdown_angle = s[THETA]
            s[DEPTH] = s[SLIP] = 0.0
            ydot, zdot = laws.touchdown_velocity(c, s[THETA], s[YDOT], s[ZDOT], s[THETA_DOT])
            s[YDOT], s[ZDOT] = float(ydot), float(zdot)
            self.events.append(self._event("touchdown", self.t, s))
            self.phase = Phase.COMPRESSION
            p = self._params()
            self.state = s = list(stance_angles(c, tuple(s), p))
            if self.kernel.guards(self._cs, STANCE, self.t, tuple(s), float(torque(self.t)), p)[0] <= 0.0:
                self._switch("liftoff", torque)    # landing with the leg extending: the toe scuffs off
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
    def _applied(self, command: float) -> float:
        """The torque the hip applies for a commanded torque (the actuator's output; in stance, lagged: its state)."""
        if self.in_contact:
            return self.state[TORQUE] if self.lag > 0.0 else float(laws.actuator_torque(self._stance_c, command))
        return float(laws.actuator_torque(self._flight_c, command))

    def applied_torque(self, torque: TorqueFunction) -> float:
        """The torque the hip applies now for the commanded `torque(t)` (the actuator's output)."""
        return self._applied(torque(self.t))

    def ground_reaction_force(self) -> tuple[float, float]:
        """Force of the ground on the robot (forward, vertical) [N]; zero in flight."""
        if not self.in_contact:
            return 0.0, 0.0
        return self.kernel.ground_reaction(self._cs, self.t, tuple(self.state), self.command_now, self._params())

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
        """Height of the toe (at rest length) above the ground [m]: touchdown at 0."""
        return self.state[Z] - float(laws.touchdown_height(self._stance_c, self.state[THETA]))
