"""Runs the MuJoCo hopper (model.py) under the apex-to-apex controller (controller.py) and reads
its encoders.

Phases, as the thesis's robot (section 4.1):
  flight   the hip is position-servoed (a PD in the drive, gains scaled to the hip's inertia,
           25 Hz, damping ratio 0.9, saturated at 12.5 N m): from lift-off it swings the leg
           along a quintic from the lift-off angle and rate to the next theta_td (at rest) in
           t_swing, then holds it; the servo is released 2 cm above the floor (the thesis's
           pre-touchdown event, z - rho0 cos theta < 0.02 m) and the hip is unpowered until
           touchdown;
  stance   from the first step the toe touches the floor (MuJoCo contact with a normal force)
           the hip gets the ramp tau = -tau_0 (1 - s/t_f) (torque mode) until t_f or lift-off;
  lift-off the first step without toe contact at least 10 ms after touchdown;
  apex     the body's vertical velocity crosses zero going down: a stride is done.
The log (1 kHz) holds the encoders and the commanded stance torque (0 in flight: the servo's
torque is the drive's own, not a command).
"""

from __future__ import annotations

import math

import numpy as np

from controller import ENVELOPE_V, ENVELOPE_Z, Command, Controller
from model import (AZ_COUNTS, EL_COUNTS, MOTOR_COUNTS, R_AZ, R_ELEV, TORQUE_LIMIT, Z_PIVOT,
                   Robot, Variant)
from nominal import Nominal, load_nominal

DT_LOG = 1e-3
PRE_TD = 0.02
SERVO_HZ = 25.0
SERVO_ZETA = 0.9


class StrideFailure(Exception):
    pass


def quintic(q0, v0, q1, T, t):
    """Position, velocity, acceleration of the quintic from (q0, v0, 0) to (q1, 0, 0) in T."""
    if t >= T:
        return q1, 0.0, 0.0
    s = t / T
    # q(s) = q0 + v0 T s + c3 s^3 + c4 s^4 + c5 s^5 with q(1)=q1, q'(1)=0, q''(1)=0
    a = q1 - q0 - v0 * T
    b = -v0 * T
    c3, c4, c5 = 10 * a - 4 * b, -15 * a + 7 * b, 6 * a - 3 * b
    q = q0 + v0 * T * s + c3 * s ** 3 + c4 * s ** 4 + c5 * s ** 5
    qd = (v0 * T + 3 * c3 * s ** 2 + 4 * c4 * s ** 3 + 5 * c5 * s ** 4) / T
    qdd = (6 * c3 * s + 12 * c4 * s ** 2 + 20 * c5 * s ** 3) / T ** 2
    return q, qd, qdd


