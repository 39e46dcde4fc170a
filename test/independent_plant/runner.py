"""Continuous hopping runs of the true plant, a stride controller, the robot's sensors, CSV logs.

A recording: one or more runs, each thrown at an apex and hopping stride after stride
(apex -> descent -> stance -> ascent -> apex); a run that would fall ends at its last apex and the
robot is re-thrown after a gap (> 3 samples) in t. Samples: uniform 1 kHz base (t = integer ms).

Sensors (appendix A of the thesis):
    elevation encoder 8192 CPR x4 quadrature through a 1:6 belt: q_el = 2 pi / (4*2048*6) rad;
        z = z_ref + L sin(psi), L = 1.65 m (boom), z_ref = 0.135 - 0.02 m (paralel height minus
        the 2 cm non-slip ground) -> about 0.21 mm per count near the ground;
    azimuth encoder, same resolution: y = (L + 0.09) psi_az -> 0.222 mm per count;
    hip motor encoder 500 CPR x4 through the 1:26 gearhead: q_theta = 2 pi / 52000 rad.
Gaussian noise (boom vibration) is added before the quantisation.
"""

from __future__ import annotations

import csv
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
from scipy.optimize import lsq_linear

from .plant import (Effect, Fall, Model, Plant, Segment, Servo, StrideCommand, apex_from)

DT = 1e-3
BOOM_L = 1.65
LEG_OFFSET = 0.09
Z_REF = 0.135 - 0.02
Q_BOOM = 2 * math.pi / (4 * 2048 * 6)
Q_THETA = 2 * math.pi / (4 * 500 * 26)


@dataclass
class NoiseSpec:
    y_std: float = 1e-4          # [m]
    z_std: float = 1e-4          # [m]
    theta_std: float = 5e-4      # [rad]
    quantise: bool = True
    boom_length: float = BOOM_L
    azimuth_radius: float = BOOM_L + LEG_OFFSET
    z_ref: float = Z_REF
    boom_quantum_rad: float = Q_BOOM
    theta_quantum_rad: float = Q_THETA

    def as_dict(self) -> dict:
        d = asdict(self)
        d["y_quantum_m"] = self.azimuth_radius * self.boom_quantum_rad
        d["z_quantum_m_near_ground"] = self.boom_length * self.boom_quantum_rad
        return d


# --------------------------------------------------------------------------------------------
# the stride controller (knows the nominal model only)

@dataclass
class ControllerSpec:
    z_range: tuple = (0.28, 0.36)        # set points of the apex height [m]
    v_range: tuple = (1.3, 2.4)          # set points of the apex speed [m/s]
    hold: tuple = (6, 12)                # strides a set point is held
    theta_bounds: tuple = (0.12, 0.62)   # [rad]
    tau_bounds: tuple = (-0.5, 7.5)      # [N m] of the controller's choice ...
    tau_limits: tuple = (-1.5, 8.0)      # ... and of the command with its excitation
    theta_jitter: float = 0.012          # [rad] std of the input excitation
    tau_jitter: float = 0.5              # [N m]
    tf_fraction: tuple = (0.85, 1.0)     # t_f / predicted stance time
    max_dz: float = 0.03                 # [m] per-stride change of the target
    max_dv: float = 0.25                 # [m/s]


