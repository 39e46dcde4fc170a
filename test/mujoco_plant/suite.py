"""The MuJoCo plant's recordings, in plant C's format (test/plant_c/README.md).

    python test/mujoco_plant/suite.py OUT_DIR [names...]

writes OUT_DIR/<name>.csv (header t,y,z,theta,tau; 1 kHz; runs of 7-13 strides separated by
gaps of 1.5-2.0 s without samples; each run from a throw at an apex to an apex) and
OUT_DIR/<name>.json (the truth: {"name", "effects": [...], "strides", "seed"}).  Every
difference of the recording from the nominal model of the thesis is an effect in the truth.
Deterministic: each case has its own seed.  Prints, per recording, how far each stride's next
apex is from the nominal model's prediction (nominal.py) from the same apex and inputs.
"""

from __future__ import annotations

import json
import math
import sys
import time
from multiprocessing import Pool
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from controller import ENVELOPE_V, ENVELOPE_Z, Controller  # noqa: E402
from model import GEAR, R_AZ, ROTOR_INERTIA, GEAR_VISCOUS, Variant  # noqa: E402
from nominal import load_nominal, next_apex  # noqa: E402
from sim import Hopper, StrideFailure, encoders  # noqa: E402

STRIDES = 50
RUN_STRIDES = (7, 14)
GAP = (1.5, 2.0)

DEFAULT = Variant()
VARIANTS = {
    "mj_default": DEFAULT,
    "mj_stiff_contact": DEFAULT.but(name="mj_stiff_contact", contact_solref=(0.0005, 1.0)),
    "mj_light_leg": DEFAULT.but(name="mj_light_leg", m_body=2.20, m_leg=0.0, i_leg=0.0),
    "mj_clean": Variant(name="mj_clean", boom="planar", m_body=2.20, m_leg=0.0, i_leg=0.0,
                        m_toe=0.03, r_toe=0.001, hip_armature=0.0, hip_damping=0.0,
                        contact_solref=(0.0005, 1.0)),
    "mj_hip_friction": DEFAULT.but(name="mj_hip_friction", hip_frictionloss=0.4),
    "mj_round_toe": DEFAULT.but(name="mj_round_toe", r_toe=0.025),
    "mj_tilted_floor": DEFAULT.but(name="mj_tilted_floor", floor_tilt=0.010, floor_tilt_dir=0.7),
}
SEEDS = {name: 5001 + i for i, name in enumerate(VARIANTS)}


# ------------------------------------------------------------------------------ the truth

def _effect(id_, family, site, magnitude, unit, parameters, words, equation):
    return {"id": id_, "family": family, "site": site, "magnitude": float(magnitude),
            "unit": unit, "parameters": parameters, "words": words, "equation": equation}


