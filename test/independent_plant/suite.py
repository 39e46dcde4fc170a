"""The judge's suite: recordings of the independent plant with known concealed effects.

    write_suite(folder, names=None)  ->  <name>.csv and <name>.json per recording

CLI (from the repository root):
    .venv/bin/python test/independent_plant/suite.py OUT_DIR [names...]
    .venv/bin/python -m test.independent_plant.suite OUT_DIR [names...]   (if `test` is a package)
    cd test && ../.venv/bin/python -m independent_plant.suite OUT_DIR [names...]
"""

from __future__ import annotations

import json
import math
import sys
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):              # run as a script: make the package importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    __package__ = "independent_plant"

import numpy as np

from . import effects as fx
from .plant import Effect, Fall, Model, Plant, Servo, StrideCommand
from .runner import NoiseSpec, measure, simulate, write_csv

STRIDES = 50
MODEL_YAML = Path(__file__).resolve().parents[2] / "config" / "model.yaml"


def nominal_model() -> Model:
    try:
        return Model.from_yaml(MODEL_YAML)
    except (OSError, KeyError):
        return Model()


@dataclass
class Spec:
    name: str
    make: callable                      # () -> list of Effect (fresh objects)
    noise: NoiseSpec = field(default_factory=NoiseSpec)
    note: str = ""

    @property
    def seed(self) -> int:
        return zlib.crc32(self.name.encode()) & 0x7FFFFFFF


def _specs() -> list:
    S = []

    def add(name, make, note=""):
        S.append(Spec(name, make, note=note))

    # clean
    add("clean_1", lambda: [])
    add("clean_2", lambda: [])
    # flight resistance
    add("flight_air_drag", lambda: [fx.QuadraticDrag(0.05)])
    add("flight_boom_coulomb", lambda: [fx.BoomBearingCoulomb(0.15)])
    add("flight_damping_vertical", lambda: [fx.ExtraVerticalDamping(0.6)])
    add("flight_damping_horizontal", lambda: [fx.ExtraHorizontalDamping(0.12)])
    # boom
    add("boom_gravity", lambda: [fx.GravityError(10.95)])
    add("boom_inertia", lambda: [fx.BoomHorizontalInertia(0.2)])
    # touchdown
    add("touchdown_loss_along", lambda: [fx.TouchdownLossAlong(0.05)])
    add("touchdown_loss_across", lambda: [fx.TouchdownLossAcross(0.05)])
    # the leg in stance
    add("leg_stiffness", lambda: [fx.StiffnessError(450.0)])
    add("leg_rest_length", lambda: [fx.RestLengthError(0.003)])
    add("leg_cubic_spring", lambda: [fx.CubicSpring(8e5)])
    add("leg_quadratic_damping", lambda: [fx.QuadraticLegDamping(3.0)])
    add("leg_slide_coulomb", lambda: [fx.LegCoulomb(5.0)])
    add("ground_compliant", lambda: [fx.CompliantGround(40000.0, 150.0)])
    # the hip actuator
    add("actuator_gain", lambda: [fx.ActuatorGain(0.85)])
    add("actuator_offset", lambda: [fx.ActuatorOffset(0.5)])
    add("actuator_delay", lambda: [fx.ActuatorDelay(0.010)])
    add("actuator_lag", lambda: [fx.ActuatorLag(0.012)])
    add("actuator_saturation", lambda: [fx.ActuatorSaturation(5.0)])
    add("hip_friction_viscous", lambda: [fx.HipViscous(0.05)])
    add("hip_friction_coulomb", lambda: [fx.HipCoulomb(0.4)])
    # lift-off
    add("liftoff_toe_mass", lambda: [fx.ToeMassError(0.09)])
    # sensors
    add("sensor_z_delay", lambda: [fx.SensorDelay(0.004, "z")])
    add("sensor_y_scale", lambda: [fx.SensorScale(1.03, "y")])
    add("sensor_theta_offset", lambda: [fx.SensorOffset(0.02, "theta")])
    # other effects
    add("other_flight_lift", lambda: [fx.FlightLift(0.5)])
    add("other_tether", lambda: [fx.Tether(40.0, 0.31)])
    add("other_hip_torsion_spring", lambda: [fx.HipTorsionSpring(2.5)])
    add("other_ground_higher", lambda: [fx.GroundHigher(0.008)])
    add("other_toe_slip", lambda: [fx.ToeSlip(0.40, mu_s=0.45)])
    add("other_bump_stop", lambda: [fx.BumpStop(4000.0, 0.025)])
    add("other_boom_bending", lambda: [fx.BoomBending(0.001, 18.0, 0.06)])
    # pairs acting in different phases
    add("pair_drag_gain", lambda: [fx.QuadraticDrag(0.05), fx.ActuatorGain(0.85)])
    add("pair_tdalong_hipviscous", lambda: [fx.TouchdownLossAlong(0.05), fx.HipViscous(0.05)])
    add("pair_stiffness_thetaoffset", lambda: [fx.StiffnessError(450.0), fx.SensorOffset(0.02, "theta")])
    add("pair_toemass_delay", lambda: [fx.ToeMassError(0.09), fx.ActuatorDelay(0.010)])
    add("pair_lift_ground", lambda: [fx.FlightLift(0.5), fx.CompliantGround(40000.0, 150.0)])
    add("pair_coulomb_cubic", lambda: [fx.BoomBearingCoulomb(0.15), fx.CubicSpring(8e5)])
    return S


