"""Identification (section 4.2): strides from recordings, Nelder-Mead on (4.4), cross-validation,
identifiability, and the `hopper identify` / `hopper report` commands, on simulated data whose
true parameters are known (Table 4.1: the simulated robot's defaults)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hopper_ros.identification.cost import stride_errors
from hopper_ros.identification.settings import FITTABLE, load_settings
from hopper_ros.identification.strides import ExtractionSettings, extract_strides, ramp_from_torque
from hopper_ros.physics.params import ModelParams
from hopper_ros.recording.recordings import Recording, RecordingError, load_bag, load_csv, write_csv

DATASET_STRIDES = 60
TRUTH = ModelParams()            # config/sim.yaml's robot with its three model effects on = Table 4.1


@pytest.fixture(scope="module")
def noisy_collection(tmp_path_factory):
    """60 strides of the simulated robot, every sensor noise on, as a bag and an unlabelled CSV."""
    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.harness.collect import CollectionSettings, collect
    from hopper_ros.sim.config import SENSORS, load_sim_config

    folder = tmp_path_factory.mktemp("noisy_collection")
    config = load_sim_config().with_sensors(**{name: True for name in SENSORS})
    assert config.model_params() == TRUTH
    collection = collect(folder / "bag", config, load_hardware(),
                         CollectionSettings(strides=DATASET_STRIDES, seed=0), csv_path=folder / "strides.csv")
    assert len(collection.kept) == DATASET_STRIDES
    return collection, folder / "bag", folder / "strides.csv"


@pytest.fixture(scope="module")
def bag_strides(noisy_collection):
    return extract_strides(load_bag(noisy_collection[1]), TRUTH.rest_length)


def test_strides_from_the_labelled_bag_and_the_unlabelled_csv_match_the_experiments(noisy_collection, bag_strides):
    collection, _, csv_path = noisy_collection
    kept = collection.kept
    csv_strides = extract_strides(load_csv(csv_path), TRUTH.rest_length)
    assert bag_strides.labelled and not csv_strides.labelled
    for strides in (bag_strides, csv_strides):
        assert len(strides) == len(kept) and not strides.rejected
        drawn = {name: np.array([getattr(k, name) for k in kept]) for name in
                 ("apex_height", "forward_speed", "touchdown_angle", "tau_0", "ramp_duration", "next_apex_height",
                  "next_forward_speed", "stride_time")}
        # from quantised, noisy encoder positions: apex heights to a count, speeds to 0.2 %
        assert np.max(np.abs(strides.apex_height - drawn["apex_height"])) < 5e-4
        assert np.max(np.abs(strides.next_apex_height - drawn["next_apex_height"])) < 5e-4
        assert np.max(np.abs(strides.forward_speed / drawn["forward_speed"] - 1)) < 2e-3
        assert np.max(np.abs(strides.next_forward_speed / drawn["next_forward_speed"] - 1)) < 2e-3
        assert np.max(np.abs(strides.stride_time - drawn["stride_time"])) < 1e-3
        assert np.max(np.abs(strides.touchdown_angle - drawn["touchdown_angle"])) < 3e-3   # the drive holds it
        tolerance = 0.0 if strides is bag_strides else 0.06       # commands, or the ramp fitted to tau
        assert np.max(np.abs(strides.tau_0 - drawn["tau_0"])) <= tolerance
        assert np.max(np.abs(strides.ramp_duration - drawn["ramp_duration"])) <= (0.0 if tolerance == 0 else 2e-3)
    # the detected phases agree with the true labels (a detected lift-off is ~1 ms late)
    labels = load_bag(noisy_collection[1]).phase
    agree = np.mean(csv_strides.phase == labels)
    assert agree > 0.97


def continuous_run(params: ModelParams, inputs: list[tuple[float, float]], apex_height: float, speed: float):
    """Back-to-back strides of the exact model, sampled at 1 kHz into one CSV-like recording."""
    from hopper_ros.physics.aas import predict_aas
    from hopper_ros.physics.exact import simulate_stride

    t, y, z, theta, tau = [], [], [], [], []
    state = (apex_height, speed, 0.0, 0.0)
    results = []
    for angle, tau_0 in inputs:
        h, v, y0, t0 = state
        ramp = float(predict_aas(params, h, v, angle, tau_0).stance_time)
        stride = simulate_stride(params, h, v, angle, tau_0, ramp, y0=y0, t0=t0, sample_period=1e-3)
        assert stride.ok, stride.failure
        trajectory = stride.trajectory
        keep = trajectory.t < stride.next_apex.t - 1e-9
        for column, values in zip((t, y, z, theta, tau), (trajectory.t, trajectory.y, trajectory.z, trajectory.theta,
                                                            trajectory.torque)):
            column.extend(values[keep])
        results.append((h, v, angle, tau_0, ramp, stride))
        state = (stride.next_apex.z, stride.next_apex.ydot, stride.next_apex.y, stride.next_apex.t)
    return Recording(*(np.asarray(c) for c in (t, y, z, theta, tau)), source="continuous run"), results


def test_back_to_back_strides_of_a_running_robot_are_found_without_labels(tmp_path):
    inputs = [(math.radians(a), tau) for a, tau in ((18, 4.0), (20, 5.0), (16, 3.0), (22, 6.0), (19, 4.5), (21, 5.5))]
    recording, results = continuous_run(TRUTH, inputs, 0.36, 1.8)
    write_csv(tmp_path / "run.csv", recording)
    strides = extract_strides(load_csv(tmp_path / "run.csv"), TRUTH.rest_length)
    assert len(strides) == len(inputs)               # the last closing apex is the last sample: found by its fit
    for k in range(len(strides)):
        h, v, angle, tau_0, ramp, stride = results[k]
        assert strides.apex_height[k] == pytest.approx(h, abs=2e-6)
        assert strides.forward_speed[k] == pytest.approx(v, rel=1e-4)
        assert strides.touchdown_angle[k] == pytest.approx(angle, abs=1e-9)
        assert strides.tau_0[k] == pytest.approx(tau_0, abs=0.02)       # from the ramp through tau
        assert strides.ramp_duration[k] == pytest.approx(ramp, abs=2e-4)
        assert strides.stride_time[k] == pytest.approx(stride.stride_time, abs=1e-4)
        assert strides.touchdown_time[k] == pytest.approx(stride.touchdown.t, abs=2e-4)
        # detected late: the toe rises (d/k) rho' cos(theta) (2-4 mm) after the leg force vanishes (2.28)
        late = stride.liftoff.rho_dot * TRUTH.damping / TRUTH.stiffness * math.cos(stride.liftoff.theta) / stride.liftoff.zdot
        assert 0.0 <= strides.liftoff_time[k] - stride.liftoff.t < late + 1.5e-3
        if k:
            assert strides.apex_time[k] == strides.next_apex_time[k - 1]   # consecutive strides share the apex
    # noise-free data and the exact model agree to the extraction's own error (tau_0 and t_f through
    # the detected touchdown, one apex fitted from one side): (4.4) is 0.04 %, the AAS's is ~10 %
    assert stride_errors(TRUTH, strides, "exact").cost() < 0.06


def test_exact_model_identification_recovers_k_d_and_g_within_3_percent(bag_strides):
    from hopper_ros.identification.fit import fit_parameters

    settings = load_settings()
    fit = fit_parameters(bag_strides, settings, "exact")
    errors = {name: 100.0 * (getattr(fit.params, name) / getattr(TRUTH, name) - 1.0) for name in settings.fitted}
    assert abs(errors["stiffness"]) < 3.0 and abs(errors["damping"]) < 3.0 and abs(errors["gravity"]) < 3.0, errors
    assert fit.params.body_mass == settings.initial.body_mass          # held at its weighed value
    # the search started far away (g_0, k 3000 N/m, d 5 N s/m) and reached the noise floor
    assert fit.cost < 0.25 and fit.exact_strides >= 2 * len(bag_strides)
    assert fit.cost <= stride_errors(TRUTH, bag_strides, "exact").cost() + 1e-9


def test_aas_cross_validation_gives_tables_4_1_and_4_2_and_shows_its_bias(bag_strides):
    from hopper_ros.identification.crossval import cross_validate, format_error_table, format_parameter_table

    settings = load_settings().with_changes(folds=3)
    cv = cross_validate(bag_strides, settings, "aas", show_progress=False)
    assert len(cv.folds) == 3
    tested = np.sort(np.concatenate([f.test for f in cv.folds]))
    assert np.array_equal(tested, np.arange(len(bag_strides)))       # every stride held out exactly once
    table = cv.parameter_table()
    assert table["body_mass"] == (settings.initial.body_mass, 0.0)
    errors = cv.error_table()
    for part in ("test", "train"):
        for name in ("E_p", "E_v", "E_t"):
            mean, std = errors[part][name]
            assert 0.0 < mean < 10.0 and std >= 0.0
    # held-out strides predict worse than the ones fitted, and the AAS far worse than the noise floor
    assert errors["test"]["E_v"][0] >= 0.9 * errors["train"]["E_v"][0]
    assert cv.test_errors().cost() > 3 * stride_errors(TRUTH, bag_strides, "exact").cost()
    # the AAS's approximation bends the dissipation parameters far from the truth
    assert abs(table["damping"][0] / TRUTH.damping - 1.0) > 0.2
    text = format_parameter_table(cv, TRUTH) + format_error_table(cv)
    assert "| k | Spring constant |" in text and "| E_v [%] |" in text and "held" in text


def test_mass_is_identified_only_through_the_torque():
    from hopper_ros.identification.identifiability import analyse, scale_invariance
    from hopper_ros.identification.strides import Strides
    from hopper_ros.physics.evaluation import sample_thesis_strides, successful
    from hopper_ros.physics.predictors import predict_stride

    drawn = sample_thesis_strides(TRUTH, 80, seed=2)
    for torque in (True, False):
        tau_0 = drawn.tau_0 if torque else np.zeros(len(drawn))
        outcome = predict_stride(TRUTH, drawn.apex_height, drawn.forward_speed, drawn.touchdown_angle, tau_0,
                                 drawn.ramp_duration, method="corrected")
        keep = successful(outcome)
        rng = np.random.default_rng(1)
        noisy = lambda values: values[keep] * (1.0 + 1e-4 * rng.standard_normal(keep.sum()))  # noqa: E731
        n = int(keep.sum())
        strides = Strides(drawn.apex_height[keep], drawn.forward_speed[keep], drawn.touchdown_angle[keep], tau_0[keep],
                          drawn.ramp_duration[keep], noisy(outcome.next_apex_height), noisy(outcome.next_forward_speed),
                          noisy(outcome.stride_length), noisy(outcome.stride_time), *(np.zeros(n) for _ in range(6)),
                          np.zeros(n, dtype=int), np.zeros(n, dtype=int))
        analysis = analyse(TRUTH, strides, FITTABLE, "corrected")
        without, with_torque = scale_invariance(TRUTH, strides)
        held_mass = analyse(TRUTH, strides, [n for n in FITTABLE if n != "body_mass"], "corrected")
        if torque:
            assert analysis.verdict("body_mass") == "identifiable" and with_torque > 0.01
        else:
            # only the ratios k/m_b, d/m_b, m_t/m_b are seen: the four scale together unnoticed
            assert without < 1e-9
            for name in ("body_mass", "stiffness", "damping", "toe_mass"):
                assert analysis.verdict(name) == "not identifiable", name
            assert all(f"ln {s}" in analysis.weakest_combination() for s in ("m_b", "k", "d", "m_t"))
        # with m_b weighed (held), k and d are identifiable again, with or without torque
        assert held_mass.verdict("stiffness") == held_mass.verdict("damping") == "identifiable"
        assert analysis.verdict("gravity") == "identifiable"


def test_bad_recordings_are_refused_with_the_line_and_column(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("t,y,z,theta\n0,0,0.3,0.1\n")
    with pytest.raises(RecordingError, match=r"lacks column\(s\) \['tau'\]"):
        load_csv(path)
    path.write_text("t,y,z,theta,tau\n0,0,0.3,0.1,0\n0.001,0,zero,0.1,0\n")
    with pytest.raises(RecordingError, match=r"bad.csv:3: expected numbers"):
        load_csv(path)
    path.write_text("t,y,z,theta,tau\n0,0,0.3,0.1,0\n0,0,0.3,0.1,0\n")
    with pytest.raises(RecordingError, match="time does not increase at sample 1"):
        load_csv(path)
    path.write_text("t,y,z,theta,tau,phase\n0,0,0.3,0.1,0,descent\n0.001,0,0.3,0.1,0,flying\n")
    with pytest.raises(RecordingError, match="phase 'flying'"):
        load_csv(path)
    path.write_text("t,y,z,theta,tau\n" + "".join(f"{k * 1e-3},0,0.3,0.1,0\n" for k in range(50)))
    from hopper_ros.identification.pipeline import identify

    with pytest.raises(RecordingError, match="0 usable stride"):
        identify(path, load_settings(), ("aas",), show_progress=False)


def test_identify_and_report_commands(noisy_collection, hopper_cli, tmp_path):
    _, bag, csv_path = noisy_collection
    run = hopper_cli("identify", str(csv_path), "-p", "aas", "--folds", "3", "--max-strides", "30",
                     "-o", str(tmp_path / "identified"))
    assert run.wait(120) == 0, run.stderr
    assert "30 strides from" in run.stdout and "phases detected" in run.stdout
    assert "| g | Corrected gravity |" in run.stdout and "| E_p [%] |" in run.stdout
    assert "aas 3-fold CV [" in run.stderr                          # the progress bar
    from hopper_ros.physics.params import load_params

    identified = load_params(tmp_path / "identified" / "identified_model.yaml")
    assert identified.body_mass == 2.2 and identified.gravity != 9.81
    report = hopper_cli("report", str(tmp_path / "report"), "--recording", str(bag), "--predictors", "aas",
                        "--folds", "2", "--no-progress")
    assert report.wait(180) == 0, report.stderr
    text = (tmp_path / "report" / "report.md").read_text()
    for section in ("Table 4.1", "Table 4.2", "What the strides can identify", "Ground reaction forces",
                    "identification_stride.png", "grf_footfalls.png"):
        assert section in text
    for png in ("identification_stride.png", "identification_errors.png", "grf_footfalls.png"):
        assert (tmp_path / "report" / png).stat().st_size > 10_000
    refused = hopper_cli("identify", str(tmp_path / "missing.csv"))
    assert refused.wait() == 3 and "no such file" in refused.stderr


@pytest.mark.parametrize("late", [0.0, 0.0006, 0.0013, 0.0021, 0.0047])
def test_a_stance_torque_that_starts_after_the_measured_touchdown_is_read_from_its_own_start(late):
    """The ramp -tau_0 (1 - t/t_f) (2.32) logged from where the leg met the ground, `late` after the touchdown the
    recording's leg length gives (a height read 1.7 % low puts it about 2 ms before): (tau_0, t_f) as the leg met
    them. Read from the measured touchdown, a torque still zero 2 ms after it was no ramp at all, and one starting
    within 2 ms a ramp extrapolated back to the touchdown (up to 3 % more impulse: plant B's height scale of
    -1.7 % was then not found)."""
    tau_0, t_f, stance = 6.3, 0.062, 0.072
    since = np.arange(0.0, stance, 1e-3) + 0.0004          # samples from just after the measured touchdown
    on = since >= late
    tau = np.where(on & (since - late < t_f), -tau_0 * (1.0 - (since - late) / t_f), 0.0)
    found_tau, found_t_f = ramp_from_torque(since, tau, stance, ExtractionSettings())
    assert found_tau == pytest.approx(tau_0, rel=0.01) and found_t_f == pytest.approx(t_f, abs=6e-4), \
        (found_tau, found_t_f)


def test_a_stance_torque_that_starts_long_after_touchdown_is_no_ramp():
    """A torque that first appears later than `late_torque` into the stance is not (2.32)'s ramp begun late."""
    since = np.arange(0.0, 0.072, 1e-3)
    tau = np.where(since >= 0.03, -3.0, 0.0)
    assert ramp_from_torque(since, tau, 0.072, ExtractionSettings())[0] == 0.0