def effects(v: Variant) -> list[dict]:
    """Every way the MuJoCo robot of variant v differs from the nominal extended TD-SLIP."""
    p = load_nominal()
    out = []
    a, b = v.contact_solref
    d0, d1, w = v.contact_solimp[:3]
    out.append(_effect(
        "soft_contact", "compliant, damped floor contact (MuJoCo soft constraint)",
        "touchdown, stance", a, "s",
        {"solref": list(v.contact_solref), "solimp": list(v.contact_solimp),
         "friction": v.friction, "cone": "pyramidal", "condim": 3, "timestep": v.timestep,
         "integrator": v.integrator},
        f"The toe meets the floor through MuJoCo's soft contact: the constraint's reference "
        f"acceleration is a spring-damper of time constant {a * 1e3:g} ms and damping ratio "
        f"{b:g} mixed with the free motion by the impedance d = {d0:g}..{d1:g} (over "
        f"{w * 1e3:g} mm of penetration), so the toe sinks into the floor (about "
        f"{'1' if a >= 0.002 else '0.2-0.4'} mm at peak force) and can creep tangentially "
        "(friction 1.0 as a soft pyramidal cone); the leg spring acts in series with it.",
        "a_ref = -b v_n - k pen, b = 2/(d_max T), k = d(pen)/(d_max^2 T^2 zeta^2); "
        "contact acceleration = d a_ref + (1 - d) a_free"))
    out.append(_effect(
        "toe_mass_in_flight", "the toe's mass moves with the body in flight and is stopped at "
        "touchdown", "touchdown, stance", v.m_toe, "kg", {"m_toe": v.m_toe, "r_toe": v.r_toe},
        f"The toe ({v.m_toe * 1e3:g} g, below the spring) is a body of its own all the time, not "
        "only at the lift-off collision (2.12): it flies with the body, is stopped by the floor "
        "at touchdown (its momentum lost, about 0.5 m_t |v_td|^2 = 0.6-0.8 % of the stride's "
        "energy) and its inertia rides on the spring in stance; at lift-off it is jerked up by "
        "the leg's stopper (the joint limit, near (2.12)) and rings on the spring after.",
        "m_t toe'' = -k(rho - rho0) - d rho' (+ contact, + stopper); "
        "touchdown: toe velocity -> 0"))
    if v.r_toe >= 0.002:
        out.append(_effect(
            "round_toe", "the toe is a sphere rolling on the floor", "touchdown, stance",
            v.r_toe, "m", {"r_toe": v.r_toe},
            f"The toe is a sphere of radius {v.r_toe * 1e3:g} mm: its contact point is below the "
            "sphere's centre, not on the leg's axis, so it rolls forward r_toe per radian of "
            "leg rotation and touchdown comes r_toe (1 - cos theta) early.",
            "contact = centre - r_toe e_z; centre = hip + (rho - r_toe)(sin theta, -cos theta)"))
    if v.m_leg > 1e-4:
        out.append(_effect(
            "leg_inertia", "the leg's mass and inertia above the spring", "flight, stance",
            v.m_leg * v.r_leg / (v.m_body + v.m_leg + v.m_toe), "m",
            {"m_leg": v.m_leg, "r_c": v.r_leg, "I_own": v.i_leg, "m_body": v.m_body,
             "I_hip_leg_and_toe": v.m_leg * v.r_leg ** 2 + v.i_leg + v.m_toe * p.rho0 ** 2},
            f"The upper leg ({v.m_leg:g} kg, centre {v.r_leg * 1e3:g} mm below the hip, own "
            f"inertia {v.i_leg:g} kg m^2) turns with the hip; the body that does not turn is "
            f"{v.m_body:g} kg (m_b = {v.m_body + v.m_leg:g} kg above the spring as the thesis). "
            "In flight the servo's swing from the lift-off angle to theta_td makes the body "
            "recoil (mu r_c per unit of sin theta); in stance the leg's rotation takes part of "
            "the hip torque and of the body's momentum.",
            "flight: body recoil = -mu r_c (sin theta, -cos theta) + const, "
            "mu r_c = m_leg r_c/(m_b + m_t)"))
    if v.hip_armature > 0:
        out.append(_effect(
            "hip_rotor_inertia", "the hip motor's rotor inertia through the gear (joint armature)",
            "touchdown, stance, flight", v.hip_armature, "kg m^2",
            {"rotor_inertia": ROTOR_INERTIA, "gear": GEAR, "armature": v.hip_armature},
            f"The EC40's rotor (8.5e-6 kg m^2) seen through the 1:26 gear adds "
            f"{v.hip_armature:.3g} kg m^2 at the hip: at touchdown the leg's sweep (theta' "
            "about -8 to -12 rad/s) must spin it up, which the body pays for in momentum, and in "
            "stance part of the commanded torque accelerates it instead of the leg.",
            "(I_leg + I_a) theta'' = tau + (leg's torque from the body and floor)"))
    if v.hip_damping > 0:
        out.append(_effect(
            "hip_viscous_friction", "viscous friction of the motor and gear at the hip",
            "stance, flight", v.hip_damping, "N m s/rad",
            {"motor_viscous": GEAR_VISCOUS, "gear": GEAR, "damping": v.hip_damping},
            f"Bearing and gear viscous friction (1e-4 N m s/rad at the motor, "
            f"{v.hip_damping:.3g} N m s/rad at the hip) brakes the leg's sweep in stance "
            "(about 0.5-0.8 N m at -8 to -12 rad/s, against the forward drive).",
            "tau_hip = tau_cmd - b_h theta'"))
    if v.hip_frictionloss > 0:
        out.append(_effect(
            "hip_coulomb_friction", "dry (Coulomb) friction in the hip's gear (joint frictionloss)",
            "stance, flight", v.hip_frictionloss, "N m", {"frictionloss": v.hip_frictionloss},
            f"The planetary gear's dry friction: a torque of up to {v.hip_frictionloss:g} N m "
            "opposes the hip's rotation (MuJoCo frictionloss: a soft dry-friction constraint), "
            "whatever the speed, so a stance's sweep loses about tau_c |delta theta| of work and "
            "the commanded torque is short by tau_c while the leg sweeps back.",
            "tau_hip = tau_cmd - tau_c sign(theta') (|theta'| > 0), |tau_f| <= tau_c at rest"))
    if v.boom == "hinge":
        out.append(_effect(
            "boom_hinges", "the boom's geometry: the body on a sphere about the pivot",
            "flight, stance, sensor", R_AZ, "m",
            {"R_elevation": 1.65, "leg_offset": 0.09, "z_pivot": 0.115,
             "four_bar": "level joint = -elevation (stiff equality)"},
            "The body rides on the boom's azimuth and elevation hinges (massless boom, its mass "
            "in g = 11.42 as the thesis): raised by beta = asin((z - 0.115)/1.65) the forward "
            "speed's centripetal acceleration y'^2/R has a component -sin(beta) y'^2/R along the "
            "elevation, gravity along the elevation is g cos(beta), the hip's radius "
            "1.65 cos(beta) + 0.09 shrinks as the body rises (y = 1.74 x azimuth is then "
            "not the hip's own arc by up to 0.5 %), and the pinned toe must slide sideways "
            "(radially) by up to s^2/(2R) ~ 2 mm per stance (its friction loads the boom).",
            "z'' += -(z - 0.115) y'^2/R^2 (approx.); hip radius = 1.65 cos beta + 0.09"))
    out.append(_effect(
        "flight_damping_in_stance", "the boom joints' damping acts in stance too", "stance",
        p.d_v, "1/s", {"d_h": p.d_h, "d_v": p.d_v},
        "Flight damping (2.8) is MuJoCo joint damping on the boom's joints, so it also acts "
        "in stance (the thesis neglects it there): at most 0.23 x 2.23 kg x 1.5 m/s = 0.8 N "
        "against a leg force of 100-300 N.", "stance: m p'' += -(d_h y', d_v z') m"))
    if v.floor_tilt:
        out.append(_effect(
            "tilted_floor", "the floor plane is tilted: it rises and falls once per lap",
            "touchdown, stance", R_AZ * math.tan(v.floor_tilt), "m",
            {"tilt": v.floor_tilt, "uphill_azimuth": v.floor_tilt_dir, "radius": R_AZ},
            f"The running surface is a plane tilted by {v.floor_tilt:g} rad: along the hip's "
            f"circle its height under the toe is h = {R_AZ * math.tan(v.floor_tilt) * 1e3:.1f} mm "
            "x cos(azimuth - phi), so touchdown comes earlier or later and the floor's normal "
            "leans by up to the tilt along the track.",
            "h(y) = R tan(alpha) cos(y/R - phi), R = 1.74 m"))
    return out


