"""Plant C's apex-to-apex controller.

Each stride it chooses the touchdown angle theta_td and the ramp (tau_0, t_f) of (2.32).  It
decides at lift-off (the apex that follows is then known from the flight's closed form (2.13)-
(2.16)) so that the leg can swing to theta_td during the ascent and hold still before touchdown;
the first stride of a run is decided at the throw's apex.

The choice is a one-step search over a grid with the controller's own copy of the nominal
extended TD-SLIP model (flight closed form, stance (2.9) integrated by a fixed-step RK4 on all
candidates at once, lift-off (2.28) or rho = rho0, collision (2.12)):

    minimise  ((z' - z*)/0.015)^2 + ((v' - v*)/0.12)^2 + ((tau_0 - tau_pref)/1.5)^2
              + ((theta_td - theta_pref)/0.12)^2

over theta_td in [0.16, 0.58] rad (22 values) and tau_0 in [0, 8] N m (9 values), with
(z', v') the predicted next apex.  The targets (z*, v*) are redrawn every 3-6 strides from
[0.25, 0.36] m x [0.8, 2.2] m/s and the preferences tau_pref ~ U(0, 8) N m, theta_pref ~
U(0.18, 0.55) rad every stride, so the apex heights, speeds and inputs spread (excitation);
candidates whose predicted next apex leaves [0.23, 0.45] m x [0.6, 2.6] m/s are excluded.
t_f = f * 0.072 s with f ~ U(0.7, 1.15) each stride (the torque stops at lift-off if t_f is
longer than the stance).  A jitter of +-0.008 rad and +-0.4 N m is added to the chosen inputs.
Throws: apex height ~ U(0.30, 0.44) m, speed ~ U(0.9, 2.3) m/s.  The controller knows nothing
of the mechanisms: feedback from stride to stride copes with them.
"""

from __future__ import annotations

import math

import numpy as np

from plant import Command, Params

THETA_RANGE = (0.16, 0.58)
TAU_RANGE = (0.0, 8.0)
T_STANCE_NOM = 0.072      # [s] the nominal stance duration that t_f is scaled from
Z_TARGETS = (0.25, 0.36)
V_TARGETS = (0.8, 2.2)
ENVELOPE_Z = (0.23, 0.45)
ENVELOPE_V = (0.6, 2.6)


