"""Vectorised strides: many (stride, model variant) lanes integrated at once, apex to next apex.

Each lane integrates one stride from an apex (height, forward speed, the leg held at theta_td) with
the laws of `hopper_ros.physics.laws` under its own coefficients (a `Coefficients` whose fields are
arrays with one entry per lane), by RK4 at `h` (0.5 ms); events (touchdown, lift-off, apex) are
located inside the step by linear interpolation of the guard and the step is split there. A lane in
flight at the start of a sample takes the whole sample in one step where no event falls in it (its
forces are smooth: the next apex moves by at most a few micrometres, and the diagnosis's integration
costs 40 % less); a sample with an event, and stance, are stepped at `h`.
Identification with effects and the mismatch tool use it; the simulated robot's plant and the exact
model integrate the same laws their own way.

State per lane: y, z, y', z', toe depth (compliant ground), applied torque (first-order actuator lag),
the toe's forward position (it slides on a ground of finite friction; a round toe's centre, which rolls:
`laws.stance_forces`), the leg's hysteresis state (reset at touchdown, `laws.hysteresis_rate`) and its relaxing
force (reset at touchdown, `laws.relaxation_rate`).
Outputs y, z, theta, y', z' every `sample` seconds of the lane's own clock from the apex, the next apex.

Two paths, one result: numba's compilation of the same laws (`physics.compiled`, each lane stepped on its
own, the default) and numpy's (all lanes stepped together, below), which runs where numba is not
installed (said once on stderr) or with HOPPER_LANES=numpy.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass

import numpy as np

from . import laws
from .exact import COLLAPSE_FRACTION, MAX_LEG_ANGLE

DESCENT, STANCE, ASCENT, DEAD = 0, 1, 2, 3


@dataclass
class LaneResult:
    y: np.ndarray          # (lanes, samples) forward position from the apex [m]
    z: np.ndarray
    theta: np.ndarray
    ydot: np.ndarray
    zdot: np.ndarray
    next_apex_height: np.ndarray
    next_forward_speed: np.ndarray
    stride_time: np.ndarray
    stride_length: np.ndarray
    touchdown_time: np.ndarray
    liftoff_time: np.ndarray
    fell: np.ndarray


def broadcast(coefficients: laws.Coefficients, n: int) -> laws.Coefficients:
    """Every field of `coefficients` as an array of `n` lanes (a field that is one already, as `stack` makes them, is
    shared: the lanes never write their coefficients)."""
    def arr(v):
        if type(v) is np.ndarray and v.dtype == np.float64 and v.shape == (n,):
            return v
        return np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()
    values = {}
    for name, value in coefficients.as_dict().items():
        values[name] = tuple(arr(v) for v in value) if name.endswith("_terms") else arr(value)
    return laws.Coefficients(**values)


def stack(variants: list[laws.Coefficients], lanes_each: int) -> laws.Coefficients:
    """One lane array per field: variant i fills lanes [i*lanes_each, (i+1)*lanes_each)."""
    scalars, terms = laws.Coefficients.scalar_names(), laws.Coefficients.term_names()
    counts = [len(getattr(variants[0], name)) for name in terms]
    rows = [[float(getattr(v, name)) for name in scalars]
            + [float(x) for name in terms for x in getattr(v, name)] for v in variants]
    table = np.repeat(np.array(rows, dtype=np.float64).T, lanes_each, axis=1)    # (fields, lanes), a row a field
    values = {name: table[k] for k, name in enumerate(scalars)}
    k = len(scalars)
    for name, count in zip(terms, counts):
        values[name] = tuple(table[k + i] for i in range(count))
        k += count
    return laws.Coefficients(**values)


_COMPILED = None      # the compiled module once looked up, False where it cannot be used


def compiled_backend():
    """`physics.compiled`, or None (numba missing, or HOPPER_LANES=numpy); the first miss is said on stderr."""
    global _COMPILED
    if _COMPILED is None:
        if os.environ.get("HOPPER_LANES", "").strip().lower() == "numpy":
            _COMPILED = False
        else:
            try:
                from . import compiled
                _COMPILED = compiled
            except Exception as exc:     # numba missing, or it cannot work here (no cache folder, no LLVM)
                print(f"hopper_ros: the compiled lanes are not available ({exc}); physics.lanes runs on numpy, "
                      "about 20 times slower (pip install numba)", file=sys.stderr)
                _COMPILED = False
    return _COMPILED or None


def simulate_lanes(c: laws.Coefficients, apex_height, forward_speed, theta_td, tau_0, ramp_duration, *,
                   duration: float, h: float = 5e-4, sample: float = 1e-3, compiled: bool | None = None,
                   needed=None) -> LaneResult:
    """Integrate every lane for `duration` seconds from its apex; `c` holds one coefficient per lane.

    `compiled`: None takes the compiled path where it is available, False the numpy path, True requires
    the compiled one. `needed` (per lane, optional): the samples the caller reads; the compiled path stops a
    lane that has them and has found its next apex, its later samples nan."""
    n = len(np.atleast_1d(apex_height))
    c = broadcast(c, n)
    apex_height, forward_speed, theta_td, tau_0, ramp_duration = (
        np.broadcast_to(np.asarray(x, dtype=float), (n,)) for x in (apex_height, forward_speed, theta_td, tau_0,
                                                                    ramp_duration))
    steps_per_sample = max(1, int(round(sample / h)))
    samples = int(np.floor(duration / sample)) + 1
    backend = compiled_backend() if compiled is not False else None
    if compiled and backend is None:
        raise RuntimeError("the compiled lanes are not available (numba missing or HOPPER_LANES=numpy)")
    if backend is not None:
        out, apex, events, fell = backend.integrate(c, apex_height, forward_speed, theta_td, tau_0, ramp_duration, h,
                                                    steps_per_sample, samples, needed)
        return LaneResult(out[0], out[1], out[2], out[3], out[4], apex[2], apex[3], apex[0], apex[1], events[0],
                          events[1], fell)
    rho0 = c.rest_length
    compliant = c.ground_stiffness > 0
    lagged = c.torque_lag > 0
    lag = np.where(lagged, c.torque_lag, 1.0)
    S = np.zeros((9, n))            # y, z, ydot, zdot, depth, applied torque (lag state), toe y, hysteresis,
    #                                 the relaxing force
    S[6] = np.nan
    S[1] = apex_height
    S[2] = forward_speed
    theta_hold = np.asarray(theta_td, dtype=float).copy()
    theta_at_td = theta_hold.copy()
    tau_0 = np.asarray(tau_0, dtype=float)
    t_f = np.maximum(np.asarray(ramp_duration, dtype=float), 1e-6)
    mode = np.full(n, DESCENT)
    t_td = np.full(n, np.nan)
    t_lo = np.full(n, np.nan)
    apex = np.full((4, n), np.nan)   # t, y, z, ydot of the next apex
    t = 0.0

    def command(tl):
        return laws.ramp_torque(tl - c.torque_delay - t_td, tau_0, t_f)

    def torque(tl, s):
        target = laws.actuator_torque(c, command(tl))
        return np.where(lagged, s[5], target), target

    def stance(tl, s):
        applied, target = torque(tl, s)
        return laws.stance_forces(c, s[0], s[1], s[2], s[3], s[4], s[6], applied, command=command(tl),
                                  theta_td=theta_at_td, since_touchdown=tl - t_td, compliant=compliant,
                                  hysteresis=s[7], relaxation=s[8]), target

    def rhs(tl, s, md):
        out = np.zeros_like(s)
        out[0], out[1] = s[2], s[3]
        st = md == STANCE
        fy, fz = laws.flight_acceleration(c, s[0], s[1], s[2], s[3])
        if st.any():
            f, target = stance(tl, s)
            out[2] = np.where(st, f.ydd, fy)
            out[3] = np.where(st, f.zdd, fz)
            out[4] = np.where(st, f.depth_rate, 0.0)
            out[5] = np.where(st & lagged, (target - s[5]) / lag, 0.0)
            out[6] = np.where(st, f.toe_rate, 0.0)
            out[7] = np.where(st, f.hysteresis_rate, 0.0)
            out[8] = np.where(st, f.relaxation_rate, 0.0)
        else:
            out[2], out[3] = fy, fz
        out[:, md == DEAD] = 0.0
        return out

    def rk4(tl, s, hh, md):
        k1 = rhs(tl, s, md)
        k2 = rhs(tl + 0.5 * hh, s + 0.5 * hh * k1, md)
        k3 = rhs(tl + 0.5 * hh, s + 0.5 * hh * k2, md)
        k4 = rhs(tl + hh, s + hh * k3, md)
        return s + hh / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)

    def guard(tl, s, md):
        """Positive before the event, <= 0 at it (per lane, for its mode)."""
        g = np.full(n, np.inf)
        des, st, asc = md == DESCENT, md == STANCE, md == ASCENT
        g[des] = (s[1] - laws.touchdown_height(c, theta_hold))[des]
        if st.any():
            f, _ = stance(tl, s)
            g[st] = np.minimum(f.force, rho0 - f.rho)[st]
        g[asc] = np.where(np.isnan(apex[0]), s[3], np.inf)[asc]
        return g

    out = np.empty((5, n, samples), dtype=np.float32)

    def record(j):
        dy, hz = laws.foot_offset(c, S[0], S[1], S[4], S[6])
        th = np.where(mode == STANCE, np.arctan2(-dy, hz), theta_hold)
        out[0, :, j], out[1, :, j], out[2, :, j], out[3, :, j], out[4, :, j] = S[0], S[1], th, S[2], S[3]

    with np.errstate(all="ignore"):
        record(0)
        big = h * steps_per_sample
        for j in range(1, samples):
            # a lane in flight takes the sample in one step where no event falls in it, and holds meanwhile
            flight = (mode == DESCENT) | (mode == ASCENT)
            whole = np.zeros(n, dtype=bool)
            if flight.any():
                g0 = guard(t, S, mode)
                S_big = rk4(t, S, np.where(flight, big, 0.0), mode)
                g1 = guard(t + big, S_big, mode)
                whole = flight & ~((g0 > 0) & (g1 <= 0) & np.isfinite(g0))
            step = np.where(whole, 0.0, h)
            for _ in range(steps_per_sample):
                g0 = guard(t, S, mode)
                S1 = rk4(t, S, step, mode)
                g1 = guard(t + h, S1, mode)
                ev = (g0 > 0) & (g1 <= 0) & np.isfinite(g0) & ~whole
                if ev.any():
                    frac = np.clip(g0 / np.where(ev, g0 - g1, 1.0), 0.0, 1.0)
                    hh = np.where(ev, frac * h, h)
                    Se = rk4(t, S, hh, mode)
                    te = t + hh
                    S1[:, ev] = Se[:, ev]
                    newmode = mode.copy()
                    td = ev & (mode == DESCENT)
                    if td.any():
                        vy, vz = laws.touchdown_velocity(c, theta_hold, S1[2], S1[3])
                        S1[6, td] = laws.foot_at_touchdown(c, S1[0], theta_hold)[td]
                        t_td[td] = te[td]
                        theta_at_td[td] = theta_hold[td]
                        S1[2, td], S1[3, td] = vy[td], vz[td]
                        S1[4, td] = 0.0
                        S1[5, td] = 0.0
                        S1[7, td] = 0.0
                        S1[8, td] = 0.0
                        newmode[td] = STANCE
                    lo = ev & (mode == STANCE)
                    if lo.any():
                        dy, hz = laws.foot_offset(c, S1[0], S1[1], S1[4], S1[6])
                        theta_lo = np.arctan2(-dy, hz)
                        vy, vz = laws.liftoff_velocity(c, theta_lo, S1[2], S1[3])
                        theta_hold[lo] = theta_lo[lo]
                        t_lo[lo] = te[lo]
                        S1[4, lo] = 0.0
                        S1[2, lo], S1[3, lo] = vy[lo], vz[lo]
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
                    dy, hz = laws.foot_offset(c, S[0], S[1], S[4], S[6])
                    rho = np.sqrt(dy * dy + hz * hz) + c.foot_radius
                    dead = st & ((rho < COLLAPSE_FRACTION * rho0) | (np.abs(np.arctan2(-dy, hz)) > MAX_LEG_ANGLE))
                    mode[dead] = DEAD
            S[:, whole] = S_big[:, whole]
            record(j)
    return LaneResult(out[0], out[1], out[2], out[3], out[4], apex[2], apex[3], apex[0], apex[1], t_td, t_lo,
                      mode == DEAD)
