"""Identification (section 4.2) on the simulated robot: 132 strides collected in lockstep with
every sensor noise on, true parameters Table 4.1's (config/sim.yaml with the model's effects).

- identification_cv_s: 10-fold cross-validation on 120 strides with the AAS, wall time (target < 60 s)
- identification_exact_cv_s: the same with the exact model (defect correction, fit.py)
- identification_{k,g,d}_err_pct: |error| of k, g, d, the exact model's 10-fold mean on those 120
- identification_132_{k,g,d}_err_pct: one exact-model fit on all 132 strides (acceptance: < 3 %)
- identification_aas_test_E{p,v,t}_pct: the AAS's held-out mean errors (Table 4.2)
- identification_aas_{k,d,g}_bias_pct: AAS estimate / exact estimate - 1 (the AAS's own bias)
- identification_collect_s: collecting the 132 strides (lockstep simulation and bag writing)
--quick: 60 strides, 3 folds.
"""
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from hopper_ros.hardware.config import load_hardware  # noqa: E402
from hopper_ros.harness.collect import CollectionSettings, collect  # noqa: E402
from hopper_ros.identification.crossval import cross_validate  # noqa: E402
from hopper_ros.identification.fit import fit_parameters  # noqa: E402
from hopper_ros.identification.settings import load_settings  # noqa: E402
from hopper_ros.identification.strides import extract_strides  # noqa: E402
from hopper_ros.recording.recordings import load_bag  # noqa: E402
from hopper_ros.sim.config import SENSORS, load_sim_config  # noqa: E402


def run(quick=False):
    total, used, folds = (60, 60, 3) if quick else (132, 120, 10)
    config = load_sim_config().with_sensors(**{name: True for name in SENSORS})
    truth = config.model_params()
    settings = load_settings().with_changes(folds=folds)
    with tempfile.TemporaryDirectory() as folder:
        started = time.perf_counter()
        collect(Path(folder) / "bag", config, load_hardware(), CollectionSettings(strides=total, seed=0))
        collect_s = time.perf_counter() - started
        strides = extract_strides(load_bag(Path(folder) / "bag"), truth.rest_length, settings.extraction)
    assert len(strides) == total, f"{len(strides)} strides extracted of {total}"
    subset = strides.subset(slice(0, used))
    aas = cross_validate(subset, settings, "aas", show_progress=False)
    exact = cross_validate(subset, settings, "exact", show_progress=False)
    full = fit_parameters(strides, settings, "exact")

    def error(params, name):
        return abs(100.0 * (getattr(params, name) / getattr(truth, name) - 1.0))

    exact_mean, aas_mean = exact.mean_params(), aas.mean_params()
    test = aas.error_table()["test"]
    figures = [
        {"name": "identification_cv_s", "value": round(aas.wall_time, 2), "unit": "s"},
        {"name": "identification_exact_cv_s", "value": round(exact.wall_time, 2), "unit": "s"},
        {"name": "identification_k_err_pct", "value": round(error(exact_mean, "stiffness"), 3), "unit": "%"},
        {"name": "identification_g_err_pct", "value": round(error(exact_mean, "gravity"), 3), "unit": "%"},
        {"name": "identification_d_err_pct", "value": round(error(exact_mean, "damping"), 3), "unit": "%"},
    ]
    figures += [{"name": f"identification_{total}_{short}_err_pct", "value": round(error(full.params, name), 3), "unit": "%"}
                for short, name in (("k", "stiffness"), ("g", "gravity"), ("d", "damping"))]
    figures += [{"name": f"identification_aas_test_{metric.replace('_', '')}_pct", "value": round(test[metric][0], 3),
                 "unit": "%"} for metric in ("E_p", "E_v", "E_t")]
    figures += [{"name": f"identification_aas_{short}_bias_pct",
                 "value": round(100.0 * (getattr(aas_mean, name) / getattr(exact_mean, name) - 1.0), 2), "unit": "%"}
                for short, name in (("k", "stiffness"), ("d", "damping"), ("g", "gravity"))]
    figures.append({"name": "identification_collect_s", "value": round(collect_s, 2), "unit": "s"})
    return figures


if __name__ == "__main__":
    for figure in run(quick="--quick" in sys.argv):
        print(figure)