class NominalModel:
    """The nominal extended TD-SLIP model, vectorised over candidate inputs."""

    def __init__(self, p: Params, dt: float = 5e-4):
        self.p = p
        self.dt = dt

    # flight
    def descent(self, z_a, v_a, theta):
        """From an apex (z_a, v_a) to touchdown at angle theta: time, vy, vz."""
        p = self.p
        z_td = p.rho0 * np.cos(theta)
        drop = np.maximum(z_a - z_td, 1e-9)
        t = np.sqrt(2 * drop / p.g)
        for _ in range(8):  # Newton on (2.14) with zero initial vertical velocity
            e = np.exp(-p.d_v * t)
            f = z_a + p.g / p.d_v**2 * (1 - e - p.d_v * t) - z_td
            fp = -p.g / p.d_v * (1 - e)
            t = t - f / fp
        vz = -p.g / p.d_v * (1 - np.exp(-p.d_v * t))
        vy = v_a * np.exp(-p.d_h * t)
        return t, vy, vz

    def apex_from(self, z, vy, vz):
        """The apex reached from a flight state with vz > 0: z_a, v_a, time to it."""
        p = self.p
        t = np.log1p(p.d_v * np.maximum(vz, 0.0) / p.g) / p.d_v
        e = np.exp(-p.d_v * t)
        z_a = p.g / p.d_v**2 * (1 - e - p.d_v * t) + vz / p.d_v * (1 - e) + z
        return z_a, vy * np.exp(-p.d_h * t), t

    # stance
    def _acc(self, rho, th, rhod, thd, tau):
        p = self.p
        rhodd = rho * thd**2 - p.g * np.cos(th) + (p.k * (p.rho0 - rho) - p.d * rhod) / p.m_b
        thdd = p.g * np.sin(th) / rho + tau / (p.m_b * rho**2) - 2 * rhod * thd / rho
        return rhodd, thdd

    def stance(self, theta, vy, vz, tau0, t_f, t_max=0.25):
        """Stance from touchdown at angle theta with body velocity (vy, vz)."""
        p = self.p
        n = np.broadcast(theta, vy, vz, tau0, t_f).shape
        th = np.broadcast_to(theta, n).astype(float).copy()
        vy = np.broadcast_to(vy, n)
        vz = np.broadcast_to(vz, n)
        tau0 = np.broadcast_to(tau0, n)
        t_f = np.broadcast_to(t_f, n)
        s, c = np.sin(th), np.cos(th)
        rho = np.full(n, p.rho0)
        rhod = -vy * s + vz * c
        thd = -(vy * c + vz * s) / p.rho0
        th0 = th.copy()
        done = np.zeros(n, bool)
        out = {k: np.full(n, np.nan) for k in ("rho", "th", "rhod", "thd", "t")}
        rho_min = rho.copy()
        dt = self.dt
        t = 0.0

        def tau_at(tt):
            return np.where(tt < t_f, -tau0 * (1 - tt / t_f), 0.0)

        def guard(r, rd):
            return np.minimum(p.k * (p.rho0 - r) - p.d * rd, p.rho0 - r)

        g_prev = guard(rho, rhod)
        while t < t_max and not done.all():
            y0 = (rho, th, rhod, thd)
            k1 = self._acc(rho, th, rhod, thd, tau_at(t))
            r2, t2, rd2, td2 = (rho + .5 * dt * rhod, th + .5 * dt * thd,
                                rhod + .5 * dt * k1[0], thd + .5 * dt * k1[1])
            k2 = self._acc(r2, t2, rd2, td2, tau_at(t + .5 * dt))
            r3, t3, rd3, td3 = (rho + .5 * dt * rd2, th + .5 * dt * td2,
                                rhod + .5 * dt * k2[0], thd + .5 * dt * k2[1])
            k3 = self._acc(r3, t3, rd3, td3, tau_at(t + .5 * dt))
            r4, t4, rd4, td4 = (rho + dt * rd3, th + dt * td3,
                                rhod + dt * k3[0], thd + dt * k3[1])
            k4 = self._acc(r4, t4, rd4, td4, tau_at(t + dt))
            rho = rho + dt / 6 * (rhod + 2 * rd2 + 2 * rd3 + rd4)
            th = th + dt / 6 * (thd + 2 * td2 + 2 * td3 + td4)
            rhod = rhod + dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            thd = thd + dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            t += dt
            rho_min = np.minimum(rho_min, rho)
            g_new = guard(rho, rhod)
            hit = (~done) & (g_new <= 0) & (t > 2e-3)
            if hit.any():
                a = np.clip(g_prev / np.where(g_prev - g_new == 0, 1, g_prev - g_new), 0, 1)
                for key, old, new in (("rho", y0[0], rho), ("th", y0[1], th),
                                      ("rhod", y0[2], rhod), ("thd", y0[3], thd)):
                    out[key] = np.where(hit, old + a * (new - old), out[key])
                out["t"] = np.where(hit, t - dt + a * dt, out["t"])
                done |= hit
            g_prev = g_new
        out["ok"] = done & (rho_min > 0.12) & (np.abs(out["th"]) < 0.8)
        out["rho_min"] = rho_min
        out["th0"] = th0
        return out

    def liftoff_state(self, st):
        """Body height and velocity after the lift-off collision (2.12), floor at 0."""
        p = self.p
        rho, th, rhod, thd = st["rho"], st["th"], st["rhod"], st["thd"]
        z = rho * np.cos(th)
        vy = -rhod * np.sin(th) - rho * thd * np.cos(th)
        vz = rhod * np.cos(th) - rho * thd * np.sin(th)
        f = p.m_b / (p.m_b + p.m_t)
        return z, f * vy, f * vz

    def next_apex(self, z_a, v_a, theta, tau0, t_f):
        t_d, vy, vz = self.descent(z_a, v_a, theta)
        st = self.stance(theta, vy, vz, tau0, t_f)
        z, vy1, vz1 = self.liftoff_state(st)
        z_n, v_n, t_a = self.apex_from(z, vy1, vz1)
        ok = st["ok"] & (vz1 > 0) & (z_a > self.p.rho0 * np.cos(theta) + 1e-3)
        return z_n, v_n, ok, st


