"""The mismatch tool (issues 14, 15 and 27, hopper_ros/diagnosis/).

Speed (issue 27):
- diagnose_50_strides_s: wall time of `diagnose` on one recording of 50 strides of the simulated robot
  (leg friction on, every sensor noise on, CSV without labels)
- diagnose_pair_s: the independent plant's toe mass + actuation delay pair (restarts)
- diagnose_worst_s: the slowest recording of the three sweeps below (its name printed)
- lanes_strides_per_s: strides integrated per second by `physics.lanes` (50 recorded strides x 20 coefficient
  sets, 1000 lanes, compiled), lanes_numpy_strides_per_s the numpy path on the same lanes in the same run,
  lanes_compiled_speedup their ratio
- diagnose_first_run_s / diagnose_cached_run_s: a new process diagnosing a clean recording with an empty
  numba cache (it compiles) and again with the cache it left; lanes_compile_s their difference

Verdicts:
- on the simulated robot, every library entry one at a time, sensor faults, pairs from different
  phases and two clean recordings (bench/diagnosis_sim_sweep.py): diagnose_hit_rate_pct (effects named
  with the magnitude within 20 %), diagnose_false_positive_pct (named effects that were not there, of
  all named), locate_hit_rate_pct (effects located at the site where they act), diagnose_sensor_on_physics
  (sensor faults named on physics-only recordings)
- on the independent plant (test/independent_plant/, bench/diagnosis_suite.py): the same as
  diagnose_independent_hit_rate_pct, diagnose_independent_false_positive_pct,
  diagnose_independent_locate_pct, diagnose_independent_pair_hit_rate_pct (both effects of the
  recordings with two), diagnose_independent_worse_count (recordings whose held-out E_p/E_v/E_t got
  worse after an accepted effect)
- on plant B (test/plant_b/, written blind, bench/plant_b_suite.py): diagnose_plant_b_hit_rate_pct,
  diagnose_plant_b_false_positive_pct, diagnose_plant_b_worse_count
- on plants B and C together (plant C: test/plant_c/, written blind with 13 mechanisms outside the library's
  families, bench/plant_c_suite.py), issue 28: diagnose_beyond_library_named_pct (effects named by mechanism,
  magnitude within 25 %), diagnose_false_verdicts (accepted effects and drifts matching nothing concealed),
  diagnose_clean_flagged (clean recordings with anything said)
--quick: the timing and a few cases of each.
"""
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "test"))

import diagnosis_sim_sweep  # noqa: E402
from _common import child_env  # noqa: E402
import diagnosis_suite  # noqa: E402
import plant_b_suite  # noqa: E402
import plant_c_suite  # noqa: E402

from hopper_ros.diagnosis import diagnose_file  # noqa: E402
from hopper_ros.diagnosis.data import prepare  # noqa: E402
from hopper_ros.diagnosis.settings import Settings  # noqa: E402
from hopper_ros.physics import effects as library  # noqa: E402
from hopper_ros.physics import lanes, laws  # noqa: E402
from hopper_ros.physics.params import load_model  # noqa: E402
from hopper_ros.recording.recordings import load_recording  # noqa: E402

QUICK_SIM = ("clean_a", "leg_friction", "torque_gain", "quadratic_drag+torque_gain")
QUICK_INDEPENDENT = ("clean_1", "flight_air_drag", "actuator_gain", "other_flight_lift", "pair_drag_gain")
QUICK_PLANT_B = ("clean", "s01_quadratic_drag", "s02_boom_descent_drag")
QUICK_PLANT_C = ("clean_a", "gear_windup", "air_chamber")


LANE_SETS = 20        # coefficient sets of the lanes figure


def lanes_speed(recording) -> dict:
    """Strides per second of the compiled and the numpy lanes on one recording's 50 strides x 20 coefficient sets
    (every library entry at its grid's middle, in turn)."""
    settings = Settings()
    params, effects = load_model("model.yaml")
    data = prepare(load_recording(recording), params, settings.min_strides, settings.liftoff_window)
    s = data.strides
    base = library.apply(laws.Coefficients.from_model(params), effects)[0]
    sets = []
    for effect in library.LIBRARY[:LANE_SETS]:
        low, high = effect.search_bounds(base)
        sets.append(library.apply(base, {effect.name: effect.physical(0.5 * (low + high))})[0])
    coefficients = lanes.stack(sets, len(s))
    columns = [np.tile(x, len(sets)) for x in (s.apex_height, s.forward_speed, s.touchdown_angle, s.tau_0,
                                               s.ramp_duration)]
    seconds = {}
    for compiled in (True, True, False):          # the first compiled call may load the cache
        started = time.perf_counter()
        lanes.simulate_lanes(coefficients, *columns, duration=data.duration + 0.02, compiled=compiled)
        seconds[compiled] = time.perf_counter() - started
    count = len(sets) * len(s)
    return {"compiled": count / seconds[True], "numpy": count / seconds[False]}


def first_runs(recording) -> tuple[float, float]:
    """Wall time of a new process diagnosing `recording` with an empty numba cache, then with the one it left."""
    cache = tempfile.mkdtemp()
    env = {**child_env(), "NUMBA_CACHE_DIR": cache}
    times = []
    for _ in range(2):
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "hopper_ros.cli", "diagnose", "--quiet", str(recording)], cwd=REPO,
                       env=env, check=True, capture_output=True, timeout=900)
        times.append(time.perf_counter() - started)
    return times[0], times[1]


