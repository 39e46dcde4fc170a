#!/usr/bin/env python3
"""What one float stride of the AAS and the corrected AAS costs in a checkout, on the thread's CPU clock.

usage: tools/float_stride_cost.py [CHECKOUT] [--record]     (CHECKOUT: a work tree, default this one)

- bytecodes: instructions the interpreter executes for one stride (sys.settrace opcode events);
- hot: microseconds a stride, the thesis strides one after another (min of repeats);
- in decision: the controller's stage 1 (`first_decision`) and each AAS stride inside it, replaying the apexes
  of bench_control's closed loop (recorded into bench/out/ when missing or with --record, then read from there), so that
  stage 2's batch and the rest of the loop run between two decisions as they do in the bench.

Checkouts compared run with the same interpreter, one after the other (not at once), each from its own tree.
"""
import json
import math
import sys
import time
from pathlib import Path

RECORDING = Path(__file__).resolve().parent.parent / "bench" / "out" / "closed_loop_apexes.json"
HERE = Path(__file__).resolve().parent.parent
CHECKOUT = Path(next((a for a in sys.argv[1:] if not a.startswith("--")), HERE)).resolve()
sys.path.insert(0, str(CHECKOUT))

import numpy as np  # noqa: E402

import hopper_ros.control.deadbeat as deadbeat  # noqa: E402
from hopper_ros.control.config import load_control  # noqa: E402
from hopper_ros.physics.aas import predict_aas  # noqa: E402
from hopper_ros.physics.corrected import predict_corrected  # noqa: E402
from hopper_ros.physics.evaluation import sample_thesis_strides  # noqa: E402
from hopper_ros.physics.params import ModelParams, load_params  # noqa: E402

SCHEDULE = ([(0.39, 2.0)] * 20 + [(0.42, 2.0)] * 20 + [(0.38, 2.5)] * 20) * 3     # bench_control's


def record() -> None:
    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.harness.lockstep import run_closed_loop
    from hopper_ros.sim.config import load_sim_config

    controller = deadbeat.DeadbeatController(load_params(), load_control().deadbeat)
    records = run_closed_loop(controller, load_sim_config(), load_hardware(), SCHEDULE)
    RECORDING.parent.mkdir(parents=True, exist_ok=True)
    RECORDING.write_text(json.dumps([(r.apex_height, r.forward_speed) for r in records]))


def bytecodes(predict, params, stride) -> int:
    count = 0

    def trace(frame, event, arg):
        nonlocal count
        frame.f_trace_opcodes = True
        count += event == "opcode"
        return trace
    sys.settrace(trace)
    predict(params, *stride)
    sys.settrace(None)
    return count


def hot(predict, params, strides, repeats=10) -> float:
    best = math.inf
    for _ in range(repeats):
        started = time.thread_time()
        for stride in strides:
            predict(params, *stride)
        best = min(best, time.thread_time() - started)
    return best / len(strides) * 1e6


def in_decision(rounds=5):
    """Stage 1 [us] (all decisions of the later rounds) and the AAS strides inside it [us each]."""
    apexes = json.loads(RECORDING.read_text())
    settings, params = load_control().deadbeat, load_params()
    inner, stage_1 = [], []
    predict_stride = deadbeat.predict_stride

    def timed(*args, **kwargs):
        started = time.thread_time()
        result = predict_stride(*args, **kwargs)
        inner.append(time.thread_time() - started)
        return result
    deadbeat.predict_stride = timed
    try:
        for index in range(rounds):
            controller = deadbeat.DeadbeatController(params, settings)
            controller.prime(*SCHEDULE[0])
            height, speed = SCHEDULE[0]
            for stride, (target_height, target_speed) in enumerate(SCHEDULE[:len(apexes)]):
                mark = len(inner)
                started = time.thread_time()
                first = controller.first_decision(height, speed, target_height, target_speed, stride)
                elapsed = time.thread_time() - started
                if index:
                    stage_1.append(elapsed)
                else:
                    del inner[mark:]
                deadbeat.predict_stride = predict_stride         # stage 2's strides are not counted
                controller.refine(first, height, speed)
                deadbeat.predict_stride = timed
                height, speed = apexes[stride]
                controller.observe(height, speed)
    finally:
        deadbeat.predict_stride = predict_stride
    return np.array(stage_1) * 1e6, np.array(inner) * 1e6


def main() -> None:
    if "--record" in sys.argv or not RECORDING.exists():
        record()
    params = ModelParams()
    columns = sample_thesis_strides(params, 300, seed=2024).columns()
    strides = [tuple(float(c[i]) for c in columns) for i in range(len(columns[0]))]
    no_ramp = [stride[:4] + (None,) for stride in strides]
    stage_1, inner = in_decision()
    print(f"{CHECKOUT}: bytecodes a stride AAS {bytecodes(predict_aas, params, no_ramp[0])}, corrected "
          f"{bytecodes(predict_corrected, params, strides[0])}; hot [us] AAS {hot(predict_aas, params, no_ramp):.2f}, "
          f"corrected {hot(predict_corrected, params, strides, 3):.2f}; in decision [us] AAS stride median "
          f"{np.median(inner):.2f}, stage 1 p50 {np.percentile(stage_1, 50):.1f} p99 {np.percentile(stage_1, 99):.1f}")


if __name__ == "__main__":
    main()