class StrideController:
    """Chooses (theta_td, tau_0, t_f) for the next stance from the predicted apex, by one Newton
    step on the NOMINAL stride map (it does not know the concealed effects), plus excitation."""

    def __init__(self, model: Model, rng: np.random.Generator, spec: ControllerSpec = ControllerSpec()):
        self.nominal = Plant(model)
        self.rng = rng
        self.spec = spec
        self.u = np.array([0.30, 4.0])
        self._new_setpoint()

    def _new_setpoint(self):
        s = self.spec
        self.z_set = self.rng.uniform(*s.z_range)
        self.v_set = self.rng.uniform(*s.v_range)
        self.left = int(self.rng.integers(s.hold[0], s.hold[1] + 1))

    def _stride(self, za, va, theta, tau0, t_f):
        p = self.nominal
        servo = Servo(0.0, theta, 0.0, theta)
        _, ttd, xtd, thtd = p.descend(0.0, np.array([0.0, za, va, 0.0]), servo)
        r = p.stance(ttd, xtd, thtd, StrideCommand(theta, tau0, t_f))
        _, _, xa = p.ascend(r.t_lo, r.x_lo, Servo(r.t_lo, r.theta_lo, r.thetadot_lo, theta))
        return np.array([xa[1], xa[2]]), r.t_lo - r.t_td

    def choose(self, za: float, va: float) -> StrideCommand:
        s = self.spec
        self.left -= 1
        if self.left <= 0:
            self._new_setpoint()
        target = np.array([za + np.clip(self.z_set - za, -s.max_dz, s.max_dz),
                           va + np.clip(self.v_set - va, -s.max_dv, s.max_dv)])
        lo = np.array([s.theta_bounds[0], s.tau_bounds[0]])
        hi = np.array([s.theta_bounds[1], s.tau_bounds[1]])
        u = np.clip(self.u, lo, hi)
        t_f = 0.062
        try:
            base, t_st = self._stride(za, va, u[0], u[1], t_f)
            t_f = t_st * self.rng.uniform(*s.tf_fraction)
            base, t_st = self._stride(za, va, u[0], u[1], t_f)
            J = np.empty((2, 2))
            for j, h in enumerate((0.01, 0.3)):
                du = np.zeros(2)
                du[j] = h
                J[:, j] = (self._stride(za, va, *(u + du), t_f)[0] - base) / h
            W = np.array([1.0 / 0.01, 1.0 / 0.05])       # weigh height and speed errors
            step_lo = np.maximum(lo - u, [-0.1, -2.5])
            step_hi = np.minimum(hi - u, [0.1, 2.5])
            step = lsq_linear(W[:, None] * J, W * (target - base),
                              bounds=(step_lo - 1e-12, step_hi + 1e-12)).x
            u = np.clip(u + step, lo, hi)
        except Fall:
            u = np.clip(np.array([math.asin(min(0.9, va * 0.062 / (2 * 0.205))), 4.0]), lo, hi)
        self.u = u
        theta = float(np.clip(u[0] + self.rng.normal(0, s.theta_jitter), lo[0], hi[0]))
        tau0 = float(np.clip(u[1] + self.rng.normal(0, s.tau_jitter), *s.tau_limits))
        return StrideCommand(theta_td=theta, tau_0=tau0, t_f=float(t_f))


# --------------------------------------------------------------------------------------------
# the continuous trajectory

@dataclass
class StanceLog:
    t_td: float
    t_lo: float
    cmd: StrideCommand
    theta_td: float
    theta_lo: float
    slip: float


@dataclass
class Trajectory:
    segments: list = field(default_factory=list)
    runs: list = field(default_factory=list)          # (t_start, t_end) at integer ms
    stances: list = field(default_factory=list)
    apexes: list = field(default_factory=list)        # (t, y, z, vy)
    liftoffs: list = field(default_factory=list)
    falls: int = 0
    fall_reasons: list = field(default_factory=list)

    def _index(self):
        self._t0 = np.array([s.t0 for s in self.segments])

    def eval(self, t):
        t = np.asarray(t, dtype=float)
        if not hasattr(self, "_t0") or len(self._t0) != len(self.segments):
            self._index()
        idx = np.clip(np.searchsorted(self._t0, t, side="right") - 1, 0, len(self.segments) - 1)
        y, z, th = np.empty_like(t), np.empty_like(t), np.empty_like(t)
        for i in np.unique(idx):
            sel = idx == i
            seg = self.segments[i]
            tt = np.clip(t[sel], seg.t0, seg.t1)
            y[sel], z[sel], th[sel] = seg.eval(tt)
        return y, z, th

    def run_start(self, t):
        starts = np.array([r[0] for r in self.runs])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
        return starts[idx]

    def commanded_torque(self, t):
        tau = np.zeros_like(t)
        for st in self.stances:
            i0, i1 = np.searchsorted(t, [st.t_td, min(st.t_lo, st.t_td + st.cmd.t_f)])
            s = t[i0:i1] - st.t_td
            tau[i0:i1] = -st.cmd.tau_0 * (1.0 - s / st.cmd.t_f)
        return tau

    def sample_times(self):
        out = []
        for t0, t1 in self.runs:
            k0, k1 = int(round(t0 / DT)), int(math.floor(t1 / DT + 1e-9))
            out.append(np.arange(k0, k1 + 1) * DT)
        return np.concatenate(out) if out else np.zeros(0)


