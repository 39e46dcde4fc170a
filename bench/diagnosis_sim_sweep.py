"""Every library effect, one at a time and in pairs from different phases, on the simulated robot.

50 strides of section 4.1's single-stride experiments (`hopper collect`, lockstep), every sensor noise
on, saved as a CSV without phase labels, diagnosed, scored by `diagnosis_suite.score`: named with the
magnitude within 20 %, located at the site where it acts, nothing else named. Physics effects are
switched on in the simulated robot (config/sim.yaml's magnitudes); a sensor fault is applied to the
recorded channel (delay by interpolation within each experiment, scale, offset). Used by test_diagnosis.py (a subset) and
bench_diagnosis.py (the whole sweep).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO))

from diagnosis_suite import diagnosed_rows, independent_line, independent_score, summarise  # noqa: E402

from hopper_ros.hardware.config import load_hardware  # noqa: E402
from hopper_ros.harness.collect import CollectionSettings, collect  # noqa: E402
from hopper_ros.physics import effects as library  # noqa: E402
from hopper_ros.recording.recordings import load_csv  # noqa: E402
from hopper_ros.sim.config import SENSORS, load_sim_config  # noqa: E402

SENSOR_FAULTS = {"z_delay": 0.004, "y_delay": 0.004, "theta_delay": 0.004, "z_scale": 1.03, "y_scale": 1.03,
                 "theta_scale": 1.03, "z_offset": 0.005, "theta_offset": 0.02}
PAIRS = (("quadratic_drag", "torque_gain"), ("touchdown_loss_along", "hip_viscous_friction"),
         ("effective_gravity", "actuation_delay"), ("liftoff_collision", "spring_cubic"))
STRIDES = 50
# entries added to the library after the cases' seeds (100 + the place in `cases`) were fixed: listed last, so that
# every earlier case keeps its recording
LATER = ("rotor_inertia",)
LOCATED = {"flight": ["flight_horizontal", "flight_vertical"],
           "touchdown": ["touchdown_along", "touchdown_across", "touchdown_timing"],
           "stance_leg": ["stance_along", "stance_hip"], "stance_hip": ["stance_hip"], "actuator": ["stance_hip"],
           "liftoff": ["liftoff_along", "liftoff_across"], "sensor": []}


def cases() -> dict:
    """name -> list of effect names (physics effects at sim.yaml's magnitudes, sensor faults above)."""
    out = {"clean_a": [], "clean_b": []}
    for e in library.LIBRARY:
        if e.name not in LATER:
            out[e.name] = [e.name]
    for name in SENSOR_FAULTS:
        out[name] = [name]
    for a, b in PAIRS:
        out[f"{a}+{b}"] = [a, b]
    for name in LATER:
        out[name] = [name]
    return out


def delayed(rec, x, delay: float):
    """Channel `x` as a sensor `delay` late would show it, within each experiment (the gap between two
    experiments is no signal to interpolate across): its first samples extend the throw's motion back."""
    out = np.empty_like(x)
    for seg in rec.segments():
        t, v = rec.t[seg], x[seg]
        slope = np.polyfit(t[:10] - t[0], v[:10], 1)[0]
        late = t - delay
        out[seg] = np.where(late < t[0], v[0] + slope * (late - t[0]), np.interp(late, t, v))
    return out


def make_recording(names: list[str], folder: Path, seed: int):
    cfg = load_sim_config().with_sensors(**{n: True for n in SENSORS})
    physics = [n for n in names if library.get(n).kind == "physics"]
    if physics:
        cfg = cfg.with_effects(**{n: True for n in physics})
    c = collect(folder / "bag", cfg, load_hardware(), CollectionSettings(strides=STRIDES, seed=seed),
                csv_path=folder / "run.csv")
    rec = load_csv(c.csv)
    truth = {"effects": []}
    enabled = cfg.enabled_effects()
    for n in names:
        e = library.get(n)
        if e.kind == "sensor":
            value = SENSOR_FAULTS[n]
            channel, op = n.split("_")
            x = getattr(rec, channel)
            if op == "delay":
                x = delayed(rec, x, value)
            elif op == "scale":
                x = x * value
            else:
                x = x + value
            setattr(rec, channel, x)
        else:
            value = enabled[n]
        truth["effects"].append({"id": n, "library": n, "magnitude": value, "site": e.site,
                                 "located_sites": LOCATED[e.site]})
    return rec, truth


def run(names=None, verbose=True) -> dict:
    jobs = []
    for k, (name, effects) in enumerate(cases().items()):
        if names and name not in names:
            continue
        rec, truth = make_recording(effects, Path(tempfile.mkdtemp()), seed=100 + k)
        jobs.append((name, rec, truth, independent_score))
    return summarise(diagnosed_rows(jobs, independent_line, verbose))


if __name__ == "__main__":
    summary = run(sys.argv[1:] or None)
    print({k: v for k, v in summary.items() if k != "rows"})
