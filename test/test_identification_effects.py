"""Identification with library effects (`hopper identify --effects`, issue 14): the model's parameters and an
effect's magnitude fitted together by the "lanes" predictor (the laws with the effects, `physics.lanes`), and the
identified model file carrying the effects (`physics.params.load_model`)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from hopper_ros.config.schemas import check_effects
from hopper_ros.identification.crossval import cross_validate
from hopper_ros.identification.lanesfit import cost_gradient, cost_of_residuals, with_effects
from hopper_ros.identification.settings import load_settings
from hopper_ros.identification.strides import Strides
from hopper_ros.physics import lanes
from hopper_ros.physics.params import ModelParams, load_model, load_params, save_params

TRUTH = ModelParams()        # Table 4.1


def lane_strides(count: int, magnitudes: dict, seed: int = 0, noise: float = 1e-4) -> Strides:
    """`count` strides of the true model with `magnitudes` on, by physics.lanes itself, from the thesis's ranges
    (apex 0.3-0.45 m, 1-2.5 m/s, tau_0 -3..6 N m, t_f 0.07 s, theta_td a few degrees about the neutral angle),
    the measured apexes with `noise` [m] (heights, stride lengths) and relative `noise` (speeds)."""
    rng = np.random.default_rng(seed)
    drawn = 2 * count
    height = rng.uniform(0.30, 0.45, drawn)
    speed = rng.uniform(1.0, 2.5, drawn)
    tau_0 = rng.uniform(-3.0, 6.0, drawn)
    angle = np.radians(2.0 + 11.0 * speed + 0.7 * tau_0 + rng.uniform(-6.0, 1.0, drawn))   # ~ neutral - 0..6 deg
    ramp = np.full(drawn, 0.07)
    lane = lanes.simulate_lanes(with_effects(TRUTH, magnitudes), height, speed, angle, tau_0, ramp, duration=1.0)
    good = np.flatnonzero(np.isfinite(lane.next_apex_height) & (lane.next_apex_height > 0.25)
                          & (lane.next_forward_speed > 0.3))[:count]
    assert len(good) == count
    n = len(good)

    def measured(values, relative=False):
        values = np.asarray(values[good], dtype=float)
        return values * (1.0 + rng.normal(0.0, noise, n)) if relative else values + rng.normal(0.0, noise, n)

    zeros = np.zeros(n)
    stride_time = lane.stride_time[good].astype(float)
    return Strides(measured(height), measured(speed, relative=True), angle[good], tau_0[good], ramp[good],
                   measured(lane.next_apex_height), measured(lane.next_forward_speed, relative=True),
                   measured(lane.stride_length), stride_time, zeros, zeros, zeros, zeros, zeros, stride_time,
                   np.zeros(n, dtype=int), np.zeros(n, dtype=int))


def test_an_effect_is_identified_with_the_model_and_predicts_held_out_strides_better():
    strides = lane_strides(60, {"torque_gain": 0.7})
    settings = load_settings().with_changes(folds=3, predictor="lanes")
    with_effect = cross_validate(strides, settings.with_changes(effects=("torque_gain",)), "lanes", show_progress=False)
    without = cross_validate(strides, settings, "lanes", show_progress=False)
    assert with_effect.effects == ("torque_gain",) and without.effects == ()
    gain, spread = with_effect.effect_table()["torque_gain"]
    assert gain == pytest.approx(0.7, rel=0.2)
    assert gain == pytest.approx(0.7, rel=0.02)          # measured: 0.6995 +- 0.0005
    fitted = with_effect.mean_params()
    assert fitted.stiffness == pytest.approx(TRUTH.stiffness, rel=0.01)
    assert fitted.gravity == pytest.approx(TRUTH.gravity, rel=0.005)
    assert fitted.damping == pytest.approx(TRUTH.damping, rel=0.1)
    held_out = with_effect.error_table()["test"]
    held_out_without = without.error_table()["test"]
    assert held_out["E_p"][0] < 0.1 < held_out_without["E_p"][0]          # measured: 0.034 % against 3.2 %
    assert held_out["E_v"][0] < held_out_without["E_v"][0]
    # without the effect the fit bends the model's parameters to make up for the weak hip
    assert abs(without.mean_params().stiffness / TRUTH.stiffness - 1) > 3 * abs(fitted.stiffness / TRUTH.stiffness - 1)
    assert with_effect.mean_effects() == {"torque_gain": gain}


def test_the_fit_uses_one_lanes_call_per_cost_evaluation_and_its_cost_is_4_4():
    from hopper_ros.identification.lanesfit import LanesProblem, LanesVector

    strides = lane_strides(12, {"leg_friction": 3.0}, seed=1)
    settings = load_settings().with_changes(effects=("leg_friction",))
    vector = LanesVector(settings.fitted, settings.effects, settings.initial, settings.bounds, settings.initial)
    problem = LanesProblem(strides, vector, settings)
    x = vector.x0({"leg_friction": 3.0})
    r, jacobian = problem.residuals_and_jacobian(x)
    assert problem.calls == 1 and problem.lanes_simulated == (len(vector) + 1) * len(strides)
    assert jacobian.shape == (len(strides), 4, len(vector))
    problem.residuals_and_jacobian(x)
    assert problem.calls == 1                       # cached: scipy asks for the residuals and then the Jacobian
    assert vector.effects_of(x)["leg_friction"] == pytest.approx(3.0)
    from hopper_ros.identification.cost import errors_of
    from hopper_ros.identification.lanesfit import lanes_outcomes

    params = vector.params_of(x)
    assert cost_of_residuals(r) == pytest.approx(
        errors_of(strides, lanes_outcomes(params, {"leg_friction": 3.0}, strides), 100.0).cost(), rel=1e-9)
    # the gradient of C (4.4) by the chain rule through the residuals' Jacobian
    _, gradient = cost_gradient(r, jacobian)
    step = 1e-6
    direction = np.zeros(len(vector))
    direction[1] = 1.0
    ahead = cost_of_residuals(r + step * jacobian @ direction)
    assert gradient[1] == pytest.approx((ahead - cost_of_residuals(r)) / step, rel=1e-3)


def test_effects_are_checked_against_the_library_and_the_fitted_parameters():
    fitted = load_settings().fitted
    assert check_effects(("leg_friction", "torque_gain"), fitted) == ("leg_friction", "torque_gain")
    with pytest.raises(ValueError, match="unknown effect 'leg_fiction'"):
        check_effects(("leg_fiction",), fitted)
    with pytest.raises(ValueError, match="sensor fault"):
        check_effects(("z_delay",), fitted)
    with pytest.raises(ValueError, match="leg_stiffness sets stiffness.*model parameter stiffness"):
        check_effects(("leg_stiffness",), fitted)
    with pytest.raises(ValueError, match="liftoff_collision sets toe_mass"):
        check_effects(("liftoff_collision",), fitted)
    check_effects(("leg_stiffness",), tuple(n for n in fitted if n != "stiffness"))     # fitted as the effect
    with pytest.raises(ValueError, match="named twice"):
        check_effects(("leg_friction", "leg_friction"), fitted)
    with pytest.raises(ValueError, match="unknown effect"):
        load_settings().with_changes(effects=("nonsense",))


def test_model_file_with_effects_round_trips_and_bad_entries_name_the_file_and_key(tmp_path):
    params = TRUTH.replace(stiffness=5100.0)
    path = save_params(params, tmp_path / "identified.yaml", comment="with effects",
                       effects={"leg_friction": 2.5, "torque_saturation": math.inf})
    data = yaml.safe_load(path.read_text())
    assert set(data) == {"model", "effects"} and data["effects"]["leg_friction"] == 2.5
    assert load_model(path) == (params, {"leg_friction": 2.5, "torque_saturation": math.inf})
    assert load_params(path) == params                       # the controller's loader: the model alone
    plain = save_params(params, tmp_path / "plain.yaml")
    assert "effects" not in plain.read_text() and load_model(plain) == (params, {})
    assert load_model("model.yaml") == (load_params(), {})   # config/model.yaml
    cases = {
        "unknown_effect.yaml": ({"model": TRUTH.as_dict(), "effects": {"leg_fiction": 1.0}},
                                "effects.leg_fiction: unknown effect"),
        "text.yaml": ({"model": TRUTH.as_dict(), "effects": {"leg_friction": "strong"}},
                      r"effects.leg_friction must be a number \(F_c \[N\]\)"),
        "infinite.yaml": ({"model": TRUTH.as_dict(), "effects": {"leg_friction": math.inf}},
                          "effects.leg_friction must be finite"),
        "list.yaml": ({"model": TRUTH.as_dict(), "effects": ["leg_friction"]}, "effects must be a mapping"),
        "bare.yaml": ({**TRUTH.as_dict(), "effects": {"leg_friction": 1.0}}, "under `model:`"),
        "extra.yaml": ({"model": TRUTH.as_dict(), "effect": {"leg_friction": 1.0}}, r"unknown top-level key\(s\) \['effect'\]"),
        "bad_model.yaml": ({"model": {**TRUTH.as_dict(), "stiffness": -1.0}, "effects": {}},
                           "model: stiffness must be positive"),
    }
    for name, (data, words) in cases.items():
        bad = tmp_path / name
        bad.write_text(yaml.safe_dump(data))
        with pytest.raises(ValueError, match=words) as info:
            load_model(bad)
        assert name in str(info.value)


def exact_run(strides: int, seed: int = 3):
    """Back-to-back strides of the exact model at 1 kHz, as a CSV-like recording (t, y, z, theta, tau)."""
    from hopper_ros.recording.recordings import Recording
    from hopper_ros.physics.aas import predict_aas
    from hopper_ros.physics.exact import simulate_stride

    rng = np.random.default_rng(seed)
    columns = [[], [], [], [], []]
    height, speed, y0, t0 = 0.36, 1.8, 0.0, 0.0
    for _ in range(strides):
        tau_0 = float(rng.uniform(1.0, 6.0))
        angle = math.radians(2.0 + 11.0 * speed + 0.7 * tau_0 + rng.uniform(-3.0, 1.0))
        ramp = float(predict_aas(TRUTH, height, speed, angle, tau_0).stance_time)
        stride = simulate_stride(TRUTH, height, speed, angle, tau_0, ramp, y0=y0, t0=t0, sample_period=1e-3)
        assert stride.ok, stride.failure
        trajectory = stride.trajectory
        keep = trajectory.t < stride.next_apex.t - 1e-9
        for column, values in zip(columns, (trajectory.t, trajectory.y, trajectory.z, trajectory.theta,
                                            trajectory.torque)):
            column.extend(values[keep])
        height, speed, y0, t0 = stride.next_apex.z, stride.next_apex.ydot, stride.next_apex.y, stride.next_apex.t
    return Recording(*(np.asarray(c) for c in columns), source="exact run")


def test_identify_with_effects_writes_a_model_file_load_model_reads(hopper_cli, tmp_path):
    from hopper_ros.recording.recordings import write_csv

    csv_path = write_csv(tmp_path / "run.csv", exact_run(12))
    out = tmp_path / "identified"
    run = hopper_cli("identify", str(csv_path), "--effects", "leg_friction", "--folds", "2", "-o", str(out),
                     "--no-progress")
    assert run.wait(150) == 0, run.stderr
    assert "## lanes: Table 4.1" in run.stdout and "| F_c | effect leg_friction:" in run.stdout
    params, effects = load_model(out / "identified_model.yaml")
    assert set(effects) == {"leg_friction"}
    assert 0.0 <= effects["leg_friction"] < 1.0            # the exact model has no leg friction
    assert params.stiffness == pytest.approx(TRUTH.stiffness, rel=0.05)
    assert load_params(out / "identified_model.yaml") == params
    assert "laws with effects (lanes)" in (out / "report.md").read_text()
    refused = hopper_cli("identify", str(csv_path), "--effects", "leg_stiffness")
    assert refused.wait(60) == 3 and "leg_stiffness sets stiffness" in refused.stderr
