"""An independent extended TD-SLIP plant (Orhon 2018, chapter 2), written from the thesis alone.

Conventions (those of the shared CSV format):
    y      forward body position [m]
    z      body height above the running surface the model assumes [m]
    theta  leg angle from the vertical [rad], positive when the toe is AHEAD of the body:
           toe = (y + rho sin(theta), z - rho cos(theta))
    tau    hip torque [N m] on the leg, positive when it increases theta. The stance command
           is tau(s) = -tau_0 (1 - s/t_f) for 0 <= s < t_f (s = time since touchdown), so a
           positive tau_0 pushes the body forward (section 4.1: "(2.32) ... multiplied by -1").

Phases and maps (equation numbers of the thesis):
    flight   y'' = -d_h y',  z'' = -g - d_v z'                                    (2.8)
    touchdown  toe reaches the ground: z - rho_0 cos(theta) = 0, velocity continuous
    stance   polar coordinates about the toe, Lagrangian of a point mass m_b:     (2.9)
                 m rho'' = m rho theta'^2 - m g cos(theta) + k (rho_0 - rho) - d rho'
                 d/dt (m rho^2 theta') = m g rho sin(theta) + tau
             integrated here in Cartesian form: the massless leg carries the force
                 F e + (tau/rho) n   on the body,  e = (-sin th, cos th) (toe -> body),
                 n = de/dtheta = (-cos th, -sin th),  F = k (rho_0 - rho) - d rho'
             (F e + (tau/rho) n is exactly the generalized-force pair (Q_rho, Q_theta) = (F, tau)
             of (2.9): Q_theta = (tau/rho) n . d(body)/dtheta = (tau/rho) n . (rho n) = tau).
    lift-off the leg force along the leg crosses zero, k (rho_0 - rho) - d rho' = 0  (2.28),
             or the leg reaches its stop length rho_0
    lift-off collision  (y', z')+ = m_b / (m_b + m_t) (y', z')-                   (2.12)

Corrections of the thesis text (derived from first principles, see README.md):
    * (2.10)-(2.11): a perfectly inelastic collision conserves momentum only; kinetic energy is
      NOT conserved (2.11 would contradict 2.12). Only (2.10) with a common final velocity gives
      (2.12). The text also swaps the meaning of the +/- superscripts ("+,- indicates
      pre-collision, post-collision") while (2.12) uses + for post-collision; we use + = after.
    * (2.5) names the ascent map R_s; it is R_as.
    * Table 4.1 gives d_h, d_v in N s/m, but in (2.8) they multiply a velocity to give an
      acceleration, so they are per unit mass, 1/s.
    * (4.7) with M = 2.22 kg, m_boom = 0.39 kg, g_0 = 9.81 gives 10.08 m/s^2, not the 11.41 the
      text reports; we only use the identified g = 11.42 of Table 4.1 (and z'' is -g, not +g).

Concealed effects: see `Effect`. An effect may change structural knobs of the plant (`configure`)
and/or add terms through hooks: flight accelerations, stance force along the leg, stance torque
about the hip, the touchdown velocity reset, the lift-off reset, the actuator (commanded ->
applied torque) and sensor channels (the latter are applied by `runner.py`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np
from scipy.integrate import solve_ivp

RTOL = 1e-9
ATOL = 1e-11


# --------------------------------------------------------------------------------------------
# nominal parameters

@dataclass(frozen=True)
class Model:
    """Nominal extended TD-SLIP parameters (SI; flight damping per unit mass, 1/s)."""

    m_b: float = 2.20
    m_t: float = 0.03
    g: float = 11.42
    k: float = 4696.0
    d: float = 9.87
    d_h: float = 0.01
    d_v: float = 0.23
    rho_0: float = 0.205

    @classmethod
    def from_yaml(cls, path: str | Path) -> "Model":
        import yaml

        raw = yaml.safe_load(Path(path).read_text())["model"]
        return cls(m_b=raw["body_mass"], m_t=raw["toe_mass"], g=raw["gravity"],
                   k=raw["stiffness"], d=raw["damping"],
                   d_h=raw["flight_damping_horizontal"], d_v=raw["flight_damping_vertical"],
                   rho_0=raw["rest_length"])

    def as_dict(self) -> dict:
        return asdict(self)


# --------------------------------------------------------------------------------------------
# concealed effects: the mechanism

@dataclass
class Structure:
    """Structural knobs of the true plant; the nominal values reproduce the thesis's model."""

    g: float                       # gravity acting on the body, both phases [m/s^2]
    m_t: float                     # toe mass in the lift-off collision [kg]
    spring_rest: float             # free length of the leg spring [m]
    leg_stop: float                # geometric leg length in flight / at touchdown / stop [m]
    ground_h: float = 0.0          # true height of the running surface [m]
    mass_ratio_h: float = 0.0      # r: horizontal stance accelerations divided by (1 + r)
    ground_k: Optional[float] = None   # compliant ground under the toe [N/m] ...
    ground_d: float = 0.0              # ... and its damper [N s/m]
    slip_mu_s: Optional[float] = None  # toe slip: static friction coefficient ...
    slip_mu_k: float = 0.0             # ... and kinetic one
    lag_T: Optional[float] = None      # first-order actuator lag time constant [s]