# ------------------------------------------------------------------------------ recordings

def simulate(name: str, strides: int = STRIDES, seed: int | None = None,
             variant: Variant | None = None):
    v = variant or VARIANTS[name]
    seed = SEEDS.get(name, 9001) if seed is None else seed
    p = load_nominal()
    rng = np.random.default_rng(seed)
    ctl = Controller(p, np.random.default_rng(seed + 2))
    hop = Hopper(v, p)
    t0, y = 0.0, 0.0
    log, rows, truth_rows = [], [], []
    done = throws = 0
    while done < strides:
        throws += 1
        if throws > 4 * strides:
            raise RuntimeError(f"{name}: the robot keeps failing")
        z0, v0 = ctl.throw_state()
        ctl.new_run()
        cmd = ctl.plan(z0, v0)
        hop.rows, hop.truth_rows = [], []
        hop.throw(t0, y, z0, v0, cmd)
        want = min(int(rng.integers(*RUN_STRIDES)), strides - done)
        k, keep = 0, 1
        z_a, v_a = z0, v0
        while k < want:
            try:
                info = hop.stride(ctl)
            except StrideFailure as exc:
                log.append({"run": throws, "failure": str(exc)})
                break
            k += 1
            info.update(run=throws, z_start=z_a, v_start=v_a)
            log.append(info)
            z_a, v_a = info["z_apex"], info["v_apex"]
            # the first sample at or after this apex: logged already, or the next one
            keep = len(hop.rows) + (0 if info["apex_logged"] else 1)
            if not (ENVELOPE_Z[0] - 0.02 < z_a < ENVELOPE_Z[1] + 0.02
                    and ENVELOPE_V[0] - 0.2 < v_a < ENVELOPE_V[1] + 0.2):
                break
        if k == 0:
            t0 += 1.0
            continue
        if len(hop.rows) >= keep:
            hop.rows, hop.truth_rows = hop.rows[:keep], hop.truth_rows[:keep]
        else:
            hop.finish_run()
        rows += hop.rows
        truth_rows += hop.truth_rows
        done += k
        y = hop.truth_rows[-1][1] + float(rng.uniform(-0.3, 0.8))
        t0 = round((hop.rows[-1][0] + rng.uniform(*GAP)) / 1e-3) * 1e-3
    rows = np.array(rows)
    meas = encoders(rows, v.boom == "hinge", np.random.default_rng(seed + 3))
    truth = {"name": name, "effects": effects(v), "strides": int(done), "seed": int(seed)}
    return meas, truth, log, np.array(truth_rows, dtype=float)


