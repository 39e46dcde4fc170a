"""AAS closed forms (2.17)-(2.37) against numerical integration of the equations they solve."""

import math

import numpy as np
import pytest
from scipy.integrate import dblquad, quad, solve_ivp

from hopper_ros.physics._backend import ARRAY, SCALAR
from hopper_ros.physics.aas import StanceSolution, full_ramp_impulse, mean_ramp_impulse, predict_aas
from hopper_ros.physics.exact import Failure
from hopper_ros.physics.params import ModelParams

PARAMS = ModelParams()


@pytest.mark.parametrize("momentum, rho_dot_td", [(-0.55, -2.4), (-0.9, -1.5), (0.3, -2.0), (-1.3, -3.0)])
def test_stance_closed_forms_solve_the_approximate_dynamics(momentum, rho_dot_td):
    """(2.17)-(2.20) equal the integrated linearised radial oscillator and theta' = w (3 - 2 rho/rho_0)."""
    m, k, d, g, rho_0 = PARAMS.body_mass, PARAMS.stiffness, PARAMS.damping, PARAMS.gravity, PARAMS.rest_length
    theta_td = 0.3
    stance = StanceSolution(SCALAR, PARAMS, momentum, rho_dot_td, theta_td)
    omega = momentum / (m * rho_0 ** 2)
    w0_sq = k / m + 3 * omega ** 2                       # Table 2.2, corrected
    forcing = -g + rho_0 * k / m + 4 * rho_0 * omega ** 2

    def rhs(t, s):
        rho, rho_dot, theta = s
        return [rho_dot, forcing - w0_sq * rho - d / m * rho_dot, omega * (3.0 - 2.0 * rho / rho_0)]

    times = np.linspace(0.0, 0.09, 31)
    sol = solve_ivp(rhs, (0.0, 0.09), [rho_0, rho_dot_td, theta_td], t_eval=times, rtol=1e-12, atol=1e-14)
    closed = np.array([[stance.leg_length(t), stance.leg_rate(t), stance.leg_angle(t)] for t in times]).T
    assert np.max(np.abs(closed - sol.y)) < 1e-10
    rates = np.array([stance.leg_angle_rate(t) for t in times])
    assert np.max(np.abs(rates - omega * (3.0 - 2.0 * sol.y[0] / rho_0))) < 1e-9


def test_liftoff_closed_form_and_root_of_2_28():
    stance = StanceSolution(SCALAR, PARAMS, -0.55, -2.4, 0.3)
    closed = stance.liftoff_time()              # (2.29): one step from 2 t_b
    root = stance.liftoff_time(None, 8)
    k, d, rho_0 = PARAMS.stiffness, PARAMS.damping, PARAMS.rest_length
    force = lambda t: k * (rho_0 - stance.leg_length(t)) - d * stance.leg_rate(t)
    assert force(root) == pytest.approx(0.0, abs=1e-9)
    assert stance.leg_force(root) == pytest.approx(force(root), abs=1e-9)   # (2.30)-(2.31)
    assert force(root - 1e-3) > 0.0 > force(root + 1e-3)                   # a decreasing zero: lift-off
    assert stance.bottom_time() < root
    assert abs(closed - root) / root < 1e-4


@pytest.mark.parametrize("t_lo, t_f", [(0.06, 0.06), (0.06, 0.08), (0.07, 0.05)])
def test_torque_correction_is_the_mean_accumulated_impulse(t_lo, t_f):
    """(2.35)-(2.36): mean over stance of int_0^t tau; t_lo/3 when the ramp ends at lift-off."""
    ramp = lambda s: max(0.0, 1.0 - s / t_f)
    nested = dblquad(lambda s, t: ramp(s), 0.0, t_lo, 0.0, lambda t: t, epsabs=1e-13)[0] / t_lo
    assert mean_ramp_impulse(SCALAR, t_lo, t_f) == pytest.approx(nested, rel=1e-8)
    assert full_ramp_impulse(SCALAR, t_lo, t_f) == pytest.approx(quad(ramp, 0.0, t_lo, points=[t_f])[0], rel=1e-10)
    if t_lo == t_f:
        assert mean_ramp_impulse(SCALAR, t_lo, t_f) == pytest.approx(t_lo / 3.0)


def test_gravity_correction_is_the_mean_accumulated_impulse():
    """(2.37) with r_lo = rho_lo: exact when rho sin(theta) runs linearly over stance."""
    m, g, rho_0 = PARAMS.body_mass, PARAMS.gravity, PARAMS.rest_length
    t_lo, theta_td, theta_lo, rho_lo = 0.065, 0.35, -0.3, 0.198
    start, end = rho_0 * math.sin(theta_td), rho_lo * math.sin(theta_lo)
    arm = lambda t: start + (end - start) * t / t_lo
    nested = m * g * dblquad(lambda s, t: arm(s), 0.0, t_lo, 0.0, lambda t: t, epsabs=1e-14)[0] / t_lo
    assert m * g * t_lo / 6.0 * (2.0 * start + end) == pytest.approx(nested, rel=1e-10)


def test_scalar_and_array_paths_agree():
    rng = np.random.default_rng(4)
    h, v = rng.uniform(0.26, 0.43, 40), rng.uniform(0.86, 2.49, 40)
    theta, tau = np.radians(rng.uniform(10, 45, 40)), rng.uniform(3, 8, 40)
    batch = predict_aas(PARAMS, h, v, theta, tau)
    assert batch.stance.xp is ARRAY
    for i in range(40):
        one = predict_aas(PARAMS, float(h[i]), float(v[i]), float(theta[i]), float(tau[i]))
        assert one.failure_code == batch.failure_code[i]
        if one.ok:
            assert one.next_apex_height == pytest.approx(batch.next_apex_height[i], rel=1e-12)
            assert one.next_forward_speed == pytest.approx(batch.next_forward_speed[i], rel=1e-12)
            assert one.stride_time == pytest.approx(batch.stride_time[i], rel=1e-12)


def test_return_map_is_consistent_and_names_failures():
    p = predict_aas(PARAMS, np.array([0.35, 0.15]), 2.0, math.radians(20), 5.0)
    assert p.ok.tolist() == [True, False]
    assert p.failure_code[1] == Failure.APEX_BELOW_TOUCHDOWN and "touchdown height" in p.failure[1]
    one = predict_aas(PARAMS, 0.35, 2.0, math.radians(20), 5.0)
    assert one.stride_time == pytest.approx(one.descent_time + one.stance_time + one.ascent_time)
    assert one.liftoff_theta < 0.0 < one.stride_length
    # the ramp ends at the predicted lift-off by default (section 4.1)
    assert one.stance_time == one.ramp_duration
    with pytest.raises(ValueError, match="liftoff"):
        predict_aas(PARAMS, 0.35, 2.0, 0.3, 5.0, liftoff="guess")