class StanceCtx:
    """What a stance hook may look at (geometry relative to the toe)."""

    __slots__ = ("s", "y", "z", "vy", "vz", "rho", "rhodot", "theta", "thetadot")

    def __init__(self, s, y, z, vy, vz, rho, rhodot, theta, thetadot):
        self.s, self.y, self.z, self.vy, self.vz = s, y, z, vy, vz
        self.rho, self.rhodot, self.theta, self.thetadot = rho, rhodot, theta, thetadot


class Effect:
    """A concealed deviation of the true plant from the nominal model.

    Metadata (class attributes or set in __init__): id, family, site, direction, equation,
    parameter, unit, words; `magnitude` (SI). `acts_in`: the phases whose dynamics it changes
    (subset of flight, touchdown, stance, liftoff, sensor).
    Override only the hooks the effect needs.
    """

    id = "effect"
    family = "other"
    site = "flight"
    direction: Optional[str] = None
    equation = ""
    parameter = ""
    unit = ""
    words = ""
    acts_in: tuple = ()

    def __init__(self, magnitude: float):
        self.magnitude = float(magnitude)

    # structure ------------------------------------------------------------------------------
    def configure(self, st: Structure, model: Model) -> None:
        pass

    # flight: extra acceleration (ay, az) of the body
    def flight_accel(self, t, y, z, vy, vz, model: Model):
        return 0.0, 0.0

    # stance: extra force along the leg [N], positive pushes the body away from the toe
    def stance_along(self, c: StanceCtx, model: Model) -> float:
        return 0.0

    # stance: extra torque about the hip [N m], positive increases theta
    def stance_hip(self, c: StanceCtx, model: Model) -> float:
        return 0.0

    # touchdown: velocity reset (after the toe reaches the ground)
    def touchdown(self, vy, vz, theta, model: Model):
        return vy, vz

    # lift-off: velocity reset, applied after the collision map (2.12)
    def liftoff(self, vy, vz, theta, model: Model):
        return vy, vz

    # actuator: wrap the torque law s -> tau (s = time since touchdown)
    def actuator(self, law: Callable[[float], float]) -> Callable[[float], float]:
        return law

    def actuator_kinks(self, t_f: float) -> list:
        """Times since touchdown where the applied torque has a kink (integration splits)."""
        return []

    # sensor: modify one channel's measured values (see runner.Trajectory)
    def sensor(self, channel: str, t: np.ndarray, values: np.ndarray, traj) -> np.ndarray:
        return values

    def describe(self) -> dict:
        return {"id": self.id, "family": self.family, "site": self.site,
                "direction": self.direction, "equation": self.equation,
                "parameter": self.parameter, "magnitude": self.magnitude, "unit": self.unit,
                "words": self.words}


def _overrides(effect: Effect, name: str) -> bool:
    return getattr(type(effect), name) is not getattr(Effect, name)


