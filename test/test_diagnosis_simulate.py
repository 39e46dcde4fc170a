"""Re-simulating recorded strides (issue 27): the compiled SSE against the numpy reference, with every sensor
model (delays, scales, offsets, a ringing); a lane stopped once it has what is read; each variant simulated
once per recording. On a recording of the independent plant (test/independent_plant/)."""

import sys
from pathlib import Path

import numpy as np
import pytest

from hopper_ros.diagnosis import simulate
from hopper_ros.diagnosis.core import base_variant
from hopper_ros.diagnosis.settings import Settings
from hopper_ros.diagnosis.data import prepare
from hopper_ros.diagnosis.ringing import key
from hopper_ros.physics import lanes
from hopper_ros.physics.params import load_model
from hopper_ros.recording.recordings import load_recording

sys.path.insert(0, str(Path(__file__).resolve().parent))
import stored_recordings  # noqa: E402


@pytest.fixture(scope="module")
def data_and_base(tmp_path_factory):
    folder = tmp_path_factory.mktemp("simulate")
    stored_recordings.independent(folder, ("pair_toemass_delay",))
    settings = Settings()
    params, effects = load_model("model.yaml")
    data = prepare(load_recording(folder / "pair_toemass_delay.csv"), params, settings.min_strides,
                   settings.liftoff_window)
    return data, base_variant(params, effects)


def _variants(base):
    return [base, base.with_changes(sensors={"z_delay": 0.004}),
            base.with_changes(sensors={"y_delay": 0.003, "y_scale": 1.02, "theta_delay": 0.006}),
            base.with_changes(sensors={"theta_offset": 0.01, "theta_scale": 0.98}),
            base.with_changes(sensors={"z_offset": 0.003, "z_scale": 1.01}),
            base.with_changes(sensors={key("z", "sin"): 0.001, key("z", "cos"): -0.0005, key("z", "hz"): 20.0,
                                       key("z", "decay"): 10.0}),
            base.with_changes(coefficients={"torque_gain": 0.8}), base.with_changes(coefficients={"stiffness": 3000.0}),
            base.with_changes(coefficients={"rest_length": 0.23})]


@pytest.mark.skipif(lanes.compiled_backend() is None, reason="numba is not installed")
def test_compiled_sse_equals_the_numpy_reference(data_and_base):
    data, base = data_and_base
    variants = _variants(base)
    reference = simulate._batched(data, variants, True)      # numpy residuals over every lane sample
    fast = simulate._batched(data, variants, False)          # compiled, each lane stopped when it has its samples
    assert np.all(reference["sse"] > 0)
    assert np.max(np.abs(fast["sse"] - reference["sse"]) / reference["sse"]) < 1e-9
    for name in reference["pred"]:
        assert np.array_equal(fast["pred"][name], reference["pred"][name], equal_nan=True), name
    # the variants differ: a sensor model that did nothing would leave its row as the model's
    assert len({round(float(row.sum()), 6) for row in reference["sse"]}) == len(variants)


def test_each_variant_is_simulated_once_per_recording(data_and_base, monkeypatch):
    data, base = data_and_base
    variants = _variants(base)[:4]
    simulated = []
    real = simulate._batched

    def counting(data, batch, keep_series):
        simulated.extend(batch)
        return real(data, batch, keep_series)

    monkeypatch.setattr(simulate, "_batched", counting)
    data.simulated.clear()
    first = simulate.simulate_variants(data, variants + variants[:2])
    again = simulate.simulate_variants(data, list(reversed(variants)))
    assert len(simulated) == len(variants)
    assert np.array_equal(first["sse"][:4], again["sse"][::-1])
    assert np.array_equal(first["sse"][4:], first["sse"][:2])
    # a variant that differs in one coefficient only is a new one
    simulate.simulate_variants(data, [base.with_changes(coefficients={"torque_gain": 0.8000001})])
    assert len(simulated) == len(variants) + 1
