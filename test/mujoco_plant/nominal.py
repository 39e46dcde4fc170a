"""The nominal extended TD-SLIP model of Orhon (2018), chapter 2, written from the thesis alone.

This is the MuJoCo plant's own copy of the nominal model (nothing from hopper_ros nor from
test/plant_c): the controller plans with it and the README's stride-by-stride sizes compare
the MuJoCo recordings with it.

Conventions: y forward [m], z height of the body (hip) above the floor [m], theta the leg angle
from the vertical, positive when the toe is ahead of the body; toe = (y + rho sin theta,
z - rho cos theta).  tau is the hip torque on the leg, positive increasing theta; the thesis's
forward-driving ramp (2.32) is tau(s) = -tau_0 (1 - s/t_f) for 0 <= s < t_f.

Flight (2.8):   y'' = -d_h y',  z'' = -g - d_v z'   closed form (2.13)-(2.16).
Touchdown:      z = rho0 cos theta_td (the toe at rest length reaches the floor).
Stance (2.9):   written here in Cartesian form about the pinned toe: r = body - toe,
                rho = |r|, u = r/rho,
                m r'' = (k (rho0 - rho) - d rho') u + (tau/rho) (-cos theta, -sin theta) - m g e_z
                (the hip torque's generalised force tau on theta = atan2(-r_y, r_z) is the force
                tau/rho along d r/d theta / rho); flight damping neglected, as in the thesis.
Lift-off:       the leg force k (rho0 - rho) - d rho' reaches zero (2.28), or rho reaches rho0;
                then (2.12): v+ = m_b/(m_b + m_t) v-.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Nominal:
    m_b: float = 2.20
    m_t: float = 0.03
    g: float = 11.42
    k: float = 4696.0
    d: float = 9.87
    d_h: float = 0.01
    d_v: float = 0.23
    rho0: float = 0.205

    def but(self, **kw) -> "Nominal":
        return replace(self, **kw)


def load_nominal() -> Nominal:
    """config/model.yaml (Table 4.1)."""
    import yaml
    m = yaml.safe_load((REPO / "config" / "model.yaml").read_text())["model"]
    return Nominal(m_b=m["body_mass"], m_t=m["toe_mass"], g=m["gravity"], k=m["stiffness"],
                   d=m["damping"], d_h=m["flight_damping_horizontal"],
                   d_v=m["flight_damping_vertical"], rho0=m["rest_length"])


# ------------------------------------------------------------------------------------ flight

def flight(p: Nominal, y0, z0, vy0, vz0, t):
    """(2.13)-(2.16): the state a time t after (y0, z0, vy0, vz0)."""
    eh, ev = np.exp(-p.d_h * t), np.exp(-p.d_v * t)
    y = y0 + vy0 / p.d_h * (1 - eh)
    z = z0 + vz0 / p.d_v * (1 - ev) + p.g / p.d_v ** 2 * (1 - ev - p.d_v * t)
    return y, z, vy0 * eh, vz0 * ev - p.g / p.d_v * (1 - ev)


def apex_after(p: Nominal, z0, vy0, vz0):
    """The apex reached from a rising flight state: (z_apex, vy_apex, time to it)."""
    t = np.log1p(p.d_v * np.maximum(vz0, 0.0) / p.g) / p.d_v
    _, z, vy, _ = flight(p, 0.0, z0, vy0, vz0, t)
    return z, vy, t


def fall_time(p: Nominal, z_a, z_end):
    """Time from an apex at z_a (vz = 0) down to the height z_end (Newton on (2.14))."""
    h = np.maximum(np.asarray(z_a, float) - z_end, 0.0)
    t = np.sqrt(2 * h / p.g)
    for _ in range(6):
        _, z, _, vz = flight(p, 0.0, 0.0, 0.0, 0.0, t)
        t = t - (z + h) / np.where(vz == 0, -1e-9, vz)
    return t


# ------------------------------------------------------------------------------------ stance

def _acc(p: Nominal, ry, rz, vy, vz, tau):
    rho = np.sqrt(ry * ry + rz * rz)
    uy, uz = ry / rho, rz / rho
    rhod = vy * uy + vz * uz
    f = p.k * (p.rho0 - rho) - p.d * rhod
    # theta = atan2(-ry, rz): (-cos, -sin) = (-uz, uy)
    ay = (f * uy - tau / rho * uz) / p.m_b
    az = (f * uz + tau / rho * uy) / p.m_b - p.g
    return ay, az, f, rho


def stance(p: Nominal, theta, vy, vz, tau0, t_f, dt=2.5e-4, t_max=0.3):
    """Stance from touchdown at angle theta with body velocity (vy, vz), vectorised over
    any broadcastable inputs.  Returns a dict of the lift-off state (before (2.12)): ry (body
    ahead of the toe), z, vy, vz, t (stance duration), theta, ok, rho_min."""
    th, vy, vz, tau0, t_f = (np.array(a, float) for a in np.broadcast_arrays(theta, vy, vz,
                                                                               tau0, t_f))
    ry, rz = -p.rho0 * np.sin(th), p.rho0 * np.cos(th)
    n = th.shape
    done = np.zeros(n, bool)
    out = {k: np.full(n, np.nan) for k in ("ry", "z", "vy", "vz", "t")}
    rho_min = np.full(n, p.rho0)
    t = 0.0

    def tau(s):
        return np.where(s < t_f, -tau0 * (1 - s / t_f), 0.0)

    def lift_guard(f, rho):
        return np.minimum(f, p.k * (p.rho0 - rho))

    g_prev = np.ones(n)
    while t < t_max and not done.all():
        s0 = (ry, rz, vy, vz)
        a1 = _acc(p, ry, rz, vy, vz, tau(t))
        h = dt / 2
        b = (ry + h * vy, rz + h * vz, vy + h * a1[0], vz + h * a1[1])
        a2 = _acc(p, *b, tau(t + h))
        c = (ry + h * b[2], rz + h * b[3], vy + h * a2[0], vz + h * a2[1])
        a3 = _acc(p, *c, tau(t + h))
        e = (ry + dt * c[2], rz + dt * c[3], vy + dt * a3[0], vz + dt * a3[1])
        a4 = _acc(p, *e, tau(t + dt))
        ry = ry + dt / 6 * (vy + 2 * b[2] + 2 * c[2] + e[2])
        rz = rz + dt / 6 * (vz + 2 * b[3] + 2 * c[3] + e[3])
        vy = vy + dt / 6 * (a1[0] + 2 * a2[0] + 2 * a3[0] + a4[0])
        vz = vz + dt / 6 * (a1[1] + 2 * a2[1] + 2 * a3[1] + a4[1])
        t += dt
        _, _, f, rho = _acc(p, ry, rz, vy, vz, 0.0)
        rho_min = np.minimum(rho_min, rho)
        g_new = lift_guard(f, rho)
        hit = (~done) & (g_new <= 0) & (t > 2e-3)
        if hit.any():
            a = np.clip(g_prev / np.where(g_prev == g_new, 1.0, g_prev - g_new), 0, 1)
            for key, old, new in (("ry", s0[0], ry), ("z", s0[1], rz), ("vy", s0[2], vy),
                                  ("vz", s0[3], vz)):
                out[key] = np.where(hit, old + a * (new - old), out[key])
            out["t"] = np.where(hit, t - dt + a * dt, out["t"])
            done |= hit
        g_prev = g_new
    out["theta"] = np.arctan2(-out["ry"], out["z"])
    out["ok"] = done & (rho_min > 0.11) & (np.abs(out["theta"]) < 0.9)
    out["rho_min"] = rho_min
    return out


def next_apex(p: Nominal, z_a, v_a, theta, tau0, t_f, dt=2.5e-4):
    """The apex-to-apex map (2.7) with the ramp (2.32): (z_next, v_next, ok, details)."""
    z_td = p.rho0 * np.cos(theta)
    t_d = fall_time(p, z_a, z_td)
    _, _, vy, vz = flight(p, 0.0, z_a, v_a, 0.0, t_d)
    st = stance(p, theta, vy, vz, tau0, t_f, dt=dt)
    f = p.m_b / (p.m_b + p.m_t)
    z_n, v_n, t_up = apex_after(p, st["z"], f * st["vy"], f * st["vz"])
    ok = st["ok"] & (st["vz"] > 0) & (np.asarray(z_a) > z_td + 1e-3)
    st.update(t_descent=t_d, t_ascent=t_up, vy_td=vy, vz_td=vz)
    return z_n, v_n, ok, st
