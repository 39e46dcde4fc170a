"""The mismatch tool (issue 9, hopper_ros/diagnosis/).

- diagnose_50_strides_s: wall time of `diagnose` on one recording of 50 strides (leg friction on,
  every sensor noise on, CSV without labels)
- diagnose_hit_rate_pct: share of the proof cases (negative control + six single effects, 20
  strides each) where the tool names exactly the right effect set with the magnitude within 20 %
--quick: the 50-stride timing only on 30 strides and three proof cases.
"""
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from hopper_ros.config import load_yaml  # noqa: E402
from hopper_ros.diagnosis import diagnose_file  # noqa: E402
from hopper_ros.identification.recordings import load_csv  # noqa: E402
from hopper_ros.recording.collect import CollectionSettings, collect  # noqa: E402
from hopper_ros.sim.config import SENSORS, load_sim_config  # noqa: E402

CASES = [
    ("none", None, None, None),
    ("leg_friction", {"leg_friction": True}, "leg_friction", 2.0),
    ("ground_compliance", {"ground_compliance": True}, "ground_compliance", 60000.0),
    ("touchdown_loss_across", {"touchdown_loss_across": True}, "touchdown_loss_across", 0.06),
    ("torque_saturation", {"torque_saturation": True}, "torque_saturation", 4.0),
    ("actuation_delay", {"actuation_delay": True}, "actuation_delay", 0.004),
    ("effective_gravity", {"effective_gravity": {"g": 10.6}}, "effective_gravity", 10.6),
]


def _recording(effects, strides, seed=3):
    cfg = load_sim_config().with_sensors(**{n: True for n in SENSORS})
    if effects:
        cfg = cfg.with_effects(**effects)
    d = Path(tempfile.mkdtemp())
    c = collect(d / "bag", cfg, load_yaml("hardware.yaml"), CollectionSettings(strides=strides, seed=seed),
                csv_path=d / "run.csv")
    return load_csv(c.csv)


def run(quick=False):
    rec = _recording({"leg_friction": True}, 30 if quick else 50, seed=11)
    started = time.perf_counter()
    diagnose_file(rec)
    wall = time.perf_counter() - started
    hits = 0
    cases = CASES[:3] if quick else CASES
    for name, effects, expected, truth in cases:
        r = diagnose_file(_recording(effects, 20))
        names = [x["name"] for x in r["chosen"]]
        if expected is None:
            ok = not names
        else:
            ok = names == [expected] and abs(r["chosen"][0]["magnitude"] - truth) <= 0.2 * truth
        hits += ok
        print(f"  {name}: {r['verdict']} ({'hit' if ok else 'miss'})", file=sys.stderr)
    return [{"name": "diagnose_50_strides_s" if not quick else "diagnose_30_strides_s", "value": round(wall, 1),
             "unit": "s"},
            {"name": "diagnose_hit_rate_pct", "value": round(100.0 * hits / len(cases), 1), "unit": "%"}]


if __name__ == "__main__":
    for row in run("--quick" in sys.argv):
        print(row)
