"""The mismatch tool (issues 14 and 15, hopper_ros/diagnosis/).

- diagnose_50_strides_s: wall time of `diagnose` on one recording of 50 strides of the simulated robot
  (leg friction on, every sensor noise on, CSV without labels)
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
--quick: the timing and a few cases of each.
"""
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "test"))

import diagnosis_sim_sweep  # noqa: E402
import diagnosis_suite  # noqa: E402
import plant_b_suite  # noqa: E402

from hopper_ros.diagnosis import diagnose_file  # noqa: E402

QUICK_SIM = ("clean_a", "leg_friction", "torque_gain", "quadratic_drag+torque_gain")
QUICK_INDEPENDENT = ("clean_1", "flight_air_drag", "actuator_gain", "other_flight_lift", "pair_drag_gain")
QUICK_PLANT_B = ("clean", "s01_quadratic_drag", "s02_boom_descent_drag")


def run(quick=False):
    rec, _ = diagnosis_sim_sweep.make_recording(["leg_friction"], Path(tempfile.mkdtemp()), seed=11)
    started = time.perf_counter()
    diagnose_file(rec)
    wall = time.perf_counter() - started
    rows = [{"name": "diagnose_50_strides_s", "value": round(wall, 1), "unit": "s"}]
    sim = diagnosis_sim_sweep.run(QUICK_SIM if quick else None)
    rows += [{"name": "diagnose_hit_rate_pct", "value": round(sim["hit_rate_pct"], 1), "unit": "%"},
             {"name": "diagnose_false_positive_pct", "value": round(sim["false_positive_pct"], 1), "unit": "%"},
             {"name": "locate_hit_rate_pct", "value": round(sim["locate_hit_rate_pct"], 1), "unit": "%"},
             {"name": "diagnose_sensor_on_physics", "value": sim["sensor_on_physics"], "unit": "recordings"}]
    from independent_plant.suite import write_suite
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
    folder = Path(tempfile.mkdtemp())
    subprocess.run([sys.executable, str(REPO / "test" / "plant_b" / "suite.py"), str(folder),
                    *(QUICK_PLANT_B if quick else ())], check=True, capture_output=True)
    blind = plant_b_suite.run(folder)
    rows += [{"name": "diagnose_plant_b_hit_rate_pct", "value": round(blind["hit_rate_pct"], 1), "unit": "%"},
             {"name": "diagnose_plant_b_false_positive_pct", "value": round(blind["false_positive_pct"], 1),
              "unit": "%"},
             {"name": "diagnose_plant_b_worse_count", "value": len(blind["worse_after"]), "unit": "recordings"}]
    return rows


if __name__ == "__main__":
    for row in run("--quick" in sys.argv):
        print(row)
