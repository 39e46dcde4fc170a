"""Self-checks of plant C against the thesis (Orhon 2018, ch. 2); exit 1 on any failure.

    python test/plant_c/check.py
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from controller import NominalModel  # noqa: E402
from effects import REGISTRY, make  # noqa: E402
from plant import (DT, Command, Plant, Sensors, concat, flight_closed_form,  # noqa: E402
                   nominal_params)

RESULTS: list[tuple[str, bool, str]] = []


def check(name: str, ok: bool, detail: str) -> None:
    RESULTS.append((name, bool(ok), detail))
    print(f"[{'PASS' if ok else 'FAIL'}] {name}: {detail}")


def one_stride(p, z, v, th, tau0, t_f, mechs=(), nxt=None, y0=0.0):
    plant = Plant(p, list(mechs), seed=3)
    plant.throw(0.0, y0, z, v, th)
    nxt = nxt or Command(theta_td=0.3, tau0=0.0, t_f=0.07, t_swing=0.1)
    r = plant.stride(Command(th, tau0, t_f), lambda *a: Command(**vars(nxt)))
    return plant, r


def check_yaml(p):
    want = dict(m_b=2.20, m_t=0.03, g=11.42, k=4696.0, d=9.87, d_h=0.01, d_v=0.23, rho0=0.205)
    bad = {k: getattr(p, k) for k, v in want.items() if abs(getattr(p, k) - v) > 1e-12}
    check("nominal parameters", not bad, f"config/model.yaml read as {p}" if not bad else
          f"differ from Table 4.1: {bad}")


def check_equations(p):
    """The plant's stance right-hand side is (2.9) (nominal geometry, torque on)."""
    plant = Plant(p, [], seed=0)
    plant.cy0, plant.h_contact, plant.th_td, plant.t_td = 0.1, 0.0, 0.3, 0.0
    plant.cmd = Command(0.3, 5.0, 0.07)
    rng = np.random.default_rng(0)
    err = 0.0
    for _ in range(200):
        rho, th = rng.uniform(0.15, 0.205), rng.uniform(-0.6, 0.6)
        rhod, thd = rng.uniform(-1.5, 1.5), rng.uniform(-12, 2)
        t = rng.uniform(0, 0.09)
        d = plant._stance_rhs(t, np.array([rho, th, rhod, thd]))
        tau = -5.0 * (1 - t / 0.07) if t < 0.07 else 0.0
        m = p.m_b
        rhodd = rho * thd**2 - p.g * math.cos(th) + (p.k * (p.rho0 - rho) - p.d * rhod) / m
        thdd = (m * p.g * rho * math.sin(th) + tau - 2 * m * rho * rhod * thd) / (m * rho**2)
        err = max(err, abs(d[2] - rhodd) / 100, abs(d[3] - thdd) / 100)
    check("stance = (2.9)", err < 1e-12, f"max relative difference {err:.1e} over 200 states")


def check_energy(p):
    """d = 0, tau = 0, no flight damping, no toe mass: energy is conserved over a stride."""
    q = p.but(d=0.0, d_h=1e-12, d_v=1e-12, m_t=0.0)
    worst = 0.0
    for z, v, th in ((0.33, 1.5, 0.3), (0.40, 2.2, 0.45), (0.27, 0.9, 0.22)):
        plant, r = one_stride(q, z, v, th, 0.0, 0.07)
        E0 = 0.5 * q.m_b * v**2 + q.m_b * q.g * z
        ch = concat(r["samples"])
        E = np.where(
            ch["stance"],
            0.5 * q.m_b * (ch["vy"]**2 + ch["vz"]**2) + q.m_b * q.g * ch["z"]
            + 0.5 * q.k * (q.rho0 - np.where(ch["stance"], ch["X"][0], q.rho0))**2,
            0.5 * q.m_b * (ch["vy"]**2 + ch["vz"]**2) + q.m_b * q.g * ch["z"])
        a = r["apex_next"]
        E1 = 0.5 * q.m_b * a["vy"]**2 + q.m_b * q.g * a["z"]
        worst = max(worst, np.max(np.abs(E - E0)) / E0, abs(E1 - E0) / E0)
    check("energy conservation (d = 0, tau = 0)", worst < 1e-7,
          f"max relative energy drift {worst:.1e} over 3 strides (every sample and the apex)")