def simulate(plant: Plant, n_strides: int, rng: np.random.Generator,
             controller: Optional[StrideController] = None, gap: float = 0.5,
             first_apex: Optional[tuple] = None, max_falls: int = 30,
             run_strides: tuple = (12, 30),
             throw_z: tuple = (0.30, 0.43), throw_v: tuple = (1.0, 2.4)) -> Trajectory:
    """Hop until n_strides apex-to-apex strides are complete.

    The operator catches the robot after a run of `run_strides` strides (uniform integer) and
    throws it again at a random apex (throw_z, throw_v), as after a fall."""
    ctrl = controller or StrideController(plant.model, rng)
    traj = Trajectory()
    strides = 0
    t_next = 0.0
    y_next = 0.0
    while strides < n_strides:
        if traj.falls > max_falls:
            raise RuntimeError("the robot keeps falling")
        t_start = math.ceil(t_next / DT - 1e-9) * DT
        if first_apex is not None and not traj.runs:
            za, va = first_apex
        else:
            za, va = rng.uniform(*throw_z), rng.uniform(*throw_v)
        run_left = int(rng.integers(run_strides[0], run_strides[1] + 1))
        t, x = t_start, np.array([y_next, za, va, 0.0])
        cmd = ctrl.choose(za, va)
        servo = Servo(t, cmd.theta_td, 0.0, cmd.theta_td, plant.servo_T)
        run_segments, run_stances, run_apexes, run_lo = [], [], [(t, x[0], za, va)], []
        t_end = t
        while strides < n_strides and run_left > 0:
            try:
                segs = []
                seg, ttd, xtd, thtd = plant.descend(t, x, servo)
                segs.append(seg)
                res = plant.stance(ttd, xtd, thtd, cmd)
                segs.extend(res.segments)
                # controller: next inputs from the nominal apex prediction at lift-off
                _, _, za_p, va_p = apex_from(*res.x_lo, ctrl.nominal.model)
                next_cmd = ctrl.choose(za_p, va_p)
                servo = Servo(res.t_lo, res.theta_lo, res.thetadot_lo, next_cmd.theta_td, plant.servo_T)
                seg, ta, xa = plant.ascend(res.t_lo, res.x_lo, servo)
                segs.append(seg)
                if not (0.24 <= xa[1] <= 0.52 and 0.6 <= xa[2] <= 3.0):
                    raise Fall(f"apex out of range z={xa[1]:.3f} v={xa[2]:.3f}")
            except Fall as exc:
                traj.falls += 1
                traj.fall_reasons.append(f"t={t:.3f}: {exc}")
                break
            run_segments.extend(segs)
            run_stances.append(StanceLog(res.t_td, res.t_lo, cmd, res.theta_td, res.theta_lo, res.slip))
            run_lo.append(res.t_lo)
            run_apexes.append((ta, xa[0], xa[1], xa[2]))
            strides += 1
            run_left -= 1
            t, x, cmd, t_end = ta, xa, next_cmd, ta
        if run_segments:
            traj.runs.append((t_start, t_end))
            traj.segments.extend(run_segments)
            traj.stances.extend(run_stances)
            traj.apexes.extend(run_apexes)
            traj.liftoffs.extend(run_lo)
            y_next = float(x[0]) + 0.5
        t_next = t_end + gap
    return traj


# --------------------------------------------------------------------------------------------
# measurement and logs

def measure(traj: Trajectory, effects: Sequence[Effect], noise: NoiseSpec,
            rng: np.random.Generator):
    t = traj.sample_times()
    y, z, th = traj.eval(t)
    chans = {"y": y, "z": z, "theta": th}
    for e in effects:
        for c in chans:
            chans[c] = e.sensor(c, t, chans[c], traj)
    y = chans["y"] + rng.normal(0.0, noise.y_std, t.size) if noise.y_std else chans["y"]
    z = chans["z"] + rng.normal(0.0, noise.z_std, t.size) if noise.z_std else chans["z"]
    th = chans["theta"] + rng.normal(0.0, noise.theta_std, t.size) if noise.theta_std else chans["theta"]
    if noise.quantise:
        qy = noise.azimuth_radius * noise.boom_quantum_rad
        y = np.round(y / qy) * qy
        psi = np.arcsin(np.clip((z - noise.z_ref) / noise.boom_length, -1, 1))
        psi = np.round(psi / noise.boom_quantum_rad) * noise.boom_quantum_rad
        z = noise.z_ref + noise.boom_length * np.sin(psi)
        th = np.round(th / noise.theta_quantum_rad) * noise.theta_quantum_rad
    tau = traj.commanded_torque(t)
    return t, y, z, th, tau


def write_csv(path, t, y, z, th, tau) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "y", "z", "theta", "tau"])
        for row in zip(t, y, z, th, tau):
            w.writerow([f"{row[0]:.3f}", f"{row[1]:.7f}", f"{row[2]:.7f}", f"{row[3]:.7f}",
                        f"{row[4]:.6f}"])


def read_csv(path):
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return {k: data[:, i] for i, k in enumerate(("t", "y", "z", "theta", "tau"))}
