"""The deadbeat controller: decision cost and closed-loop accuracy on the simulated robot.

The closed loop runs in lockstep without ROS (hopper_ros.harness.lockstep): the simulated robot
of config/sim.yaml (flight damping, lift-off collision and boom gravity on) follows the Fig 5.5
schedule (0.39 m / 2 m/s -> 0.42 m / 2 m/s -> 0.38 m / 2.5 m/s), 20 strides per segment, the
schedule three times (180 strides; quick: once with 12 per segment), with adaptation on, then
again with it off.

- controller_decision_p50_us / _p99_us: tau_0 plus theta_td per apex, the decision the 1 ms loop
  waits for (stage 1: Newton on the scalar AAS with the corrected predictor's last defect), over
  every apex of the run with adaptation, this process on SCHED_FIFO priority 50 as the controller
  node runs in the demo (`controller_realtime_priority`, 0 where not permitted); target p99 < 200 us.
- controller_refine_p50_us / _p99_us: stage 2, the refinement on the corrected AAS computed during
  the flight (the stride uses its inputs).
- closed_loop_height_err_pct / closed_loop_speed_err_pct: steady state (mean of the last 10
  strides of a segment against its setpoint), the worst segment, adaptation on;
  `..._noadapt_...` the same with adaptation off.
- strides_to_settle: the most strides any setpoint step needed to come within 1 cm and 0.05 m/s
  (and stay there).
"""
import dataclasses
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from _common import available_realtime_priority, realtime  # noqa: E402
from hopper_ros.control.config import load_control  # noqa: E402
from hopper_ros.control.deadbeat import DeadbeatController  # noqa: E402
from hopper_ros.hardware.config import load_hardware  # noqa: E402
from hopper_ros.harness.lockstep import run_closed_loop, summarise  # noqa: E402
from hopper_ros.physics.params import load_params  # noqa: E402
from hopper_ros.sim.config import load_sim_config  # noqa: E402


def run(quick=False):
    per_segment, repeats = (12, 1) if quick else (20, 3)
    schedule = ([(0.39, 2.0)] * per_segment + [(0.42, 2.0)] * per_segment + [(0.38, 2.5)] * per_segment) * repeats
    hardware = load_hardware()
    base = load_control().deadbeat
    priority = available_realtime_priority()
    figures = [{"name": "controller_realtime_priority", "value": priority, "unit": "SCHED_FIFO"}]
    for adaptation in (True, False):
        settings = dataclasses.replace(base, adaptation=adaptation)
        with realtime(priority if adaptation else 0):
            records = run_closed_loop(DeadbeatController(load_params(), settings), load_sim_config(), hardware,
                                      schedule)
        if len(records) < len(schedule):
            raise RuntimeError(f"the robot fell after {len(records)} strides (adaptation {adaptation})")
        segments = summarise(records, window=10)
        suffix = "" if adaptation else "_noadapt"
        figures += [
            {"name": f"closed_loop_height_err{suffix}_pct", "value": max(s.height_error_pct for s in segments), "unit": "%"},
            {"name": f"closed_loop_speed_err{suffix}_pct", "value": max(s.speed_error_pct for s in segments), "unit": "%"},
        ]
        if adaptation:
            times = np.array([r.decision_time for r in records]) * 1e6
            refine = np.array([r.refine_time for r in records]) * 1e6
            settle = [s.strides_to_settle for s in segments]
            figures += [
                {"name": "controller_decision_p50_us", "value": float(np.percentile(times, 50)), "unit": "us"},
                {"name": "controller_decision_p99_us", "value": float(np.percentile(times, 99)), "unit": "us"},
                {"name": "controller_refine_p50_us", "value": float(np.percentile(refine, 50)), "unit": "us"},
                {"name": "controller_refine_p99_us", "value": float(np.percentile(refine, 99)), "unit": "us"},
                {"name": "strides_to_settle", "value": max(s if s is not None else 99 for s in settle), "unit": "strides"},
            ]
    return figures


if __name__ == "__main__":
    for figure in run(quick="--quick" in sys.argv):
        print(figure)
