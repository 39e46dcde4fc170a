"""Self-checks of the MuJoCo plant against the thesis's nominal model; exit 1 on a failure.

    python test/mujoco_plant/check.py

1. config/model.yaml is Table 4.1, and the MJCF carries its k, d, rho0, g.
2. Energy (mj_clean with d = 0, no flight damping, no hip torque): MuJoCo's energy is constant in
   flight; through a stance the body's own energy (m_b |v|^2/2 + m_b g z + k (rho0 - rho)^2/2)
   is kept within 1 % (the pinned toe does no work; the soft contact's penetration, 0.2-0.4 mm
   under up to 300 N, stores and damps the rest), and the whole robot loses at most the toe's touchdown kinetic energy plus the
   lift-off collision's loss (2.12) plus 1 %.
3. Flight is (2.8): from a throw, mj_clean's body follows (2.13)-(2.16) within 0.02 mm and
   0.1 mm/s until 2 cm above touchdown; mj_default (the boom's hinges) keeps its angular
   momentum about the vertical axis within 0.2 % (so its forward speed changes by about 3 % as
   the hip's radius grows on the way down: the sphere) and its height within 1.5 mm of (2.14).
4. Stance is the spring-mass hop (2.9) at the nominal parameters: mj_clean's lift-off state (before
   the collision) from its own touchdown state, at 6 states and inputs across the envelope, is
   the nominal stance's within 30 mm/s and 1.5 ms (measured 10-21 mm/s, always slower: the soft
   contact's damping in series with the leg spring, and the 30 g toe's inertia on the spring), and its next apex is the nominal model's from the same
   apex and inputs within 6 mm and 60 mm/s.
5. A short recording of every case: header, 1 kHz, gaps >= 1 s between runs, theta on the motor
   encoder's steps, tau <= 0, the truth's keys; mj_default hops 50 strides without a fall.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from controller import Command  # noqa: E402
from model import LEG_OFFSET, MOTOR_COUNTS, R_ELEV, Robot  # noqa: E402
from nominal import apex_after, flight, load_nominal, next_apex, stance  # noqa: E402
from sim import Hopper  # noqa: E402
from suite import VARIANTS, simulate  # noqa: E402

FAILS: list[str] = []


def check(ok: bool, what: str):
    print(("ok   " if ok else "FAIL ") + what)
    if not ok:
        FAILS.append(what)


class Fixed:
    """A controller that keeps one command."""

    def __init__(self, cmd):
        self.cmd = cmd

    def at_liftoff(self, z, vy, vz):
        return Command(self.cmd.theta_td, self.cmd.tau0, self.cmd.t_f, 0.08)


def one_stride(v, p, z0, v0, cmd):
    h = Hopper(v, p)
    h.throw(0.0, 0.0, z0, v0, cmd)
    return h.stride(Fixed(cmd)), h


def main() -> int:
    p = load_nominal()
    # 1
    check((p.m_b, p.m_t, p.g, p.k, p.d, p.d_h, p.d_v, p.rho0)
          == (2.20, 0.03, 11.42, 4696.0, 9.87, 0.01, 0.23, 0.205), "config/model.yaml is Table 4.1")
    r = Robot(VARIANTS["mj_default"], p)
    leg = r.model.joint("leg")
    check(abs(leg.stiffness[0] - p.k) < 1e-9 and abs(r.model.dof_damping[leg.dofadr[0]] - p.d)
          < 1e-12 and abs(r.model.opt.gravity[2] + p.g) < 1e-12, "the MJCF has k, d and g")

    # 2 energy
    p0 = p.but(d=0.0, d_h=0.0, d_v=0.0)
    v = VARIANTS["mj_clean"]
    rob = Robot(v, p0)
    rob.model.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    rob.set_state(0.0, 0.36, 1.4, 0.0, 0.30)
    mujoco.mj_forward(rob.model, rob.data)
    e0 = rob.energy()
    e_fl, body_e, phase, e_td, toe_ke, v_lo = [], [], "flight", None, None, None
    m_b = v.m_body + v.m_leg

    def body_energy():
        y, z, vy, vz = rob.yz()
        rho, _ = rob.rho()
        return 0.5 * m_b * (vy * vy + vz * vz) + m_b * p.g * z + 0.5 * p.k * (p.rho0 - rho) ** 2

    n = 0
    while n < 8000:
        pre = rob.yz()
        rob.step(0.0)
        n += 1
        touch, _ = rob.toe_contact()
        if phase == "flight" and not touch:
            e_fl.append(rob.energy())
        if phase == "flight" and touch:
            phase = "stance"
            e_td = e_fl[-1]
            toe_ke = 0.5 * v.m_toe * (pre[2] ** 2 + pre[3] ** 2)
        if phase == "stance":
            if touch:
                body_e.append(body_energy())
            else:
                phase = "after"
                v_lo = rob.yz()[2:]
                n_after = n
        if phase == "after" and n - n_after > 400:
            break
    e_end = rob.energy()
    drift = max(abs(e - e0) for e in e_fl) / e0
    check(drift < 1e-6, f"energy constant in flight (relative drift {drift:.1e} < 1e-6)")
    spread = (max(body_e) - min(body_e)) / body_e[0]
    check(spread < 1e-2, f"the body's energy through the stance kept within {spread * 100:.2f} % "
          "(< 1 %: the soft contact's penetration stores and damps up to ~0.1 J)")
    coll = 0.5 * m_b * v.m_toe / (m_b + v.m_toe) * (v_lo[0] ** 2 + v_lo[1] ** 2)
    lost = e_td - e_end
    check(0 < lost < (toe_ke + coll) + 0.01 * e0,
          f"stance loses {lost * 1e3:.1f} mJ <= toe's touchdown KE {toe_ke * 1e3:.1f} mJ + "
          f"(2.12)'s {coll * 1e3:.1f} mJ + 1 % of {e0:.2f} J")

    # 3 flight
    h = Hopper(VARIANTS["mj_clean"], p)
    h.throw(0.0, 0.0, 0.42, 1.8, Command(0.3, 0.0, 0.07))
    errs = []
    while True:
        y, z, vy, vz = h.robot.yz()
        yn, zn, vyn, vzn = flight(p, 0.0, 0.42, 1.8, 0.0, h.robot.data.time)
        errs.append((abs(y - yn), abs(z - zn), abs(vy - vyn), abs(vz - vzn)))
        if z - p.rho0 * math.cos(h.robot.theta()[0]) < 0.02:
            break
        h.robot.step(h._servo())
    e = np.max(np.array(errs), axis=0)
    check(e[0] < 2e-5 and e[1] < 2e-5 and e[2] < 1e-4 and e[3] < 1e-4,
          f"mj_clean: flight is (2.13)-(2.16) within y {e[0] * 1e3:.5f} z {e[1] * 1e3:.5f} mm, "
          f"vy {e[2] * 1e3:.4f} vz {e[3] * 1e3:.4f} mm/s (bounds 0.02 mm, 0.1 mm/s)")
    # the boom's hinges: the body on a sphere keeps its angular momentum about the vertical
    # axis (r^2 azimuth' e^{d_h t} constant, r = 1.65 cos(elevation) + 0.09 the hip's radius),
    # so its forward speed changes as it rises and falls; its height stays near (2.14)
    h = Hopper(VARIANTS["mj_default"], p)
    h.throw(0.0, 0.0, 0.42, 1.8, Command(0.3, 0.0, 0.07))
    rob = h.robot
    L0 = None
    dl = dz = dv = 0.0
    while True:
        y, z, vy, vz = rob.yz()
        t = rob.data.time
        r_hip = R_ELEV * math.cos(rob.q("elevation")) + LEG_OFFSET
        L = r_hip ** 2 * rob.qd("azimuth") * math.exp(p.d_h * t)
        L0 = L0 or L
        dl = max(dl, abs(L / L0 - 1))
        dz = max(dz, abs(z - flight(p, 0.0, 0.42, 1.8, 0.0, t)[1]))
        dv = max(dv, abs(vy - flight(p, 0.0, 0.42, 1.8, 0.0, t)[2]))
        if z - p.rho0 * math.cos(rob.theta()[0]) < 0.02:
            break
        rob.step(h._servo())
    check(dl < 2e-3 and dz < 1.5e-3,
          f"mj_default (boom hinges): angular momentum about the vertical kept within "
          f"{dl * 100:.3f} % (< 0.2 %), height within {dz * 1e3:.2f} mm of (2.14) (< 1.5 mm); "
          f"the forward speed differs from (2.15) by up to {dv * 1e3:.0f} mm/s (the sphere)")

    # 4 stance
    cases = [(0.30, 1.0, 0.25, 0.0, 0.07), (0.35, 1.5, 0.30, 4.0, 0.07),
             (0.40, 2.0, 0.38, 8.0, 0.06), (0.26, 0.8, 0.20, 6.0, 0.08),
             (0.42, 1.2, 0.22, 2.0, 0.065), (0.28, 1.8, 0.42, 8.0, 0.075)]
    worst_v = worst_t = worst_az = worst_av = 0.0
    for z0, v0, th, tau0, tf in cases:
        info, h = one_stride(VARIANTS["mj_clean"], p, z0, v0, Command(th, tau0, tf))
        st = stance(p, info["theta_at_td"], info["vy_td"], info["vz_td"], tau0, tf, dt=1e-4)
        dv = math.hypot(info["vy_lo"] - float(st["vy"]), info["vz_lo"] - float(st["vz"]))
        dt = abs(info["t_stance"] - float(st["t"]))
        zn, vn, ok, _ = next_apex(p, z0, v0, info["theta_at_td"], tau0, tf, dt=1e-4)
        worst_v, worst_t = max(worst_v, dv), max(worst_t, dt)
        worst_az = max(worst_az, abs(info["z_apex"] - float(zn)))
        worst_av = max(worst_av, abs(info["v_apex"] - float(vn)))
    check(worst_v < 0.03 and worst_t < 1.5e-3,
          f"mj_clean's stance is (2.9)'s: lift-off velocity within {worst_v * 1e3:.1f} mm/s, "
          f"stance time within {worst_t * 1e3:.2f} ms (bounds 30 mm/s, 1.5 ms)")
    check(worst_az < 6e-3 and worst_av < 0.06,
          f"mj_clean's next apex is the nominal model's within {worst_az * 1e3:.1f} mm and "
          f"{worst_av * 1e3:.0f} mm/s (bounds 6 mm, 60 mm/s)")

    # 5 recordings
    for name in VARIANTS:
        meas, truth, log, _ = simulate(name, 50 if name == "mj_default" else 4)
        t = meas["t"]
        steps = np.diff(t)
        fine = np.isclose(steps, 1e-3, atol=1e-9) | (steps >= 1.0)
        on_steps = np.allclose(meas["theta"] / (2 * math.pi / MOTOR_COUNTS),
                               np.round(meas["theta"] / (2 * math.pi / MOTOR_COUNTS)), atol=1e-6)
        keys = set(truth) == {"name", "effects", "strides", "seed"} and all(
            set(e) == {"id", "family", "site", "magnitude", "unit", "parameters", "words",
                       "equation"} for e in truth["effects"])
        fails = sum("failure" in e for e in log)
        want = 50 if name == "mj_default" else 4
        check(fine.all() and on_steps and (meas["tau"] <= 0).all() and keys
              and truth["strides"] == want and (name != "mj_default" or fails == 0),
              f"{name}: {truth['strides']} strides, 1 kHz with gaps, theta on encoder steps, "
              f"tau <= 0, truth keys, {fails} failures")
    print(f"{len(FAILS)} failed" if FAILS else "all checks passed")
    return 1 if FAILS else 0


if __name__ == "__main__":
    sys.exit(main())