def write(out_dir: Path, name: str, meas: dict, truth: dict) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    data = np.column_stack([meas["t"], meas["y"], meas["z"], meas["theta"], meas["tau"]])
    np.savetxt(out_dir / f"{name}.csv", data, delimiter=",", header="t,y,z,theta,tau",
               comments="", fmt=["%.3f", "%.7f", "%.7f", "%.8f", "%.6f"])
    (out_dir / f"{name}.json").write_text(json.dumps(truth, indent=1) + "\n")


def nominal_errors(log: list[dict]) -> dict:
    """Each stride's next apex against the nominal model's prediction from the same start
    apex and inputs: arrays dz [m], dv [m/s] (plant - nominal)."""
    p = load_nominal()
    ok = [e for e in log if "z_apex" in e]
    zs = np.array([e["z_start"] for e in ok])
    vs = np.array([e["v_start"] for e in ok])
    th = np.array([e["theta_at_td"] for e in ok])   # the leg angle the robot landed with
    tau = np.array([e["tau0"] for e in ok])
    tf = np.array([e["t_f"] for e in ok])
    zn, vn, good, _ = next_apex(p, zs, vs, th, tau, tf, dt=1e-4)
    return {"dz": np.array([e["z_apex"] for e in ok]) - zn,
            "dv": np.array([e["v_apex"] for e in ok]) - vn, "ok": good}


def summary(name: str, truth: dict, log: list[dict], seconds: float) -> str:
    ok = [e for e in log if "z_apex" in e]
    fails = [e for e in log if "failure" in e]
    err = nominal_errors(log)
    dz, dv = err["dz"] * 1e3, err["dv"] * 1e3
    z = [e["z_apex"] for e in ok]
    v = [e["v_apex"] for e in ok]
    tau = [e["tau0"] for e in ok]
    th = [e["theta_td"] for e in ok]
    hold = min(e["hold"] for e in ok)
    return (f"{name:17s} strides {truth['strides']:3d} runs {len(set(e['run'] for e in ok)):2d}"
            f" fail {len(fails)}  apex z {min(z):.3f}-{max(z):.3f} v {min(v):.2f}-{max(v):.2f}"
            f" tau0 {min(tau):.1f}-{max(tau):.1f} th_td {min(th):.2f}-{max(th):.2f}"
            f" hold>={hold * 1e3:.0f}ms | vs nominal: dz mean {dz.mean():+.1f} rms "
            f"{np.sqrt((dz ** 2).mean()):.1f} max {np.abs(dz).max():.1f} mm, dv mean "
            f"{dv.mean():+.0f} rms {np.sqrt((dv ** 2).mean()):.0f} max {np.abs(dv).max():.0f} mm/s"
            f"  {seconds:4.1f} s")


def _job(args):
    out_dir, name, strides = args
    t0 = time.time()
    meas, truth, log, _ = simulate(name, strides)
    write(Path(out_dir), name, meas, truth)
    return summary(name, truth, log, time.time() - t0)


def main(argv: list[str]) -> int:
    strides = STRIDES
    if argv[:1] == ["--strides"]:
        strides, argv = int(argv[1]), argv[2:]
    if not argv:
        print(__doc__)
        print("cases:", " ".join(VARIANTS))
        return 2
    out_dir = Path(argv[0])
    names = argv[1:] or list(VARIANTS)
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        print("unknown cases:", unknown, "\nknown:", " ".join(VARIANTS))
        return 2
    t0 = time.time()
    jobs = [(str(out_dir), n, strides) for n in names]
    if len(names) == 1:
        print(_job(jobs[0]), flush=True)
    else:
        with Pool(2) as pool:
            for line in pool.imap_unordered(_job, jobs):
                print(line, flush=True)
    print(f"{len(names)} recordings in {time.time() - t0:.1f} s -> {out_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
