"""Plant B recording suite.

    cd /work/main && .venv/bin/python test/plant_b/suite.py OUT_DIR [names...]

writes OUT_DIR/<name>.csv (t,y,z,theta,tau at 1 kHz) and OUT_DIR/<name>.json
(truth) for each recording, and prints strides, runs and apex impact.
"""
from __future__ import annotations

import json
import math
import os
import sys
import zlib

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    __package__ = "plant_b"

from plant_b import effects as E                       # noqa: E402
from plant_b.controller import ApexController          # noqa: E402
from plant_b.plant import Fall, Plant, commanded_torque, load_params  # noqa: E402

N_STRIDES = 50
Q_Y, Q_Z, Q_TH = 0.21e-3, 0.17e-3, 2 * math.pi / 52000   # encoder resolutions
SIG_YZ, SIG_TH = 1.0e-4, 5.0e-4                           # noise std
APEX_Z_OK = (0.24, 0.47)
APEX_V_OK = (0.5, 2.9)


def recordings():
    """name -> list of effects (deterministic)."""
    R = {
        "clean": [],
        "s01_quadratic_drag": [E.QuadraticDrag(0.047)],
        "s02_boom_descent_drag": [E.BoomDescentDrag(0.61)],
        "s03_gravity_error": [E.GravityError(-0.147)],
        "s04_softening_spring": [E.SofteningSpring(11300.0)],
        "s05_extension_damping": [E.AsymmetricDamping(6.3)],
        "s06_unsprung_toe": [E.UnsprungToeImpact(0.047)],
        "s07_undulating_floor": [E.FloorUndulation(0.0213, 10.9, 0.6)],
        "s08_backemf": [E.BackEMF(137.0)],
        "s09_torque_deadband": [E.TorqueDeadband(0.27)],
        "s10_harder_liftoff": [E.HeavierLiftoffCollision(0.037)],
        "s11_z_scale": [E.ZScale(0.023)],
        "s12_theta_delay": [E.ThetaDelay(0.0027)],
        "s13_theta_backlash": [E.ThetaBacklash(0.0093)],
        "o1_cogging_ripple": [E.CoggingRipple(0.83, 0.71, 1.1)],
        "o2_stiffness_drift": [E.StiffnessDrift(-0.087)],
        "o3_torque_axial_coupling": [E.TorqueAxialCoupling(1.6)],
        "o4_boom_ringing": [E.BoomRinging(1.9, 7.3, 0.12)],
        "o5_tether_pull": [E.TetherPull(0.21)],
        "p1_drag_and_deadband": [E.QuadraticDrag(0.031), E.TorqueDeadband(0.21)],
        "p2_softspring_and_zscale": [E.SofteningSpring(8600.0), E.ZScale(-0.017)],
        "p3_toeimpact_and_harderliftoff": [E.UnsprungToeImpact(0.036),
                                           E.HeavierLiftoffCollision(0.029)],
    }
    return R


def seed_of(name):
    return zlib.crc32(name.encode()) % 100000


def _eval_pieces(pieces, t):
    """Evaluate the (start, end, fn) pieces of one run at times t."""
    starts = np.array([p[0] for p in pieces])
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(pieces) - 1)
    y = np.empty_like(t)
    z = np.empty_like(t)
    th = np.empty_like(t)
    for i in np.unique(idx):
        m = idx == i
        a, b, fn = pieces[i]
        tt = np.clip(t[m], a, b)
        yy, zz, hh = fn(tt)
        y[m], z[m], th[m] = yy, zz, hh
    return y, z, th


def _tau_log(stance_windows, t):
    tau = np.zeros_like(t)
    for t_td, t_lo, c in stance_windows:
        m = (t >= t_td) & (t < t_lo)
        s = t[m] - t_td
        tau[m] = np.where(s < c.t_f, -c.tau0 * (1 - s / c.t_f), 0.0)
    return tau


