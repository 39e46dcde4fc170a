"""Diagnoses the recordings of the MuJoCo plant (test/mujoco_plant/: the hopper on its boom as MuJoCo models
robots, written by an author who read neither the diagnosis code nor the library): several effects at once (soft
contact, a 30 g toe the ground stops, a leg and rotor with inertia, hip friction, the boom's geometry).

    python bench/mujoco_suite.py FOLDER [names...]      (FOLDER from test/mujoco_plant/suite.py)

Per recording: what was named, the held-out next-apex errors before and after against the noise floor (a model
without mismatch on the same strides), and whether the verdict says explained. Issue 28 asks for the held-out
errors within 2 x the floor by named effects. Not part of `make bench` (about 10 minutes on 2 cores).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def run(folder: Path, names=None) -> list[dict]:
    from hopper_ros.diagnosis import diagnose_file

    rows = []
    for truth_path in sorted(folder.glob("*.json")):
        if truth_path.stem == "score" or names and truth_path.stem not in names:
            continue
        truth = json.loads(truth_path.read_text())
        result = diagnose_file(truth_path.with_suffix(".csv"))
        complete = result.completeness
        row = {"name": truth_path.stem, "seconds": round(result.wall_time, 1),
               "concealed": [e["id"] for e in truth.get("effects", [])],
               "named": [r.name for r in result.chosen] + [f"drift of {d.parameter}" for d in result.drifts],
               "before": result.before.as_dict(), "after": result.after.as_dict(),
               "floor": complete.floor.as_dict(), "after_over_floor": complete.over_floor,
               "within_2x_floor": all(v <= 2.0 for v in complete.over_floor.values()),
               "explained": complete.explained, "verdict": result.verdict}
        print(f"{row['name']}: named {row['named']}; held-out E_p {row['before']['E_p']:.3f} -> "
              f"{row['after']['E_p']:.3f} % (floor {row['floor']['E_p']:.3f}), E_v {row['before']['E_v']:.3f} -> "
              f"{row['after']['E_v']:.3f} % (floor {row['floor']['E_v']:.3f}); after / floor "
              + "/".join(f"{v:.1f}" for v in complete.over_floor.values())
              + f"; {row['seconds']:.0f} s | {row['verdict']}", flush=True)
        rows.append(row)
    return rows


if __name__ == "__main__":
    repo = Path(__file__).resolve().parent.parent
    sys.path.insert(0, str(repo))
    rows = run(Path(sys.argv[1]), sys.argv[2:] or None)
    print(json.dumps({"recordings": len(rows), "within_2x_floor": sum(r["within_2x_floor"] for r in rows),
                      "explained": sum(r["explained"] for r in rows)}, indent=1))
    (Path(sys.argv[1]) / "score.json").write_text(json.dumps(rows, indent=1))