def check_flight(p):
    """Descent and ascent against the closed form (2.13)-(2.16)."""
    plant, r = one_stride(p, 0.36, 1.7, 0.35, 3.0, 0.06)
    ch = concat(r["samples"])
    fl = ~ch["stance"]
    desc = fl & (ch["t"] < r["t_td"])
    asc = fl & (ch["t"] > r["t_lo"])
    y, z, vy, vz = flight_closed_form(p, 0.0, 0.36, 1.7, 0.0, ch["t"][desc])
    e1 = max(np.max(np.abs(y - ch["y"][desc])), np.max(np.abs(z - ch["z"][desc])),
             np.max(np.abs(vy - ch["vy"][desc])), np.max(np.abs(vz - ch["vz"][desc])))
    lo = r["liftoff"]
    y, z, vy, vz = flight_closed_form(p, lo["y"], lo["z"], lo["vy_after"], lo["vz_after"],
                                      ch["t"][asc] - r["t_lo"])
    e2 = max(np.max(np.abs(y - ch["y"][asc])), np.max(np.abs(z - ch["z"][asc])),
             np.max(np.abs(vy - ch["vy"][asc])), np.max(np.abs(vz - ch["vz"][asc])))
    # the apex: vertical velocity zero, at the closed form's time ln(1 + d_v vz/g)/d_v
    t_ap = math.log1p(p.d_v * lo["vz_after"] / p.g) / p.d_v
    e3 = abs(r["t_next_apex"] - r["t_lo"] - t_ap)
    check("flight = (2.13)-(2.16)", max(e1, e2) < 1e-9 and e3 < 1e-9,
          f"descent {e1:.1e}, ascent {e2:.1e} (m, m/s), apex time {e3:.1e} s "
          f"({desc.sum()} + {asc.sum()} samples)")


def check_collision(p):
    plant, r = one_stride(p, 0.34, 1.6, 0.33, 5.0, 0.07)
    lo = r["liftoff"]
    f = p.m_b / (p.m_b + p.m_t)
    e = max(abs(lo["vy_after"] - f * lo["vy"]), abs(lo["vz_after"] - f * lo["vz"]))
    check("lift-off collision (2.12)", e < 1e-14,
          f"v+ = {lo['vy_after']:.6f}, {lo['vz_after']:.6f} = {f:.6f} v- (error {e:.1e})")
    F = p.k * (p.rho0 - lo["rho"]) - p.d * lo["rhod"]
    ok = abs(F) < 1e-6 or abs(lo["rho"] - p.rho0) < 1e-9
    check("lift-off event (2.28)", ok, f"leg force at lift-off {F:.1e} N, rho0 - rho = "
          f"{p.rho0 - lo['rho']:.2e} m")


def check_touchdown(p):
    worst_z, worst_pin, worst_th = 0.0, 0.0, 0.0
    for z, v, th in ((0.30, 1.0, 0.25), (0.40, 2.2, 0.5), (0.34, 1.6, 0.33)):
        plant, r = one_stride(p, z, v, th, 4.0, 0.07)
        td = r["touchdown"]
        worst_z = max(worst_z, abs(td["z"] - p.rho0 * math.cos(td["theta"])))
        worst_th = max(worst_th, abs(td["theta"] - th))
        ch = concat(r["samples"])
        st = ch["stance"]
        rho = ch["X"][0][st]
        toe_y = ch["y"][st] + rho * np.sin(ch["theta"][st])
        toe_z = ch["z"][st] - rho * np.cos(ch["theta"][st])
        worst_pin = max(worst_pin, np.max(np.abs(toe_y - td["toe_y"])), np.max(np.abs(toe_z)))
    check("touchdown geometry", worst_z < 1e-9 and worst_th < 1e-12 and worst_pin < 1e-12,
          f"|z_td - rho0 cos theta_td| {worst_z:.1e} m, leg at theta_td ({worst_th:.0e}), "
          f"toe pinned in stance to {worst_pin:.1e} m")


def check_torque_sign(p):
    _, r0 = one_stride(p, 0.34, 1.5, 0.33, 0.0, 0.07)
    _, r1 = one_stride(p, 0.34, 1.5, 0.33, 4.0, 0.07)
    ch = concat(r1["samples"])
    st = ch["stance"]
    tau_ok = np.all(ch["tau_cmd"][st] <= 0) and np.all(ch["tau_cmd"][~st] == 0) and \
        abs(ch["tau_cmd"][st][0] + 4.0) < 0.1
    faster = r1["apex_next"]["vy"] > r0["apex_next"]["vy"] + 0.05
    swept = r1["liftoff"]["theta"] < r0["liftoff"]["theta"]
    check("torque sign", tau_ok and faster and swept,
          f"tau_0 = 4 N m logged as -tau_0(1 - s/t_f) in stance, 0 in flight: {tau_ok}; next "
          f"apex speed {r0['apex_next']['vy']:.3f} -> {r1['apex_next']['vy']:.3f} m/s; lift-off "
          f"angle {r0['liftoff']['theta']:.3f} -> {r1['liftoff']['theta']:.3f} rad")