SPECS = {s.name: s for s in _specs()}

# reference strides for the impact figures: apex z, apex speed, theta_td, tau_0, t_f
REFERENCE_STRIDES = ((0.31, 1.8, 0.39, 6.5, 0.058), (0.35, 1.5, 0.37, 7.5, 0.060),
                     (0.29, 2.2, 0.42, 5.5, 0.056))


def one_stride(plant: Plant, za, va, theta, tau0, t_f):
    servo = Servo(0.0, theta, 0.0, theta, plant.servo_T)
    _, ttd, xtd, thtd = plant.descend(0.0, np.array([0.0, za, va, 0.0]), servo)
    r = plant.stance(ttd, xtd, thtd, StrideCommand(theta, tau0, t_f))
    _, ta, xa = plant.ascend(r.t_lo, r.x_lo, Servo(r.t_lo, r.theta_lo, r.thetadot_lo, theta))
    return np.array([xa[1], xa[2], ta, r.t_lo - r.t_td])


def impact(effect: Effect, model: Model) -> dict | None:
    """Mean change of the next apex (height, speed) over the reference strides, same inputs."""
    if effect.acts_in == ("sensor",):
        return None
    nominal, true = Plant(model), Plant(model, [effect])
    dz, dv, rz, rv, rt = [], [], [], [], []
    for ref in REFERENCE_STRIDES:
        try:
            a, b = one_stride(nominal, *ref), one_stride(true, *ref)
        except Fall:
            continue
        dz.append(b[0] - a[0]); dv.append(b[1] - a[1])
        rz.append((b[0] - a[0]) / a[0]); rv.append((b[1] - a[1]) / a[1])
        rt.append((b[2] - a[2]) / a[2])
    if not dz:
        return None
    return {"apex_height_change_m": float(np.mean(dz)), "apex_speed_change_mps": float(np.mean(dv)),
            "apex_height_change_pct": 100 * float(np.mean(rz)),
            "apex_speed_change_pct": 100 * float(np.mean(rv)),
            "stride_time_change_pct": 100 * float(np.mean(rt)),
            "reference_strides": [list(r) for r in REFERENCE_STRIDES]}


def make_recording(spec: Spec, model: Model | None = None, strides: int = STRIDES,
                   noise: NoiseSpec | None = None):
    model = model or nominal_model()
    noise = noise or spec.noise
    effects = spec.make()
    seq = np.random.SeedSequence(spec.seed)
    rng_run, rng_noise = (np.random.default_rng(s) for s in seq.spawn(2))
    plant = Plant(model, effects)
    traj = simulate(plant, strides, rng_run)
    t, y, z, th, tau = measure(traj, effects, noise, rng_noise)
    ap = np.array(traj.apexes)
    cmds = [s.cmd for s in traj.stances]
    truth = {
        "name": spec.name,
        "seed": spec.seed,
        "model": model.as_dict(),
        "effects": [dict(e.describe(), impact=impact(e, model)) for e in effects],
        "noise": noise.as_dict(),
        "strides": len(traj.stances),
        "runs": len(traj.runs),
        "falls": traj.falls,
        "fall_reasons": traj.fall_reasons,
        "samples": int(t.size),
        "ranges": {
            "apex_height_m": [float(ap[:, 2].min()), float(ap[:, 2].max())],
            "apex_speed_mps": [float(ap[:, 3].min()), float(ap[:, 3].max())],
            "theta_td_rad": [min(c.theta_td for c in cmds), max(c.theta_td for c in cmds)],
            "tau_0_Nm": [min(c.tau_0 for c in cmds), max(c.tau_0 for c in cmds)],
            "t_f_s": [min(c.t_f for c in cmds), max(c.t_f for c in cmds)],
            "stance_time_s": [min(s.t_lo - s.t_td for s in traj.stances),
                              max(s.t_lo - s.t_td for s in traj.stances)],
        },
        "conventions": ("tau column = commanded torque -tau_0 (1 - s/t_f) from the true touchdown "
                        "until min(t_f, lift-off), 0 otherwise; theta positive with the toe ahead; "
                        "z above the assumed ground"),
    }
    return (t, y, z, th, tau), truth, traj


def write_suite(folder, names=None, verbose: bool = False, noise: NoiseSpec | None = None) -> list:
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    names = list(names) if names else list(SPECS)
    unknown = [n for n in names if n not in SPECS]
    if unknown:
        raise KeyError(f"unknown recordings: {unknown}; known: {list(SPECS)}")
    written = []
    for name in names:
        t0 = time.perf_counter()
        cols, truth, _ = make_recording(SPECS[name], noise=noise)
        write_csv(folder / f"{name}.csv", *cols)
        (folder / f"{name}.json").write_text(json.dumps(truth, indent=1) + "\n")
        written.append(name)
        if verbose:
            print(f"{name}: {truth['strides']} strides, {truth['runs']} runs, "
                  f"{time.perf_counter() - t0:.1f} s", flush=True)
    return written


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        print("recordings:", " ".join(SPECS))
        return 0 if argv else 2
    t0, c0 = time.perf_counter(), time.process_time()
    written = write_suite(argv[0], argv[1:] or None, verbose=True)
    print(f"{len(written)} recordings in {time.perf_counter() - t0:.1f} s "
          f"({time.process_time() - c0:.1f} s CPU) -> {argv[0]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
