"""How much each mechanism changes a stride, against the sensors' noise.

    python test/plant_c/impact.py [ids...]

For a few apex states and inputs spanning the envelope, one stride is simulated with the
nominal plant and with the mechanism alone (same apex, same command, same next command); the
table gives the largest change of the next apex (height, speed) and of the measured channels
(noise-free, before quantisation: the mechanisms' sensor hooks applied) over the stride, in
units of the channels' noise (y, z: 0.2 mm white + 0.21 mm steps; theta: 0.12 mrad steps).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from effects import REGISTRY, make  # noqa: E402
from plant import Command, Plant, Sensors, concat, nominal_params  # noqa: E402

CONDITIONS = [  # z_a, v_a, theta_td, tau0, t_f
    (0.30, 1.0, 0.25, 2.0, 0.065),
    (0.34, 1.6, 0.33, 5.0, 0.070),
    (0.40, 2.2, 0.45, 8.0, 0.060),
    (0.27, 1.4, 0.30, 0.0, 0.070),
    (0.36, 1.9, 0.40, 6.0, 0.075),
]
NEXT = Command(theta_td=0.35, tau0=0.0, t_f=0.07, t_swing=0.10)


def one(mechs, cond, y0=3.0):
    z, v, th, tau0, tf = cond
    plant = Plant(nominal_params(), mechs, seed=5)
    plant.throw(0.0, y0, z, v, th)
    r = plant.stride(Command(th, tau0, tf), lambda *a: Command(**vars(NEXT)))
    ch = concat(r["samples"])
    ch["meas"] = {"y": ch["y"].copy(), "z": ch["z"].copy(), "theta": ch["theta"].copy()}
    for m in plant.mechs:
        if m.sense is not None:
            m.sense(ch)
    return r, ch


def impact(mid: str) -> dict:
    sn = Sensors()
    noise = {"y": np.hypot(sn.sigma_y, sn.dy / 12**0.5), "z": np.hypot(sn.sigma_z, sn.dz / 12**0.5),
             "theta": sn.dtheta / 12**0.5}
    worst = dict(dz_apex=0.0, dv_apex=0.0, y=0.0, z=0.0, theta=0.0)
    for cond in CONDITIONS:
        r0, c0 = one([], cond)
        r1, c1 = one([make(mid)], cond)
        worst["dz_apex"] = max(worst["dz_apex"], abs(r1["apex_next"]["z"] - r0["apex_next"]["z"]))
        worst["dv_apex"] = max(worst["dv_apex"], abs(r1["apex_next"]["vy"] - r0["apex_next"]["vy"]))
        n = min(len(c0["t"]), len(c1["t"]))
        for k in ("y", "z", "theta"):
            d = np.max(np.abs(c1["meas"][k][:n] - c0["meas"][k][:n]))
            worst[k] = max(worst[k], d / noise[k])
    return worst


def main(ids):
    ids = ids or list(REGISTRY)
    print(f"{'mechanism':26s} {'dz_apex mm':>10s} {'dv_apex mm/s':>12s} "
          f"{'y/noise':>8s} {'z/noise':>8s} {'theta/noise':>11s}")
    for mid in ids:
        w = impact(mid)
        print(f"{mid:26s} {1e3 * w['dz_apex']:10.2f} {1e3 * w['dv_apex']:12.1f} "
              f"{w['y']:8.1f} {w['z']:8.1f} {w['theta']:11.1f}")


if __name__ == "__main__":
    main(sys.argv[1:])