class Controller:
    """Apex-to-apex controller with excitation; deterministic given its seed."""

    def __init__(self, p: Params, rng: np.random.Generator):
        self.p = p
        self.rng = rng
        self.model = NominalModel(p)
        th = np.linspace(*THETA_RANGE, 22)
        tau = np.linspace(*TAU_RANGE, 9)
        self.TH, self.TAU = (a.ravel() for a in np.meshgrid(th, tau, indexing="ij"))
        self._countdown = 0
        self.z_star = self.v_star = None

    def _targets(self):
        if self._countdown <= 0:
            self.z_star = self.rng.uniform(*Z_TARGETS)
            self.v_star = self.rng.uniform(*V_TARGETS)
            self._countdown = int(self.rng.integers(3, 7))
        self._countdown -= 1

    def plan(self, z_a: float, v_a: float) -> Command:
        """Inputs for the stride that starts at the apex (z_a, v_a)."""
        rng = self.rng
        self._targets()
        tau_pref = rng.uniform(*TAU_RANGE)
        th_pref = rng.uniform(0.18, 0.55)
        t_f = rng.uniform(0.7, 1.15) * T_STANCE_NOM
        z_n, v_n, ok, st = self.model.next_apex(z_a, v_a, self.TH, self.TAU, t_f)
        ok &= (z_n > ENVELOPE_Z[0]) & (z_n < ENVELOPE_Z[1])
        ok &= (v_n > ENVELOPE_V[0]) & (v_n < ENVELOPE_V[1])
        cost = (((z_n - self.z_star) / 0.015) ** 2 + ((v_n - self.v_star) / 0.12) ** 2
                + ((self.TAU - tau_pref) / 1.5) ** 2 + ((self.TH - th_pref) / 0.12) ** 2)
        cost = np.where(ok & np.isfinite(cost), cost, np.inf)
        i = int(np.argmin(cost))
        if not np.isfinite(cost[i]):
            # nothing predicted inside the envelope: the least bad stride that lifts off
            fallback = np.where(st["ok"], np.abs(z_n - 0.33) / 0.02 + np.abs(v_n - 1.5) / 0.2,
                                np.inf)
            i = int(np.argmin(fallback))
        th = float(np.clip(self.TH[i] + rng.uniform(-0.008, 0.008), *THETA_RANGE))
        tau0 = float(np.clip(self.TAU[i] + rng.uniform(-0.4, 0.4), *TAU_RANGE))
        return Command(theta_td=th, tau0=tau0, t_f=float(t_f))

    def at_liftoff(self, z: float, vy: float, vz: float) -> tuple[Command, float, float]:
        """The next stride's command from the lift-off state (after the collision), with the
        swing's duration; also returns the predicted apex (z_a, v_a)."""
        z_a, v_a, t_up = self.model.apex_from(z, vy, vz)
        z_a, v_a, t_up = float(z_a), float(v_a), float(t_up)
        cmd = self.plan(z_a, v_a)
        t_down = float(self.model.descent(z_a, v_a, cmd.theta_td)[0]) if z_a > (
            self.p.rho0 * math.cos(cmd.theta_td)) else 0.0
        t_fl = t_up + t_down
        cmd.t_swing = float(max(0.04, min(0.15, 0.55 * t_fl, t_fl - 0.03)))
        return cmd, z_a, v_a

    def throw_state(self) -> tuple[float, float]:
        return float(self.rng.uniform(0.30, 0.44)), float(self.rng.uniform(0.9, 2.3))