# --------------------------------------------------------------------------------------------
# stride inputs and results

@dataclass
class StrideCommand:
    theta_td: float     # touchdown angle commanded to the flight servo [rad]
    tau_0: float        # ramp amplitude [N m]; commanded tau(s) = -tau_0 (1 - s/t_f)
    t_f: float          # ramp duration [s]

    def torque(self, s: float) -> float:
        if 0.0 <= s < self.t_f:
            return -self.tau_0 * (1.0 - s / self.t_f)
        return 0.0


@dataclass
class Servo:
    """Flight leg servo: critically damped second order from (theta_0, omega_0) at t_0 to target."""

    t_0: float
    theta_0: float
    omega_0: float
    target: float
    T: float = 0.02

    def __call__(self, t):
        s = np.maximum(np.asarray(t, dtype=float) - self.t_0, 0.0)
        e0 = self.theta_0 - self.target
        return self.target + (e0 + (self.omega_0 + e0 / self.T) * s) * np.exp(-s / self.T)

    def scalar(self, t: float) -> float:
        s = max(t - self.t_0, 0.0)
        e0 = self.theta_0 - self.target
        return self.target + (e0 + (self.omega_0 + e0 / self.T) * s) * math.exp(-s / self.T)


@dataclass
class Segment:
    """A piece of continuous trajectory: kind 'flight' (state y,z,vy,vz; theta from a servo) or
    'stance' (state y,z,vy,vz,y_toe,z_toe,lag; theta from geometry)."""

    t0: float
    t1: float
    kind: str
    sol: object
    servo: Optional[Servo] = None

    def eval(self, t: np.ndarray):
        x = self.sol(t)
        if self.kind == "flight":
            return x[0], x[1], self.servo(t)
        theta = np.arctan2(-(x[0] - x[4]), x[1] - x[5])
        return x[0], x[1], theta


class Fall(Exception):
    """The robot did not complete the stride (it would fall)."""


@dataclass
class StanceResult:
    t_td: float
    t_lo: float
    x_lo: np.ndarray          # y, z, vy, vz after the lift-off collision
    theta_lo: float
    thetadot_lo: float
    theta_td: float
    td_state: np.ndarray      # y, z, vy, vz just before touchdown
    segments: list = field(default_factory=list)
    slip: float = 0.0         # toe travel during stance [m]
    unloaded_by_slip: bool = False


# --------------------------------------------------------------------------------------------
# the plant

