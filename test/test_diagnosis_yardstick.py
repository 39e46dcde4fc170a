"""The trajectory test's noise level (issue 28, point 5): a re-simulated stride starts from the apex the recording
gives, and that estimate's own error is part of what noise alone produces. Proven on recordings of plant C (an
independent plant, test/plant_c/) whose leg angle is quantised only, as an incremental encoder gives it."""

import json
import math

import numpy as np
import pytest

import stored_recordings
from hopper_ros.diagnosis import diagnose_file
from hopper_ros.diagnosis.core import base_variant
from hopper_ros.diagnosis.data import PHASES, prepare
from hopper_ros.diagnosis.settings import Settings
from hopper_ros.diagnosis.simulate import CHANNELS, simulate_variants
from hopper_ros.diagnosis.yardstick import (locate_by_trajectory, start_moves, trajectory_by_phase,
                                             trajectory_sd)
from hopper_ros.identification.strides import ExtractionSettings, _apex
from hopper_ros.physics.params import load_params
from hopper_ros.recording.recordings import load_recording



@pytest.fixture(scope="module")
def clean_recordings(tmp_path_factory):
    folder = stored_recordings.plant_c(tmp_path_factory.mktemp("plant_c"), """
        import sys
        from suite import main
        main([sys.argv[1], "clean_a", "clean_b"])
        """)
    return [folder / "clean_a.csv", folder / "clean_b.csv"]


def test_a_clean_recording_with_a_quantised_angle_is_clean(clean_recordings):
    """Nothing accepted and nothing located above the threshold by any basis (force, fit, trajectory), while
    the sensors' noise level alone puts the stance angle tens of noise levels off (what flagged them before)."""
    settings = Settings()
    params = load_params()
    for path in clean_recordings:
        result = diagnose_file(path, json_path=path.with_suffix(".diagnosis.json"))
        assert not result.chosen and result.verdict == "no significant mismatch", (path.name, result.verdict)
        # the model's held-out next-apex errors are within twice those of a model without mismatch
        complete = json.loads(path.with_suffix(".diagnosis.json").read_text())["completeness"]
        assert complete["explained"] and max(complete["over_noise_floor"].values()) <= settings.floor_factor, complete
        assert all(loc.ratio < settings.locate_threshold for loc in result.location), \
            (path.name, [loc.words() for loc in result.location[:3]])
        data = prepare(load_recording(path), params, settings.min_strides, settings.liftoff_window)
        assert data.quantum["theta"] > 0 and data.sigma["theta"] == pytest.approx(data.quantum["theta"] / math.sqrt(12))
        base = base_variant(params)
        sim = simulate_variants(data, [base], keep_series=True)
        sensors_only = np.sqrt(sim["by_phase"][0].sum(0) / np.maximum(sim["counts"].sum(0), 1))
        compression, theta = PHASES.index("compression"), CHANNELS.index("theta")
        assert sensors_only[compression, theta] > settings.trajectory_threshold
        moves = start_moves(data, base, sim)
        by_phase, counts = trajectory_by_phase(data, sim["series"], trajectory_sd(data, sim["series"], moves))
        with_start = np.sqrt(by_phase.sum(0) / np.maximum(counts.sum(0), 1))
        # what noise alone produces: about one noise level in every phase and channel
        assert np.all(with_start[counts.sum(0) > 0] < 3.0), with_start
        assert locate_by_trajectory(data, sim["series"], moves, settings) is None


def test_the_apex_fits_report_their_own_errors():
    """Quantised ballistic flights, each at its own sub-quantum offset: the spread of the apex estimates over
    flights is the standard error the fits report (height, vertex time, speed), within a factor 1.6."""
    rng = np.random.default_rng(4)
    settings, step, gravity = ExtractionSettings(), 2.1e-4, 11.42
    t = np.arange(0.0, 0.4, 1e-3)
    found, reported = [], []
    for _ in range(300):
        apex_time, speed = 0.2 + rng.uniform(-1e-3, 1e-3), rng.uniform(0.8, 2.0)
        z = 0.3 - 0.5 * gravity * (t - apex_time) ** 2 + rng.uniform(0, step)
        y = speed * (t - apex_time) + rng.uniform(0, step)
        zq, yq = np.round(z / step) * step, np.round(y / step) * step
        vertex, height, _, fitted_speed, errors = _apex(t, yq, zq, 0, len(t), settings, 1e-3)
        truth_height = 0.3 + (z[0] - 0.3 + 0.5 * gravity * apex_time ** 2)
        found.append((height - truth_height, vertex - apex_time, fitted_speed - speed))
        reported.append((errors[0], errors[1], errors[3]))
    spread = np.std(np.array(found), axis=0)
    typical = np.median(np.array(reported), axis=0)
    assert np.all(spread < 1.6 * typical) and np.all(spread > typical / 1.6), (spread, typical)
