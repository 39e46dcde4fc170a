"""Plant B core: extended TD-SLIP hopper (Orhon 2018, ch. 2) with effect hooks.

Conventions
-----------
y  forward body position [m], z body height above the datum floor [m],
theta leg angle from the vertical [rad], positive when the toe is ahead of the
body: toe = (y + rho sin(theta), z - rho cos(theta)).

Flight (2.8):   y'' = -d_h y',  z'' = -g - d_v z'        (+ effect accelerations)
Stance (2.9):   m rho'' = m rho theta'^2 - m g cos(theta) + F_leg + Q_rho
                d/dt(m rho^2 theta') = m g rho sin(theta) + tau + Q_theta
    with F_leg = k (rho0 - rho) - d rho' and the toe pinned at (y_t, h(y_t)).
    Derivation: body - toe = rho e_r, e_r = (-sin th, cos th),
    e_th = d e_r/d th = (-cos th, -sin th); generalised forces Q_rho = F.e_r,
    Q_theta = rho F.e_th; gravity (0,-mg) gives -mg cos th and +mg rho sin th.
Lift-off (2.28): F_leg falls to zero (or rho reaches rho0) while extending.
Lift-off collision (2.12): v+ = m_b/(m_b+m_t) v-.
Hip torque (2.32, sign flipped so positive tau_0 pushes forward):
    tau(s) = -tau_0 (1 - s/t_f) for 0 <= s < t_f, else 0.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace

import numpy as np
from scipy.integrate import solve_ivp

HERE = os.path.dirname(os.path.abspath(__file__))
MODEL_YAML = os.path.join(HERE, "..", "..", "config", "model.yaml")

RTOL = 1e-10
ATOL = 1e-12


@dataclass(frozen=True)
class Params:
    m_b: float = 2.20
    m_t: float = 0.03
    g: float = 11.42
    k: float = 4696.0
    d: float = 9.87
    d_h: float = 0.01
    d_v: float = 0.23
    rho0: float = 0.205


def load_params(path: str = MODEL_YAML) -> Params:
    """Read the nominal parameters from config/model.yaml (simple line parser)."""
    keys = {"body_mass": "m_b", "toe_mass": "m_t", "gravity": "g",
            "stiffness": "k", "damping": "d",
            "flight_damping_horizontal": "d_h",
            "flight_damping_vertical": "d_v", "rest_length": "rho0"}
    vals = {}
    try:
        with open(path) as fh:
            for line in fh:
                line = line.split("#", 1)[0].strip()
                if ":" not in line:
                    continue
                key, val = (s.strip() for s in line.split(":", 1))
                if key in keys and val:
                    vals[keys[key]] = float(val)
    except OSError:
        pass
    return replace(Params(), **vals)


@dataclass
class Control:
    theta_td: float   # touchdown leg angle [rad]
    tau0: float       # torque ramp amplitude [N m], positive pushes forward
    t_f: float        # ramp duration [s]


def commanded_torque(s: float, c: Control) -> float:
    if 0.0 <= s < c.t_f:
        return -c.tau0 * (1.0 - s / c.t_f)
    return 0.0


class Effect:
    """Base class of a concealed effect.  Every hook defaults to 'no change'."""
    id = "none"
    family = "other"
    site = "flight"
    magnitude = 0.0
    unit = ""
    words = ""
    equation = ""

    def parameters(self) -> dict:
        return {}

    def describe(self) -> dict:
        return {"id": self.id, "family": self.family, "site": self.site,
                "magnitude": self.magnitude, "unit": self.unit,
                "parameters": self.parameters(), "words": self.words,
                "equation": self.equation}

    # --- physics hooks ---------------------------------------------------
    def gravity(self, g, ctx):                 # all phases
        return g

    def flight_accel(self, t, x, ctx):         # x = (y, z, yd, zd); extra accel
        return 0.0, 0.0

    def ground_height(self, y):                # floor height at y
        return 0.0

    def touchdown(self, vel, toe, theta, ctx):  # -> (vel, toe) at impact
        return vel, toe

    def stiffness(self, k, ctx):
        return k

    def leg_force(self, F, rho, rhod, theta, ctx):  # along-leg force (+ pushes)
        return F

    def hip_torque(self, tau, s, x, ctx):      # x = (rho, th, rhod, thd)
        return tau

    def stance_force(self, s, x, ctx):         # extra Cartesian force on body
        return 0.0, 0.0

    def liftoff_threshold(self, ctx):          # leg force at lift-off [N]
        return 0.0

    def liftoff(self, vel, ctx):               # after the (2.12) collision
        return vel

    # --- sensor hooks (applied to the logged true signals) ---------------
    def sensor(self, t, y, z, theta):          # arrays -> arrays
        return y, z, theta

    def theta_delay(self):
        return 0.0


class Plant:
    def __init__(self, params: Params | None = None, effects=(), rtol=RTOL,
                 atol=ATOL, swing_time=0.075):
        self.p = params or load_params()
        self.effects = list(effects)
        self.rtol, self.atol = rtol, atol
        self.swing_time = swing_time
        self.ctx = {"stride": 0, "n_strides": 50, "t_lo": None,
                    "rho0": self.p.rho0, "m_b": self.p.m_b, "m_t": self.p.m_t, "tau_cmd": 0.0}

    # ---------------------------------------------------------------- helpers
    def g(self):
        g = self.p.g
        for e in self.effects:
            g = e.gravity(g, self.ctx)
        return g

    def h(self, y):
        return sum(e.ground_height(y) for e in self.effects)

    def leg_angle_flight(self, t, t_apex, th_from, th_to):
        """Swing servo: hold, then a quintic (minimum-jerk) move of fixed
        duration starting at the apex, then hold at theta_td."""
        if t_apex is None or t <= t_apex:
            return th_from
        u = (t - t_apex) / self.swing_time
        if u >= 1.0:
            return th_to
        b = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
        return th_from + (th_to - th_from) * b

    # ---------------------------------------------------------------- flight
    def _flight_rhs(self, t, x):
        g = self.g()
        ay, az = -self.p.d_h * x[2], -g - self.p.d_v * x[3]
        for e in self.effects:
            ey, ez = e.flight_accel(t, x, self.ctx)
            ay += ey
            az += ez
        return [x[2], x[3], ay, az]

    def flight_to_apex(self, t0, x0, tmax=2.0):
        """Ascent from lift-off until z' = 0."""
        def ev(t, x):
            return x[3]
        ev.terminal, ev.direction = True, -1
        if x0[3] <= 0:
            return t0, np.array(x0, float), None
        sol = solve_ivp(self._flight_rhs, (t0, t0 + tmax), x0, method="DOP853",
                        rtol=self.rtol, atol=self.atol, events=ev,
                        dense_output=True)
        if sol.status != 1:
            raise Fall("no apex")
        return sol.t_events[0][0], sol.y_events[0][0], sol.sol

    def flight_to_touchdown(self, t0, x0, th_from, th_to, tmax=2.0):
        rho0 = self.p.rho0
        t_apex = t0

        def ev(t, x):
            th = self.leg_angle_flight(t, t_apex, th_from, th_to)
            return x[1] - rho0 * math.cos(th) - self.h(x[0] + rho0 * math.sin(th))
        ev.terminal, ev.direction = True, -1

        sol = solve_ivp(self._flight_rhs, (t0, t0 + tmax), x0, method="DOP853",
                        rtol=self.rtol, atol=self.atol, events=ev,
                        dense_output=True, max_step=0.01)
        if sol.status != 1:
            raise Fall("no touchdown")
        t_td = sol.t_events[0][0]
        th = self.leg_angle_flight(t_td, t_apex, th_from, th_to)
        if sol.y_events[0][0][3] >= 0:
            raise Fall("touchdown while ascending")
        return t_td, sol.y_events[0][0], th, sol.sol

    # ---------------------------------------------------------------- stance
    def _leg_force(self, rho, rhod, th, s=None, c=None):
        self.ctx["tau_cmd"] = commanded_torque(s, c) if c is not None else 0.0
        k = self.p.k
        for e in self.effects:
            k = e.stiffness(k, self.ctx)
        F = k * (self.p.rho0 - rho) - self.p.d * rhod
        for e in self.effects:
            F = e.leg_force(F, rho, rhod, th, self.ctx)
        return F

    def _stance_rhs(self, s, x, c: Control):
        rho, th, rhod, thd = x
        m, g = self.p.m_b, self.g()
        F = self._leg_force(rho, rhod, th, s, c)
        tau = commanded_torque(s, c)
        for e in self.effects:
            tau = e.hip_torque(tau, s, x, self.ctx)
        Fy = Fz = 0.0
        for e in self.effects:
            fy, fz = e.stance_force(s, x, self.ctx)
            Fy += fy
            Fz += fz
        er = (-math.sin(th), math.cos(th))
        eth = (-math.cos(th), -math.sin(th))
        Qr = Fy * er[0] + Fz * er[1]
        Qth = rho * (Fy * eth[0] + Fz * eth[1])
        rhodd = rho * thd * thd - g * math.cos(th) + (F + Qr) / m
        # d/dt(m rho^2 thd) = m g rho sin th + tau + Qth
        thdd = (m * g * rho * math.sin(th) + tau + Qth
                - 2.0 * m * rho * rhod * thd) / (m * rho * rho)
        return [rhod, thd, rhodd, thdd]

    def stance(self, t_td, x_td, th_td, c: Control, tmax=0.5):
        """x_td = body (y,z,yd,zd) at touchdown. Returns lift-off info."""
        rho0 = self.p.rho0
        toe = (x_td[0] + rho0 * math.sin(th_td),
               x_td[1] - rho0 * math.cos(th_td))
        vel = (x_td[2], x_td[3])
        for e in self.effects:
            vel, toe = e.touchdown(vel, toe, th_td, self.ctx)
        dy, dz = x_td[0] - toe[0], x_td[1] - toe[1]
        rho = math.hypot(dy, dz)
        th = math.atan2(-dy, dz)
        er = (-math.sin(th), math.cos(th))
        eth = (-math.cos(th), -math.sin(th))
        rhod = vel[0] * er[0] + vel[1] * er[1]
        thd = (vel[0] * eth[0] + vel[1] * eth[1]) / rho
        x0 = [rho, th, rhod, thd]

        def ev_force(s, x):
            F = self._leg_force(x[0], x[2], x[1], s, c)
            return F - max(thr(), 0.0)
        ev_force.terminal, ev_force.direction = True, -1

        def thr():
            return sum(e.liftoff_threshold(self.ctx) for e in self.effects)

        def ev_rest(s, x):
            return x[0] - rho0
        ev_rest.terminal, ev_rest.direction = True, 1

        def ev_fall(s, x):
            return min(x[0] - 0.5 * rho0, 1.3 - abs(x[1]))
        ev_fall.terminal, ev_fall.direction = True, -1

        rhs = lambda s, x: self._stance_rhs(s, x, c)
        # the torque ramp ends at t_f: integrate in two pieces so that the
        # kink is a step boundary
        pieces = [(0.0, c.t_f), (c.t_f, tmax)] if c.t_f > 0 else [(0.0, tmax)]
        sols = []
        xs = x0
        done = None
        for a, b in pieces:
            sol = solve_ivp(rhs, (a, b), xs, method="DOP853", rtol=self.rtol,
                            atol=self.atol, events=(ev_force, ev_rest, ev_fall),
                            dense_output=True, max_step=0.004)
            sols.append((a, sol.t[-1], sol.sol))
            if sol.status == 1:
                for i in range(3):
                    if len(sol.t_events[i]):
                        done = (i, sol.t_events[i][0], sol.y_events[i][0])
                        break
                break
            xs = sol.y[:, -1]
        if done is None or done[0] == 2:
            raise Fall("stance did not end normally")
        _, s_lo, x_lo = done
        rho, th, rhod, thd = x_lo
        er = (-math.sin(th), math.cos(th))
        eth = (-math.cos(th), -math.sin(th))
        v = (rhod * er[0] + rho * thd * eth[0], rhod * er[1] + rho * thd * eth[1])
        body = (toe[0] - rho * math.sin(th), toe[1] + rho * math.cos(th))
        return {"s_lo": s_lo, "x_lo": x_lo, "toe": toe, "v_lo": v,
                "body_lo": body, "sols": sols}

    def liftoff(self, v):
        f = self.p.m_b / (self.p.m_b + self.p.m_t)
        v = (f * v[0], f * v[1])
        for e in self.effects:
            v = e.liftoff(v, self.ctx)
        return v

    # ---------------------------------------------------------------- stride
    def stride(self, t0, apex, th_prev, c: Control, record=False):
        """One stride from an apex (y, z, yd) with the leg at th_prev to the
        next apex.  Returns dict with the next apex and optional trajectory
        pieces for logging."""
        x0 = [apex[0], apex[1], apex[2], 0.0]
        t_td, x_td, th_td, fsol = self.flight_to_touchdown(t0, x0, th_prev,
                                                           c.theta_td)
        st = self.stance(t_td, x_td, th_td, c)
        t_lo = t_td + st["s_lo"]
        v = self.liftoff(st["v_lo"])
        self.ctx["t_lo"] = t_lo
        x_lo = [st["body_lo"][0], st["body_lo"][1], v[0], v[1]]
        th_lo = st["x_lo"][1]
        t_ap, x_ap, asol = self.flight_to_apex(t_lo, x_lo)
        out = {"t_td": t_td, "t_lo": t_lo, "t_apex": t_ap,
               "apex": (x_ap[0], x_ap[1], x_ap[2]), "th_lo": th_lo,
               "th_td": th_td, "stance_time": st["s_lo"], "x_td": x_td}
        if record:
            out["pieces"] = self._pieces(t0, t_td, fsol, th_prev, c, st,
                                         t_td, t_lo, asol, th_lo, t_ap)
        return out

    def _pieces(self, t0, t_td, fsol, th_prev, c, st, t_td2, t_lo, asol,
                th_lo, t_ap):
        """Functions t -> (y, z, theta) for each phase."""
        pieces = []

        def flight_fn(t, sol=fsol):
            x = sol(t)
            th = np.array([self.leg_angle_flight(ti, t0, th_prev, c.theta_td)
                           for ti in np.atleast_1d(t)])
            return x[0], x[1], th
        pieces.append((t0, t_td, flight_fn))
        toe = st["toe"]
        for a, b, sol in st["sols"]:
            def stance_fn(t, sol=sol):
                x = sol(np.asarray(t) - t_td)
                rho, th = x[0], x[1]
                return toe[0] - rho * np.sin(th), toe[1] + rho * np.cos(th), th
            pieces.append((t_td + a, min(t_td + b, t_lo), stance_fn))
        if asol is not None:
            def asc_fn(t, sol=asol):
                x = sol(t)
                return x[0], x[1], np.full(np.shape(x[0]), th_lo)
            pieces.append((t_lo, t_ap, asc_fn))
        return pieces


class Fall(Exception):
    pass
