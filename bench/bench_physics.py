"""Model library costs and accuracy (issue 3): AAS and corrected AAS against the exact model
on the same strides from the thesis ranges, timed in the same run."""

import numpy as np

from hopper_ros.physics.evaluation import compare_predictors, time_predictors
from hopper_ros.physics.params import ModelParams


def run(quick=False):
    params = ModelParams()
    count = 200 if quick else 1000
    comparison = compare_predictors(params, int(count * 2.6), seed=2024, keep=count)
    cost = time_predictors(params, comparison.strides, repeats=5)
    exact_us = cost["exact"][0]
    figures = [
        {"name": "aas_stride_us", "value": cost["aas"][0], "unit": "us"},
        {"name": "exact_stride_us", "value": exact_us, "unit": "us"},
        {"name": "aas_speedup", "value": exact_us / cost["aas"][0], "unit": "x"},
        {"name": "aas_batch_strides_per_s", "value": cost["aas"][1], "unit": "strides/s"},
        {"name": "improved_stride_us", "value": cost["corrected"][0], "unit": "us"},
        {"name": "improved_speedup", "value": exact_us / cost["corrected"][0], "unit": "x"},
        {"name": "improved_batch_strides_per_s", "value": cost["corrected"][1], "unit": "strides/s"},
        {"name": "predictor_strides", "value": len(comparison.strides), "unit": "strides"},
    ]
    for label, method in (("aas", "aas"), ("improved", "corrected")):
        errors = comparison.errors[method]
        figures += [
            {"name": f"{label}_mean_Ep_pct", "value": float(np.mean(errors.position)), "unit": "%"},
            {"name": f"{label}_mean_Ev_pct", "value": float(np.mean(errors.velocity)), "unit": "%"},
            {"name": f"{label}_mean_Et_pct", "value": float(np.mean(errors.time)), "unit": "%"},
        ]
    return figures


if __name__ == "__main__":
    for figure in run():
        print(figure)