class Plant:
    def __init__(self, model: Model = Model(), effects: Sequence[Effect] = (), servo_T: float = 0.02):
        self.model = model
        self.effects = list(effects)
        self.servo_T = servo_T
        st = Structure(g=model.g, m_t=model.m_t, spring_rest=model.rho_0, leg_stop=model.rho_0)
        for e in self.effects:
            e.configure(st, model)
        if st.ground_k is not None and st.slip_mu_s is not None:
            raise ValueError("compliant ground and toe slip together are not supported")
        self.st = st
        self._flight = [e for e in self.effects if _overrides(e, "flight_accel")]
        self._along = [e for e in self.effects if _overrides(e, "stance_along")]
        self._hip = [e for e in self.effects if _overrides(e, "stance_hip")]
        self._td = [e for e in self.effects if _overrides(e, "touchdown")]
        self._lo = [e for e in self.effects if _overrides(e, "liftoff")]
        self._act = [e for e in self.effects if _overrides(e, "actuator")]

    # ---------------------------------------------------------------------------- flight
    def flight_rhs(self, t, x):
        m = self.model
        y, z, vy, vz = x
        ay = -m.d_h * vy
        az = -self.st.g - m.d_v * vz
        for e in self._flight:
            dy, dz = e.flight_accel(t, y, z, vy, vz, m)
            ay += dy
            az += dz
        return [vy, vz, ay, az]

    def ascend(self, t0: float, x0, servo: Servo):
        """Lift-off (or any ascending state) -> apex. Returns (segment, t_apex, x_apex)."""
        if x0[3] <= 0.0:
            raise Fall("no upward velocity at lift-off")

        def apex(t, x):
            return x[3]
        apex.terminal, apex.direction = True, -1
        sol = solve_ivp(self.flight_rhs, (t0, t0 + 3.0), x0, method="DOP853", rtol=RTOL,
                        atol=ATOL, events=apex, dense_output=True)
        if not sol.t_events[0].size:
            raise Fall("no apex")
        ta = float(sol.t_events[0][0])
        xa = sol.y_events[0][0].copy()
        xa[3] = 0.0
        return Segment(t0, ta, "flight", sol.sol, servo), ta, xa

    def descend(self, t0: float, x0, servo: Servo):
        """Apex -> touchdown. Returns (segment, t_td, x_td, theta_td)."""
        st = self.st
        clearance0 = x0[1] - st.leg_stop * math.cos(servo.scalar(t0)) - st.ground_h
        if clearance0 <= 0.0:
            raise Fall("toe below the ground at apex")

        def touch(t, x):
            return x[1] - st.leg_stop * math.cos(servo.scalar(t)) - st.ground_h
        touch.terminal, touch.direction = True, -1
        sol = solve_ivp(self.flight_rhs, (t0, t0 + 3.0), x0, method="DOP853", rtol=RTOL,
                        atol=ATOL, events=touch, dense_output=True)
        if not sol.t_events[0].size:
            raise Fall("no touchdown")
        ttd = float(sol.t_events[0][0])
        xtd = sol.y_events[0][0].copy()
        return Segment(t0, ttd, "flight", sol.sol, servo), ttd, xtd, servo.scalar(ttd)

    # ---------------------------------------------------------------------------- stance
    def _torque_law(self, cmd: StrideCommand) -> Callable[[float], float]:
        law = cmd.torque
        for e in self._act:
            law = e.actuator(law)
        return law

    def _leg(self, x, s, vyt, vzt, law):
        """Forces of the massless leg for body state x and toe velocity (vyt, vzt).

        Returns Gy, Gz (force of the leg on the body = force of the ground on the toe),
        F (along the leg), tau (about the hip), rho, rhodot, theta, thetadot."""
        m, st = self.model, self.st
        y, z, vy, vz, yt, zt, lag = x
        dy, dz = y - yt, z - zt
        rho = math.hypot(dy, dz)
        ey, ez = dy / rho, dz / rho                  # unit vector toe -> body = (-sin th, cos th)
        ny, nz = -ez, ey                             # de/dtheta = (-cos th, -sin th)
        ry, rz = vy - vyt, vz - vzt
        rhodot = ey * ry + ez * rz
        thetadot = (ny * ry + nz * rz) / rho
        theta = math.atan2(-dy, dz)
        F = m.k * (st.spring_rest - rho) - m.d * rhodot
        tau = lag if st.lag_T is not None else law(s)
        if self._along or self._hip:
            c = StanceCtx(s, y, z, vy, vz, rho, rhodot, theta, thetadot)
            for e in self._along:
                F += e.stance_along(c, m)
            for e in self._hip:
                tau += e.stance_hip(c, m)
        T = tau / rho
        return F * ey + T * ny, F * ez + T * nz, F, tau, rho, rhodot, theta, thetadot

    def _toe_velocity(self, x, s, mode, law):
        """Toe velocity (vyt, vzt): zero when stuck on rigid ground; otherwise the root of the
        massless-toe force balance (scalar, nearly linear: a few secant steps)."""
        st = self.st
        if st.ground_k is not None:
            # ground: vertical force on the toe -k_g (z_t - h) - d_g z_t' equals Gz (massless toe)
            def resid(u):
                Gz = self._leg(x, s, 0.0, u, law)[1]
                return Gz + st.ground_k * (x[5] - st.ground_h) + st.ground_d * u
            return 0.0, _root(resid)
        if mode != 0:
            # slipping toe: ground force on the friction cone edge, Gy = -sgn(u) mu_k Gz
            def resid(u):
                Gy, Gz = self._leg(x, s, u, 0.0, law)[:2]
                return Gy + mode * st.slip_mu_k * Gz
            return _root(resid), 0.0
        return 0.0, 0.0

    def _stance_full(self, t, x, t_td, mode, law):
        s = t - t_td
        vyt, vzt = self._toe_velocity(x, s, mode, law)
        Gy, Gz, F, tau, rho, rhodot, theta, thetadot = self._leg(x, s, vyt, vzt, law)
        return Gy, Gz, F, tau, rho, rhodot, theta, thetadot, vyt, vzt

    def _stance_rhs(self, t, x, t_td, mode, law):
        m, st = self.model, self.st
        Gy, Gz, F, tau, rho, rhodot, theta, thetadot, vyt, vzt = self._stance_full(t, x, t_td, mode, law)
        ay = Gy / (m.m_b * (1.0 + st.mass_ratio_h))
        az = Gz / m.m_b - st.g
        dlag = 0.0
        if st.lag_T is not None:
            dlag = (law(t - t_td) - x[6]) / st.lag_T
        return [x[2], x[3], ay, az, vyt, vzt, dlag]

    def stance(self, t_td: float, x_td, theta_td: float, cmd: StrideCommand) -> StanceResult:
        m, st = self.model, self.st
        vy, vz = float(x_td[2]), float(x_td[3])
        for e in self._td:
            vy, vz = e.touchdown(vy, vz, theta_td, m)
        yt = x_td[0] + st.leg_stop * math.sin(theta_td)
        x = np.array([x_td[0], x_td[1], vy, vz, yt, st.ground_h, 0.0])
        law = self._torque_law(cmd)
        kinks = {cmd.t_f}
        for e in self._act:
            kinks.update(e.actuator_kinks(cmd.t_f))
        kinks = sorted(k for k in kinks if k > 0)
        res = StanceResult(t_td=t_td, t_lo=math.nan, x_lo=None, theta_lo=math.nan,
                           thetadot_lo=math.nan, theta_td=theta_td, td_state=np.array(x_td[:4]))
        mode = 0
        if st.slip_mu_s is not None:
            mode = self._slip_start(t_td, x, t_td, law)
        bottom_seen = False
        t = t_td
        t_max = t_td + 0.4
        for _ in range(200):
            t_end = t_max
            for k in kinks:
                if t_td + k > t + 1e-12:
                    t_end = min(t_end, t_td + k)
                    break
            events, tags = self._stance_events(t_td, mode, law, bottom_seen)
            rhs = (lambda tt, xx, _m=mode: self._stance_rhs(tt, xx, t_td, _m, law))
            sol = solve_ivp(rhs, (t, t_end), x, method="DOP853", rtol=RTOL,
                            atol=ATOL, events=events, dense_output=True)
            hit = None
            for i, te in enumerate(sol.t_events):
                if te.size and (hit is None or te[0] < hit[1]):
                    hit = (i, float(te[0]))
            if hit is None:
                res.segments.append(Segment(t, t_end, "stance", sol.sol))
                t, x = t_end, sol.y[:, -1].copy()
                if t >= t_max - 1e-12:
                    raise Fall("stance too long")
                continue
            i, te = hit
            res.segments.append(Segment(t, te, "stance", sol.sol))
            x = sol.y_events[i][0].copy()
            t = te
            tag = tags[i]
            if tag == "fall":
                raise Fall("body too low in stance")
            if tag == "bottom":
                bottom_seen = True
            elif tag == "slip":
                mode = self._slip_start(t, x, t_td, law)
                if mode == 0:
                    # no consistent sliding state: the ground force left the friction cone
                    # because the leg unloads (G_z -> 0 with F -> 0): the toe leaves the ground
                    res.unloaded_by_slip = True
                    break
            elif tag == "stick":
                mode = 0
            elif tag == "liftoff":
                break
        else:
            raise Fall("stance did not converge (event chatter)")
        # lift-off
        Gy, Gz, F, tau, rho, rhodot, theta, thetadot, vyt, vzt = self._stance_full(t, x, t_td, mode, law)
        res.t_lo = t
        res.theta_lo, res.thetadot_lo = theta, thetadot
        res.slip = float(x[4] - yt)
        factor = m.m_b / (m.m_b + st.m_t)                      # (2.12)
        vy, vz = factor * x[2], factor * x[3]
        for e in self._lo:
            vy, vz = e.liftoff(vy, vz, theta, m)
        res.x_lo = np.array([x[0], x[1], vy, vz])
        return res

    def _slip_start(self, t, x, t_td, law) -> int:
        """Mode at a stick->slip check: 0 (stick) or the slip direction sign of the toe."""
        st = self.st
        Gy, Gz = self._leg(x, t - t_td, 0.0, 0.0, law)[:2]
        if Gz <= 0.0 or abs(Gy) <= st.slip_mu_s * Gz:
            return 0
        mode = -1 if Gy > 0 else 1                 # toe slides against the ground force
        u = self._toe_velocity(x, t - t_td, mode, law)[0]
        return mode if mode * u > 0 else 0

    def _stance_events(self, t_td, mode, law, bottom_seen):
        st = self.st
        events, tags = [], []

        def lo_force(t, x):
            return self._stance_full(t, x, t_td, mode, law)[2]
        lo_force.terminal, lo_force.direction = True, -1
        events.append(lo_force); tags.append("liftoff")

        def lo_stop(t, x):
            return st.leg_stop - math.hypot(x[0] - x[4], x[1] - x[5])
        lo_stop.terminal, lo_stop.direction = True, -1
        events.append(lo_stop); tags.append("liftoff")

        def low(t, x):
            return (x[1] - x[5]) - 0.06
        low.terminal, low.direction = True, -1
        events.append(low); tags.append("fall")

        if not bottom_seen:
            def bottom(t, x):
                return self._stance_full(t, x, t_td, mode, law)[5]
            bottom.terminal, bottom.direction = True, 1
            events.append(bottom); tags.append("bottom")
        if st.slip_mu_s is not None:
            if mode == 0:
                def slip(t, x):
                    Gy, Gz = self._leg(x, t - t_td, 0.0, 0.0, law)[:2]
                    return abs(Gy) - st.slip_mu_s * Gz
                slip.terminal, slip.direction = True, 1
                events.append(slip); tags.append("slip")
            else:
                def stick(t, x):
                    return mode * self._toe_velocity(x, t - t_td, mode, law)[0]
                stick.terminal, stick.direction = True, -1
                events.append(stick); tags.append("stick")
        return events, tags


