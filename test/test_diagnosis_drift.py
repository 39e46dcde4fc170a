"""Drift over a recording (`diagnosis.drift`, issue 28 point 2) of the ground's height as the height reading gives
it: plant C's elevation encoder whose coupling slips at each touchdown's shock (test/plant_c/, written blind), made
with its own generator at a size and seed its suite does not use. The plant's stiffness drift is test_plant_b's."""

from __future__ import annotations

import json

import pytest

import stored_recordings
from hopper_ros.diagnosis.api import load_model, load_recording
from hopper_ros.diagnosis.core import start
from hopper_ros.diagnosis.drift import find_drift
from hopper_ros.diagnosis.settings import load_settings

pytestmark = pytest.mark.compute   # CPU-bound: `make test` runs these beside the node tests (tools/test.sh)

STRIDES = 44                       # a drift is judged on 4 strides a fold at least (10 folds)
SLIPS = 3.0                        # plant C's mean counts the coupling slips per touchdown (0.21 mm each)


@pytest.fixture(scope="module")
def slipping(tmp_path_factory):
    folder = tmp_path_factory.mktemp("drift")
    stored_recordings.plant_c(folder, f"""
        import sys
        from pathlib import Path
        from effects import make
        from suite import simulate, write
        mechanism = make("elevation_coupling_slip", lam={SLIPS})
        meas, truth, _ = simulate("slip", [mechanism.id], 4201, strides={STRIDES}, mechanisms=[mechanism])
        write(Path(sys.argv[1]), "slip", meas, truth)
        """)
    return folder


def test_a_height_reading_that_slips_at_each_touchdown_is_a_drift_of_the_ground(slipping):
    """The height reading falls by Poisson(3) counts at each touchdown and is never re-homed: the model, started
    from each measured apex, meets a floor that seems to fall through the recording. The drift stage on the plain
    model (what `diagnose` runs after the rounds; the whole verdict on plant C's own recording is in its suite,
    bench/plant_c_suite.py) finds the ground's height, as the reading gives it, falling over the recording, said
    in mm and mm/s, its fall per touchdown within 25 % of the plant's mean slip, and the held-out E_p + E_v + E_t
    at least halved with it; no other main parameter's trend stands in for it."""
    truth = json.loads((slipping / "slip.json").read_text())["effects"][0]
    params, model_effects = load_model("model.yaml")
    search, _, _ = start(load_recording(slipping / "slip.csv"), params, load_settings("diagnosis.yaml"), model_effects)
    drifts = find_drift(search.data, search.base, search.settings)
    assert drifts and drifts[0].parameter == "ground_height", [d.sentence() for d in drifts]
    drift = drifts[0]
    per_touchdown = -drift.change / (len(search.data.strides) - 1)
    assert abs(per_touchdown - truth["magnitude"]) <= 0.25 * truth["magnitude"], (per_touchdown, drift.sentence())
    said = drift.sentence()
    assert "as the height reading gives it" in said and " falls " in said and "mm over the recording" in said, said
    assert "mm/s" in said and drift.after.total < 0.5 * drift.before.total, said