def check_controller_model(p):
    model = NominalModel(p)
    worst_z, worst_v = 0.0, 0.0
    for z, v, th, tau0, tf in ((0.30, 1.0, 0.25, 2.0, 0.065), (0.40, 2.2, 0.45, 8.0, 0.06),
                               (0.34, 1.6, 0.33, 5.0, 0.07)):
        _, r = one_stride(p, z, v, th, tau0, tf)
        zn, vn, ok, _ = model.next_apex(z, v, np.array([th]), np.array([tau0]), tf)
        worst_z = max(worst_z, abs(zn[0] - r["apex_next"]["z"]))
        worst_v = max(worst_v, abs(vn[0] - r["apex_next"]["vy"]))
    check("controller's model = plant (nominal)", worst_z < 3e-4 and worst_v < 3e-3,
          f"next apex differs by {worst_z * 1e3:.3f} mm, {worst_v * 1e3:.2f} mm/s")


def check_recording():
    import suite

    meas, truth, log = suite.simulate("check", [], 7, strides=16)
    with tempfile.TemporaryDirectory() as tmp:
        suite.write(Path(tmp), "check", meas, truth)
        text = (Path(tmp) / "check.csv").read_text().splitlines()
        header = text[0]
        data = np.loadtxt(Path(tmp) / "check.csv", delimiter=",", skiprows=1)
        js = json.loads((Path(tmp) / "check.json").read_text())
    t, y, z, th, tau = data.T
    dt = np.diff(t)
    gaps = dt[dt > 1.5 * DT]
    steady = np.all(np.abs(dt[dt <= 1.5 * DT] - DT) < 1e-9)
    sn = Sensors()
    quant = np.max(np.abs(th / sn.dtheta - np.round(th / sn.dtheta)))
    runs = np.split(np.arange(len(t)), np.nonzero(dt > 1.5 * DT)[0] + 1)
    ok = (header == "t,y,z,theta,tau" and steady and np.all(gaps >= 1.0) and quant < 1e-3
          and np.all(tau <= 0) and js["strides"] == 16 and len(runs) >= 2 and js["effects"] == []
          and set(js) == {"name", "effects", "strides", "seed"})
    check("recording format", ok,
          f"header {header!r}, 1 kHz {steady}, {len(runs)} runs, gaps >= {gaps.min() if len(gaps) else 0:.2f} s, "
          f"theta on its {sn.dtheta:.3e} rad steps ({quant:.0e}), tau <= 0, {js['strides']} "
          "strides in the truth")


def check_mechanisms(p):
    """Every mechanism runs a stride, describes itself fully and changes what is measured."""
    import impact

    keys = {"id", "family", "site", "magnitude", "unit", "parameters", "words", "equation"}
    bad = []
    for mid in REGISTRY:
        m = make(mid)
        tr = m.truth()
        if set(tr) != keys or not tr["words"] or not tr["equation"] or tr["magnitude"] == 0:
            bad.append(f"{mid}: truth incomplete")
        w = impact.impact(mid) if len(sys.argv) > 1 and sys.argv[1] == "--impact" else None
        if w is not None and max(w["y"], w["z"], w["theta"]) < 3:
            bad.append(f"{mid}: changes less than 3 noise units")
    check("mechanisms", not bad, f"{len(REGISTRY)} mechanisms described" if not bad else
          "; ".join(bad))


def main() -> int:
    t0 = time.time()
    p = nominal_params()
    check_yaml(p)
    check_equations(p)
    check_energy(p)
    check_flight(p)
    check_collision(p)
    check_touchdown(p)
    check_torque_sign(p)
    check_controller_model(p)
    check_recording()
    check_mechanisms(p)
    n_bad = sum(not ok for _, ok, _ in RESULTS)
    print(f"{len(RESULTS) - n_bad}/{len(RESULTS)} checks passed in {time.time() - t0:.1f} s")
    return 1 if n_bad else 0


if __name__ == "__main__":
    sys.exit(main())
