"""Energy terms (5.1)-(5.5), corrected, against the exact model's bookkeeping."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from hopper_ros.physics.aas import predict_aas
from hopper_ros.physics.boom import boom_effective_gravity, boom_mass_for_gravity
from hopper_ros.physics.energy import (apex_energy, damping_loss, exact_energy_budget, predicted_energy_budget,
                                       required_torque_work, torque_work)
from hopper_ros.physics.evaluation import sample_thesis_strides
from hopper_ros.physics.exact import simulate_stride
from hopper_ros.physics.params import ModelParams
from hopper_ros.physics.predictors import predict_stride

PARAMS = ModelParams()


@pytest.fixture(scope="module")
def strides():
    s = sample_thesis_strides(PARAMS, 30, seed=5)
    out = []
    for i in range(len(s)):
        args = tuple(float(getattr(s, f)[i]) for f in ("apex_height", "forward_speed", "touchdown_angle", "tau_0", "ramp_duration"))
        result = simulate_stride(PARAMS, *args, sample_period=1e-3)
        if result.ok:
            out.append((args, result))
    assert len(out) >= 20
    return out


def test_exact_bookkeeping_closes(strides):
    for (h, v, theta, tau, ramp), result in strides:
        budget = exact_energy_budget(PARAMS, result, tau, ramp)
        assert abs(budget.residual) < 1e-6 * budget.apex_energy
        # (5.1) with the exact losses asks for exactly the work the torque did
        need = required_torque_work(PARAMS, h, v, result.next_apex_height, result.next_forward_speed, budget.losses)
        assert need == pytest.approx(budget.torque_work, abs=1e-6 * budget.apex_energy)


def test_closed_forms_5_3_and_5_5_equal_quadrature_of_the_aas():
    p = predict_aas(PARAMS, 0.35, 2.0, math.radians(20), 5.0, 0.07)
    stance, t_lo, tau = p.stance, p.stance_time, 5.0
    quad_loss = quad(lambda t: PARAMS.damping * stance.leg_rate(t) ** 2, 0.0, t_lo, epsabs=1e-14)[0]
    quad_work = quad(lambda t: -tau * max(0.0, 1.0 - t / 0.07) * stance.leg_angle_rate(t), 0.0, t_lo, epsabs=1e-14)[0]
    assert damping_loss(PARAMS, stance, t_lo) == pytest.approx(quad_loss, rel=1e-10)
    assert float(torque_work(stance, tau, t_lo, 0.07)) == pytest.approx(quad_work, rel=1e-10)
    assert quad_work > 0.0                      # the thrust ramp injects energy running forward


def test_predicted_terms_track_the_exact_ones(strides):
    errors = {"aas": [], "corrected": []}
    for (h, v, theta, tau, ramp), result in strides:
        exact = exact_energy_budget(PARAMS, result, tau, ramp)
        for method in errors:
            pred = predicted_energy_budget(PARAMS, predict_stride(PARAMS, h, v, theta, tau, ramp, method=method), tau, h, v)
            errors[method].append([(pred.damping_loss - exact.damping_loss) / exact.damping_loss,
                                   (pred.torque_work - exact.torque_work) / exact.apex_energy])
    aas, corrected = np.abs(errors["aas"]).mean(axis=0), np.abs(errors["corrected"]).mean(axis=0)
    assert aas[0] < 0.05 and aas[1] < 0.02              # the thesis's closed forms, corrected
    assert corrected[0] < 0.005 and corrected[1] < 1e-3  # on the corrected stance
    assert np.all(corrected < aas)


def test_apex_energy_and_boom_gravity():
    assert apex_energy(PARAMS, 0.35, 2.0) == pytest.approx(2.2 * (2.0 + 11.42 * 0.35))
    assert boom_effective_gravity(2.22, 0.39) == pytest.approx(10.08, abs=0.01)    # not the 11.41 of (4.7)'s text
    assert boom_effective_gravity(2.22, boom_mass_for_gravity(2.22, 11.41)) == pytest.approx(11.41)
    with pytest.raises(ValueError):
        boom_mass_for_gravity(2.22, 20.0)