class Hopper:
    """One recording's robot: the MuJoCo model, the servo, the stride loop and the log."""

    def __init__(self, v: Variant, p: Nominal | None = None):
        self.p = p or load_nominal()
        self.robot = Robot(v, self.p)
        self.v = v
        r = self.robot
        r.set_state(0.0, 0.4, 1.0, 0.0, 0.3)
        self.J = r.hip_inertia()
        w = 2 * math.pi * SERVO_HZ
        self.kp, self.kd = self.J * w * w, 2 * SERVO_ZETA * w * self.J
        self.steps_per_log = int(round(DT_LOG / v.timestep))
        assert abs(self.steps_per_log * v.timestep - DT_LOG) < 1e-12
        self.rows: list[tuple] = []          # (t, az/y, el/z, theta, tau_cmd) true axes
        self.truth_rows: list[tuple] = []    # (t, y, z, vy, vz, theta, stance)

    # ------------------------------------------------------------------ one run
    def throw(self, t0: float, y: float, z: float, vy: float, cmd: Command):
        self.t_off = t0
        self.robot.set_state(y, z, vy, 0.0, cmd.theta_td)
        self.swing = (cmd.theta_td, 0.0, cmd.theta_td, 1e-3, 0.0)   # hold
        self.phase = "flight"
        self.servo_on = True
        self.cmd = cmd
        self.tau_cmd = 0.0
        self.n_step = 0
        self.hold_from = 0.0
        self._log()

    def _servo(self) -> float:
        q0, v0, q1, T, ts = self.swing
        qr, vr, ar = quintic(q0, v0, q1, T, self.robot.data.time - ts)
        th, thd = self.robot.theta()
        tau = self.J * ar + self.kp * (qr - th) + self.kd * (vr - thd)
        return float(np.clip(tau, -TORQUE_LIMIT, TORQUE_LIMIT))

    def _log(self):
        r = self.robot
        t = self.t_off + round(r.data.time / DT_LOG) * DT_LOG
        a, e, th = r.angles()
        self.rows.append((t, a, e, th, self.tau_cmd))
        y, z, vy, vz = r.yz()
        self.truth_rows.append((t, y, z, vy, vz, th, self.phase == "stance"))

    def stride(self, controller: Controller) -> dict:
        """From an apex to the next; the samples are appended to the log.  Raises
        StrideFailure when the robot falls, the leg bottoms out or the stance never ends."""
        r, p = self.robot, self.p
        cmd = self.cmd
        td = lo = None
        info = {"theta_td": cmd.theta_td, "tau0": cmd.tau0, "t_f": cmd.t_f}
        vz_prev = r.yz()[3]
        t_start = r.data.time
        apex_seen = False
        while True:
            t = r.data.time
            y, z, vy, vz = r.yz()
            th, thd = r.theta()
            if self.phase == "flight":
                if self.servo_on and vz < 0 and z - p.rho0 * math.cos(th) < PRE_TD:
                    self.servo_on = False
                    info["release_err"] = th - cmd.theta_td
                tau = self._servo() if self.servo_on else 0.0
                self.tau_cmd = 0.0
            else:
                s = t - td
                self.tau_cmd = -cmd.tau0 * (1 - s / cmd.t_f) if s < cmd.t_f else 0.0
                tau = self.tau_cmd
            r.step(tau)
            self.n_step += 1
            if self.n_step % self.steps_per_log == 0:
                self._log()
            t = r.data.time
            y, z, vy, vz = r.yz()
            touch, _ = r.toe_contact()
            if self.phase == "flight" and td is None and touch:
                td = t
                self.phase = "stance"
                info["z_td"], info["vy_td"], info["vz_td"] = z, vy, vz
                info["theta_at_td"] = r.theta()[0]
                info["hold"] = t - self.hold_from
            elif self.phase == "stance" and not touch and t - td > 0.01:
                lo = t
                self.phase = "flight"
                self.tau_cmd = 0.0
                info["t_stance"] = lo - td
                info["z_lo"], info["vy_lo"], info["vz_lo"] = z, vy, vz
                nxt = controller.at_liftoff(z, vy, vz)
                th, thd = r.theta()
                self.swing = (th, thd, nxt.theta_td, nxt.t_swing, t)
                self.hold_from = t + nxt.t_swing
                self.servo_on = True
                self.next_cmd = nxt
                info["theta_lo"] = th
            if self.phase == "stance" and t - td > 0.3:
                raise StrideFailure("stance does not end")
            if r.rho()[0] < 0.09 or z < 0.06 or abs(r.theta()[0]) > 1.2:
                raise StrideFailure("fell")
            if lo is not None and vz_prev > 0 >= vz:
                apex_seen = True
            vz_prev = vz
            if apex_seen:
                break
            if t - t_start > 2.0:
                raise StrideFailure("no apex")
        info["z_apex"], info["v_apex"], info["y_apex"] = z, vy, y
        info["t_apex"] = self.t_off + t
        info["apex_logged"] = self.n_step % self.steps_per_log == 0
        self.cmd = self.next_cmd
        return info

    def finish_run(self):
        """Steps on (servo holding) to the first log instant at or after the apex (if the
        apex was not itself on one)."""
        if self.n_step % self.steps_per_log == 0:
            return
        while self.n_step % self.steps_per_log != 0:
            self.robot.step(self._servo())
            self.n_step += 1
        self._log()


# ------------------------------------------------------------------ encoders

def encoders(rows: np.ndarray, hinge: bool, rng: np.random.Generator) -> dict:
    """Quantise the axes as incremental encoders homed at a random phase within one count.
    rows: columns t, azimuth (or y), elevation (or z), theta, tau."""
    t, a, e, th, tau = rows.T
    da, de, dth = 2 * math.pi / AZ_COUNTS, 2 * math.pi / EL_COUNTS, 2 * math.pi / MOTOR_COUNTS
    if not hinge:   # the planar boom: the same encoders read the same arc and height
        a = a / R_AZ
        e = np.arcsin((e - Z_PIVOT) / R_ELEV)
    pa, pe, pth = rng.uniform(0, 1, 3)
    ca = np.floor(a / da + pa)
    ce = np.floor(e / de + pe)
    cth = np.floor(th / dth + pth)
    return {"t": t, "y": R_AZ * da * ca, "z": Z_PIVOT + R_ELEV * np.sin(de * ce),
            "theta": dth * cth, "tau": tau,
            "counts": {"azimuth": ca, "elevation": ce, "motor": cth}}
