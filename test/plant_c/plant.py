"""Plant C: an independent simulator of the boom-mounted one-legged hopper (Orhon 2018, ch. 2).

Conventions (all SI):
  y      body forward position [m] (arc length along the boom's circle)
  z      body height above the nominal floor [m]
  theta  leg angle from the vertical [rad], positive when the toe is ahead of the body;
         toe = (y + rho sin theta, z - rho cos theta); the body does not rotate (the boom holds it)
  tau    hip torque on the leg [N m], positive increases theta (swings the toe forward); with
         the toe pinned a positive tau pushes the body backward, so the thesis's forward-driving
         ramp is logged as tau(s) = -tau_0 (1 - s/t_f).

Flight (2.8):  y'' = -d_h y',  z'' = -g - d_v z'  (damping per unit mass); the leg is kept at
rest length rho0; the servo catches it at lift-off and swings it rest to rest (a quintic) from
the lift-off angle to the next touchdown angle, where it is held still until touchdown.

Stance: the toe is pinned at the touchdown point.  Generalised coordinates q = (rho, theta),
body p = toe + rho u(theta), u = (-sin theta, cos theta).  Lagrange with T = m |p'|^2 / 2,
V = m g p_z, generalised forces Q_rho = k (rho0 - rho) - d rho' (the leg's spring-damper along
the leg) and Q_theta = tau (the hip torque does work tau dtheta as the body does not rotate):
    m rho''              = m rho theta'^2 - m g cos theta + k (rho0 - rho) - d rho'
    d/dt(m rho^2 theta') = m g rho sin theta + tau
which is the thesis's (2.9).  The code writes it as  m J^T J q'' = J^T F + Q - m J^T b  with
J = dp/dq and b the velocity part of p'' so that mechanisms can change the geometry (a round
foot) or add forces.  Flight damping is neglected in stance, as in the thesis.

Events: touchdown when the toe at rest length reaches the floor (z - rho0 cos theta = h);
lift-off when the leg force k (rho0 - rho) - d rho' reaches zero (2.28) or rho reaches rho0,
followed by the collision (2.12)  v+ = m_b / (m_b + m_t) v-.

Nothing here is shared with hopper_ros; the nominal numbers are read from config/model.yaml.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from scipy.integrate import solve_ivp

REPO = Path(__file__).resolve().parents[2]
DT = 1e-3  # [s] sample period of the recordings

RTOL = 1e-9
ATOL = 1e-11


# --------------------------------------------------------------------------------------------
# Parameters and sensors
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Params:
    m_b: float = 2.20     # body mass [kg]
    m_t: float = 0.03     # toe mass [kg], lift-off collision only (2.12)
    g: float = 11.42      # corrected gravity [m/s^2]
    k: float = 4696.0     # leg stiffness [N/m]
    d: float = 9.87       # leg damping [N s/m]
    d_h: float = 0.01     # horizontal flight damping per unit mass [1/s]
    d_v: float = 0.23     # vertical flight damping per unit mass [1/s]
    rho0: float = 0.205   # leg rest length [m]

    def but(self, **kw) -> "Params":
        return replace(self, **kw)


_YAML_KEYS = {
    "body_mass": "m_b", "toe_mass": "m_t", "gravity": "g", "stiffness": "k", "damping": "d",
    "flight_damping_horizontal": "d_h", "flight_damping_vertical": "d_v", "rest_length": "rho0",
}


def nominal_params(path: Path | None = None) -> Params:
    """The nominal model of config/model.yaml (section `model:`); the defaults if unreadable."""
    path = path or REPO / "config" / "model.yaml"
    try:
        import yaml  # the repository's environment has PyYAML

        model = yaml.safe_load(Path(path).read_text())["model"]
        return Params(**{_YAML_KEYS[k]: float(v) for k, v in model.items() if k in _YAML_KEYS})
    except Exception:  # noqa: BLE001 - a missing file or PyYAML: the thesis's Table 4.1
        return Params()


@dataclass(frozen=True)
class Sensors:
    """Encoders of config/hardware.yaml, as counts converted to the recorded channels."""

    boom_length: float = 1.65          # [m] pivot to body
    leg_offset: float = 0.09           # [m] forward position measured at length + offset
    boom_counts: int = 2048 * 4 * 6    # counts per boom turn (2048 lines x4 through 1:6)
    motor_counts: int = 500 * 4 * 26   # counts per leg turn (500 lines x4 through 1:26)
    sigma_y: float = 0.2e-3            # [m] white noise on y before quantisation
    sigma_z: float = 0.2e-3            # [m] white noise on z before quantisation
    sigma_theta: float = 0.0           # [rad] the leg angle is quantised only

    @property
    def dy(self) -> float:
        return 2 * math.pi * (self.boom_length + self.leg_offset) / self.boom_counts

    @property
    def dz(self) -> float:
        return 2 * math.pi * self.boom_length / self.boom_counts

    @property
    def dtheta(self) -> float:
        return 2 * math.pi / self.motor_counts


def quantise(x: np.ndarray, step: float) -> np.ndarray:
    return np.round(np.asarray(x) / step) * step


# --------------------------------------------------------------------------------------------
# Mechanism interface (effects.py subclasses it); every hook is optional
# --------------------------------------------------------------------------------------------

class Mechanism:
    id = "base"
    family = ""
    site: str | list = "stance"
    unit = ""
    words = ""
    equation = ""
    n_states = 0           # extra continuous states carried in flight and stance
    foot_radius = 0.0      # [m] a round foot (geometry of the stance)
    boom_mass = 0.0        # [kg] part of m_b that does not ride with the hip (boom bending)
    torque_order = 0       # order of hip_torque hooks (lower first)

    def __init__(self, **parameters):
        self.parameters = dict(self.defaults())
        unknown = set(parameters) - set(self.parameters)
        if unknown:
            raise TypeError(f"{self.id}: unknown parameters {sorted(unknown)}")
        self.parameters.update(parameters)
        for key, value in self.parameters.items():
            setattr(self, key, value)
        self.slot = None
        self.plant = None

    @classmethod
    def defaults(cls) -> dict:
        return {}

    # ---- description
    @property
    def magnitude(self) -> float:
        return 0.0

    def truth(self) -> dict:
        return {
            "id": self.id, "family": self.family, "site": self.site,
            "magnitude": float(self.magnitude), "unit": self.unit,
            "parameters": {k: (float(v) if isinstance(v, (int, float)) else v)
                           for k, v in self.parameters.items()},
            "words": self.words, "equation": self.equation,
        }

    # ---- lifecycle
    def attach(self, plant: "Plant") -> None:
        self.plant = plant

    def init_states(self, y: float, z: float, vy: float, vz: float) -> list:
        return [0.0] * self.n_states

    # ---- hooks (return None when not used)
    force = None          # force(ctx) -> (Fy, Fz) on the body [N], flight and stance
    deriv = None          # deriv(ctx) -> derivatives of the extra states
    leg_force = None      # leg_force(ctx) -> extra force along the leg, pushing out [N] (stance)
    hip_torque = None     # hip_torque(tau, ctx) -> torque applied on the leg [N m] (stance)
    floor = None          # floor(y) -> floor height [m]
    on_touchdown = None   # on_touchdown(plant, t, X) -> X (may edit the extra states)
    sense = None          # sense(ch) -> None; edits the measured channels in place
    breakpoints = None    # breakpoints() -> stance times s where the dynamics has a kink


class StrideFailure(RuntimeError):
    """The robot fell, stumbled, or left the envelope: the run ends at the previous apex."""


@dataclass
class Command:
    theta_td: float      # touchdown angle [rad]
    tau0: float          # ramp's initial value [N m] (positive drives the body forward)
    t_f: float           # ramp's duration [s]
    t_swing: float = 0.0  # [s] the swing to theta_td after lift-off (0: leg already there)


# --------------------------------------------------------------------------------------------
# Leg swing in flight
# --------------------------------------------------------------------------------------------

class Swing:
    """theta(t): quintic from (a, v0, 0) at t0 to (b, 0, 0) at t0 + T, then held at b."""

    def __init__(self, t0: float, a: float, v0: float, b: float, T: float):
        self.t0, self.a, self.v0, self.b, self.T = t0, a, v0, b, T
        if T > 0:
            A = np.array([[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4],
                          [6 * T, 12 * T**2, 20 * T**3]])
            self.c3, self.c4, self.c5 = np.linalg.solve(A, [b - a - v0 * T, -v0, 0.0])

    @property
    def t_end(self) -> float:
        return self.t0 + self.T

    def __call__(self, t: float):
        s = t - self.t0
        if self.T <= 0 or s >= self.T:
            return self.b, 0.0, 0.0
        if s < 0:
            s = 0.0
        c3, c4, c5 = self.c3, self.c4, self.c5
        th = self.a + self.v0 * s + c3 * s**3 + c4 * s**4 + c5 * s**5
        thd = self.v0 + 3 * c3 * s**2 + 4 * c4 * s**3 + 5 * c5 * s**4
        thdd = 6 * c3 * s + 12 * c4 * s**2 + 20 * c5 * s**3
        return th, thd, thdd

    def arrays(self, t: np.ndarray):
        s = np.clip(np.asarray(t) - self.t0, 0.0, None)
        if self.T <= 0:
            return np.full_like(s, self.b), np.zeros_like(s), np.zeros_like(s)
        s = np.minimum(s, self.T)
        c3, c4, c5 = self.c3, self.c4, self.c5
        th = self.a + self.v0 * s + c3 * s**3 + c4 * s**4 + c5 * s**5
        thd = self.v0 + 3 * c3 * s**2 + 4 * c4 * s**3 + 5 * c5 * s**4
        thdd = 6 * c3 * s + 12 * c4 * s**2 + 20 * c5 * s**3
        return th, thd, thdd


# --------------------------------------------------------------------------------------------
# The plant
# --------------------------------------------------------------------------------------------

def _grid(ta: float, tb: float, include_end: bool = False) -> np.ndarray:
    """Sample times k*DT with ta <= t < tb (or <= the first grid time >= tb)."""
    k0 = math.ceil(ta / DT - 1e-7)
    k1 = math.ceil(tb / DT - 1e-7)
    if include_end:
        k1 += 1
    return np.arange(k0, k1) * DT


class Plant:
    """The robot: hybrid flight/stance dynamics with optional mechanisms."""

    FAIL_RHO = 0.10      # [m] the leg bottoms out
    FAIL_THETA = 1.1     # [rad] the leg swept too far
    MAX_STANCE = 0.35    # [s]
    MAX_FLIGHT = 1.2     # [s]

    def __init__(self, params: Params | None = None, mechanisms=(), seed: int = 0,
                 sensors: Sensors | None = None):
        self.p = params or nominal_params()
        self.sensors = sensors or Sensors()
        self.mechs = list(mechanisms)
        self.rng = np.random.default_rng(seed)
        self.m1 = sum(m.boom_mass for m in self.mechs)
        # inertia of the body where the leg acts: forward the whole m_b, vertically less the
        # part that rides on a bending boom (m1 moves with the body forward, not up and down)
        self.m_y = self.p.m_b
        self.m_z = self.p.m_b - self.m1
        self.r_f = sum(m.foot_radius for m in self.mechs)
        n = 4
        for m in self.mechs:
            m.slot = n
            n += m.n_states
        self.n_state = n
        for m in self.mechs:
            m.attach(self)
        self._force = [m for m in self.mechs if m.force is not None]
        self._deriv = [m for m in self.mechs if m.deriv is not None]
        self._legf = [m for m in self.mechs if m.leg_force is not None]
        self._torque = sorted((m for m in self.mechs if m.hip_torque is not None),
                              key=lambda m: m.torque_order)
        self._floor = [m for m in self.mechs if m.floor is not None]
        self.ctx = SimpleNamespace(phase="flight", t=0.0, s=0.0, y=0.0, z=0.0, vy=0.0, vz=0.0,
                                   th=0.0, thd=0.0, thdd=0.0, rho=self.p.rho0, rhod=0.0,
                                   x=0.0, xd=0.0, X=None, th_td=0.0, plant=self)
        self.state = None

    # ---- floor
    def floor(self, y: float) -> float:
        h = 0.0
        for m in self._floor:
            h += m.floor(y)
        return h

    # ---- run start
    def throw(self, t0: float, y0: float, z0: float, vy0: float, theta: float) -> None:
        """The robot thrown: at an apex (vertical velocity 0), the leg held at theta."""
        X = np.zeros(self.n_state)
        X[:4] = [y0, z0, vy0, 0.0]
        for m in self.mechs:
            if m.n_states:
                X[m.slot:m.slot + m.n_states] = m.init_states(y0, z0, vy0, 0.0)
        self.t = t0
        self.X = X
        self.swing = Swing(t0, theta, 0.0, theta, 0.0)

    # ---- torque
    def tau_command(self, s: float) -> float:
        c = self.cmd
        if 0.0 <= s < c.t_f:
            return -c.tau0 * (1.0 - s / c.t_f)
        return 0.0

    def tau_applied(self, ctx) -> float:
        tau = self.tau_command(ctx.s)
        for m in self._torque:
            tau = m.hip_torque(tau, ctx)
        return tau

    # ---- flight
    def _flight_ctx(self, t, X):
        c = self.ctx
        c.phase = "flight"
        c.t = t
        c.y, c.z, c.vy, c.vz = X[0], X[1], X[2], X[3]
        c.th, c.thd, c.thdd = self.swing(t)
        c.rho, c.rhod, c.x, c.xd = self.p.rho0, 0.0, 0.0, 0.0
        c.X = X
        return c

    def _flight_rhs(self, t, X):
        p = self.p
        c = self._flight_ctx(t, X)
        Fy = Fz = 0.0
        for m in self._force:
            fy, fz = m.force(c)
            Fy += fy
            Fz += fz
        dX = np.empty_like(X)
        dX[0] = X[2]
        dX[1] = X[3]
        dX[2] = -p.d_h * X[2] + Fy / self.m_y
        dX[3] = -p.g - p.d_v * X[3] + Fz / self.m_z
        for m in self._deriv:
            dX[m.slot:m.slot + m.n_states] = m.deriv(c)
        return dX

    def apex_velocity(self, X) -> float:
        """Vertical velocity whose zero is the apex: the body's, or the boom+body centre of
        mass's when part of the mass rides on a bending boom."""
        if self.m1 > 0:
            for m in self.mechs:
                if m.boom_mass > 0:
                    return (self.m_z * X[3] + self.m1 * X[m.slot + 1]) / self.p.m_b
        return X[3]

    def toe_clearance(self, t, X) -> float:
        th = self.swing(t)[0]
        rf = self.r_f
        L = self.p.rho0 - rf
        cy = X[0] + L * math.sin(th)
        return X[1] - L * math.cos(th) - rf - self.floor(cy)

    def _integrate_flight(self, t0, X0, event, t_max):
        """Integrate flight from t0 until `event` (terminal) fires; splits at the swing's end."""
        segments = []
        t, X = t0, X0
        stops = [ts for ts in (self.swing.t_end,) if t0 < ts < t_max]
        for t_stop in stops + [t_max]:
            sol = solve_ivp(self._flight_rhs, (t, t_stop), X, method="DOP853", rtol=RTOL,
                            atol=ATOL, events=[event], dense_output=True)
            if sol.status == 1 and len(sol.t_events[0]):
                te = sol.t_events[0][0]
                segments.append((t, te, sol.sol))
                return te, sol.y_events[0][0].copy(), segments
            if sol.status < 0:
                raise StrideFailure(f"flight integration failed: {sol.message}")
            segments.append((t, sol.t[-1], sol.sol))
            t, X = sol.t[-1], sol.y[:, -1].copy()
        raise StrideFailure("no event in flight")

    def _sample_flight(self, segments):
        out = []
        for ta, tb, sol in segments:
            ts = _grid(ta, tb)
            if len(ts) == 0:
                continue
            Xs = sol(ts)
            th, thd, thdd = self.swing.arrays(ts)
            out.append(dict(t=ts, y=Xs[0], z=Xs[1], vy=Xs[2], vz=Xs[3], theta=th, thdd=thdd,
                            tau_cmd=np.zeros_like(ts), tau_app=np.zeros_like(ts),
                            stance=np.zeros(len(ts), bool), X=Xs))
        return out

    # ---- stance geometry and dynamics
    def _geom(self, rho, th, rhod, thd):
        rf = self.r_f
        s, co = math.sin(th), math.cos(th)
        L = rho - rf
        py = self.cy0 - rf * (th - self.th_td) - L * s
        pz = self.h_contact + rf + L * co
        J11, J21 = -s, co
        J12, J22 = -rf - L * co, -L * s
        vy = J11 * rhod + J12 * thd
        vz = J21 * rhod + J22 * thd
        by = 2 * rhod * thd * (-co) - L * thd * thd * (-s)
        bz = 2 * rhod * thd * (-s) - L * thd * thd * co
        return py, pz, vy, vz, J11, J21, J12, J22, by, bz

    def _stance_ctx(self, t, X):
        rho, th, rhod, thd = X[0], X[1], X[2], X[3]
        g = self._geom(rho, th, rhod, thd)
        c = self.ctx
        c.phase = "stance"
        c.t = t
        c.s = t - self.t_td
        c.y, c.z, c.vy, c.vz = g[0], g[1], g[2], g[3]
        c.th, c.thd, c.thdd = th, thd, 0.0
        c.rho, c.rhod = rho, rhod
        c.x, c.xd = self.p.rho0 - rho, -rhod
        c.X = X
        return c, g

    def leg_force(self, c) -> float:
        p = self.p
        F = p.k * (p.rho0 - c.rho) - p.d * c.rhod
        for m in self._legf:
            F += m.leg_force(c)
        return F

    def _stance_rhs(self, t, X):
        p = self.p
        c, g = self._stance_ctx(t, X)
        _, _, _, _, J11, J21, J12, J22, by, bz = g
        my, mz = self.m_y, self.m_z
        Fy, Fz = 0.0, -mz * p.g
        for mech in self._force:
            fy, fz = mech.force(c)
            Fy += fy
            Fz += fz
        Fl = self.leg_force(c)
        tau = self.tau_applied(c)
        Q1 = J11 * Fy + J21 * Fz + Fl - (J11 * my * by + J21 * mz * bz)
        Q2 = J12 * Fy + J22 * Fz + tau - (J12 * my * by + J22 * mz * bz)
        M11 = my * J11 * J11 + mz * J21 * J21
        M12 = my * J11 * J12 + mz * J21 * J22
        M22 = my * J12 * J12 + mz * J22 * J22
        det = M11 * M22 - M12 * M12
        dX = np.empty_like(X)
        dX[0] = X[2]
        dX[1] = X[3]
        dX[2] = (M22 * Q1 - M12 * Q2) / det
        dX[3] = (M11 * Q2 - M12 * Q1) / det
        for mech in self._deriv:
            dX[mech.slot:mech.slot + mech.n_states] = mech.deriv(c)
        return dX

    # ---- events
    def _stance_events(self):
        def liftoff_force(t, X):
            c, _ = self._stance_ctx(t, X)
            return self.leg_force(c)
        liftoff_force.terminal, liftoff_force.direction = True, -1

        def liftoff_length(t, X):
            return X[0] - self.p.rho0
        liftoff_length.terminal, liftoff_length.direction = True, 1

        def bottom(t, X):
            return X[0] - self.FAIL_RHO
        bottom.terminal, bottom.direction = True, -1

        def swept(t, X):
            return self.FAIL_THETA - abs(X[1])
        swept.terminal, swept.direction = True, -1
        return [liftoff_force, liftoff_length, bottom, swept]

    # ---- one stride: apex -> touchdown -> lift-off -> apex
    def stride(self, cmd: Command, plan_next) -> dict:
        """Simulate from the current apex with command `cmd`.  `plan_next(t, y, z, vy, vz)` is
        called at lift-off (after the collision) and returns the next stride's Command (its
        t_swing sets the swing).  Returns the samples in [apex, next apex) and the events."""
        p = self.p
        self.cmd = cmd
        t_apex0 = self.t
        X = self.X.copy()
        # descent
        if self.toe_clearance(self.t, X) <= 0:
            raise StrideFailure("toe below the floor at the apex")

        def touchdown(t, X):
            return self.toe_clearance(t, X)
        touchdown.terminal, touchdown.direction = True, -1
        t_td, X_td, seg_desc = self._integrate_flight(self.t, X, touchdown,
                                                      self.t + self.MAX_FLIGHT)
        samples = self._sample_flight(seg_desc)
        # touchdown geometry
        th_td, thd_sw, _ = self.swing(t_td)
        rf, rho0 = self.r_f, p.rho0
        L = rho0 - rf
        cy = X_td[0] + L * math.sin(th_td)
        toe_z = X_td[1] - L * math.cos(th_td) - rf
        h = self.floor(cy)
        self.h_contact = toe_z if abs(toe_z - h) > 1e-6 else h  # toe caught on a step's edge
        self.cy0, self.th_td, self.t_td = cy, th_td, t_td
        self.ctx.th_td = th_td
        # joint velocities from the body's velocity: p' = J q'
        g = self._geom(rho0, th_td, 0.0, 0.0)
        J11, J21, J12, J22 = g[4], g[5], g[6], g[7]
        det = J11 * J22 - J12 * J21
        vy, vz = X_td[2], X_td[3]
        rhod = (J22 * vy - J12 * vz) / det
        thd = (-J21 * vy + J11 * vz) / det
        Xs = np.empty(self.n_state)
        Xs[:4] = [rho0, th_td, rhod, thd]
        Xs[4:] = X_td[4:]
        for m in self.mechs:
            if m.on_touchdown is not None:
                Xs = m.on_touchdown(self, t_td, Xs)
        # stance, split at the kinks of the torque
        kinks = {cmd.t_f}
        for m in self.mechs:
            if m.breakpoints is not None:
                kinks.update(m.breakpoints())
        stops = sorted(t_td + s for s in kinks if 0 < s < self.MAX_STANCE) + [
            t_td + self.MAX_STANCE]
        events = self._stance_events()
        t, Xc, t_lo, X_lo, seg_st = t_td, Xs, None, None, []
        for t_stop in stops:
            if t_stop <= t:
                continue
            sol = solve_ivp(self._stance_rhs, (t, t_stop), Xc, method="DOP853", rtol=RTOL,
                            atol=ATOL, events=events, dense_output=True, max_step=0.01)
            if sol.status < 0:
                raise StrideFailure(f"stance integration failed: {sol.message}")
            if sol.status == 1:
                fired = [i for i, te in enumerate(sol.t_events) if len(te)]
                i = min(fired, key=lambda j: sol.t_events[j][0])
                if i >= 2:
                    raise StrideFailure(["leg bottomed out", "leg swept too far"][i - 2])
                t_lo = sol.t_events[i][0]
                X_lo = sol.y_events[i][0].copy()
                seg_st.append((t, t_lo, sol.sol))
                break
            seg_st.append((t, sol.t[-1], sol.sol))
            t, Xc = sol.t[-1], sol.y[:, -1].copy()
        if t_lo is None:
            raise StrideFailure("no lift-off")
        for ta, tb, sol in seg_st:
            ts = _grid(ta, tb)
            if len(ts):
                samples.append(self._sample_stance(ts, sol))
        # lift-off collision (2.12)
        c, g = self._stance_ctx(t_lo, X_lo)
        fy = self.m_y / (self.m_y + p.m_t)
        fz = self.m_z / (self.m_z + p.m_t)
        Xf = np.empty(self.n_state)
        Xf[:4] = [g[0], g[1], fy * g[2], fz * g[3]]
        Xf[4:] = X_lo[4:]
        liftoff = dict(t=t_lo, y=g[0], z=g[1], vy=g[2], vz=g[3], theta=X_lo[1],
                       thetad=X_lo[3], rho=X_lo[0], rhod=X_lo[2], force=self.leg_force(c),
                       vy_after=Xf[2], vz_after=Xf[3])
        nxt = plan_next(t_lo, Xf[0], Xf[1], Xf[2], Xf[3])
        # the position servo catches the leg at lift-off (its relative motion is stopped, the
        # toe's momentum being the collision (2.12)) and swings it rest to rest to theta_td
        self.swing = Swing(t_lo, X_lo[1], 0.0, nxt.theta_td, nxt.t_swing)

        # ascent to the apex
        def apex(t, X):
            return self.apex_velocity(X)
        apex.terminal, apex.direction = True, -1
        if self.apex_velocity(Xf) <= 0:
            raise StrideFailure("no upward velocity after lift-off")
        t_ap, X_ap, seg_asc = self._integrate_flight(t_lo, Xf, apex, t_lo + self.MAX_FLIGHT)
        samples += self._sample_flight(seg_asc)
        self.t, self.X = t_ap, X_ap
        self.cmd_next = nxt
        return dict(
            t_apex=t_apex0, t_td=t_td, t_lo=t_lo, t_next_apex=t_ap,
            touchdown=dict(y=X_td[0], z=X_td[1], vy=X_td[2], vz=X_td[3], theta=th_td,
                           thetad_swing=thd_sw, floor=self.h_contact, toe_y=cy),
            liftoff=liftoff, apex_next=dict(y=X_ap[0], z=X_ap[1], vy=X_ap[2]),
            cmd=cmd, next_cmd=nxt, samples=samples)

    def final_sample(self) -> dict:
        """One sample at the first grid time >= the current apex (brackets the run's last
        apex); the leg is wherever the swing puts it."""
        t = self.t
        ts = _grid(t, t, include_end=True)
        ts = ts[ts >= t - 1e-12][:1]
        if len(ts) == 0:
            ts = np.array([math.ceil(t / DT - 1e-7) * DT])
        dtau = ts[0] - t
        X = self.X.copy()
        if dtau > 0:
            sol = solve_ivp(self._flight_rhs, (t, ts[0]), X, method="DOP853", rtol=RTOL,
                            atol=ATOL)
            X = sol.y[:, -1]
        th, thd, thdd = self.swing.arrays(ts)
        Xs = X[:, None]
        return dict(t=ts, y=Xs[0], z=Xs[1], vy=Xs[2], vz=Xs[3], theta=th, thdd=thdd,
                    tau_cmd=np.zeros(1), tau_app=np.zeros(1), stance=np.zeros(1, bool), X=Xs)

    def _sample_stance(self, ts, sol):
        Xs = sol(ts)
        n = len(ts)
        y = np.empty(n); z = np.empty(n); vy = np.empty(n); vz = np.empty(n)
        tau_c = np.empty(n); tau_a = np.empty(n)
        for i in range(n):
            c, g = self._stance_ctx(ts[i], Xs[:, i])
            y[i], z[i], vy[i], vz[i] = g[0], g[1], g[2], g[3]
            tau_c[i] = self.tau_command(c.s)
            tau_a[i] = self.tau_applied(c)
        return dict(t=ts, y=y, z=z, vy=vy, vz=vz, theta=Xs[1].copy(), thdd=np.zeros(n),
                    tau_cmd=tau_c, tau_app=tau_a, stance=np.ones(n, bool), X=Xs)

    # ---- sensors
    def measure(self, ch: dict, rng: np.random.Generator) -> dict:
        """Channels as the encoders give them: the mechanisms' sensor hooks on the true
        signals, then white noise (y, z) and quantisation to the encoders' steps."""
        out = {"y": ch["y"].copy(), "z": ch["z"].copy(), "theta": ch["theta"].copy()}
        ch = dict(ch)
        ch["meas"] = out
        for m in self.mechs:
            if m.sense is not None:
                m.sense(ch)
        sn = self.sensors
        n = len(ch["t"])
        y = out["y"] + (sn.sigma_y * rng.standard_normal(n) if sn.sigma_y else 0.0)
        z = out["z"] + (sn.sigma_z * rng.standard_normal(n) if sn.sigma_z else 0.0)
        th = out["theta"] + (sn.sigma_theta * rng.standard_normal(n) if sn.sigma_theta else 0.0)
        return {"t": ch["t"], "y": quantise(y, sn.dy), "z": quantise(z, sn.dz),
                "theta": quantise(th, sn.dtheta), "tau": ch["tau_cmd"]}


def concat(samples: list[dict]) -> dict:
    """Concatenate sample blocks (dicts of arrays) along time; extra states as rows of X."""
    keys = ["t", "y", "z", "vy", "vz", "theta", "thdd", "tau_cmd", "tau_app", "stance"]
    out = {k: np.concatenate([s[k] for s in samples]) for k in keys}
    out["X"] = np.concatenate([s["X"] for s in samples], axis=1)
    return out


def flight_closed_form(p: Params, y0, z0, vy0, vz0, t):
    """(2.13)-(2.16)."""
    eh, ev = np.exp(-p.d_h * t), np.exp(-p.d_v * t)
    y = vy0 / p.d_h * (1 - eh) + y0
    z = p.g / p.d_v**2 * (1 - ev - p.d_v * t) + vz0 / p.d_v * (1 - ev) + z0
    vy = vy0 * eh
    vz = vz0 * ev - p.g / p.d_v * (1 - ev)
    return y, z, vy, vz
