"""Model library costs and accuracy (issue 3): AAS and corrected AAS against the exact model
on the same strides from the thesis ranges, timed in the same run."""

import time

import numpy as np

from hopper_ros.physics.aas import predict_aas
from hopper_ros.physics.corrected import predict_corrected
from hopper_ros.physics.evaluation import prediction_errors, sample_thesis_strides, successful
from hopper_ros.physics.exact import simulate_stride
from hopper_ros.physics.params import ModelParams
from hopper_ros.physics.predictors import predict_exact


def _per_call_us(function, rows):
    start = time.perf_counter()
    for row in rows:
        function(*row)
    return (time.perf_counter() - start) / len(rows) * 1e6


def _batch_rate(function, columns, repeats):
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        function(*columns)
        best = min(best, time.perf_counter() - start)
    return len(columns[0]) / best


def run(quick=False):
    params = ModelParams()
    count = 200 if quick else 1000
    drawn = sample_thesis_strides(params, int(count * 2.6), seed=2024)
    exact_all = predict_exact(params, drawn.apex_height, drawn.forward_speed, drawn.touchdown_angle,
                              drawn.tau_0, drawn.ramp_duration)
    keep = np.flatnonzero(successful(exact_all))[:count]
    strides = drawn.subset(keep)
    columns = (strides.apex_height, strides.forward_speed, strides.touchdown_angle, strides.tau_0, strides.ramp_duration)
    rows = [tuple(float(c[i]) for c in columns) for i in range(len(strides))]

    exact_us = _per_call_us(lambda *r: simulate_stride(params, *r), rows)
    aas_us = _per_call_us(lambda *r: predict_aas(params, *r), rows)
    corrected_us = _per_call_us(lambda *r: predict_corrected(params, *r), rows)
    aas_rate = _batch_rate(lambda *c: predict_aas(params, *c), columns, 5)
    corrected_rate = _batch_rate(lambda *c: predict_corrected(params, *c), columns, 5)

    exact = predict_exact(params, *columns)
    figures = [
        {"name": "aas_stride_us", "value": aas_us, "unit": "us"},
        {"name": "exact_stride_us", "value": exact_us, "unit": "us"},
        {"name": "aas_speedup", "value": exact_us / aas_us, "unit": "x"},
        {"name": "aas_batch_strides_per_s", "value": aas_rate, "unit": "strides/s"},
        {"name": "improved_stride_us", "value": corrected_us, "unit": "us"},
        {"name": "improved_speedup", "value": exact_us / corrected_us, "unit": "x"},
        {"name": "improved_batch_strides_per_s", "value": corrected_rate, "unit": "strides/s"},
        {"name": "predictor_strides", "value": len(strides), "unit": "strides"},
    ]
    for label, method in (("aas", predict_aas), ("improved", predict_corrected)):
        errors = prediction_errors(label, exact, method(params, *columns))
        figures += [
            {"name": f"{label}_mean_Ep_pct", "value": float(np.mean(errors.position)), "unit": "%"},
            {"name": f"{label}_mean_Ev_pct", "value": float(np.mean(errors.velocity)), "unit": "%"},
            {"name": f"{label}_mean_Et_pct", "value": float(np.mean(errors.time)), "unit": "%"},
        ]
    return figures


if __name__ == "__main__":
    for figure in run():
        print(figure)