def _root(f, u0: float = 0.0) -> float:
    """Root of a nearly linear scalar function (secant iterations from u0)."""
    a, fa = u0, f(u0)
    b = u0 + 1e-3
    fb = f(b)
    for _ in range(8):
        if fb == fa:
            break
        a, fa, b = b, fb, b - fb * (b - a) / (fb - fa)
        fb = f(b)
        if abs(b - a) < 1e-13:
            break
    return b


# --------------------------------------------------------------------------------------------
# closed forms used by the controller and the tests (nominal model only)

def flight_closed_form(t, y0, z0, vy0, vz0, model: Model):
    """Exact solution of (2.8): (2.13)-(2.16)."""
    dh, dv, g = model.d_h, model.d_v, model.g
    eh, ev = np.exp(-dh * t), np.exp(-dv * t)
    y = y0 + vy0 / dh * (1.0 - eh)
    z = z0 + g / dv ** 2 * (1.0 - ev - dv * t) + vz0 / dv * (1.0 - ev)
    vy = vy0 * eh
    vz = vz0 * ev - g / dv * (1.0 - ev)
    return y, z, vy, vz


def apex_from(y0, z0, vy0, vz0, model: Model):
    """Nominal apex (time after start, y, z, vy) from an ascending state, closed form."""
    ta = math.log1p(model.d_v * vz0 / model.g) / model.d_v
    y, z, vy, _ = flight_closed_form(ta, y0, z0, vy0, vz0, model)
    return ta, float(y), float(z), float(vy)
