"""Plant B self-checks (a few seconds):
  1. stance energy conservation with d = 0, tau = 0;
  2. flight against the closed form (2.13)-(2.16);
  3. the lift-off collision factor (2.12);
  4. sign conventions: touchdown geometry and positive tau_0 pushing forward.
    cd /work/main && .venv/bin/python test/plant_b/check.py
"""
import math
import os
import sys
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from plant_b.plant import Control, Plant, load_params  # noqa: E402

ok = True


def report(name, err, tol):
    global ok
    good = err < tol
    ok &= good
    print("%-48s err %.2e (tol %.0e) %s" % (name, err, tol, "OK" if good else "FAIL"))


p = load_params()

# 1. stance energy with d=0, tau=0
q = replace(p, d=0.0)
P = Plant(q)
th_td = 0.31
x_td = [0.0, q.rho0 * math.cos(th_td), 1.6, -1.7]
st = P.stance(0.0, x_td, th_td, Control(th_td, 0.0, 0.0))
m, g, k = q.m_b, q.g, q.k
E = []
for a, b, sol in st["sols"]:
    for s in np.linspace(a, b, 200):
        rho, th, rd, td = sol(s)
        E.append(0.5 * m * (rd * rd + rho * rho * td * td) + m * g * rho * math.cos(th)
                 + 0.5 * k * (q.rho0 - rho) ** 2)
E = np.array(E)
report("stance energy drift (d=0, tau=0), relative", np.ptp(E) / E[0], 1e-8)
# with d=0 the force event and rho=rho0 coincide: exit at rest length
report("lift-off at rho0 when d=0", abs(st["x_lo"][0] - q.rho0), 1e-9)
# velocity at touchdown recovered from polar state
rho, th, rd, td = st["sols"][0][2](0.0)
vy = -rd * math.sin(th) - rho * td * math.cos(th)
vz = rd * math.cos(th) - rho * td * math.sin(th)
report("touchdown velocity polar<->Cartesian", abs(vy - 1.6) + abs(vz + 1.7), 1e-12)

# 2. flight vs closed form
P = Plant(p)
x0 = [0.1, 0.3, 1.7, 1.2]
t_ap, x_ap, sol = P.flight_to_apex(0.0, x0)
err = 0.0
for t in np.linspace(0, t_ap, 50):
    dh, dv = p.d_h, p.d_v
    y = x0[2] / dh * (1 - math.exp(-dh * t)) + x0[0]                      # (2.13)
    z = (p.g / dv ** 2 * (1 - math.exp(-dv * t) - dv * t)
         + x0[3] / dv * (1 - math.exp(-dv * t)) + x0[1])                   # (2.14)
    yd = x0[2] * math.exp(-dh * t)                                         # (2.15)
    zd = x0[3] * math.exp(-dv * t) - p.g / dv * (1 - math.exp(-dv * t))   # (2.16)
    err = max(err, np.max(np.abs(sol(t) - [y, z, yd, zd])))
report("flight vs closed form (2.13)-(2.16), max abs", err, 1e-9)
t_star = math.log(1 + x0[3] * p.d_v / p.g) / p.d_v
report("apex time vs closed form", abs(t_ap - t_star), 1e-9)

# 3. lift-off factor (2.12)
r = P.stride(0.0, (0.0, 0.34, 1.6), -0.1, Control(0.32, 5.0, 0.06), record=True)
st_end = r["pieces"][-2][2](r["t_lo"] - 1e-12)
asc0 = r["pieces"][-1][2]
f = p.m_b / (p.m_b + p.m_t)
v = P.liftoff((1.3, 0.7))
report("(2.12) factor m_b/(m_b+m_t)", abs(v[0] / 1.3 - f) + abs(v[1] / 0.7 - f), 1e-14)
# position continuity across lift-off (stance piece vs ascent piece)
yA, zA, _ = asc0(r["t_lo"])
report("position continuity at lift-off", abs(st_end[0] - yA) + abs(st_end[1] - zA), 1e-8)

# 4. conventions
x_td = r["x_td"]
report("toe on ground at touchdown (z - rho0 cos th_td)",
       abs(x_td[1] - p.rho0 * math.cos(r["th_td"])), 1e-9)
r1 = P.stride(0.0, (0.0, 0.34, 1.6), -0.1, Control(0.32, 2.0, 0.06))
r2 = P.stride(0.0, (0.0, 0.34, 1.6), -0.1, Control(0.32, 6.0, 0.06))
gain = r2["apex"][2] - r1["apex"][2]
print("positive tau_0 pushes forward: apex speed gain %.3f m/s for +4 N m" % gain)
ok &= gain > 0
print("theta at touchdown %.3f > 0 (toe ahead), at lift-off %.3f" % (r["th_td"], r["th_lo"]))
print("ALL OK" if ok else "SOME CHECKS FAILED")
sys.exit(0 if ok else 1)
