"""How much each recording's robot changes one stride, against the nominal model and against
mj_default:  python test/mujoco_plant/impact.py

Five apex states and inputs across the envelope; the same throw and command in each variant;
the next apex (z, y') compared with the nominal model's prediction (nominal.py) from the same
apex and inputs, and with mj_default's.  Prints the largest differences over the five."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from check import one_stride  # noqa: E402
from controller import Command  # noqa: E402
from nominal import load_nominal, next_apex  # noqa: E402
from suite import VARIANTS  # noqa: E402

STATES = [(0.30, 1.0, 0.25, 0.0, 0.07), (0.35, 1.5, 0.30, 4.0, 0.07),
          (0.40, 2.0, 0.38, 8.0, 0.06), (0.26, 0.8, 0.20, 6.0, 0.08),
          (0.42, 1.2, 0.22, 2.0, 0.065)]


def main() -> int:
    p = load_nominal()
    res = {}
    for name, v in VARIANTS.items():
        out = []
        for z0, v0, th, tau0, tf in STATES:
            info, _ = one_stride(v, p, z0, v0, Command(th, tau0, tf))
            zn, vn, _, _ = next_apex(p, z0, v0, info["theta_at_td"], tau0, tf, dt=1e-4)
            out.append((info["z_apex"], info["v_apex"], float(zn), float(vn)))
        res[name] = out
    print(f"{'recording':17s} | vs nominal: max |dz| mm, max |dv| mm/s | vs mj_default: max |dz| mm,"
          " max |dv| mm/s")
    for name, out in res.items():
        dzn = max(abs(a[0] - a[2]) for a in out) * 1e3
        dvn = max(abs(a[1] - a[3]) for a in out) * 1e3
        dzd = max(abs(a[0] - b[0]) for a, b in zip(out, res["mj_default"])) * 1e3
        dvd = max(abs(a[1] - b[1]) for a, b in zip(out, res["mj_default"])) * 1e3
        print(f"{name:17s} | {dzn:6.1f} {dvn:6.0f} | {dzd:6.1f} {dvd:6.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
