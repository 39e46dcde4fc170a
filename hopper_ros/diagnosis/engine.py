"""Vectorised re-simulation of recorded strides: many (stride, model variant) lanes at once.

Each lane integrates one stride from its recorded apex with the extended TD-SLIP model plus the
simulated robot's extra effects (equations as in hopper_ros/sim/plant.py and docs/sim.md), by
RK4 at `h` (0.5 ms, the simulated robot's step), events located inside the step by linear
interpolation of the guard and the step split there. Outputs y (relative to the apex), z and
theta every millisecond of the lane's own clock, and the lane's next apex.

Per-lane parameters (numpy arrays of the lane count; 0 switches an extra effect off):
g, dh, dv (flight damping), collision (m_b/(m_b+m_t)), friction F_c, friction_speed v_c,
compliance 1/k_g, ground_damping d_g, impact c, inv_max_torque 1/tau_max, delay.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

COLLAPSE_FRACTION = 0.3
DESCENT, STANCE, ASCENT, DEAD = 0, 1, 2, 3
LANE_PARAMS = ("g", "dh", "dv", "collision", "friction", "friction_speed", "compliance", "ground_damping",
               "impact", "inv_max_torque", "delay")


@dataclass
class LaneResult:
    y: np.ndarray          # (lanes, samples) forward position from the apex [m], every ms of the lane's clock
    z: np.ndarray
    theta: np.ndarray
    ydot: np.ndarray
    zdot: np.ndarray
    next_apex_height: np.ndarray
    next_forward_speed: np.ndarray
    stride_time: np.ndarray
    stride_length: np.ndarray
    fell: np.ndarray


def simulate_lanes(z0, ydot0, theta_td, tau_0, t_f, params: dict, *, mass: float, stiffness: float, damping: float,
                   rest_length: float, duration: float, h: float = 5e-4, sample: float = 1e-3) -> LaneResult:
    """Integrate every lane for `duration` seconds from its apex (z0, ydot0, theta held at theta_td)."""
    n = len(z0)
    p = {k: np.broadcast_to(np.asarray(params[k], dtype=float), (n,)).copy() for k in LANE_PARAMS}
    m, k, d, rho0 = mass, stiffness, damping, rest_length
    compliant = p["compliance"] > 0
    kg = np.where(compliant, 1.0 / np.where(compliant, p["compliance"], 1.0), 0.0)
    dg = np.where(compliant, p["ground_damping"], 1.0)
    tmax = np.where(p["inv_max_torque"] > 0, 1.0 / np.where(p["inv_max_torque"] > 0, p["inv_max_torque"], 1.0), np.inf)
    vc = np.maximum(p["friction_speed"], 1e-6)
    S = np.zeros((5, n))            # y, z, ydot, zdot, depth
    S[1], S[2] = z0, ydot0
    theta_hold = np.asarray(theta_td, dtype=float).copy()
    tau_0 = np.asarray(tau_0, dtype=float)
    t_f = np.maximum(np.asarray(t_f, dtype=float), 1e-6)
    mode = np.full(n, DESCENT)
    toe_y = np.full(n, np.nan)
    t_td = np.full(n, np.nan)
    apex = np.full((4, n), np.nan)   # t, y, z, ydot of the next apex
    t = 0.0

    def torque(tl):
        since = tl - p["delay"] - t_td
        ramp = np.where((since >= 0) & (since < t_f), -tau_0 * (1.0 - since / t_f), 0.0)
        return np.clip(ramp, -tmax, tmax)

    def leg(tl, s):
        dy = s[0] - toe_y
        hz = s[1] + s[4]
        rho = np.sqrt(dy * dy + hz * hz)
        sin, cos = -dy / rho, hz / rho
        tau = torque(tl)
        approach = -sin * s[2] + cos * s[3]
        spring = k * (rho0 - rho) - p["friction"] * np.tanh(approach / vc)
        push = (spring - d * approach) * cos - tau / rho * sin
        depth_rate = np.where(compliant, (push - kg * s[4]) / (dg + d * cos * cos), 0.0)
        force = spring - d * (approach + cos * depth_rate)
        return sin, cos, rho, force, tau, depth_rate

    def rhs(tl, s, md):
        out = np.empty_like(s)
        out[0], out[1] = s[2], s[3]
        sin, cos, rho, force, tau, depth_rate = leg(tl, s)
        across = tau / rho
        st = md == STANCE
        out[2] = np.where(st, (-force * sin - across * cos) / m, -p["dh"] * s[2])
        out[3] = np.where(st, (force * cos - across * sin) / m - p["g"], -p["g"] - p["dv"] * s[3])
        out[4] = np.where(st, depth_rate, 0.0)
        dead = md == DEAD
        out[:, dead] = 0.0
        return out

    def rk4(tl, s, hh, md):
        k1 = rhs(tl, s, md)
        k2 = rhs(tl + 0.5 * hh, s + 0.5 * hh * k1, md)
        k3 = rhs(tl + 0.5 * hh, s + 0.5 * hh * k2, md)
        k4 = rhs(tl + hh, s + hh * k3, md)
        return s + hh / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)

    def guard(s, md):
        """Positive before the event, <= 0 at it (per lane, for its mode)."""
        g = np.full(n, np.inf)
        des, st, asc = md == DESCENT, md == STANCE, md == ASCENT
        g[des] = s[1, des] - rho0 * np.cos(theta_hold[des])
        if st.any():
            _, _, rho, force, _, _ = leg(t, s)
            g[st] = np.minimum(force, rho0 - rho)[st]
        g[asc] = np.where(np.isnan(apex[0, asc]), s[3, asc], np.inf)
        return g

    steps_per_sample = max(1, int(round(sample / h)))
    samples = int(np.floor(duration / sample)) + 1
    out = np.empty((5, n, samples), dtype=np.float32)

    def record(j):
        dy = S[0] - toe_y
        th = np.where(mode == STANCE, np.arctan2(-dy, S[1] + S[4]), theta_hold)
        out[0, :, j], out[1, :, j], out[2, :, j], out[3, :, j], out[4, :, j] = S[0], S[1], th, S[2], S[3]

    with np.errstate(all="ignore"):
        record(0)
        for j in range(1, samples):
            for _ in range(steps_per_sample):
                g0 = guard(S, mode)
                S1 = rk4(t, S, h, mode)
                g1 = guard(S1, mode)
                ev = (g0 > 0) & (g1 <= 0) & np.isfinite(g0)
                if ev.any():
                    frac = np.clip(g0 / np.where(ev, g0 - g1, 1.0), 0.0, 1.0)
                    hh = np.where(ev, frac * h, h)
                    Se = rk4(t, S, hh, mode)
                    te = t + hh
                    S1[:, ev] = Se[:, ev]
                    newmode = mode.copy()
                    # touchdown
                    td = ev & (mode == DESCENT)
                    if td.any():
                        sn, cs = np.sin(theta_hold[td]), np.cos(theta_hold[td])
                        toe_y[td] = S1[0, td] + rho0 * sn
                        t_td[td] = te[td]
                        S1[4, td] = 0.0
                        c = p["impact"][td]
                        across = -cs * S1[2, td] - sn * S1[3, td]
                        S1[2, td] += c * across * cs
                        S1[3, td] += c * across * sn
                        newmode[td] = STANCE
                    lo = ev & (mode == STANCE)
                    if lo.any():
                        dy = S1[0, lo] - toe_y[lo]
                        theta_hold[lo] = np.arctan2(-dy, S1[1, lo] + S1[4, lo])
                        S1[4, lo] = 0.0
                        S1[2, lo] *= p["collision"][lo]
                        S1[3, lo] *= p["collision"][lo]
                        newmode[lo] = np.where(S1[3, lo] > 0, ASCENT, DEAD)
                    ap = ev & (mode == ASCENT)
                    if ap.any():
                        apex[0, ap], apex[1, ap], apex[2, ap], apex[3, ap] = te[ap], S1[0, ap], S1[1, ap], S1[2, ap]
                    rest = h - hh
                    S2 = rk4(te, S1, np.where(ev, rest, 0.0), newmode)
                    S1[:, ev] = S2[:, ev]
                    mode = newmode
                S = S1
                t += h
                st = mode == STANCE
                if st.any():    # collapse or tipping: the stride failed
                    dy = S[0] - toe_y
                    rho = np.sqrt(dy * dy + (S[1] + S[4]) ** 2)
                    dead = st & ((rho < COLLAPSE_FRACTION * rho0) | (np.abs(np.arctan2(-dy, S[1])) > np.radians(80)))
                    mode[dead] = DEAD
            record(j)
    return LaneResult(out[0], out[1], out[2], out[3], out[4], apex[2], apex[3], apex[0], apex[1], mode == DEAD)
