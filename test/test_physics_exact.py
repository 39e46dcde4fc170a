"""Exact hybrid model: conservation, events on their guards, (2.12), conventions."""

import math

import numpy as np
import pytest

from hopper_ros.physics.exact import Failure, Phase, simulate_stride
from hopper_ros.physics.params import ModelParams

PARAMS = ModelParams()
STRIDE = dict(apex_height=0.35, forward_speed=2.0, touchdown_angle=math.radians(20.0), tau_0=5.0, ramp_duration=0.065)


def test_energy_is_conserved_without_losses_or_torque():
    lossless = PARAMS.replace(damping=0.0, flight_damping_horizontal=0.0, flight_damping_vertical=0.0, toe_mass=0.0)
    stride = simulate_stride(lossless, 0.35, 2.0, math.radians(20.0), 0.0, 0.065, sample_period=2e-4)
    assert stride.ok
    tr = stride.trajectory
    m, g, k, rho_0 = lossless.body_mass, lossless.gravity, lossless.stiffness, lossless.rest_length
    energy = m * (0.5 * (tr.ydot ** 2 + tr.zdot ** 2) + g * tr.z) + 0.5 * k * (tr.rho - rho_0) ** 2
    start = energy[0]
    assert np.max(np.abs(energy - start)) / start < 1e-6
    after = m * (0.5 * stride.next_apex.ydot ** 2 + g * stride.next_apex.z)
    assert abs(after - start) / start < 1e-6
    assert {Phase.DESCENT, Phase.COMPRESSION, Phase.DECOMPRESSION, Phase.ASCENT} == set(np.unique(tr.phase))


def test_liftoff_collision_conserves_momentum():
    stride = simulate_stride(PARAMS, **STRIDE)
    before, after = stride.liftoff, stride.liftoff_after_collision
    m_b, m_t = PARAMS.body_mass, PARAMS.toe_mass
    # body before, toe at rest on the ground; both together after (2.10), (2.12)
    assert m_b * before.ydot == pytest.approx((m_b + m_t) * after.ydot, rel=1e-14)
    assert m_b * before.zdot == pytest.approx((m_b + m_t) * after.zdot, rel=1e-14)
    assert after.zdot < before.zdot  # it is a loss, not the kinetic-energy conservation (2.11) states


def test_events_lie_on_their_guards():
    stride = simulate_stride(PARAMS, **STRIDE)
    assert stride.ok and stride.liftoff_reason == "leg_force"
    td, bottom, lo, nxt = stride.touchdown, stride.bottom, stride.liftoff, stride.next_apex
    rho_0, k, d = PARAMS.rest_length, PARAMS.stiffness, PARAMS.damping
    assert td.z - rho_0 * math.cos(td.theta) == pytest.approx(0.0, abs=1e-12)         # toe on the ground
    assert bottom.zdot == pytest.approx(0.0, abs=1e-9)                                 # lowest point
    assert k * (rho_0 - lo.rho) - d * lo.rho_dot == pytest.approx(0.0, abs=1e-7)       # (2.28), force [N]
    assert nxt.zdot == 0.0 and nxt.z > td.z
    assert td.t < bottom.t < lo.t < nxt.t


def test_forward_running_conventions_and_mirror_symmetry():
    stride = simulate_stride(PARAMS, **STRIDE)
    assert stride.touchdown.theta > 0.0 > stride.liftoff.theta       # toe ahead at touchdown, behind at lift-off
    assert stride.touchdown.theta_dot < 0.0                            # leg sweeps back in stance
    assert stride.stride_length > 0.0 and stride.next_forward_speed > 0.0
    tr = simulate_stride(PARAMS, **STRIDE, sample_period=1e-3).trajectory
    assert np.all(tr.torque[tr.phase == Phase.COMPRESSION] <= 0.0)   # thrust: -tau_0 ramp pushes forward
    mirrored = simulate_stride(PARAMS, 0.35, -2.0, -STRIDE["touchdown_angle"], -5.0, 0.065)
    assert mirrored.next_apex_height == pytest.approx(stride.next_apex_height, rel=1e-9)
    assert mirrored.next_forward_speed == pytest.approx(-stride.next_forward_speed, rel=1e-9)


def test_thrust_adds_energy():
    passive = simulate_stride(PARAMS, **{**STRIDE, "tau_0": 0.0})
    pushed = simulate_stride(PARAMS, **STRIDE)
    energy = lambda s: s.next_apex.ydot ** 2 / 2 + PARAMS.gravity * s.next_apex.z
    assert energy(pushed) > energy(passive) + 0.3


@pytest.mark.parametrize("inputs, failure", [
    (dict(apex_height=0.15), Failure.APEX_BELOW_TOUCHDOWN),
    (dict(touchdown_angle=math.radians(85.0)), Failure.ANGLE_OUT_OF_RANGE),
    (dict(apex_height=0.4, forward_speed=0.0, touchdown_angle=math.radians(60.0)), Failure.TIPPED_OVER),
])
def test_failures_are_named(inputs, failure):
    stride = simulate_stride(PARAMS, **{**STRIDE, **inputs})
    assert not stride.ok and stride.failure_code == failure and stride.failure
