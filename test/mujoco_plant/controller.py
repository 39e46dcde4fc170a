"""Apex-to-apex controller of the MuJoCo plant, with stride-to-stride excitation.

The same design as test/plant_c/controller.py (which is independent of hopper_ros), planning
with this directory's own nominal model (nominal.py).  Each stride's touchdown angle theta_td
and ramp (tau_0, t_f) of (2.32) are chosen at the previous lift-off from the apex the nominal
flight predicts, so the hip servo can swing the leg during the ascent and hold it still before
touchdown; the first stride of a run is chosen at the throw.

One-step search over theta_td in [0.16, 0.58] rad (22 values) x tau_0 in [0, 8] N m (9):

    minimise ((z' - z*)/0.015)^2 + ((v' - v*)/0.12)^2 + ((tau_0 - tau_pref)/1.5)^2
             + ((theta_td - theta_pref)/0.12)^2

over candidates whose predicted next apex stays in [0.23, 0.45] m x [0.6, 2.6] m/s.  Targets
(z*, v*) ~ U(0.25, 0.36) m x U(0.8, 2.2) m/s redrawn every 3-6 strides; tau_pref ~ U(0, 8),
theta_pref ~ U(0.18, 0.55) each stride; t_f = f 0.072 s, f ~ U(0.7, 1.15); jitter +-0.008 rad,
+-0.4 N m.  The controller knows nothing of MuJoCo's extra physics: the stride-to-stride
feedback copes with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nominal import Nominal, apex_after, fall_time, next_apex

THETA_RANGE = (0.16, 0.58)
TAU_RANGE = (0.0, 8.0)
T_STANCE_NOM = 0.072
Z_TARGETS = (0.25, 0.36)
V_TARGETS = (0.8, 2.2)
ENVELOPE_Z = (0.23, 0.45)
ENVELOPE_V = (0.6, 2.6)


@dataclass
class Command:
    theta_td: float
    tau0: float
    t_f: float
    t_swing: float = 0.1


class Controller:
    def __init__(self, p: Nominal, rng: np.random.Generator):
        self.p = p
        self.rng = rng
        th = np.linspace(*THETA_RANGE, 22)
        tau = np.linspace(*TAU_RANGE, 9)
        self.TH, self.TAU = (a.ravel() for a in np.meshgrid(th, tau, indexing="ij"))
        self.countdown = 0
        self.z_star = self.v_star = 0.0

    def new_run(self):
        self.countdown = 0

    def _targets(self):
        if self.countdown <= 0:
            self.z_star = self.rng.uniform(*Z_TARGETS)
            self.v_star = self.rng.uniform(*V_TARGETS)
            self.countdown = int(self.rng.integers(3, 7))
        self.countdown -= 1

    def plan(self, z_a: float, v_a: float) -> Command:
        rng = self.rng
        self._targets()
        tau_pref = rng.uniform(*TAU_RANGE)
        th_pref = rng.uniform(0.18, 0.55)
        t_f = rng.uniform(0.7, 1.15) * T_STANCE_NOM
        z_n, v_n, ok, st = next_apex(self.p, z_a, v_a, self.TH, self.TAU, t_f, dt=5e-4)
        ok &= (z_n > ENVELOPE_Z[0]) & (z_n < ENVELOPE_Z[1])
        ok &= (v_n > ENVELOPE_V[0]) & (v_n < ENVELOPE_V[1])
        cost = (((z_n - self.z_star) / 0.015) ** 2 + ((v_n - self.v_star) / 0.12) ** 2
                + ((self.TAU - tau_pref) / 1.5) ** 2 + ((self.TH - th_pref) / 0.12) ** 2)
        cost = np.where(ok & np.isfinite(cost), cost, np.inf)
        i = int(np.argmin(cost))
        if not np.isfinite(cost[i]):
            fb = np.where(st["ok"], np.abs(z_n - 0.33) / 0.02 + np.abs(v_n - 1.5) / 0.2, np.inf)
            fb = np.where(np.isfinite(fb), fb, np.inf)
            i = int(np.argmin(fb))
        th = float(np.clip(self.TH[i] + rng.uniform(-0.008, 0.008), *THETA_RANGE))
        tau0 = float(np.clip(self.TAU[i] + rng.uniform(-0.4, 0.4), *TAU_RANGE))
        return Command(theta_td=th, tau0=tau0, t_f=float(t_f))

    def at_liftoff(self, z: float, vy: float, vz: float) -> Command:
        """The next stride's command from the lift-off state; sets the swing's duration."""
        z_a, v_a, t_up = (float(x) for x in apex_after(self.p, z, vy, vz))
        cmd = self.plan(z_a, v_a)
        z_td = self.p.rho0 * math.cos(cmd.theta_td)
        t_down = float(fall_time(self.p, z_a, z_td)) if z_a > z_td else 0.0
        t_fl = t_up + t_down
        cmd.t_swing = float(max(0.04, min(0.15, 0.55 * t_fl, t_fl - 0.03)))
        return cmd

    def throw_state(self) -> tuple[float, float]:
        return float(self.rng.uniform(0.30, 0.44)), float(self.rng.uniform(0.9, 2.3))