def simulate(name, effs, seed, n_strides=N_STRIDES, impact=True):
    rng = np.random.default_rng(seed)
    ctrl = ApexController(np.random.default_rng(seed + 1))
    params = load_params()
    plant = Plant(params, effs)
    plant.ctx["n_strides"] = n_strides
    nominal = Plant(params, ())
    singles = [Plant(params, [e]) for e in effs] if len(effs) > 1 else []
    for sp in singles:
        sp.ctx["n_strides"] = n_strides
    per_eff = [[] for _ in singles]
    rows = []
    clean_rows = []
    impacts = []
    strides = 0
    runs = 0
    t_next = 0.5
    y_next = 0.0
    stride_log = []
    while strides < n_strides:
        runs += 1
        t0 = round(t_next, 3)
        apex = (y_next, rng.uniform(0.30, 0.41), rng.uniform(1.2, 2.3))
        th_prev = rng.uniform(-0.3, 0.0)
        plant.ctx["t_lo"] = None
        pieces, windows = [], []
        n_run = int(rng.integers(7, 16))
        t = t0
        k = 0
        while k < n_run and strides < n_strides:
            c = ctrl.command(apex, th_prev)
            plant.ctx["stride"] = strides
            prev_tlo = plant.ctx["t_lo"]
            try:
                r = plant.stride(t, apex, th_prev, c, record=True)
            except Fall:
                break
            if impact and effs:
                try:
                    rn = nominal.stride(t, apex, th_prev, c)
                    impacts.append(((r["apex"][1] - rn["apex"][1]) / rn["apex"][1],
                                    (r["apex"][2] - rn["apex"][2]) / rn["apex"][2]))
                    for j, sp in enumerate(singles):
                        sp.ctx["stride"] = strides
                        sp.ctx["t_lo"] = prev_tlo
                        rs = sp.stride(t, apex, th_prev, c)
                        per_eff[j].append(max(
                            abs(rs["apex"][1] - rn["apex"][1]) / rn["apex"][1],
                            abs(rs["apex"][2] - rn["apex"][2]) / rn["apex"][2]))
                except Fall:
                    pass
            pieces += r["pieces"]
            windows.append((r["t_td"], r["t_lo"], c))
            stride_log.append({"run": runs, "theta_td": c.theta_td, "tau0": c.tau0,
                               "t_f_frac": c.t_f / r["stance_time"],
                               "apex_z": r["apex"][1], "apex_v": r["apex"][2]})
            strides += 1
            k += 1
            t, apex, th_prev = r["t_apex"], r["apex"], r["th_lo"]
            if not (APEX_Z_OK[0] < apex[1] < APEX_Z_OK[1]
                    and APEX_V_OK[0] < apex[2] < APEX_V_OK[1]):
                break          # a fall: caught, thrown again
        if pieces:
            t_end = pieces[-1][1]
            ms = np.arange(math.ceil(t0 * 1000 - 1e-9), math.floor(t_end * 1000 + 1e-9) + 1)
            tt = ms / 1000.0
            y, z, th = _eval_pieces(pieces, tt)
            delay = sum(e.theta_delay() for e in effs)
            if delay:
                _, _, th = _eval_pieces(pieces, np.maximum(tt - delay, t0))
            y0, z0, th0 = y.copy(), z.copy(), th.copy()
            if delay:
                _, _, th0 = _eval_pieces(pieces, tt)
            for e in effs:
                y, z, th = e.sensor(tt, y, z, th)
            tau = _tau_log(windows, tt)
            rows.append((ms, y, z, th, tau))
            clean_rows.append((y0, z0, th0))
            t_next = t_end + rng.uniform(1.2, 2.8)
            y_next = y[-1] + rng.uniform(-0.5, 0.5)
        else:
            t_next = t_next + 1.0
    # noise + quantisation
    nrng = np.random.default_rng(seed + 2)
    out = []
    for ms, y, z, th, tau in rows:
        yq = np.round((y + nrng.normal(0, SIG_YZ, y.shape)) / Q_Y) * Q_Y
        zq = np.round((z + nrng.normal(0, SIG_YZ, z.shape)) / Q_Z) * Q_Z
        thq = np.round((th + nrng.normal(0, SIG_TH, th.shape)) / Q_TH) * Q_TH
        out.append((ms, yq + 0.0, zq + 0.0, thq + 0.0, tau + 0.0))
    sens = {}
    for ch, i in (("y", 1), ("z", 2), ("theta", 3)):
        d = np.concatenate([r[i] - c[i - 1] for r, c in zip(rows, clean_rows)])
        sens[ch] = float(np.sqrt(np.mean(d * d)))
    imp = np.array(impacts) if impacts else np.zeros((1, 2))
    summary = {
        "runs": runs if rows else 0,
        "apex_z_pct_median": float(np.median(np.abs(imp[:, 0])) * 100),
        "apex_v_pct_median": float(np.median(np.abs(imp[:, 1])) * 100),
        "apex_z_pct_mean_signed": float(np.mean(imp[:, 0]) * 100),
        "apex_v_pct_mean_signed": float(np.mean(imp[:, 1]) * 100),
        "sensor_rms": sens,
        "per_effect_pct_median": {e.id: float(np.median(v) * 100)
                                  for e, v in zip(effs, per_eff) if v},
    }
    return out, strides, summary, stride_log


def write(out_dir, name, effs, seed, out, strides, summary):
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, name + ".csv"), "w") as fh:
        fh.write("t,y,z,theta,tau\n")
        for ms, y, z, th, tau in out:
            for i in range(len(ms)):
                fh.write("%.3f,%.5f,%.5f,%.6f,%.5f\n" % (ms[i] / 1000.0, y[i], z[i],
                                                       th[i], tau[i]))
    truth = {"name": name, "effects": [e.describe() for e in effs],
             "strides": strides, "seed": seed, "runs": summary["runs"],
             "apex_impact": summary}
    with open(os.path.join(out_dir, name + ".json"), "w") as fh:
        json.dump(truth, fh, indent=1)


def main(argv):
    if not argv:
        print(__doc__)
        return 2
    out_dir, names = argv[0], argv[1:]
    R = recordings()
    names = names or list(R)
    for n in names:
        if n not in R:
            print("unknown recording", n, "choices:", ", ".join(R))
            return 2
    for n in names:
        seed = seed_of(n)
        out, strides, summ, slog = simulate(n, R[n], seed)
        write(out_dir, n, R[n], seed, out, strides, summ)
        ids = ",".join("%s=%g" % (e.id, e.magnitude) for e in R[n]) or "-"
        th = [s["theta_td"] for s in slog]
        ta = [s["tau0"] for s in slog]
        az = [s["apex_z"] for s in slog]
        av = [s["apex_v"] for s in slog]
        print("%-30s strides %2d runs %d | apex dz %.2f%% dv %.2f%% (median |.|) "
              "sensor rms z %.1e th %.1e | th_td %.2f-%.2f tau0 %.1f-%.1f "
              "z %.3f-%.3f v %.2f-%.2f | %s" % (
                  n, strides, summ["runs"], summ["apex_z_pct_median"],
                  summ["apex_v_pct_median"], summ["sensor_rms"]["z"],
                  summ["sensor_rms"]["theta"], min(th), max(th), min(ta), max(ta),
                  min(az), max(az), min(av), max(av), ids), flush=True)
        for eid, v in summ["per_effect_pct_median"].items():
            print("    %-34s alone: apex max(|dz|,|dv|) median %.2f%%" % (eid, v))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