def blind_recordings(plant: str, names=()) -> Path:
    """A folder with the recordings of a blind plant's suite (test/<plant>/suite.py; all, or `names`)."""
    folder = Path(tempfile.mkdtemp())
    subprocess.run([sys.executable, str(REPO / "test" / plant / "suite.py"), str(folder), *names], check=True,
                   capture_output=True)
    return folder


def run(quick=False):
    rec, _ = diagnosis_sim_sweep.make_recording(["leg_friction"], Path(tempfile.mkdtemp()), seed=11)
    started = time.perf_counter()
    diagnose_file(rec)
    wall = time.perf_counter() - started
    rows = [{"name": "diagnose_50_strides_s", "value": round(wall, 1), "unit": "s"}]
    from independent_plant.suite import write_suite
    pair = Path(tempfile.mkdtemp())
    write_suite(pair, ("pair_toemass_delay", "clean_1"))
    started = time.perf_counter()
    diagnose_file(pair / "pair_toemass_delay.csv")
    rows.append({"name": "diagnose_pair_s", "value": round(time.perf_counter() - started, 1), "unit": "s"})
    speed = lanes_speed(pair / "pair_toemass_delay.csv")
    rows += [{"name": "lanes_strides_per_s", "value": round(speed["compiled"]), "unit": "strides/s"},
             {"name": "lanes_numpy_strides_per_s", "value": round(speed["numpy"]), "unit": "strides/s"},
             {"name": "lanes_compiled_speedup", "value": round(speed["compiled"] / speed["numpy"], 1), "unit": "x"}]
    cold, warm = first_runs(pair / "clean_1.csv")
    rows += [{"name": "diagnose_first_run_s", "value": round(cold, 1), "unit": "s"},
             {"name": "diagnose_cached_run_s", "value": round(warm, 1), "unit": "s"},
             {"name": "lanes_compile_s", "value": round(cold - warm, 1), "unit": "s"}]
    sim = diagnosis_sim_sweep.run(QUICK_SIM if quick else None)
    rows += [{"name": "diagnose_hit_rate_pct", "value": round(sim["hit_rate_pct"], 1), "unit": "%"},
             {"name": "diagnose_false_positive_pct", "value": round(sim["false_positive_pct"], 1), "unit": "%"},
             {"name": "locate_hit_rate_pct", "value": round(sim["locate_hit_rate_pct"], 1), "unit": "%"},
             {"name": "diagnose_sensor_on_physics", "value": sim["sensor_on_physics"], "unit": "recordings"}]
    folder = Path(tempfile.mkdtemp())
    write_suite(folder, QUICK_INDEPENDENT if quick else None)
    ind = diagnosis_suite.run(folder)
    rows += [{"name": "diagnose_independent_hit_rate_pct", "value": round(ind["hit_rate_pct"], 1), "unit": "%"},
             {"name": "diagnose_independent_false_positive_pct", "value": round(ind["false_positive_pct"], 1),
              "unit": "%"},
             {"name": "diagnose_independent_locate_pct", "value": round(ind["locate_hit_rate_pct"], 1), "unit": "%"},
             {"name": "diagnose_independent_pair_hit_rate_pct", "value": round(ind["pair_hit_rate_pct"], 1),
              "unit": "%"},
             {"name": "diagnose_independent_worse_count", "value": len(ind["worse_after"]), "unit": "recordings"}]
    blind = plant_b_suite.run(blind_recordings("plant_b", QUICK_PLANT_B if quick else ()))
    rows += [{"name": "diagnose_plant_b_hit_rate_pct", "value": round(blind["hit_rate_pct"], 1), "unit": "%"},
             {"name": "diagnose_plant_b_false_positive_pct", "value": round(blind["false_positive_pct"], 1),
              "unit": "%"},
             {"name": "diagnose_plant_b_worse_count", "value": len(blind["worse_after"]), "unit": "recordings"}]
    third = plant_c_suite.run(blind_recordings("plant_c", QUICK_PLANT_C if quick else ()))
    both = blind["rows"] + third["rows"]
    rows += [{"name": "diagnose_beyond_library_named_pct", "unit": "%",
              "value": round(100.0 * sum(len(r["by_mechanism"]) for r in both)
                             / max(sum(r["effects"] for r in both), 1), 1)},
             {"name": "diagnose_false_verdicts", "unit": "verdicts",
              "value": sum(len(r["false_verdicts"]) for r in both)},
             {"name": "diagnose_clean_flagged", "unit": "recordings",
              "value": sum(1 for r in both if r["clean"] and r["flagged"])}]
    worst = max(sim["rows"] + ind["rows"] + blind["rows"] + third["rows"], key=lambda r: r["seconds"])
    print(f"bench_diagnosis: the slowest recording of the sweeps: {worst['name']} ({worst['seconds']:.0f} s)")
    rows.append({"name": "diagnose_worst_s", "value": round(worst["seconds"], 1), "unit": "s"})
    return rows


if __name__ == "__main__":
    for row in run("--quick" in sys.argv):
        print(row)
