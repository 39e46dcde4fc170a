"""Which difference of the MuJoCo plant (test/mujoco_plant/) makes which share of the model's next-apex error.

    python bench/mujoco_ablation.py FOLDER [case ...]      (records what is missing in FOLDER, then scores)

Each case is a variant of the plant's own recordings with one difference switched on (mj_clean + X) or off
(mj_default - X, mj_clean - X), recorded with its seed and controller as test/mujoco_plant/suite.py records them
(its default recordings are not changed). Scored without a search: the model's next-apex errors E_p/E_v/E_t
(4.1)-(4.3) over every stride (config/model.yaml; a case may give the model library effects at a known magnitude,
`case@effect=value,...`), and the noise floor of the diagnosis (`diagnosis.yaml`'s yardstick). Fast: a few seconds
a recording once it is recorded.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PLANT = REPO / "test" / "mujoco_plant"

# name -> (base recording, changes of the plant's Variant, changes of its nominal model (the plant and ours))
CASES = {
    "mj_clean": ("mj_clean", {}, {}),
    "clean+hinges": ("mj_clean", {"boom": "hinge"}, {}),
    "clean+leg_inertia": ("mj_clean", {"m_body": 2.00, "m_leg": 0.20, "i_leg": 2.4e-4}, {}),
    "clean+rotor": ("mj_clean", {"hip_armature": 8.5e-6 * 26 ** 2}, {}),
    "clean+viscous": ("mj_clean", {"hip_damping": 1e-4 * 26 ** 2}, {}),
    "clean+rotor,friction_3": ("mj_clean", {"hip_armature": 8.5e-6 * 26 ** 2, "friction": 3.0}, {}),
    "clean,friction_3": ("mj_clean", {"friction": 3.0}, {}),
    "clean+rotor+viscous": ("mj_clean", {"hip_armature": 8.5e-6 * 26 ** 2, "hip_damping": 1e-4 * 26 ** 2}, {}),
    "clean+contact_2ms": ("mj_clean", {"contact_solref": (0.002, 1.0)}, {}),
    "clean+toe_4mm": ("mj_clean", {"r_toe": 0.004}, {}),
    "clean-boom_damping": ("mj_clean", {}, {"d_h": 1e-4, "d_v": 1e-4}),
    "clean-soft_contact": ("mj_clean", {"contact_solref": (0.00025, 1.0), "timestep": 1.25e-4}, {}),
    "clean-boom_damping-soft_contact": ("mj_clean", {"contact_solref": (0.00025, 1.0), "timestep": 1.25e-4},
                                        {"d_h": 1e-4, "d_v": 1e-4}),
    "clean-toe_mass": ("mj_clean", {"m_toe": 0.01}, {"m_t": 0.01}),
    **{name: (name, {}, {}) for name in ("mj_default", "mj_stiff_contact", "mj_light_leg", "mj_hip_friction",
                                         "mj_round_toe", "mj_tilted_floor")},
    "default-rotor": ("mj_default", {"hip_armature": 0.0}, {}),
    "default-viscous": ("mj_default", {"hip_damping": 0.0}, {}),
    "default-rotor-viscous": ("mj_default", {"hip_armature": 0.0, "hip_damping": 0.0}, {}),
}


def record(folder: Path, case: str) -> Path:
    sys.path.insert(0, str(PLANT))
    import suite  # noqa: E402  (the plant's own module)
    path = folder / f"{case}.csv"
    if path.exists():
        return path
    base, changes, nominal = CASES[case]
    loaded = suite.load_nominal
    try:
        if nominal:
            suite.load_nominal = lambda: loaded().but(**nominal)
        variant = suite.VARIANTS[base].but(name=case, **changes)
        meas, truth, _, _ = suite.simulate(base, variant=variant, seed=suite.SEEDS[base])
    finally:
        suite.load_nominal = loaded
    suite.write(folder, case, meas, truth)
    return path


def score(path: Path, nominal: dict, effects: dict) -> dict:
    from hopper_ros.diagnosis.core import base_variant
    from hopper_ros.diagnosis.data import prepare
    from hopper_ros.diagnosis.records import Errors
    from hopper_ros.diagnosis.settings import load_settings
    from hopper_ros.diagnosis.simulate import simulate_variants
    from hopper_ros.diagnosis.yardstick import noise_floor, start_moves
    from hopper_ros.physics.params import load_model
    from hopper_ros.recording.recordings import load_recording

    params, _ = load_model("model.yaml")
    ours = {"d_h": "flight_damping_horizontal", "d_v": "flight_damping_vertical", "m_t": "toe_mass"}
    params = params.replace(**{ours[k]: v for k, v in nominal.items()})
    settings = load_settings("diagnosis.yaml")
    data = prepare(load_recording(path), params, settings.min_strides, settings.liftoff_window)
    base = base_variant(params, effects)
    sim = simulate_variants(data, [base], keep_series=True)
    errors = Errors.of(data, {k: v[0] for k, v in sim["pred"].items()})
    floor = noise_floor(data, start_moves(data, base, sim))
    return {"E": errors.as_dict(), "floor": floor.as_dict(),
            "over_floor": [getattr(errors, k) / getattr(floor, k) for k in ("E_p", "E_v", "E_t")]}


def main(argv: list[str]) -> int:
    folder = Path(argv[0])
    folder.mkdir(parents=True, exist_ok=True)
    for spec in argv[1:] or list(CASES):
        case, _, given = spec.partition("@")
        effects = {k: float(v) for k, v in (kv.split("=") for kv in given.split(",") if kv)}
        path = record(folder, case)
        s = score(path, CASES[case][2], effects)
        e, f = s["E"], s["floor"]
        print(f"{spec:45s} E_p {e['E_p']:.3f} E_v {e['E_v']:.3f} E_t {e['E_t']:.3f} % | floor {f['E_p']:.3f} "
              f"{f['E_v']:.3f} {f['E_t']:.3f} | x floor " + "/".join(f"{v:.1f}" for v in s["over_floor"]),
              flush=True)
        with open(folder / "ablation.jsonl", "a") as out:
            out.write(json.dumps({"case": spec, **s}) + "\n")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main(sys.argv[1:]))
